"""Accepting a proposal without a click, under a strict gate.

A proposal is accepted automatically (a pair tagged ``auto``) only when

* it is a new pair (not a re-click) of a kind in ``kinds`` whose laser
  corner measure is at least ``min_laser_strength``;
* its predicted 3-sigma ellipse is small enough to search
  (``max_ellipse_px``, major half-axis);
* within that ellipse the image has a clean isolated corner (strict
  :class:`~calib_core.guide.image_corners.CornerGate`, with an isolation
  radius covering twice the ellipse): no rival corner of more than
  ``isolation`` of its strength anywhere near, so the match cannot be confused;
* ``cv2.cornerSubPix`` from it lands close to the prediction: Mahalanobis
  distance under the proposal's pixel covariance at most ``max_offset_sigma``
  (a wrong match sits where the pose does not predict one);
* optionally (``min_contrast`` > 0) the laser's silhouette matches the image
  there: the near-side and far-side points of the 7x7 cells around the cell,
  projected with the current pose and shifted so the cell lands on the image
  corner, fall on image colours that differ by at least ``min_contrast``
  pooled standard deviations.

The defaults are tuned by ``python -m bench.guide_auto`` against the truth of
the synthetic scenes (sample and seeds 1, 2): the decisive tests are the
isolation and the offset; the colour test did not separate right from wrong
matches there and is off.  Wrong matches stay at or under 2 %; the solve's
outlier check catches the rest.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .candidates import KINDS, near_fraction, window_cells
from .image_corners import CornerGate, CornerImage, clean_corner, refine_subpixel, strongest_near
from .propose import Proposal

__all__ = ["AutoGate", "auto_accept"]


class AutoGate:
    """Thresholds of :func:`auto_accept` (defaults: the tuned strict gate, module docstring).

    Parameters
    ----------
    max_ellipse_px : float
        Largest 3-sigma major half-axis searched, px.
    min_laser_strength : float
        Smallest laser corner measure (:attr:`Candidates.strength`).
    corner : CornerGate
        The clean-isolated-corner test of the image corner.
    min_contrast : float
        Silhouette colour contrast needed (0: test off).
    max_offset_sigma : float
        Largest Mahalanobis distance of the found corner from the predicted pixel.
    kinds : tuple of str
        Candidate kinds that may be accepted (:data:`calib_core.guide.candidates.KINDS`).
    """

    def __init__(self, max_ellipse_px: float = 12.0, min_laser_strength: float = 0.5,
                 corner: CornerGate = CornerGate(min_strength=0.03, min_ratio=0.3, isolation=0.3,
                                                 isolation_radius_px=6.0),
                 min_contrast: float = 0.0, max_offset_sigma: float = 2.0**0.5,
                 kinds: tuple[str, ...] = KINDS) -> None:
        self.max_ellipse_px = float(max_ellipse_px)
        self.min_laser_strength = float(min_laser_strength)
        self.corner = corner
        self.min_contrast = float(min_contrast)
        self.max_offset_sigma = float(max_offset_sigma)
        self.kinds = tuple(kinds)


def silhouette_contrast(image: np.ndarray, depth, camera, T_camera_lidar: np.ndarray, rows_cols: np.ndarray,
                        shift_px: np.ndarray, half: int = 3) -> np.ndarray:
    """Colour contrast across each cell's projected depth step (:class:`AutoGate`), (N,); NaN without a step.

    ``|mean_near - mean_far| / sqrt((var_near + var_far) / 2 + 4)`` over RGB
    (grey levels; the 4 keeps flat synthetic colours from dividing by 0).
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    rows, cols = window_cells(depth.shape, rc, half)
    frac = near_fraction(depth, rc, half)
    ok_cell = depth.valid[rows, cols]
    lr = np.where(ok_cell, np.log(np.where(ok_cell, depth.range_m[rows, cols], 1.0)), np.nan)
    lo, hi = np.nanmin(lr, axis=(1, 2)), np.nanmax(lr, axis=(1, 2))
    with np.errstate(invalid="ignore"):
        near = lr < (0.5 * (lo + hi))[:, None, None]
    far = ok_cell & ~near
    P = depth.points[rows, cols].reshape(-1, 3)
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    pix, valid = camera.project(np.nan_to_num(P) @ T[:3, :3].T + T[:3, 3])
    pix = np.asarray(pix, dtype=np.float64).reshape(len(rc), -1, 2) + np.asarray(shift_px)[:, None, :]
    valid = np.asarray(valid, dtype=bool).reshape(len(rc), -1) & ok_cell.reshape(len(rc), -1)
    img = np.asarray(image, dtype=np.float32)
    u = np.clip(np.rint(pix[..., 0]).astype(np.int64), 0, img.shape[1] - 1)
    v = np.clip(np.rint(pix[..., 1]).astype(np.int64), 0, img.shape[0] - 1)
    colours = img[v, u].reshape(len(rc), -1, img.shape[2] if img.ndim == 3 else 1)
    out = np.full(len(rc), np.nan)
    for i in range(len(rc)):  # a few proposals
        a = colours[i][valid[i] & near[i].ravel()]
        b = colours[i][valid[i] & far[i].ravel()]
        if len(a) < 4 or len(b) < 4 or not np.isfinite(frac[i]):
            continue
        pooled = np.sqrt(0.5 * (a.var(axis=0).sum() + b.var(axis=0).sum()) + 4.0)
        out[i] = float(np.linalg.norm(a.mean(axis=0) - b.mean(axis=0)) / pooled)
    return out


def auto_accept(ci: CornerImage, proposals: Sequence[Proposal], gate: AutoGate | None = None, *,
                image: np.ndarray | None = None, depth=None, camera=None,
                T_camera_lidar: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Which proposals pass the gate, and their sub-pixel image corners.

    Parameters
    ----------
    ci : CornerImage
    proposals : sequence of Proposal
    gate : AutoGate, optional
    image, depth, camera, T_camera_lidar
        The RGB image, the scan, the camera and the current pose, for the
        silhouette test; when the gate has one (``min_contrast`` > 0) and
        they are missing, no proposal passes.

    Returns
    -------
    accepted : (N,) bool
    pixels : (N, 2) ndarray
        The corner found where accepted, NaN elsewhere.
    """
    g = gate or AutoGate()
    n = len(proposals)
    pixels = np.full((n, 2), np.nan)
    if n == 0:
        return np.zeros(0, dtype=bool), pixels
    pred = np.array([p.pixel for p in proposals], dtype=np.float64)
    cov = np.array([p.pixel_cov for p in proposals], dtype=np.float64)
    major = np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, -1], 0.0))
    ok = np.array([p.kind in g.kinds and p.replaces is None for p in proposals])
    strength = np.array([p.strength for p in proposals], dtype=np.float64)
    ok &= (np.nan_to_num(strength, nan=-np.inf) >= g.min_laser_strength) & (3.0 * major <= g.max_ellipse_px)
    # Search each ellipse's 3-sigma disc; no rival corner may sit anywhere in it.
    radius = np.ceil(np.clip(3.0 * major, 1.5, g.max_ellipse_px))
    peak = np.zeros((n, 2))
    for r in np.unique(radius[ok]):  # a few distinct radii
        sel = ok & (radius == r)
        peak[sel] = strongest_near(ci, pred[sel], float(r))[0]
        iso = g.corner._replace(isolation_radius_px=max(g.corner.isolation_radius_px, 2.0 * float(r)))
        ok[sel] &= clean_corner(ci, peak[sel], iso)
    if ok.any():
        pixels[ok] = refine_subpixel(ci, peak[ok])
    d = pixels - pred
    with np.errstate(invalid="ignore"):
        m2 = np.einsum("na,nab,nb->n", d, np.linalg.inv(cov), d)
    ok &= np.isfinite(m2) & (m2 <= g.max_offset_sigma**2)
    if g.min_contrast <= 0:
        pass
    elif image is None or depth is None or camera is None or T_camera_lidar is None:
        ok[:] = False
    elif ok.any():
        rc = np.array([p.laser_rc for p in proposals])[ok]
        contrast = silhouette_contrast(image, depth, camera, T_camera_lidar, rc, d[ok])
        ok[ok] = np.nan_to_num(contrast, nan=-np.inf) >= g.min_contrast
    pixels[~ok] = np.nan
    return ok, pixels
