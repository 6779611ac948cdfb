"""Read laser scans from common point-cloud files and turn them into depth matrices.

Two entry points:

* :func:`read_point_cloud` -- the points and per-point fields of a file, as a
  :class:`PointCloud`, without any interpretation;
* :func:`load_scan` -- a :class:`~calib_core.lidar.depth_matrix.DepthMatrix`,
  organizing unorganized clouds with :mod:`calib_core.lidar.organize`.

Supported files (dispatch on the extension, case-insensitive):

=========  ================================================================
``.npz``   with a ``model`` key: the native scan (:func:`load_depth_npz`);
           otherwise arrays ``x``, ``y``, ``z`` (+ same-length fields), or
           ``points``/``xyz``, or a single array as for ``.npy``
``.pcd``   PCL's format, VERSION .5 to 0.7, ascii / binary /
           binary_compressed, any fields, organized when ``HEIGHT > 1`` and
           ``WIDTH > 1`` (decoded with pypcd4)
``.ply``   vertices and their properties as stored (read with trimesh)
``.las``   LAS / LAZ (read with laspy; LAZ needs lazrs); scaled coordinates
``.laz``
``.bin``   float32 records: KITTI ``x, y, z, reflectance`` (4 per point),
           nuScenes / Lyft ``x, y, z, intensity, ring`` (5), Waymo-KITTI or
           SUN RGB-D (6); the layout is detected or given (``bin_columns``)
``.npy``   ``(N, 3)``, ``(N, 4)`` (4th column = intensity), ``(H, W, 3)`` or
           ``(H, W, 4)`` (organized), or a structured array with x, y, z
=========  ================================================================

Field names ``X Y Z`` (PDAL) are accepted for ``x y z``.  Coordinates are
taken as given: the lidar frame of the file, metres.

Every file is checked before it is decoded: a regular file, at most
``max_points`` points (or grid cells) as declared by its header, and a size
that matches the declaration.  After decoding, a cloud needs at least
:data:`MIN_POINTS` finite points and no infinite or absurd coordinate.
Every problem raises :class:`~calib_core.errors.CalibError` with a one-line
message naming the file; what a library printed or warned meanwhile is folded
into that line instead of being printed.
"""

from __future__ import annotations

import dataclasses
import zipfile
from pathlib import Path

import numpy as np

from ..errors import CalibError, one_line
from ..lidar.depth_matrix import DepthMatrix
from ..lidar.npz_format import (
    DEFAULT_MAX_CELLS,
    MAX_ABS_COORDINATE_M,
    MAX_CELLS_OPTION,
    check_regular_file,
    load_depth_npz,
)
from ..lidar.organize import RING_FIELD_NAMES
from ..lidar.organize_cloud import ORGANIZE_METHODS, organize_cloud
from ..lidar.report import organize_report
from .point_clouds.cloud import PointCloud
from .point_clouds.float_bin import BIN_COLUMNS_DETECTED, detect_bin_columns, read_bin
from .point_clouds.las import read_las
from .point_clouds.numpy_files import read_npy, read_npz
from .point_clouds.pcd import read_pcd
from .point_clouds.ply import read_ply
from .quiet import library_output

__all__ = [
    "BIN_COLUMNS_DETECTED",
    "DEFAULT_MAX_POINTS",
    "MIN_POINTS",
    "ORGANIZE_METHODS",
    "SUPPORTED_EXTENSIONS",
    "PointCloud",
    "detect_bin_columns",
    "load_scan",
    "read_point_cloud",
]

SUPPORTED_EXTENSIONS = (".npz", ".pcd", ".ply", ".las", ".laz", ".bin", ".npy")


#: Default cap on the points of a cloud (and the cells of an organized grid); ``max_points`` raises it.
DEFAULT_MAX_POINTS = DEFAULT_MAX_CELLS
#: Fewest finite points a cloud must have: fewer cannot make a depth matrix with any neighbours.
MIN_POINTS = 3
#: Largest file accepted, in bytes per allowed point (an ASCII PCD line with many fields is < 256 bytes).
_FILE_BYTES_PER_POINT = 256


_READERS = {
    ".pcd": read_pcd,
    ".ply": read_ply,
    ".las": read_las,
    ".laz": read_las,
    ".bin": read_bin,
    ".npy": read_npy,
    ".npz": read_npz,
}


def _check_max_points(max_points) -> int:
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)) or max_points < MIN_POINTS:
        raise CalibError(f"max_points must be an integer of at least {MIN_POINTS}, got {max_points!r}")
    return int(max_points)


def _check_path(path, max_points: int = DEFAULT_MAX_POINTS) -> Path:
    path = Path(path)
    info = check_regular_file(path)
    if path.suffix.lower() not in _READERS:
        raise CalibError(
            f"{path}: unknown scan file type '{path.suffix or '(none)'}' (supported: {', '.join(SUPPORTED_EXTENSIONS)})"
        )
    limit = max_points * _FILE_BYTES_PER_POINT
    if info.st_size > limit:
        raise CalibError(
            f"{path}: the file has {info.st_size:,} bytes, more than {_FILE_BYTES_PER_POINT} for each of the "
            f"{max_points:,} points allowed (raise the limit with {MAX_CELLS_OPTION})"
        )
    return path


def _check_points(path: Path, cloud: PointCloud) -> None:
    """Refuse clouds too small to use and coordinates that are not measurements."""
    xyz = cloud.xyz
    if len(xyz) == 0:
        raise CalibError(f"{path}: the point cloud is empty")
    infinite = np.isinf(xyz).any(axis=1)
    if infinite.any():
        raise CalibError(f"{path}: {int(infinite.sum())} of {len(xyz)} points have an infinite coordinate")
    good = np.isfinite(xyz).all(axis=1)
    n_good = int(good.sum())
    if n_good == 0:
        raise CalibError(f"{path}: all {len(xyz)} points are NaN or inf")
    if n_good < MIN_POINTS:
        raise CalibError(f"{path}: only {n_good} finite point(s); a scan needs at least {MIN_POINTS}")
    largest = float(np.max(np.abs(xyz[good])))
    if largest > MAX_ABS_COORDINATE_M:
        raise CalibError(f"{path}: a coordinate of {largest:.3g}: not metres in a sensor frame")


#: An axis along which the points spread less than this share of their largest extent is no extent.
FLAT_EXTENT_SHARE = 1e-6


def _check_three_dimensional(path: Path, cloud: PointCloud) -> None:
    """Refuse 2-D data stored as a point cloud: no extent along x, y or z (PCL's lena.pcd: pixels, z = 0)."""
    xyz = cloud.xyz[np.isfinite(cloud.xyz).all(axis=1)]
    extent = np.ptp(xyz, axis=0)
    flat = extent <= FLAT_EXTENT_SHARE * extent.max()
    if flat.any():
        axis = int(np.argmax(flat))
        raise CalibError(
            f"{path}: not a 3-D scan: all {len(xyz)} points have {'xyz'[axis]} = {xyz[0, axis]:.6g} "
            f"(no extent along {'xyz'[axis]}; 2-D data such as an image stored as a point cloud?)"
        )


#: Fewest rows and columns of a depth matrix: every Bearing Angle trace needs a previous neighbour.
MIN_GRID_SIDE = 2


def _check_grid(path: Path, depth: DepthMatrix) -> None:
    """Refuse a depth matrix of one row or one column: a single scan line, too small for BA images."""
    rows, cols = depth.shape
    if min(rows, cols) < MIN_GRID_SIDE:
        raise CalibError(
            f"{path}: the scan is a {rows} x {cols} depth matrix, a single line: too small for Bearing Angle images "
            f"(at least {MIN_GRID_SIDE} x {MIN_GRID_SIDE} cells; a 3-D scan is needed)"
        )


def read_point_cloud(path, bin_columns: int | None = None, max_points: int = DEFAULT_MAX_POINTS) -> PointCloud:
    """Read the points and per-point fields of a scan file.

    Parameters
    ----------
    path : str or Path
        A ``.pcd``, ``.ply``, ``.las``, ``.laz``, ``.bin``, ``.npy`` or
        ``.npz`` file (see the module docstring).  A native ``.npz`` scan
        gives the points of its depth matrix, organized.
    bin_columns : int, optional
        Float32 values per point of a ``.bin`` file (KITTI 4, nuScenes 5,
        Waymo-KITTI / SUN RGB-D 6); detected when not given.  Ignored for
        other files.
    max_points : int
        Refuse files declaring more points or grid cells (checked from the
        header, before decoding) and files larger than 256 bytes per point.

    Returns
    -------
    PointCloud
        Points in the file's lidar frame, metres; ``meta["source"]`` is the path.

    Raises
    ------
    CalibError
        Missing or non-regular file, unknown extension, bad header, declared
        counts that the data does not match, truncated data, missing x/y/z,
        fewer than :data:`MIN_POINTS` finite points, an infinite coordinate or
        one beyond 1e8 m, more than ``max_points``.
    """
    max_points = _check_max_points(max_points)
    path = _check_path(path, max_points)
    with library_output() as said:
        try:
            with np.errstate(all="ignore"):
                cloud = _READERS[path.suffix.lower()](path, max_points=max_points, bin_columns=bin_columns)
        except CalibError as err:
            raise CalibError(f"{err}{said.suffix()}") from None
        except OSError as err:
            raise CalibError(f"{path}: cannot read ({err.strerror or one_line(err)}){said.suffix()}") from None
        except MemoryError:
            raise CalibError(f"{path}: not enough memory to read the file{said.suffix()}") from None
    _check_points(path, cloud)
    return dataclasses.replace(cloud, meta={**cloud.meta, "source": str(path)})


# --------------------------------------------------------------------------
# Scans as depth matrices
# --------------------------------------------------------------------------


def _is_native_npz(path: Path) -> bool:
    if path.suffix.lower() != ".npz":
        return False
    try:
        with zipfile.ZipFile(path) as archive:
            return "model.npy" in archive.namelist()
    except Exception:  # unreadable: let read_point_cloud report it
        return False


def _field_images(cloud: PointCloud, point_index: np.ndarray) -> dict[str, np.ndarray]:
    """Per-cell images (float64, NaN where empty) of the cloud's 1-D numeric fields."""
    images = {}
    has = point_index >= 0
    for name, values in cloud.fields.items():
        if values.ndim != 1 or values.dtype.kind not in "biuf":
            continue
        image = np.full(point_index.shape, np.nan)
        image[has] = values[point_index[has]]
        images[name] = image
    return images


def load_scan(
    path,
    organize: str = "auto",
    beams: int | None = None,
    n_cols: int | None = None,
    v_res_deg: float | None = None,
    h_res_deg: float | None = None,
    v_range_deg: tuple[float, float] | None = None,
    wrap_cols: bool | None = None,
    sensor_origin=None,
    bin_columns: int | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
) -> DepthMatrix:
    """Read a scan file as a depth matrix.

    Parameters
    ----------
    path : str or Path
        Any file :func:`read_point_cloud` reads; a native ``.npz`` (with a
        ``model`` key) is loaded with :func:`load_depth_npz` and the other
        options are ignored.
    organize, beams, n_cols, v_res_deg, h_res_deg, v_range_deg, wrap_cols, sensor_origin
        How the cloud becomes a grid: see :func:`calib_core.lidar.organize_cloud.organize_cloud`
        (the report says which method and why).
    bin_columns : int, optional
        Float32 values per point of a ``.bin`` file; see :func:`read_point_cloud`.
    max_points : int
        Cap on the points (or cells) read from the file; see :func:`read_point_cloud`.

    Returns
    -------
    DepthMatrix
        Lidar frame, metres.  ``meta`` holds ``source``, ``format``,
        ``organize`` (the method used), ``organize_report`` (an
        :class:`~calib_core.lidar.report.OrganizeReport`: method, reason,
        rows x columns, cells valid, points kept; ``.line()`` is the one
        line the CLI prints) and the method's parameters and counts; for
        clouds, ``point_index`` ((H, W) index of each cell's point in the
        file, -1 where empty) and ``field_images`` (per-cell images of the
        1-D fields, e.g. intensity, NaN where empty).

    Raises
    ------
    CalibError
        Bad file or options (see :func:`read_point_cloud`), a cloud with no
        extent along x, y or z (not a 3-D scan), a cloud of which organising
        keeps too few points to be one sensor's view, or a depth matrix of a
        single row or column (too small for Bearing Angle images).
    """
    if organize not in ORGANIZE_METHODS:
        raise CalibError(f"unknown organize method '{organize}' (one of {', '.join(ORGANIZE_METHODS)})")
    max_points = _check_max_points(max_points)
    path = _check_path(path, max_points)
    if _is_native_npz(path):
        depth = load_depth_npz(path, max_cells=max_points)
        _check_grid(path, depth)
        meta = {**depth.meta, "source": str(path), "format": "native_npz", "organize": "native"}
        meta["organize_report"] = organize_report(dataclasses.replace(depth, meta=meta), "native scan file")
        return dataclasses.replace(depth, meta=meta)

    cloud = read_point_cloud(path, bin_columns=bin_columns, max_points=max_points)
    _check_three_dimensional(path, cloud)
    ring = cloud.ring_field()
    ring_name = next((name for name in RING_FIELD_NAMES if cloud.fields.get(name) is ring), "ring")
    try:
        depth = organize_cloud(
            cloud.xyz,
            ring=ring,
            ring_name=ring_name,
            organized_shape=cloud.organized_shape,
            organize=organize,
            beams=beams,
            n_cols=n_cols,
            v_res_deg=v_res_deg,
            h_res_deg=h_res_deg,
            v_range_deg=v_range_deg,
            wrap_cols=wrap_cols,
            sensor_origin=sensor_origin,
        )
    except CalibError as err:
        raise CalibError(f"{path}: {err}") from None

    _check_grid(path, depth)
    meta = {**depth.meta, "source": str(path), "format": cloud.meta.get("format")}
    meta["field_images"] = _field_images(cloud, meta["point_index"])
    return dataclasses.replace(depth, meta=meta)
