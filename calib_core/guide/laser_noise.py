"""Error of a laser point picked as a whole depth-matrix cell: the guide's view of the one model.

The model is :func:`calib_core.solve.whiten.cell_pick_covariance` (the solve
and the benchmark's bound use it too): an offset of ``cell_sigma`` cells
across the beam (along the row and the column) plus ``range_sigma_m`` along
it.  A careful pick: :data:`PICK_CELL_SIGMA` (fitted to ground truth).  A
proposed cell found by a detector may sit up to two cells off the corner,
hence the default for proposals: the standard deviation of a uniform offset
over -2..2 cells, sqrt((5^2 - 1) / 12) = 1.41.
"""

from __future__ import annotations

import numpy as np

from ..solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M, cell_pick_covariance

__all__ = ["cell_covariance", "DEFAULT_CELL_SIGMA", "WHOLE_CELL_SIGMA", "PICK_CELL_SIGMA", "DEFAULT_RANGE_SIGMA_M"]

#: Offset (cells, 1-sigma) of a careful whole-cell pick: uniform within the cell.
WHOLE_CELL_SIGMA = 12.0**-0.5
#: Standard deviation of the picked cell's offset from the feature, in cells.
DEFAULT_CELL_SIGMA = 1.41
#: Error along the beam, metres: the solve's own laser model, so proposals are ranked by the
#: information the solve will draw from them.
DEFAULT_RANGE_SIGMA_M = PICK_RANGE_SIGMA_M


def cell_covariance(
    depth,
    rows_cols: np.ndarray,
    cell_sigma: float = DEFAULT_CELL_SIGMA,
    range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
) -> np.ndarray:
    """Covariance (N, 3, 3), metres^2, of the points of picked cells:
    :func:`calib_core.solve.whiten.cell_pick_covariance` with the proposals' default offset."""
    return cell_pick_covariance(depth, rows_cols, cell_sigma, range_sigma_m)
