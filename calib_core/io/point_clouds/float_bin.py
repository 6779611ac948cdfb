"""Headerless ``.bin`` files of float32 records, and how many values make one record.

KITTI writes x, y, z, reflectance (4 per point); nuScenes and Lyft x, y, z,
intensity, ring index (5); Waymo converted to KITTI's layout and SUN RGB-D 6.
Nothing in the file says which, so the layout is given (``bin_columns``) or
detected from the data's period; when it cannot be told the file is refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import CalibError
from .cloud import PointCloud, too_many_points


#: Float32 values per point the ``.bin`` layout detection considers.
BIN_COLUMNS_DETECTED = (3, 4, 5, 6, 7, 8)
#: A lidar's median point is metres away; under a millimetre the bytes are not float32 metres (e.g. text).
_SMALLEST_MEDIAN_RANGE_M = 1e-3


def _lag_spread(squashed: np.ndarray, lag: int) -> float:
    """Median change between values ``lag`` apart; ``squashed`` is ``asinh`` of the values (a log-like scale)."""
    if len(squashed) <= lag:
        return float("nan")
    return float(np.median(np.abs(squashed[lag:] - squashed[:-lag])))


def detect_bin_columns(values: np.ndarray) -> tuple[int | None, str]:
    """Float32 values per point of a headerless ``.bin``, from the data's period.

    A record's columns differ in kind (metres, intensity, ring index), so
    values one record apart resemble each other far more than values at any
    other distance, and most of all when the points are in scan order.  The
    period is the smallest lag whose median change (:func:`_lag_spread`) is
    the least, and clearly below every lag that is not its multiple.

    Parameters
    ----------
    values : (M,) float32
        The start of the file's values (a few hundred thousand suffice).

    Returns
    -------
    (int or None, str)
        The number of columns, or None when the data shows no clear period;
        and the spreads it was decided on, for messages.
    """
    finite = np.where(np.isfinite(values), values, 0.0).astype(np.float64)
    squashed = np.arcsinh(finite)  # once, not per lag: the asinh is most of the cost
    spreads = {lag: _lag_spread(squashed, lag) for lag in range(1, max(BIN_COLUMNS_DETECTED) + 1)}
    summary = ", ".join(f"{lag}: {s:.3g}" for lag, s in spreads.items() if np.isfinite(s))
    candidates = {lag: s for lag, s in spreads.items() if lag in BIN_COLUMNS_DETECTED and np.isfinite(s)}
    if not candidates:
        return None, summary
    best = min(candidates.values())
    period = min(lag for lag, s in candidates.items() if s <= 1.25 * best)
    others = [s for lag, s in spreads.items() if lag % period and np.isfinite(s)]
    if not others or not min(others) > 0 or not spreads[period] < 0.75 * min(others):
        return None, summary
    return period, summary


def read_float_records(path: str | Path, columns: int) -> np.ndarray:
    """The raw ``(N, columns)`` little-endian float32 records of a ``.bin`` (e.g. KITTI's 4), as stored.

    For callers that rewrite a cloud in the same layout (cropped or shuffled
    copies in tests and benchmarks); :func:`read_bin` is the checked reader.
    """
    data = np.fromfile(path, dtype="<f4")
    if data.size % columns:
        raise CalibError(f"{path}: {data.size} float32 values do not split into records of {columns}")
    return data.reshape(-1, columns)


def read_bin(path: Path, max_points: int, bin_columns: int | None = None, **_) -> PointCloud:
    """A ``.bin`` of float32 records of ``bin_columns`` values (detected when None)."""
    size = path.stat().st_size
    if size == 0:
        raise CalibError(f"{path}: the point cloud is empty (0 bytes)")
    if size % 4:
        raise CalibError(f"{path}: size {size} bytes is not a whole number of float32 values (a .bin holds float32 records)")
    n_values = size // 4
    with open(path, "rb") as handle:
        head = np.frombuffer(handle.read(4 * 240_000), dtype="<f4")
    detected, _ = detect_bin_columns(head)
    if bin_columns is not None:
        if isinstance(bin_columns, bool) or not isinstance(bin_columns, (int, np.integer)) or not 3 <= bin_columns <= 64:
            raise CalibError(f"bin_columns must be an integer from 3 to 64, got {bin_columns!r}")
        columns, how = int(bin_columns), "given"
        if n_values % columns:
            raise CalibError(
                f"{path}: {n_values} float32 values do not split into records of {columns} (--bin-columns {columns})"
            )
        if detected is not None and columns % detected:
            # The data say otherwise, clearly: a wrong option would misread every point.
            raise CalibError(
                f"{path}: --bin-columns {columns} does not fit the data, whose values repeat every {detected} "
                f"(pass --bin-columns {detected})"
            )
    else:
        columns, how = detected, "detected"
        if columns is None:
            raise CalibError(
                f"{path}: cannot tell how many float32 values make one point (KITTI 4, nuScenes 5, Waymo/SUN RGB-D 6); "
                f"pass --bin-columns N"
            )
        if n_values % columns:
            raise CalibError(
                f"{path}: the values repeat every {columns} but {n_values} values are not whole records of {columns}; "
                f"truncated? (or pass --bin-columns N)"
            )
    n_points = n_values // columns
    if n_points > max_points:
        raise too_many_points(path, "holds", n_points, max_points)
    data = read_float_records(path, columns)
    distance = np.linalg.norm(data[:, :3].astype(np.float64), axis=1)
    distance = distance[np.isfinite(distance)]
    if len(distance) and np.median(distance) < _SMALLEST_MEDIAN_RANGE_M:
        raise CalibError(
            f"{path}: read as {columns} float32 values per point, the median point is {np.median(distance):.3g} m "
            f"from the sensor: not points in metres (another layout? pass --bin-columns N)"
        )
    fields: dict[str, np.ndarray] = {}
    names = {3: "intensity"} if columns in (4, 5) else {}
    if columns == 5:
        ring = data[:, 4]
        # nuScenes / Lyft store the laser (ring) index as a float.
        if np.isfinite(ring).all() and (ring == np.round(ring)).all() and ring.min() >= 0 and ring.max() < 1024:
            names[4] = "ring"
    for column in range(3, columns):
        name = names.get(column, f"column{column}")
        fields[name] = data[:, column].astype(np.uint16) if name == "ring" else data[:, column].copy()
    return PointCloud(
        xyz=data[:, :3].astype(np.float64),
        fields=fields,
        meta={"format": "bin", "bin_columns": columns, "bin_columns_how": how},
    )
