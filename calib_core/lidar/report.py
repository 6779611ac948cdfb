"""What organising a cloud into a depth matrix kept: one line for the user.

Every organiser records its counts in ``DepthMatrix.meta``;
:func:`organize_report` turns them into an :class:`OrganizeReport`, which
``load_scan`` stores as ``meta["organize_report"]`` and the CLI prints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix

#: Below this share of usable points kept, a cloud is not one sensor's view.
MIN_POINTS_KEPT_SHARE = 0.5


@dataclass(frozen=True)
class OrganizeReport:
    """Outcome of organising one cloud.

    Attributes
    ----------
    method : str
        ``ring``, ``firing_order``, ``elevation``, ``spherical``,
        ``organized`` or ``native``.
    reason : str
        Why this method was used (empty when the user forced it).
    rows, cols : int
        Depth-matrix shape.
    valid_cells : int
        Cells holding a point.
    points_in : int
        Points in the file.
    points_usable : int
        Points with finite coordinates, not at the origin.
    points_kept : int
        Points that are in a cell (the others fell outside the grid or
        behind a nearer point in the same cell).
    """

    method: str
    reason: str
    rows: int
    cols: int
    valid_cells: int
    points_in: int
    points_usable: int
    points_kept: int

    @property
    def valid_share(self) -> float:
        """Share of cells holding a point, 0..1."""
        return self.valid_cells / max(self.rows * self.cols, 1)

    @property
    def kept_share(self) -> float:
        """Share of usable points that are in a cell, 0..1."""
        return self.points_kept / max(self.points_usable, 1)

    def line(self) -> str:
        """One line: method, rows x columns, % cells valid, % points kept (and why)."""
        text = (
            f"organised by {self.method}: {self.rows} x {self.cols}, {100 * self.valid_share:.1f} % of cells valid, "
            f"{100 * self.kept_share:.2f} % of points kept ({self.points_kept} of {self.points_usable})"
        )
        return f"{text}; {self.reason}" if self.reason else text


def organize_report(depth: DepthMatrix, reason: str = "") -> OrganizeReport:
    """The report of a depth matrix made by :mod:`calib_core.lidar.organize` or read natively."""
    meta = depth.meta
    rows, cols = depth.shape
    valid = int(np.count_nonzero(depth.valid))
    points_in = int(meta.get("n_points_in", valid))
    usable = points_in - int(meta.get("n_points_dropped", 0))
    kept = int(meta.get("n_points_kept", valid))
    if meta.get("organize") == "organized":
        usable = kept  # a grid's empty cells are no-returns, not lost points
    return OrganizeReport(
        method=str(meta.get("organize", meta.get("model", "unknown"))),
        reason=reason,
        rows=int(rows),
        cols=int(cols),
        valid_cells=valid,
        points_in=points_in,
        points_usable=usable,
        points_kept=kept,
    )


def check_points_kept(report: OrganizeReport, min_share: float = MIN_POINTS_KEPT_SHARE) -> None:
    """Refuse a cloud of which organisation kept too few points.

    A scan seen from the lidar origin keeps nearly all its points (one per
    beam and firing).  An object scan or an aerial tile seen from an
    arbitrary origin piles many points into few cells.

    Raises
    ------
    CalibError
        When the kept share is below ``min_share``.
    """
    if report.kept_share < min_share:
        raise CalibError(
            f"organising kept only {report.points_kept} of {report.points_usable} points "
            f"({100 * report.kept_share:.1f} %): the cloud does not look like a scan seen from the lidar origin "
            f"(give the scanner position with --sensor-origin X Y Z if the points are in a world frame)"
        )
