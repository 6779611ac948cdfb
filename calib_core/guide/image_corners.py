"""Corners of the camera image: the structure tensor, an isolated-corner test, sub-pixel refinement.

The structure tensor ``M = sum_w [gx^2, gx gy; gx gy, gy^2]`` over a small
window of the grey image (0..1) has two large eigenvalues at a corner, one at
an edge and none on a flat patch.  A *clean isolated corner* is one whose
smaller eigenvalue is strong, whose eigenvalues are similar (an L or X
corner, not a wedge or a textured blob), and that is the only such peak
nearby, so a sub-pixel refinement (``cv2.cornerSubPix``) cannot slide to a
neighbouring corner or along a double edge.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

__all__ = ["CornerImage", "corner_image", "content_mask", "strongest_near", "clean_corner", "refine_subpixel", "CornerGate"]


class CornerImage(NamedTuple):
    """Grey image and its per-pixel structure-tensor eigenvalues.

    Attributes
    ----------
    gray : (H, W) float32
        Grey levels 0..1.
    lam_min, lam_max : (H, W) float32
        Eigenvalues of the structure tensor over a ``window`` box (gradients
        in grey levels per pixel).
    window : int
    """

    gray: np.ndarray
    lam_min: np.ndarray
    lam_max: np.ndarray
    window: int


class CornerGate(NamedTuple):
    """Thresholds of :func:`clean_corner`.

    Attributes
    ----------
    min_strength : float
        Minimum smaller eigenvalue at the corner (grey levels^2).
    min_ratio : float
        Minimum ``lam_min / lam_max`` at the corner.
    isolation : float
        No other peak within ``isolation_radius_px`` may exceed this fraction of the corner's ``lam_min``.
    isolation_radius_px : float
    """

    min_strength: float = 0.01
    min_ratio: float = 0.3
    isolation: float = 0.3
    isolation_radius_px: float = 6.0


def content_mask(gray_u8: np.ndarray, margin_px: int = 6) -> np.ndarray:
    """Pixels of the picture proper: not in a black region touching the image border
    (the outside of a fisheye's image circle), and at least ``margin_px`` from it."""
    dark = (gray_u8 <= 2).astype(np.uint8)
    n, labels = cv2.connectedComponents(dark, connectivity=8)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    outside = np.isin(labels, border[border > 0]) & (dark > 0)
    content = (~outside).astype(np.uint8)
    if margin_px > 0:
        content = cv2.erode(content, np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8), borderValue=1)
    return content > 0


def corner_image(image: np.ndarray, window: int = 5) -> CornerImage:
    """Structure tensor eigenvalues of an RGB or grey uint8 image.

    Corners are zeroed outside :func:`content_mask`: the rim of a fisheye's
    image circle is a strong but meaningless corner.
    """
    img = np.asarray(image)
    gray8 = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    gray = gray8.astype(np.float32) / 255.0
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    box = lambda a: cv2.boxFilter(a, -1, (window, window), normalize=False)  # noqa: E731
    a, b, c = box(gx * gx), box(gx * gy), box(gy * gy)
    half, root = 0.5 * (a + c), np.sqrt(np.maximum(0.25 * (a - c) ** 2 + b * b, 0.0))
    inside = content_mask(np.asarray(gray8, dtype=np.uint8))
    return CornerImage(gray, np.where(inside, half - root, 0.0).astype(np.float32), half + root, window)


def _windows(ci: CornerImage, pixels: np.ndarray, radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``lam_min`` in square windows of half-size ``radius`` around pixels: (N, k, k) and the offsets."""
    H, W = ci.lam_min.shape
    px = np.rint(np.asarray(pixels, dtype=np.float64).reshape(-1, 2)).astype(np.int64)
    off = np.arange(-radius, radius + 1)
    rows = px[:, 1, None, None] + off[None, :, None]
    cols = px[:, 0, None, None] + off[None, None, :]
    inside = (rows >= 0) & (rows < H) & (cols >= 0) & (cols < W)
    vals = np.where(inside, ci.lam_min[np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)], 0.0)
    return vals, np.broadcast_to(rows, vals.shape), np.broadcast_to(cols, vals.shape)


def strongest_near(ci: CornerImage, pixels: np.ndarray, radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The strongest corner pixel within ``radius_px`` of each pixel.

    Returns
    -------
    peak_pixels : (N, 2) float64
        ``(u, v)`` of the strongest ``lam_min`` in the disc.
    strength : (N,) float64
        Its ``lam_min`` (0 where the pixel is not finite).
    """
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    finite = np.all(np.isfinite(p), axis=1)
    p = np.where(finite[:, None], p, 0.0)
    r = max(int(np.ceil(radius_px)), 1)
    vals, rows, cols = _windows(ci, p, r)
    off = np.arange(-r, r + 1)
    disc = (off[:, None] ** 2 + off[None, :] ** 2) <= radius_px**2 + 1e-9
    vals = np.where(disc[None], vals, -np.inf).reshape(len(p), -1)
    best = np.argmax(vals, axis=1)
    k = np.arange(len(p))
    peak = np.stack([cols.reshape(len(p), -1)[k, best], rows.reshape(len(p), -1)[k, best]], axis=1).astype(np.float64)
    return peak, np.where(finite, vals[k, best], 0.0)


def clean_corner(ci: CornerImage, peak_pixels: np.ndarray, gate: CornerGate = CornerGate()) -> np.ndarray:
    """True where the corner at each (integer) peak pixel is a clean isolated corner (module docstring)."""
    p = np.asarray(peak_pixels, dtype=np.float64).reshape(-1, 2)
    H, W = ci.lam_min.shape
    u = np.clip(np.rint(p[:, 0]).astype(np.int64), 0, W - 1)
    v = np.clip(np.rint(p[:, 1]).astype(np.int64), 0, H - 1)
    lmin, lmax = ci.lam_min[v, u].astype(np.float64), ci.lam_max[v, u].astype(np.float64)
    ok = (lmin >= gate.min_strength) & (lmin >= gate.min_ratio * np.maximum(lmax, 1e-30))
    # Isolation: other local peaks in the ring between the corner's own
    # footprint (one window) and the isolation radius.
    r = int(np.ceil(gate.isolation_radius_px))
    vals, _, _ = _windows(ci, np.stack([u, v], axis=1), r)
    off = np.arange(-r, r + 1)
    d2 = off[:, None] ** 2 + off[None, :] ** 2
    ring = (d2 > ci.window**2) & (d2 <= gate.isolation_radius_px**2)
    rival = np.where(ring[None], vals, 0.0).reshape(len(p), -1).max(axis=1)
    return ok & (rival <= gate.isolation * lmin)


def refine_subpixel(ci: CornerImage, pixels: np.ndarray, half_window: int = 3) -> np.ndarray:
    """``cv2.cornerSubPix`` from each pixel: (N, 2) ``(u, v)``; NaN where it moved more than ``half_window``."""
    p = np.asarray(pixels, dtype=np.float32).reshape(-1, 1, 2)
    if len(p) == 0:
        return np.empty((0, 2))
    start = p.copy()
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
    out = cv2.cornerSubPix(ci.gray, p, (half_window, half_window), (-1, -1), criteria)
    out = out.reshape(-1, 2).astype(np.float64)
    moved = np.linalg.norm(out - start.reshape(-1, 2), axis=1)
    return np.where((moved <= half_window)[:, None], out, np.nan)
