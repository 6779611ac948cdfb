"""The points of a scan file and the helpers every format reader shares."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import CalibError
from ...lidar.npz_format import MAX_CELLS_OPTION
from ...lidar.organize import RING_FIELD_NAMES


@dataclass(frozen=True)
class PointCloud:
    """The points of a scan file and their per-point fields.

    Attributes
    ----------
    xyz : (N, 3) float64
        Points in the file's (lidar) frame, metres.  For an organized cloud
        the points are in row-major order over ``organized_shape`` and may be
        NaN (no return).
    fields : dict[str, ndarray]
        Other per-point fields by their name in the file, in the file's dtype:
        ``(N,)`` arrays, or ``(N, k)`` for PCD fields with ``COUNT k``.
        Typical: ``intensity``, ``ring``, ``time`` / ``timestamp``.
    organized_shape : (H, W) or None
        The grid of an organized cloud, None for a flat list of points.
    meta : dict
        Facts about the file (``source``, ``format``, encoding, ...).
    """

    xyz: np.ndarray
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    organized_shape: tuple[int, int] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.xyz)

    def ring_field(self) -> np.ndarray | None:
        """The per-point beam index (``ring``, ``laser_id`` or ``channel``), if the file has one."""
        for name in RING_FIELD_NAMES:
            values = self.fields.get(name)
            if values is not None and values.ndim == 1:
                return values
        return None


def too_many_points(path: Path, what: str, count: int, max_points: int) -> CalibError:
    return CalibError(
        f"{path}: {what} {count:,} points, above the limit of {max_points:,} (raise it with {MAX_CELLS_OPTION})"
    )


def xyz_field_names(path: Path, names, what: str) -> tuple[str, str, str]:
    """The field names holding x, y, z: lower case, else PDAL's upper case."""
    chosen = []
    for axis in "xyz":
        if axis in names:
            chosen.append(axis)
        elif axis.upper() in names:
            chosen.append(axis.upper())
    if len(chosen) < 3:
        missing = [a for a in "xyz" if a not in names and a.upper() not in names]
        raise CalibError(f"{path}: {what} has no {'/'.join(missing)} field (fields: {' '.join(names)})")
    return chosen[0], chosen[1], chosen[2]


def values_per_line(data: bytes) -> np.ndarray:
    """Number of values on each line of :func:`normalise_text` output (single spaces, one final newline).

    A missing final newline is not a truncation: readers count the values of
    every line against the header instead (a cut file loses values or lines).
    """
    codes = np.frombuffer(data, dtype=np.uint8)
    space = (codes == 32) | (codes == 10)
    starts = ~space & np.concatenate(([True], space[:-1]))
    line_of_token = np.cumsum(codes == 10)[starts]
    return np.bincount(line_of_token, minlength=int(np.count_nonzero(codes == 10)))


def normalise_text(data: bytes) -> bytes:
    """ASCII records with single spaces between values and one point per line.

    PCL splits on blanks and tabs, PDAL also on commas; pypcd4 and trimesh
    split on single spaces.  Empty lines are dropped.
    """
    data = data.translate(bytes.maketrans(b",\t\r\x00", b"    "))
    if b"  " in data or b" \n" in data or b"\n " in data or data.startswith(b" ") or b"\n\n" in data:
        data = b"\n".join(b" ".join(words) for line in data.split(b"\n") if (words := line.split()))
    return data.strip(b" \n") + b"\n"
