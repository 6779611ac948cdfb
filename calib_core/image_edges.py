"""The direction of a straight image edge at a clicked pixel (for edge pairs, :attr:`calib_core.pairs.Pair.edge_deg`).

The structure tensor ``J = G_r * [gx^2, gx gy; gx gy, gy^2]`` (Scharr gradients -- OpenCV's Sobel
with its 3x3 Scharr kernel, chosen for its rotational symmetry: the plain 3x3 Sobel read a 30 deg edge
as 28.9 deg -- and a Gaussian window) at the
pixel: its eigenvalues ``l1 >= l2`` give the coherence ``((l1 - l2) / (l1 + l2))^2`` (1 for one straight
edge, near 0 for a corner, a blob or noise) and its main eigenvector the gradient's direction; the edge
runs at right angles to it.  Windows grow (:data:`EDGE_RADII_PX`) until one is coherent, so a click in the
middle of a wide painted line, uniform inside, still finds the line's direction from its two sides.

Angles are degrees from +u (right) towards +v (down), in [0, 180); pixels ``(u, v)``, the top-left
pixel's centre at (0, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import CalibError

__all__ = ["EdgeAt", "edge_at", "EDGE_COHERENCE", "EDGE_RADII_PX", "NOISE_ENERGY_FACTOR"]

#: Window radii tried, px (the Gaussian's sigma is half the radius; the window ends at the radius).
EDGE_RADII_PX = (4, 8, 16, 32)
#: Coherence from which a window holds one straight edge.
EDGE_COHERENCE = 0.75
#: A window's mean squared gradient must exceed this many times the median squared gradient around the
#: pixel (the noise of the image's flat parts) to count: else its direction is the noise's.
NOISE_ENERGY_FACTOR = 4.0
#: Floor of that noise energy (grey levels^2 per px^2): a noise-free flat image has none.
MIN_ENERGY = 1e-6


@dataclass(frozen=True)
class EdgeAt:
    """The straight edge found at a pixel.

    Attributes
    ----------
    angle_deg : float
        Direction of the edge, degrees from +u towards +v, in [0, 180); NaN when no window held gradient
        energy above the noise.
    coherence : float
        ``((l1 - l2) / (l1 + l2))^2`` in [0, 1] of the window used: 1 for one straight edge.
    radius_px : int
        The window used: the smallest coherent one (with energy above noise), else the most coherent.
    """

    angle_deg: float
    coherence: float
    radius_px: int

    @property
    def ok(self) -> bool:
        """The window holds one straight edge (coherence >= :data:`EDGE_COHERENCE`)."""
        return bool(self.coherence >= EDGE_COHERENCE and math.isfinite(self.angle_deg))


def edge_at(gray: np.ndarray, uv, radii=EDGE_RADII_PX) -> EdgeAt:
    """The direction of the straight edge at pixel ``uv`` of ``gray`` (structure tensor, module docstring).

    Parameters
    ----------
    gray : (H, W) array_like
        Grey levels (any scale; uint8 or float).
    uv : (2,) array_like
        The pixel ``(u, v)`` = (column, row), px; sub-pixel values are taken at the nearest pixel.
    radii : sequence of int
        Window radii to try, px, smallest first.

    Returns
    -------
    EdgeAt
        The smallest radius whose coherence reaches :data:`EDGE_COHERENCE` with gradient energy above the
        noise; otherwise the most coherent one with energy above noise (the caller decides: ``.ok``); a
        NaN angle and coherence 0 when none has.

    Raises
    ------
    CalibError
        ``gray`` not a 2-D image, ``uv`` not two finite numbers inside it, or no radius given.
    """
    import cv2

    img = np.asarray(gray)
    if img.ndim != 2 or min(img.shape) < 3:
        raise CalibError(f"edge_at: expected a 2-D grey image of at least 3x3 pixels, got shape {img.shape}")
    p = np.asarray(uv, dtype=np.float64).reshape(-1)
    H, W = img.shape
    if p.shape != (2,) or not np.isfinite(p).all():
        raise CalibError(f"edge_at: expected a pixel (u, v) of two finite numbers, got {uv!r}"[:300])
    if not (-0.5 <= p[0] < W - 0.5 and -0.5 <= p[1] < H - 0.5):
        raise CalibError(f"edge_at: pixel ({p[0]:.1f}, {p[1]:.1f}) is outside the {W}x{H} image")
    radii = sorted(int(r) for r in radii)
    if not radii or radii[0] < 1:
        raise CalibError(f"edge_at: radii must be whole numbers >= 1, got {radii!r}")
    u, v = int(round(p[0])), int(round(p[1]))
    # A crop around the pixel (the largest window, three times over for the noise estimate, plus the Sobel's border).
    half = 3 * radii[-1] + 2
    u0, u1, v0, v1 = max(u - half, 0), min(u + half + 1, W), max(v - half, 0), min(v + half + 1, H)
    crop = np.ascontiguousarray(img[v0:v1, u0:u1], dtype=np.float64)
    gx = cv2.Scharr(crop, cv2.CV_64F, 1, 0, borderType=cv2.BORDER_REPLICATE) / 32.0
    gy = cv2.Scharr(crop, cv2.CV_64F, 0, 1, borderType=cv2.BORDER_REPLICATE) / 32.0
    energy = gx * gx + gy * gy
    noise = max(float(np.median(energy)), MIN_ENERGY)
    cu, cv_ = u - u0, v - v0
    best: EdgeAt | None = None
    for r in radii:
        a0, a1, b0, b1 = max(cu - r, 0), min(cu + r + 1, crop.shape[1]), max(cv_ - r, 0), min(cv_ + r + 1, crop.shape[0])
        g = cv2.getGaussianKernel(2 * r + 1, r / 2.0, cv2.CV_64F).ravel()
        w = np.outer(g[b0 - cv_ + r:b1 - cv_ + r], g[a0 - cu + r:a1 - cu + r])
        w /= w.sum()
        sx, sy = gx[b0:b1, a0:a1], gy[b0:b1, a0:a1]
        jxx, jyy, jxy = float((w * sx * sx).sum()), float((w * sy * sy).sum()), float((w * sx * sy).sum())
        trace = jxx + jyy
        if not trace > NOISE_ENERGY_FACTOR * noise:
            continue
        # l1 - l2 = sqrt((jxx - jyy)^2 + 4 jxy^2); the gradient at 0.5 atan2(2 jxy, jxx - jyy), the edge across it.
        coherence = min(((jxx - jyy) ** 2 + 4.0 * jxy * jxy) / (trace * trace), 1.0)
        angle = (math.degrees(0.5 * math.atan2(2.0 * jxy, jxx - jyy)) + 90.0) % 180.0
        angle = 0.0 if angle >= 180.0 else angle  # (-tiny % 180 rounds to 180.0)
        found = EdgeAt(angle, coherence, r)
        if coherence >= EDGE_COHERENCE:
            return found
        if best is None or coherence > best.coherence:
            best = found
    return best if best is not None else EdgeAt(math.nan, 0.0, radii[-1])
