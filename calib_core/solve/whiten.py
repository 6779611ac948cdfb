"""Whitening of the angular residuals: click noise is isotropic in pixels, not in angle.

The log-map residual ``r_i`` of pair i lives in the tangent plane of the
clicked bearing (radians).  A pixel error ``dm`` moves the bearing by
``A_i^-1 dm`` in that plane, with ``A_i`` (2x2, px/rad) the derivative of the
camera's projection along the tangent plane.  With click noise ``sigma_i`` px
per axis the residual's covariance is ``sigma_i^2 A_i^-1 A_i^-T``, so

    z_i = W_i r_i,   W_i = A_i / sigma_i

has unit covariance (when ``sigma_i`` is the true noise) and eq. 7 with
``z_i`` weighs each pair as the pixel cost (eq. 6) would, at the angular
cost's speed.  ``J_i`` is computed once per solve, at the clicked pixels.

The laser side has its own error: a pick lands on a whole depth-matrix cell
(:func:`cell_pick_covariance`, metres^2 in the lidar frame, the package's one
pick-error model).  Seen from the
camera it moves the bearing by ``Sigma_L,i`` (:func:`laser_tangent_covariance`,
which needs the pose), added to the click's covariance:
``C_i = sigma_i^2 A_i^-1 A_i^-T + Sigma_L,i`` and ``W_i = chol(C_i)^-1``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import CalibError
from .kernels import laser_bearing_cov, laser_whitening, probe_jacobians, tangent_probes

__all__ = ["tangent_to_pixel", "whitening", "click_whitening_inputs", "check_pixel_sigma", "cell_pick_covariance",
           "pairs_pick_covariance",
           "laser_tangent_covariance", "PICK_CELL_SIGMA", "PICK_RANGE_SIGMA_M",
           "BY_EYE_SHARED_RATIO"]

#: Central-difference step on the sphere, radians (a fraction of a pixel for any real camera).
STEP_RAD = 1e-4


def check_pixel_sigma(pixel_sigma: object, n: int) -> np.ndarray | None:
    """Validate a per-pair 1-sigma ``(N,)`` in px (None passes through)."""
    if pixel_sigma is None:
        return None
    s = np.asarray(pixel_sigma, dtype=np.float64)
    if s.ndim == 0:
        s = np.full(n, float(s))
    if s.shape != (n,):
        raise CalibError(f"pixel_sigma must hold one value per pair ({n}), got shape {s.shape}")
    bad = np.nonzero(~(np.isfinite(s) & (s > 0)))[0]
    if bad.size:
        raise CalibError(f"pair {bad[0]}: pixel_sigma must be a positive number of pixels, got {s[bad[0]]!r}")
    return s


#: Offset of a picked cell's point from the feature, across the beam, in cells (1-sigma along the
#: row axis, then along the column axis).  A careful pick takes, among the 3x3 cells around the
#: feature, the one whose point is nearest it (:func:`calib_core.synthetic.picks.laser_picks`),
#: often not the cell that contains it: wider than uniform within one cell (``1/sqrt(12) = 0.29``),
#: and wider along the finer axis (the synthetic scans' cells are 1 deg tall and 0.5 deg wide, so
#: a neighbour in the row is more often the nearest point).  Fitted by maximum likelihood to the
#: 3-D pick errors against the true corners of the sample and seeds 1-3 (494 corners), checked on
#: held-out scenes; see bench/pick_model.py.  One value per axis: a single value over-stated the
#: vertical error and under-stated the horizontal one (sigma coverage of ty too high, tx too low).
PICK_CELL_SIGMA = (0.37, 0.52)
#: Error of a picked cell's point along its beam, metres (1-sigma): the range noise (1 cm in the
#: synthetic scans) plus the slope of the surface the nearest cell lies on.  Same fit (folds 1.49-1.54 cm).
PICK_RANGE_SIGMA_M = 0.015

#: Pairs picked by eye share part of their error: variance of that shared part over the independent part's.
#:
#: The noise model of a by-eye pair, in three parts:
#:
#: 1. the click, ``precision_px`` (1 px when not stated), independent between pairs;
#: 2. the correspondence: which point of the object the laser cell really is, about one cell's
#:    footprint -- the cell's angular size (the depth matrix's row and column steps) times the range,
#:    seen through the camera at the pose (:func:`cell_pick_covariance`, :func:`laser_tangent_covariance`,
#:    ``C_i = sigma_i^2 A_i^-1 A_i^-T + Sigma_L,i``).  Also independent, so the residuals measure the
#:    sum of 1 and 2 and the solve scales its covariance by them (Student-t).  This term already keeps a
#:    0.3 px loupe click from outweighing a 1 px one: with cells of 2.7 x 4.8 px (KITTI) and 7.7 x 6.4 px
#:    (PJLab; medians of the kept sessions, column x row), times PICK_CELL_SIGMA, it weighs 1.3-1.4x
#:    (KITTI) and 1.1-1.2x (PJLab) as much, not 11x; solved without any click weighting, the sessions'
#:    median results move by 0.01 deg and 0.1 cm (bench.by_eye_limits, "unweighted");
#: 3. a part the session's pairs have in common -- a person reads "the corner" of every object
#:    the same way (the same side of an edge, the same cell of a corner), so the offsets repeat
#:    across pairs in a pattern the pose can follow.  The fit absorbs it whole: it moves the pose and
#:    leaves no residual, so no single session can measure it.  Modelled as a pose error whose
#:    covariance is this ratio times the independent parts' (1 and 2): the solve's covariance widened
#:    ``1 + BY_EYE_SHARED_RATIO`` times (:func:`calib_core.solve.solve_extrinsics`' ``shared_ratio``).
#:
#: Fitted by ``python -m bench.by_eye_limits`` on the 24 kept by-eye sessions (tests/by_eye_sessions, KITTI
#: and PJLab, 12 each) scored against the published calibrations: the median squared Mahalanobis distance
#: of the pose error under the covariance of 1 and 2 alone, over both scenes pooled, divided by the
#: median of chi^2 with 6 dof (5.348), minus 1.  One value for both scenes; each scene's own fit and the
#: other scene's d^2 under it are printed there.  Alternatives the same sessions reject: a common pixel
#: offset of all pairs (it explains 2 of the 6 directions: d^2 stays near 20 and 30 however large), a
#: shared term growing with the number of pairs (a worse likelihood), widening the correspondence
#: term to a whole cell (d^2 38 and 50 instead of 49 and 65: the independent part was not the gap).
#: Where it applies: :func:`calib_core.solve.calibrate.default_shared_ratio` (cells of a measured scan).
#: Simulated clicks on synthetic scenes have no shared part: their solves keep the exact covariance.
BY_EYE_SHARED_RATIO = 8.4


def cell_pick_covariance(depth: Any, rows_cols: np.ndarray, cell_sigma: float | tuple[float, float] = PICK_CELL_SIGMA,
                         range_sigma_m: float = PICK_RANGE_SIGMA_M) -> np.ndarray:
    """Laser-point covariance ``(N, 3, 3)`` (metres^2, lidar frame) of picks of whole cells.

    The one pick-error model of the package (the solve's whitening and
    sigma, the guide's information, the benchmark's Cramer-Rao bound):

        Sigma = rho^2 (s_row^2 g_row g_row^T + s_col^2 g_col g_col^T) + range_sigma_m^2 b b^T

    ``g_row``, ``g_col`` the change of the beam direction over one row and
    one column (central differences of the depth matrix's directions,
    one-sided at the borders, wrapping the columns of a 360 deg scan; a
    missing direction takes the other axis' step), ``rho`` the range and
    ``b`` the beam, ``(s_row, s_col) = cell_sigma``.  (Propagating the offset along the scanned surface, the
    3-D differences of neighbouring points, fitted the same errors worse on
    held-out scenes: at a corner the neighbours lie on different surfaces.)

    Parameters
    ----------
    depth : DepthMatrix
    rows_cols : (N, 2) int array_like
        Picked ``(row, col)`` cells (valid).
    cell_sigma : float or (float, float)
        1-sigma offset across the beam, in cells: one value for both axes, or
        ``(along the row axis, along the column axis)`` (:data:`PICK_CELL_SIGMA`).
    range_sigma_m : float
        1-sigma along the beam, metres (:data:`PICK_RANGE_SIGMA_M`).
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    H, W = depth.shape
    r, c = rc[:, 0], rc[:, 1]
    dirs = np.asarray(depth.directions, dtype=np.float64)
    wrap = bool(depth.meta.get("wrap_cols", False))
    r_lo, r_hi = np.clip(r - 1, 0, H - 1), np.clip(r + 1, 0, H - 1)
    if wrap:
        c_lo, c_hi, c_span = (c - 1) % W, (c + 1) % W, np.full(len(c), 2)
    else:
        c_lo, c_hi = np.clip(c - 1, 0, W - 1), np.clip(c + 1, 0, W - 1)
        c_span = np.maximum(c_hi - c_lo, 1)
    r_span = np.maximum(r_hi - r_lo, 1)
    g_row = (dirs[r_hi, c] - dirs[r_lo, c]) / r_span[:, None]
    g_col = (dirs[r, c_hi] - dirs[r, c_lo]) / c_span[:, None]
    g_row = np.where(np.isfinite(g_row), g_row, np.nan_to_num(g_col))
    g_col = np.where(np.isfinite(g_col), g_col, np.nan_to_num(g_row))
    rho = np.asarray(depth.range_m, dtype=np.float64)[r, c]
    beam = np.nan_to_num(dirs[r, c])
    s_row, s_col = np.broadcast_to(np.asarray(cell_sigma, dtype=np.float64), (2,))

    def outer(a):
        return a[:, :, None] * a[:, None, :]

    return (rho**2)[:, None, None] * (s_row**2 * outer(g_row) + s_col**2 * outer(g_col)) + range_sigma_m**2 * outer(beam)


def pairs_pick_covariance(pairs: Any, depth: Any, cell_sigma: float | tuple[float, float] = PICK_CELL_SIGMA,
                          range_sigma_m: float = PICK_RANGE_SIGMA_M) -> np.ndarray | None:
    """Laser-point covariance ``(N, 3, 3)`` (metres^2, lidar frame) of :class:`calib_core.pairs.Pair` objects:
    :func:`cell_pick_covariance` for a pair naming a cell, zero for a ``laser_xyz`` pair; None when no pair names a
    cell (or there is no depth matrix).

    An edge pair (``edge_deg`` set) takes no offset along the row axis: its laser end is the measured point
    where one ring crosses the photo's line, on that ring by definition; only which cell along the ring is on the
    line is a guess (the column axis).  (With the corner's row term, PJLab's lane-line pairs 8-14 m away weighed
    next to nothing: by-eye run 16's result moved from 41.6 to 15.9 cm without it.)
    """
    rows = [k for k, p in enumerate(pairs) if p.laser_rc is not None]
    if not rows or depth is None:
        return None
    cov = np.zeros((len(pairs), 3, 3))
    rc = np.array([pairs[k].laser_rc for k in rows], dtype=np.int64)
    cov[rows] = cell_pick_covariance(depth, rc, cell_sigma, range_sigma_m)
    edge = [j for j, k in enumerate(rows) if getattr(pairs[k], "edge_deg", None) is not None]
    if edge:
        col_sigma = np.broadcast_to(np.asarray(cell_sigma, dtype=np.float64), (2,))[1]
        cov[[rows[j] for j in edge]] = cell_pick_covariance(depth, rc[edge], (0.0, float(col_sigma)), range_sigma_m)
    return cov


def laser_tangent_covariance(T_camera_lidar: np.ndarray, points_lidar: np.ndarray, frames: np.ndarray,
                             laser_cov_m2: np.ndarray) -> np.ndarray:
    """Covariance ``(N, 2, 2)`` (rad^2) of the bearing residual caused by laser-point errors.

    First order: ``dr = E_i R dX / |R X + t|`` (the tangent-plane part of the
    moved point over its range), so ``Sigma_i = E_i R S_i R^T E_i^T / |P_i|^2``.
    """
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    return laser_bearing_cov(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
                             np.ascontiguousarray(points_lidar, dtype=np.float64),
                             np.ascontiguousarray(frames, dtype=np.float64),
                             np.ascontiguousarray(laser_cov_m2, dtype=np.float64))


def tangent_to_pixel(camera: Any, frames: np.ndarray) -> np.ndarray:
    """``d pixel / d(tangent coordinates of the bearing)`` at each bearing, ``(N, 2, 2)`` px/rad.

    Central differences of ``camera.project`` at ``b +- h e1`` and
    ``b +- h e2`` (one call; projecting is cheaper than un-distorting pixels).

    Parameters
    ----------
    camera : CameraModel
    frames : (N, 3, 3) ndarray
        Rows ``e1, e2, b`` of each clicked bearing.

    Returns
    -------
    A : (N, 2, 2) ndarray
        Columns: along ``e1``, along ``e2``.  NaN where the camera cannot
        project one of the probes.
    ok : (N,) bool ndarray
        ``A`` is finite and invertible.
    """
    probe = tangent_probes(np.ascontiguousarray(frames, dtype=np.float64), STEP_RAD)
    uv = np.ascontiguousarray(camera.project(probe)[0], dtype=np.float64)
    return probe_jacobians(uv, STEP_RAD)


def whitening(
    n: int,
    *,
    camera: Any = None,
    frames: np.ndarray | None = None,
    pixel_sigma: np.ndarray | None = None,
    noise_rad: float | None = None,
    laser_tangent_cov: np.ndarray | None = None,
    tangent: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, str]:
    """Whitening matrices ``W (N, 2, 2)`` and the unit of the whitened residuals.

    * ``noise_rad`` given: ``W = I / noise_rad`` (known isotropic angular
      noise; the whitened residuals are in units of that noise).
    * a camera: ``W_i = A_i / sigma_i``, or with a laser term
      ``W_i = chol(sigma_i^2 A_i^-1 A_i^-T + Sigma_L,i)^-1``
      (``sigma_i`` from ``pixel_sigma``, default 1 px; ``Sigma_L,i`` =
      ``laser_tangent_cov``, default 0): residuals in px of click noise (or
      in sigmas when ``pixel_sigma`` is given).
    * neither: ``W_i = I / sigma_i`` (radians; ``pixel_sigma`` then only sets
      relative weights).

    ``tangent``: :func:`tangent_to_pixel` of ``camera`` and ``frames`` when the caller has it (it does
    not depend on the pose: a second whitening at a new pose reuses it).

    Returns
    -------
    W : (N, 2, 2) ndarray
    unit : {"noise", "px", "sigma", "rad"}
    """
    if noise_rad is not None:
        return np.broadcast_to(np.eye(2) / noise_rad, (n, 2, 2)).copy(), "noise"
    if camera is not None:
        # px/rad: the whitened residual is the linearised pixel error.
        A, ok = tangent_to_pixel(camera, frames) if tangent is None else tangent
        unit = "px" if pixel_sigma is None else "sigma"
        if laser_tangent_cov is None and pixel_sigma is None and ok.all():
            return A, unit  # the common case first, without the arrays below
    s = np.ones(n) if pixel_sigma is None else pixel_sigma
    eye = np.broadcast_to(np.eye(2), (n, 2, 2))
    if camera is None:
        return eye / s[:, None, None], "rad"
    if laser_tangent_cov is None and ok.all():
        return A / s[:, None, None], unit
    if not ok.any():
        return eye / s[:, None, None], "rad"
    A = _projectable_tangent(A, ok)
    if laser_tangent_cov is None:
        return A / s[:, None, None], unit
    # C = s^2 A^-1 A^-T + Sigma_L (rad^2) = L L^T (2x2 Cholesky, closed form); W = L^-1, W^T W = C^-1.
    return laser_whitening(np.ascontiguousarray(A), np.ascontiguousarray(s, dtype=np.float64),
                           np.ascontiguousarray(laser_tangent_cov, dtype=np.float64)), unit


def _projectable_tangent(A: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``A`` where a probe the camera cannot project is replaced by the median isotropic px-per-radian
    of the other pairs (a copy then: the caller's ``tangent`` stays as it was)."""
    if ok.all():
        return A
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    A = A.copy()
    A[~ok] = np.eye(2) * float(np.median(np.sqrt(np.abs(det[ok]))))
    return A


def click_whitening_inputs(tangent: tuple[np.ndarray, np.ndarray], pixel_sigma: np.ndarray | None
                           ) -> tuple[np.ndarray, np.ndarray] | None:
    """``(A (N, 2, 2) px/rad, sigma (N,) px)`` of the clicks as :func:`whitening` uses them (a probe the
    camera cannot project replaced), contiguous for the kernels; None where it whitens without the
    camera (no probe projectable).  With a laser-point covariance the solve re-whitens from these at
    each pose (:func:`calib_core.solve.kernels.fit_pose_laser`)."""
    A, ok = tangent
    if not ok.any():
        return None
    s = np.ones(len(A)) if pixel_sigma is None else np.ascontiguousarray(pixel_sigma, dtype=np.float64)
    return np.ascontiguousarray(_projectable_tangent(A, ok)), s
