"""The depth matrix: a range scan laid out as an image (paper Sec. III).

Every laser model produces a :class:`DepthMatrix`.  Cell ``(row, col)`` holds
the measured range ``rho`` of one beam, its unit direction and its 3-D point,
all in the lidar frame (metres).  Cells without a return are *invalid*: their
range and point are NaN, never a point at distance zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class DepthMatrix:
    """A range image with per-cell beam geometry.

    Attributes
    ----------
    range_m : (H, W) float64
        Measured range rho_ij in metres along the beam; NaN where invalid.
    directions : (H, W, 3) float64
        Unit beam direction of every cell in the lidar frame.  May be NaN for
        invalid cells whose direction is unknown (e.g. an organized cloud with
        a missing return).
    points : (H, W, 3) float64
        3-D point of every cell in the lidar frame, metres; NaN where invalid.
        For a scanner with axis offsets (paper eq. 3) the point is *not*
        ``range_m * directions``: the beam starts off the origin.
    valid : (H, W) bool
        The cell has a return.
    meta : dict
        Free-form description of the source (model name, angles, file).
    """

    range_m: np.ndarray
    directions: np.ndarray
    points: np.ndarray
    valid: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return self.range_m.shape  # type: ignore[return-value]

    @property
    def organize_report(self):
        """What organising the source cloud kept (``meta["organize_report"]``,
        a :class:`calib_core.lidar.report.OrganizeReport`), or None when the
        matrix was not made by ``load_scan``/``organize_cloud``."""
        return self.meta.get("organize_report")

    def cell_points(self, rows_cols: np.ndarray) -> np.ndarray:
        """Points of cells ``(N, 2)`` integer ``(row, col)``; NaN rows where invalid."""
        rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
        return self.points[rc[:, 0], rc[:, 1]]

    def valid_points(self) -> tuple[np.ndarray, np.ndarray]:
        """All valid points ``(M, 3)`` and their ``(row, col)`` indices ``(M, 2)``."""
        rows, cols = np.nonzero(self.valid)
        return self.points[rows, cols], np.stack([rows, cols], axis=1)
