"""LAS / LAZ files, read with laspy (LAZ through lazrs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import CalibError, one_line
from .cloud import PointCloud, too_many_points


def read_las(path: Path, max_points: int, **_) -> PointCloud:
    """A LAS / LAZ file's scaled coordinates, intensity, GPS time and extra dimensions."""
    import laspy

    try:
        with laspy.open(str(path)) as reader:
            header = reader.header
            expected = int(header.point_count)
            if expected > max_points:
                raise too_many_points(path, "LAS header declares", expected, max_points)
            if not header.are_points_compressed:
                needed = header.offset_to_point_data + expected * header.point_format.size
                if path.stat().st_size < needed:
                    raise CalibError(
                        f"{path}: truncated LAS: header declares {expected} points of {header.point_format.size} bytes "
                        f"after byte {header.offset_to_point_data}, the file has {path.stat().st_size} bytes"
                    )
            las = reader.read()
        xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1).astype(np.float64)
    except (KeyboardInterrupt, SystemExit, GeneratorExit, CalibError):
        raise
    except BaseException as err:  # noqa: BLE001 - lazrs panics raise pyo3's PanicException, a BaseException
        kind = "LAZ decoder failure: " if type(err).__name__ == "PanicException" else ""
        raise CalibError(f"{path}: unreadable LAS/LAZ ({kind}{one_line(err)})") from None
    if len(xyz) != expected:
        raise CalibError(f"{path}: truncated LAS/LAZ: header says {expected} points, file holds {len(xyz)}")
    fields: dict[str, np.ndarray] = {}
    dimension_names = set(las.point_format.dimension_names)
    for name in ("intensity", "gps_time", *las.point_format.extra_dimension_names):
        if name in dimension_names:
            values = np.asarray(las[name])
            if values.ndim == 1:
                fields[name] = values.copy()
    return PointCloud(xyz=xyz, fields=fields, meta={"format": path.suffix.lower().lstrip(".")})
