"""How likely a proposed laser cell is a corner the person can click: laser and image evidence combined.

A laser corner candidate (:mod:`.candidates`) is often no clickable corner:
a junction on a floor seen at a grazing angle (its normals are noise), the
corner of a table leg one or two cells wide, a depth-edge kink.  Each of
those costs the person a "Not a corner".  The features, per candidate:

* ``junction`` -- 1 for a plane-junction candidate, 0 for a depth jump;
* ``log_strength`` -- log of the laser corner measure (:attr:`Candidates.strength`);
* ``image_offset`` -- Mahalanobis distance (under the proposal's pixel
  covariance) from the predicted pixel to the strongest image corner in the
  3-sigma disc: a clickable corner shows up near where the laser says;
* ``image_ratio`` -- ``lam_min / lam_max`` of that image corner (an L or X
  corner, not an edge);
* ``log_image_strength`` -- log of its ``lam_min``;
* ``flatness`` -- log of the window's plane-fit residual over the scan's
  range noise (:func:`.candidates.plane_residual_m`): about 0 on one plane;
* ``wide`` -- 1 where the near side of the window is at least 3 cells wide
  (:func:`.candidates.near_region_width`);
* ``log_discontinuity`` -- log of the depth step spike (:func:`.candidates.depth_discontinuity`).

They are combined by a logistic model, ``P = 1 / (1 + exp(-(b + w . f)))``,
whose weights :data:`WEIGHTS` were fitted by ``python -m bench.guide_fit`` on
the committed sample (seed 0) only, with the sample's ground-truth corner
list as labels; the benchmark measures the resulting precision on the
held-out scenes (seeds 1 and 2) as well.
"""

from __future__ import annotations

import numpy as np

from .candidates import Candidates, depth_discontinuity, near_region_width, plane_residual_m
from .image_corners import CornerImage, strongest_near

__all__ = ["FEATURES", "WEIGHTS", "corner_features", "corner_probability", "scan_range_noise_m"]

FEATURES = ("junction", "log_strength", "image_offset", "image_ratio", "log_image_strength", "flatness", "wide",
            "log_discontinuity")
#: Intercept and weights per :data:`FEATURES` (``python -m bench.guide_fit``, sample seed 0).
WEIGHTS = (-5.098, (0.1192, 0.6836, -0.3401, 1.451, -0.3719, 0.6487, 0.9961, -0.007188))


def scan_range_noise_m(depth, step: int = 4) -> float:
    """Robust range noise of the scan (m): median plane-fit residual of 3x3 windows on a grid of cells."""
    rows, cols = np.nonzero(depth.valid[::step, ::step])
    if len(rows) == 0:
        return 0.01
    rc = np.stack([rows * step, cols * step], axis=1)
    res = plane_residual_m(depth, rc, half=1)
    res = res[np.isfinite(res)]
    return float(max(np.median(res), 1e-4)) if res.size else 0.01


def laser_features(depth, cand: Candidates, noise_m: float) -> np.ndarray:
    """The laser columns of :func:`corner_features` (N, 5): junction, log_strength, flatness, wide, log_discontinuity."""
    junction = (cand.kind == 1).astype(np.float64)
    flat = np.log(np.maximum(np.nan_to_num(plane_residual_m(depth, cand.rows_cols), nan=0.0), 1e-4) / noise_m)
    wide = near_region_width(depth, cand.rows_cols).astype(np.float64)
    disc = np.log(depth_discontinuity(depth, cand.rows_cols) + 1e-3)
    return np.stack([junction, np.log(np.maximum(cand.strength, 1e-3)), flat, wide, disc], axis=1)


def corner_features(laser: np.ndarray, ci: CornerImage, pixels: np.ndarray, pixel_cov: np.ndarray) -> np.ndarray:
    """Feature matrix (N, len(FEATURES)) in the order of :data:`FEATURES`.

    Parameters
    ----------
    laser : (N, 5) ndarray
        :func:`laser_features` of the candidates.
    ci : CornerImage
    pixels : (N, 2) ndarray
        Predicted pixels.
    pixel_cov : (N, 2, 2) ndarray
        Their covariances, px^2.
    """
    n = len(pixels)
    major = np.sqrt(np.maximum(np.linalg.eigvalsh(np.nan_to_num(pixel_cov))[:, -1], 0.0))
    radius = np.ceil(np.clip(3.0 * major, 2.0, 12.0))
    peak, strength = np.zeros((n, 2)), np.zeros(n)
    for r in np.unique(radius):  # a few distinct radii
        sel = radius == r
        peak[sel], strength[sel] = strongest_near(ci, np.nan_to_num(pixels[sel]), float(r))
    d = peak - np.nan_to_num(pixels)
    cov = np.nan_to_num(pixel_cov) + 1e-6 * np.eye(2)
    offset = np.sqrt(np.maximum(np.einsum("na,nab,nb->n", d, np.linalg.inv(cov), d), 0.0))
    H, W = ci.lam_min.shape
    u = np.clip(peak[:, 0].astype(np.int64), 0, W - 1)
    v = np.clip(peak[:, 1].astype(np.int64), 0, H - 1)
    ratio = strength / np.maximum(ci.lam_max[v, u], 1e-9)
    return np.stack([laser[:, 0], laser[:, 1], offset, ratio, np.log(np.maximum(strength, 1e-4)),
                     laser[:, 2], laser[:, 3], laser[:, 4]], axis=1)


def corner_probability(features: np.ndarray, weights=WEIGHTS) -> np.ndarray:
    """Logistic probability (N,) that each candidate is a clickable corner (module docstring)."""
    b, w = weights
    z = b + np.asarray(features, dtype=np.float64) @ np.asarray(w, dtype=np.float64)
    return 1.0 / (1.0 + np.exp(-np.clip(z, -50.0, 50.0)))
