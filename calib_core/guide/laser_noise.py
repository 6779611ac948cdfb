"""Error of a laser point picked as a whole depth-matrix cell.

The feature a person pairs lies somewhere in (or, at a depth edge, next to)
the picked cell, so the cell's point differs from it by up to a cell's
extent along the row and the column, plus the range noise along the beam.
Modelled as a zero-mean error of covariance (metres^2)

    Sigma_L = s^2 (g_row g_row^T + g_col g_col^T) rho^2 + sigma_r^2 b b^T

with ``g_row``, ``g_col`` the change of the beam direction over one row and
one column, ``rho`` the range, ``b`` the beam and ``s^2`` the variance of the
offset in cells: 1/12 for a uniform offset within the cell (a careful whole-cell
pick); a proposed cell found by a detector may sit up to two cells off the
corner, hence the default: the standard deviation of a uniform offset over
-2..2 cells, sqrt((5^2 - 1) / 12) = 1.41.
"""

from __future__ import annotations

import numpy as np

from ..solve.calibrate import RANGE_SIGMA_M

__all__ = ["cell_covariance", "DEFAULT_CELL_SIGMA", "WHOLE_CELL_SIGMA", "PICK_CELL_SIGMA", "DEFAULT_RANGE_SIGMA_M"]

#: Offset (cells, 1-sigma) of a careful whole-cell pick: uniform within the cell.
WHOLE_CELL_SIGMA = 12.0**-0.5
#: Offset (cells, 1-sigma) of a careful pick as measured: the picked cell is the one whose point is
#: nearest the corner among the 3x3 around the beam through it, often not the cell containing it, so the
#: offset is wider than uniform within one cell.  On the synthetic scenes (sample, seeds 1, 2: 373
#: corners, :func:`calib_core.synthetic.picks.laser_picks` against the true corners) the image-plane
#: offsets' mean squared Mahalanobis distance is 4.1-4.9 under :data:`WHOLE_CELL_SIGMA` and
#: 1.5-1.8 under 0.5 cells (2 for a calibrated model); the pick's information uses this value.
PICK_CELL_SIGMA = 0.45
#: Standard deviation of the picked cell's offset from the feature, in cells.
DEFAULT_CELL_SIGMA = 1.41
#: Range noise along the beam, metres: the solve's own laser model
#: (:data:`calib_core.solve.calibrate.RANGE_SIGMA_M`), so proposals are ranked
#: by the information the solve will draw from them.
DEFAULT_RANGE_SIGMA_M = RANGE_SIGMA_M


def cell_covariance(
    depth,
    rows_cols: np.ndarray,
    cell_sigma: float = DEFAULT_CELL_SIGMA,
    range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
) -> np.ndarray:
    """Covariance (N, 3, 3), metres^2, of the points of picked cells (module docstring).

    Neighbouring beam directions come from the depth matrix itself (central
    differences, one-sided at the borders, wrapping columns of a 360 deg
    scan), so any laser model works.
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    H, W = depth.shape
    r, c = rc[:, 0], rc[:, 1]
    dirs = depth.directions
    wrap = bool(depth.meta.get("wrap_cols", False))
    r_lo, r_hi = np.clip(r - 1, 0, H - 1), np.clip(r + 1, 0, H - 1)
    if wrap:
        c_lo, c_hi = (c - 1) % W, (c + 1) % W
        c_span = np.full(len(c), 2)
    else:
        c_lo, c_hi = np.clip(c - 1, 0, W - 1), np.clip(c + 1, 0, W - 1)
        c_span = np.maximum(c_hi - c_lo, 1)
    r_span = np.maximum(r_hi - r_lo, 1)
    g_row = (dirs[r_hi, c] - dirs[r_lo, c]) / r_span[:, None]
    g_col = (dirs[r, c_hi] - dirs[r, c_lo]) / c_span[:, None]
    # A neighbour without a known direction: take the other axis' step (same order of size).
    g_row = np.where(np.isfinite(g_row), g_row, np.nan_to_num(g_col))
    g_col = np.where(np.isfinite(g_col), g_col, np.nan_to_num(g_row))
    rho = depth.range_m[r, c]
    beam = np.nan_to_num(dirs[r, c])
    outer = lambda a: a[:, :, None] * a[:, None, :]  # noqa: E731
    return (cell_sigma**2 * rho**2)[:, None, None] * (outer(g_row) + outer(g_col)) + range_sigma_m**2 * outer(beam)
