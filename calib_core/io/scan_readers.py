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
``.pcd``   PCL's format, ascii / binary / binary_compressed, any fields,
           organized when ``HEIGHT > 1`` (read with pypcd4)
``.ply``   vertices and their properties (read with trimesh)
``.las``   LAS / LAZ (read with laspy; LAZ needs lazrs); scaled coordinates
``.laz``
``.bin``   KITTI velodyne: float32 ``x, y, z, reflectance`` per point
``.npy``   ``(N, 3)``, ``(N, 4)`` (4th column = intensity), ``(H, W, 3)`` or
           ``(H, W, 4)`` (organized), or a structured array with x, y, z
=========  ================================================================

Coordinates are taken as given: the lidar frame of the file, metres.  Every
problem with a file raises :class:`~calib_core.errors.CalibError` with a
one-line message naming the file.
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibError
from ..lidar.depth_matrix import DepthMatrix
from ..lidar.npz_format import load_depth_npz
from ..lidar.organize import RING_FIELD_NAMES
from ..lidar.organize_cloud import ORGANIZE_METHODS, organize_cloud  # noqa: F401  (ORGANIZE_METHODS: public choices)
from ..lidar.report import organize_report

SUPPORTED_EXTENSIONS = (".npz", ".pcd", ".ply", ".las", ".laz", ".bin", ".npy")



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


def _one_line(err: BaseException, limit: int = 160) -> str:
    """An exception as a short single line."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


# --------------------------------------------------------------------------
# PCD
# --------------------------------------------------------------------------

_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_PCD_TYPES = {("F", 4), ("F", 8), ("U", 1), ("U", 2), ("U", 4), ("U", 8), ("I", 1), ("I", 2), ("I", 4), ("I", 8)}


def _pcd_header(path: Path) -> tuple[dict[str, list[str]], int]:
    """Header entries of a PCD file (key -> values) and the byte offset of its data."""
    header: dict[str, list[str]] = {}
    offset = 0
    with open(path, "rb") as handle:
        for _ in range(200):
            raw = handle.readline()
            if not raw:
                break
            offset += len(raw)
            try:
                line = raw.decode("ascii").strip()
            except UnicodeDecodeError:
                raise CalibError(f"{path}: not a PCD file (binary bytes before the DATA line)") from None
            if not line or line.startswith("#"):
                continue
            key, *values = line.split()
            key = key.upper()
            if key not in _PCD_KEYS:
                raise CalibError(f"{path}: not a PCD file (unexpected header line '{line[:40]}')")
            header[key] = values
            if key == "DATA":
                return header, offset
    raise CalibError(f"{path}: not a PCD file (no DATA line in the header)")


def _check_pcd_header(path: Path, header: dict[str, list[str]]) -> dict[str, Any]:
    """Validate the header's consistency; return the parsed numbers."""
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "DATA"):
        if not header.get(key):
            raise CalibError(f"{path}: PCD header lacks {key}")
    names = header["FIELDS"]
    try:
        sizes = [int(v) for v in header["SIZE"]]
        counts = [int(v) for v in header.get("COUNT", ["1"] * len(names))]
        width, height = int(header["WIDTH"][0]), int(header["HEIGHT"][0])
        points = int(header["POINTS"][0]) if header.get("POINTS") else width * height
    except ValueError:
        raise CalibError(f"{path}: PCD header has a non-integer SIZE, COUNT, WIDTH, HEIGHT or POINTS") from None
    types = [t.upper() for t in header["TYPE"]]
    for key, values in (("SIZE", sizes), ("TYPE", types), ("COUNT", counts)):
        if len(values) != len(names):
            raise CalibError(f"{path}: PCD header has {len(names)} FIELDS but {len(values)} {key} entries")
    bad = [f"{n}:{t}{s}" for n, t, s in zip(names, types, sizes) if (t, s) not in _PCD_TYPES]
    if bad:
        raise CalibError(f"{path}: PCD header has unsupported field types {', '.join(bad)}")
    if min(counts) < 1 or width < 0 or height < 0:
        raise CalibError(f"{path}: PCD header has a non-positive COUNT or negative WIDTH/HEIGHT")
    if points != width * height:
        raise CalibError(f"{path}: PCD header says POINTS {points} but WIDTH x HEIGHT = {width} x {height}")
    missing = [axis for axis in "xyz" if axis not in names]
    if missing:
        raise CalibError(f"{path}: PCD has no {'/'.join(missing)} field (fields: {' '.join(names)})")
    encoding = header["DATA"][0].lower()
    if encoding not in ("ascii", "binary", "binary_compressed"):
        raise CalibError(f"{path}: PCD DATA '{encoding}' is not ascii, binary or binary_compressed")
    return {
        "names": names,
        "sizes": sizes,
        "counts": counts,
        "width": width,
        "height": height,
        "points": points,
        "encoding": encoding,
        "row_bytes": int(np.dot(sizes, counts)),
    }


def _read_pcd(path: Path) -> PointCloud:
    import pypcd4

    header, data_offset = _pcd_header(path)
    info = _check_pcd_header(path, header)
    n_points = info["points"]
    data_bytes = path.stat().st_size - data_offset
    # pypcd4 reads short binary data without complaint: check the sizes first.
    if info["encoding"] == "binary" and data_bytes < n_points * info["row_bytes"]:
        raise CalibError(
            f"{path}: truncated binary PCD: {data_bytes} data bytes for {n_points} points of {info['row_bytes']} bytes"
        )
    if info["encoding"] == "binary_compressed" and n_points > 0:
        with open(path, "rb") as handle:
            handle.seek(data_offset)
            sizes = handle.read(8)
        if len(sizes) < 8:
            raise CalibError(f"{path}: truncated binary_compressed PCD: no compressed-size header")
        compressed, uncompressed = struct.unpack("<II", sizes)
        if uncompressed != n_points * info["row_bytes"]:
            raise CalibError(
                f"{path}: corrupt binary_compressed PCD: {uncompressed} uncompressed bytes for {n_points} points "
                f"of {info['row_bytes']} bytes"
            )
        if data_bytes - 8 < compressed:
            raise CalibError(f"{path}: truncated binary_compressed PCD: {data_bytes - 8} of {compressed} compressed bytes")
    try:
        with open(path, "rb") as handle:
            cloud = pypcd4.PointCloud.from_fileobj(handle)
    except CalibError:
        raise
    except Exception as err:  # pypcd4, lzf and numpy raise many types; all mean "bad file"
        raise CalibError(f"{path}: unreadable {info['encoding']} PCD data ({_one_line(err)})") from None
    if cloud.pc_data is None:
        raise CalibError(f"{path}: unreadable {info['encoding']} PCD data")
    data = np.atleast_1d(cloud.pc_data)
    if len(data) != n_points:
        raise CalibError(f"{path}: truncated {info['encoding']} PCD: header says {n_points} points, file holds {len(data)}")

    xyz = np.stack([data[axis].astype(np.float64) for axis in "xyz"], axis=1) if n_points else np.zeros((0, 3))
    fields: dict[str, np.ndarray] = {}
    for name, count in zip(info["names"], info["counts"]):
        if name in ("x", "y", "z", "_"):
            continue  # "_" is PCL's padding
        if count == 1:
            fields[name] = np.ascontiguousarray(data[name]) if n_points else np.zeros(0)
        else:
            # pypcd4 splits COUNT > 1 fields into name__0000, name__0001, ...
            parts = [f"{name}__{i:04d}" for i in range(count)]
            fields[name] = np.stack([data[p] for p in parts], axis=1) if n_points else np.zeros((0, count))
    organized = (info["height"], info["width"]) if info["height"] > 1 else None
    meta: dict[str, Any] = {"format": "pcd", "encoding": info["encoding"]}
    viewpoint = [float(v) for v in header.get("VIEWPOINT", [])]
    if viewpoint and viewpoint != [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]:
        # Recorded, not applied: the points are returned in the file's frame.
        meta["viewpoint"] = viewpoint
    return PointCloud(xyz=xyz, fields=fields, organized_shape=organized, meta=meta)


# --------------------------------------------------------------------------
# PLY, LAS/LAZ, KITTI .bin
# --------------------------------------------------------------------------


def _read_ply(path: Path) -> PointCloud:
    import trimesh

    try:
        geometry = trimesh.load(str(path), file_type="ply", process=False)
    except Exception as err:  # trimesh raises ValueError, KeyError, IndexError, ... for bad files
        message = _one_line(err)
        if isinstance(err, KeyError):
            message = f"missing vertex property {message}"
        raise CalibError(f"{path}: unreadable PLY ({message})") from None
    vertices = getattr(geometry, "vertices", None)
    if vertices is None or len(vertices) == 0:
        raise CalibError(f"{path}: the point cloud is empty (PLY without vertices)")
    xyz = np.asarray(vertices, dtype=np.float64)
    fields: dict[str, np.ndarray] = {}
    raw = getattr(geometry, "metadata", {}).get("_ply_raw", {}).get("vertex", {}).get("data")
    if isinstance(raw, np.ndarray) and raw.dtype.names:
        columns = {name: raw[name] for name in raw.dtype.names}
    elif isinstance(raw, dict):
        columns = dict(raw)
    else:
        columns = {}
    for name, values in columns.items():
        values = np.asarray(values)
        if name in ("x", "y", "z") or values.dtype.kind not in "biuf" or len(values) != len(xyz):
            continue
        fields[name] = values.reshape(len(xyz), -1)[:, 0] if values.ndim > 1 and values.shape[1] == 1 else values
    return PointCloud(xyz=xyz, fields=fields, meta={"format": "ply"})


def _read_las(path: Path) -> PointCloud:
    import laspy

    try:
        las = laspy.read(str(path))
        xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1).astype(np.float64)
    except Exception as err:  # laspy, lazrs and numpy errors for bad or truncated files
        raise CalibError(f"{path}: unreadable LAS/LAZ ({_one_line(err)})") from None
    expected = int(las.header.point_count)
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


def _read_kitti_bin(path: Path) -> PointCloud:
    size = path.stat().st_size
    if size == 0:
        raise CalibError(f"{path}: the point cloud is empty (0 bytes)")
    if size % 16:
        raise CalibError(
            f"{path}: size {size} bytes is not a multiple of 16 (KITTI .bin holds float32 x, y, z, reflectance per point)"
        )
    data = np.fromfile(path, dtype="<f4").reshape(-1, 4)
    return PointCloud(
        xyz=data[:, :3].astype(np.float64),
        fields={"intensity": data[:, 3].copy()},
        meta={"format": "kitti_bin"},
    )


# --------------------------------------------------------------------------
# numpy files
# --------------------------------------------------------------------------


def _cloud_from_array(array: np.ndarray, path: Path, what: str) -> PointCloud:
    """A PointCloud from an array of the shapes documented for ``.npy``."""
    if array.dtype.names:
        missing = [axis for axis in "xyz" if axis not in array.dtype.names]
        if missing:
            raise CalibError(f"{path}: {what} has no {'/'.join(missing)} field (fields: {' '.join(array.dtype.names)})")
        flat = array.reshape(-1)
        xyz = np.stack([flat[axis].astype(np.float64) for axis in "xyz"], axis=1)
        fields = {n: flat[n].copy() for n in array.dtype.names if n not in "xyz" and flat[n].ndim == 1}
        organized = tuple(array.shape) if array.ndim == 2 and array.shape[0] > 1 else None
        return PointCloud(xyz=xyz, fields=fields, organized_shape=organized)
    if array.dtype.kind not in "biuf":
        raise CalibError(f"{path}: {what} must be numeric, got dtype {array.dtype}")
    if array.ndim == 2 and array.shape[1] in (3, 4):
        fields = {"intensity": array[:, 3].copy()} if array.shape[1] == 4 else {}
        return PointCloud(xyz=array[:, :3].astype(np.float64), fields=fields)
    if array.ndim == 3 and array.shape[2] in (3, 4):
        height, width = array.shape[:2]
        flat = array.reshape(-1, array.shape[2])
        fields = {"intensity": flat[:, 3].copy()} if array.shape[2] == 4 else {}
        return PointCloud(xyz=flat[:, :3].astype(np.float64), fields=fields, organized_shape=(height, width))
    raise CalibError(f"{path}: {what} has shape {array.shape}; expected (N, 3), (N, 4), (H, W, 3) or (H, W, 4)")


def _read_npy(path: Path) -> PointCloud:
    try:
        array = np.load(path, allow_pickle=False)
    except Exception as err:  # ValueError (pickles, bad header), OSError, EOFError
        raise CalibError(f"{path}: unreadable .npy ({_one_line(err)})") from None
    if not isinstance(array, np.ndarray):
        raise CalibError(f"{path}: holds several arrays; name it .npz")
    cloud = _cloud_from_array(array, path, "the array")
    return dataclasses.replace(cloud, meta={"format": "npy"})


def _read_npz(path: Path) -> PointCloud:
    try:
        with np.load(path, allow_pickle=False) as data:
            if not isinstance(data, np.lib.npyio.NpzFile):
                raise CalibError(f"{path}: holds a single array; name it .npy")
            if "model" in data.files:
                native = True
                arrays = {}
            else:
                native = False
                arrays = {key: data[key] for key in data.files}
    except CalibError:
        raise
    except Exception as err:  # BadZipFile, ValueError (pickled arrays), OSError, EOFError
        raise CalibError(f"{path}: unreadable .npz ({_one_line(err)})") from None
    if native:
        depth = load_depth_npz(path)
        return PointCloud(
            xyz=depth.points.reshape(-1, 3).copy(),
            organized_shape=depth.shape,
            meta={"format": "native_npz", "model": depth.meta.get("model")},
        )
    if {"x", "y", "z"} <= arrays.keys():
        columns = [arrays[axis] for axis in "xyz"]
        n = columns[0].shape[0] if columns[0].ndim == 1 else -1
        if any(c.ndim != 1 or c.shape[0] != n or c.dtype.kind not in "biuf" for c in columns):
            raise CalibError(f"{path}: arrays x, y, z must be numeric and 1-D of one length")
        xyz = np.stack(columns, axis=1).astype(np.float64)
        fields = {
            k: v for k, v in arrays.items() if k not in "xyz" and v.ndim == 1 and len(v) == n and v.dtype.kind in "biuf"
        }
        return PointCloud(xyz=xyz, fields=fields, meta={"format": "npz"})
    for key in ("points", "xyz"):
        if key in arrays:
            cloud = _cloud_from_array(arrays[key], path, f"array '{key}'")
            extra = {
                k: v
                for k, v in arrays.items()
                if k != key and v.ndim == 1 and len(v) == len(cloud.xyz) and v.dtype.kind in "biuf"
            }
            return dataclasses.replace(cloud, fields={**cloud.fields, **extra}, meta={"format": "npz"})
    if len(arrays) == 1:
        (key, array), = arrays.items()
        return dataclasses.replace(_cloud_from_array(array, path, f"array '{key}'"), meta={"format": "npz"})
    raise CalibError(
        f"{path}: .npz has neither 'model' (native scan), x/y/z nor 'points' arrays (keys: {', '.join(arrays) or 'none'})"
    )


_READERS = {
    ".pcd": _read_pcd,
    ".ply": _read_ply,
    ".las": _read_las,
    ".laz": _read_las,
    ".bin": _read_kitti_bin,
    ".npy": _read_npy,
    ".npz": _read_npz,
}


def _check_path(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise CalibError(f"scan file not found: {path}")
    if not path.is_file():
        raise CalibError(f"{path}: is not a file")
    if path.suffix.lower() not in _READERS:
        raise CalibError(
            f"{path}: unknown scan file type '{path.suffix or '(none)'}' (supported: {', '.join(SUPPORTED_EXTENSIONS)})"
        )
    return path


def read_point_cloud(path) -> PointCloud:
    """Read the points and per-point fields of a scan file.

    Parameters
    ----------
    path : str or Path
        A ``.pcd``, ``.ply``, ``.las``, ``.laz``, ``.bin`` (KITTI), ``.npy`` or
        ``.npz`` file (see the module docstring).  A native ``.npz`` scan
        gives the points of its depth matrix, organized.

    Returns
    -------
    PointCloud
        Points in the file's lidar frame, metres; ``meta["source"]`` is the path.

    Raises
    ------
    CalibError
        Missing file, unknown extension, bad header, truncated data, missing
        x/y/z, an empty cloud or one whose points are all NaN/inf.
    """
    path = _check_path(path)
    try:
        cloud = _READERS[path.suffix.lower()](path)
    except OSError as err:
        raise CalibError(f"{path}: cannot read ({err.strerror or _one_line(err)})") from None
    if len(cloud.xyz) == 0:
        raise CalibError(f"{path}: the point cloud is empty")
    if not np.isfinite(cloud.xyz).all(axis=1).any():
        raise CalibError(f"{path}: all {len(cloud.xyz)} points are NaN or inf")
    return dataclasses.replace(cloud, meta={**cloud.meta, "source": str(path)})


# --------------------------------------------------------------------------
# Scans as depth matrices
# --------------------------------------------------------------------------


def _is_native_npz(path: Path) -> bool:
    if path.suffix.lower() != ".npz":
        return False
    try:
        with np.load(path, allow_pickle=False) as data:
            return isinstance(data, np.lib.npyio.NpzFile) and "model" in data.files
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
) -> DepthMatrix:
    """Read a scan file as a depth matrix.

    Parameters
    ----------
    path : str or Path
        Any file :func:`read_point_cloud` reads; a native ``.npz`` (with a
        ``model`` key) is loaded with :func:`load_depth_npz` and the other
        options are ignored.
    organize : str
        How the cloud becomes a grid (see
        :func:`calib_core.lidar.organize_cloud.organize_cloud`):

        * ``"auto"`` -- an organized cloud keeps its grid; else the ring
          field if present; else the scan order when the points are stored
          laser after laser (KITTI); else elevation clustering when
          ``beams`` is given; else a spherical projection.  The report says
          which and why;
        * ``"organized"`` -- the file's own grid (error if it has none);
        * ``"ring"``, ``"elevation"``, ``"firing_order"`` (alias
          ``"firing"``), ``"spherical"`` -- force that method (an organized
          cloud is then treated as a flat list).
    beams : int, optional
        Number of beams, for ``"elevation"`` and ``"firing_order"``.
    n_cols : int, optional
        Azimuth columns for the beam-based methods (default: estimated).
    v_res_deg, h_res_deg, v_range_deg : optional
        Spherical projection grid (degrees); see :func:`organize_spherical`.
    wrap_cols : bool, optional
        For organized clouds: whether the columns close 360 degrees
        (default: detected from the azimuths).
    sensor_origin : (3,) float, optional
        Scanner position in the file's frame (metres), for scans stored in a
        world frame: the points are shifted so that it is the lidar origin.

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
        Bad file or options (see :func:`read_point_cloud`), or a cloud of
        which organising keeps too few points to be one sensor's view.
    """
    if organize not in ORGANIZE_METHODS:
        raise CalibError(f"unknown organize method '{organize}' (one of {', '.join(ORGANIZE_METHODS)})")
    path = _check_path(path)
    if _is_native_npz(path):
        depth = load_depth_npz(path)
        meta = {**depth.meta, "source": str(path), "format": "native_npz", "organize": "native"}
        meta["organize_report"] = organize_report(dataclasses.replace(depth, meta=meta), "native scan file")
        return dataclasses.replace(depth, meta=meta)

    cloud = read_point_cloud(path)
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

    meta = {**depth.meta, "source": str(path), "format": cloud.meta.get("format")}
    meta["field_images"] = _field_images(cloud, meta["point_index"])
    return dataclasses.replace(depth, meta=meta)
