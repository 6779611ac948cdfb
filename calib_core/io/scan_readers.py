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
import io
import math
import struct
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibError
from ..lidar.depth_matrix import DepthMatrix
from ..lidar.npz_format import (
    DEFAULT_MAX_CELLS,
    MAX_ABS_COORDINATE_M,
    MAX_CELLS_OPTION,
    check_regular_file,
    load_depth_npz,
    npz_members,
)
from ..lidar.organize import (
    RING_FIELD_NAMES,
    default_spherical_resolution_deg,
    organize_by_elevation,
    organize_by_firing_order,
    organize_by_ring,
    organize_grid,
    organize_spherical,
)
from .quiet import library_output

SUPPORTED_EXTENSIONS = (".npz", ".pcd", ".ply", ".las", ".laz", ".bin", ".npy")

#: ``load_scan(organize=...)`` choices; "firing" is a short alias of "firing_order".
ORGANIZE_METHODS = ("auto", "organized", "ring", "elevation", "firing_order", "firing", "spherical")

#: Default cap on the points of a cloud (and the cells of an organized grid); ``max_points`` raises it.
DEFAULT_MAX_POINTS = DEFAULT_MAX_CELLS
#: Fewest finite points a cloud must have: fewer cannot make a depth matrix with any neighbours.
MIN_POINTS = 3
#: Largest file accepted, in bytes per allowed point (an ASCII PCD line with many fields is < 256 bytes).
_FILE_BYTES_PER_POINT = 256
#: Float32 values per point the ``.bin`` layout detection considers.
BIN_COLUMNS_DETECTED = (3, 4, 5, 6, 7, 8)


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


def _too_many(path: Path, what: str, count: int, max_points: int) -> CalibError:
    return CalibError(
        f"{path}: {what} {count:,} points, above the limit of {max_points:,} (raise it with {MAX_CELLS_OPTION})"
    )


def _xyz_names(path: Path, names, what: str) -> tuple[str, str, str]:
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


def _ends_mid_line(data: bytes) -> bool:
    """Text data that may have been cut in the middle of its last number.

    A final line without an end of line is accepted only when its last
    number has the same width as the last number of every line before it
    (fixed-width writers such as ``%f``), so a cut number cannot pass.
    """
    stripped = data.rstrip(b" \t\r\x00")
    if not stripped or stripped.endswith(b"\n"):
        return False
    lines = [line.split() for line in stripped[-65536:].split(b"\n")[1:]]
    lines = [words for words in lines if words]
    if len(lines) < 2:
        return True
    widths = {len(words[-1].lstrip(b"+-")) for words in lines[:-1]}
    return widths != {len(lines[-1][-1].lstrip(b"+-"))}


def _normalise_text(data: bytes) -> bytes:
    """ASCII records with single spaces between values and one point per line.

    PCL splits on blanks and tabs, PDAL also on commas; pypcd4 and trimesh
    split on single spaces.  Empty lines are dropped.
    """
    data = data.translate(bytes.maketrans(b",\t\r\x00", b"    "))
    if b"  " in data or b" \n" in data or b"\n " in data or data.startswith(b" ") or b"\n\n" in data:
        data = b"\n".join(b" ".join(words) for line in data.split(b"\n") if (words := line.split()))
    return data.strip(b" \n") + b"\n"


# --------------------------------------------------------------------------
# PCD
# --------------------------------------------------------------------------

_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_PCD_TYPES = {("F", 4), ("F", 8), ("U", 1), ("U", 2), ("U", 4), ("U", 8), ("I", 1), ("I", 2), ("I", 4), ("I", 8)}
#: Header versions PCL has written; their layout is the same for what we read.
_PCD_VERSIONS = {".5", "0.5", ".6", "0.6", ".7", "0.7"}


def _pcd_header(path: Path) -> tuple[dict[str, list[str]], int]:
    """Header entries of a PCD file (key -> values) and the byte offset of its data."""
    header: dict[str, list[str]] = {}
    offset = 0
    with open(path, "rb") as handle:
        for _ in range(200):
            raw = handle.readline(4096)
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
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "DATA"):
        if not header.get(key):
            raise CalibError(f"{path}: PCD header lacks {key}")
    version = (header.get("VERSION") or ["0.7"])[0]
    if version not in _PCD_VERSIONS:
        raise CalibError(f"{path}: PCD VERSION {version[:20]} is not one PCL wrote (.5, .6 or 0.7)")
    names = header["FIELDS"]
    try:
        sizes = [int(v) for v in header["SIZE"]]
        counts = [int(v) for v in header.get("COUNT", ["1"] * len(names))]
        # VERSION .5 files may omit HEIGHT: a flat list.
        width, height = int(header["WIDTH"][0]), int((header.get("HEIGHT") or ["1"])[0])
        points = int(header["POINTS"][0]) if header.get("POINTS") else width * height
    except ValueError:
        raise CalibError(f"{path}: PCD header has a non-integer SIZE, COUNT, WIDTH, HEIGHT or POINTS") from None
    types = [t.upper() for t in header["TYPE"]]
    for key, values in (("SIZE", sizes), ("TYPE", types), ("COUNT", counts)):
        if len(values) != len(names):
            raise CalibError(f"{path}: PCD header has {len(names)} FIELDS but {len(values)} {key} entries")
    if len(set(names)) != len(names):
        raise CalibError(f"{path}: PCD header names a field twice (FIELDS {' '.join(names)})")
    bad = [f"{n}:{t}{s}" for n, t, s in zip(names, types, sizes) if (t, s) not in _PCD_TYPES]
    if bad:
        raise CalibError(f"{path}: PCD header has unsupported field types {', '.join(bad)}")
    if min(counts) < 1 or width < 0 or height < 0:
        raise CalibError(f"{path}: PCD header has a non-positive COUNT or negative WIDTH/HEIGHT")
    if points != width * height:
        raise CalibError(f"{path}: PCD header says POINTS {points} but WIDTH x HEIGHT = {width} x {height}")
    axes = _xyz_names(path, names, "PCD")
    for axis in axes:
        if counts[names.index(axis)] != 1:
            raise CalibError(f"{path}: PCD field {axis} has COUNT {counts[names.index(axis)]}; x, y and z need COUNT 1")
    encoding = header["DATA"][0].lower()
    if encoding not in ("ascii", "binary", "binary_compressed"):
        raise CalibError(f"{path}: PCD DATA '{encoding[:20]}' is not ascii, binary or binary_compressed")
    viewpoint = header.get("VIEWPOINT") or ["0", "0", "0", "1", "0", "0", "0"]
    try:
        viewpoint_values = [float(v) for v in viewpoint]
    except ValueError:
        raise CalibError(f"{path}: PCD VIEWPOINT is not 7 numbers") from None
    if len(viewpoint_values) != 7 or not np.isfinite(viewpoint_values).all():
        raise CalibError(f"{path}: PCD VIEWPOINT is not 7 finite numbers")
    return {
        "names": names,
        "sizes": sizes,
        "types": types,
        "counts": counts,
        "width": width,
        "height": height,
        "points": points,
        "axes": axes,
        "encoding": encoding,
        "viewpoint": viewpoint_values,
        "row_bytes": int(np.dot(sizes, counts)),
    }


def _refuse_trailing(path: Path, extra: int, row_bytes: int, n_points: int) -> None:
    """More data after the declared points than a padding byte or two: the counts are wrong."""
    if extra >= max(row_bytes, 16):
        raise CalibError(
            f"{path}: the PCD holds {extra:,} bytes after the {n_points:,} points its header declares "
            f"(at least {extra // max(row_bytes, 1):,} more points?)"
        )


def _pcd_ascii_check(path: Path, data: bytes, n_points: int, values_per_point: int) -> None:
    """Every data line holds one point's values; the last line is complete."""
    codes = np.frombuffer(data, dtype=np.uint8)
    space = (codes == 32) | (codes == 10)
    starts = ~space & np.concatenate(([True], space[:-1]))
    line_of_token = np.cumsum(codes == 10)[starts]
    lines, per_line = np.unique(line_of_token, return_counts=True)
    if len(lines) != n_points:
        raise CalibError(f"{path}: truncated or padded ascii PCD: header says {n_points} points, data has {len(lines)} lines")
    wrong = np.flatnonzero(per_line != values_per_point)
    if len(wrong):
        raise CalibError(
            f"{path}: ascii PCD point {wrong[0] + 1} has {per_line[wrong[0]]} values, "
            f"the header declares {values_per_point} per point"
        )


def _read_pcd(path: Path, max_points: int, **_) -> PointCloud:
    import pypcd4

    header, data_offset = _pcd_header(path)
    info = _check_pcd_header(path, header)
    n_points = info["points"]
    if n_points > max_points:
        raise _too_many(path, "PCD header declares", n_points, max_points)
    data_bytes = path.stat().st_size - data_offset
    needed = n_points * info["row_bytes"]
    values_per_point = sum(info["counts"])
    encoding = info["encoding"]
    with open(path, "rb") as handle:
        handle.seek(data_offset)
        if encoding == "binary":
            # pypcd4 reads short binary data without complaint: check the sizes first.
            if data_bytes < needed:
                raise CalibError(
                    f"{path}: truncated binary PCD: {data_bytes} data bytes for {n_points} points of {info['row_bytes']} bytes"
                )
            data = handle.read(needed)
            _refuse_trailing(path, data_bytes - needed, info["row_bytes"], n_points)
        elif encoding == "binary_compressed":
            sizes = handle.read(8) if n_points else b"\0" * 8
            if len(sizes) < 8:
                raise CalibError(f"{path}: truncated binary_compressed PCD: no compressed-size header")
            compressed, uncompressed = struct.unpack("<II", sizes)
            if uncompressed != needed:
                raise CalibError(
                    f"{path}: corrupt binary_compressed PCD: {uncompressed} uncompressed bytes for {n_points} points "
                    f"of {info['row_bytes']} bytes"
                )
            if data_bytes - 8 < compressed:
                raise CalibError(
                    f"{path}: truncated binary_compressed PCD: {max(data_bytes - 8, 0)} of {compressed} compressed bytes"
                )
            # No check of what follows: PCL's own writer leaves a few kB after the compressed block.
            data = sizes + handle.read(compressed)
        else:
            # The shortest point is one digit and a separator per value.
            if data_bytes < 2 * values_per_point * n_points:
                raise CalibError(
                    f"{path}: truncated ascii PCD: {data_bytes} data bytes cannot hold the {n_points} points the header declares"
                )
            data = handle.read()
            if _ends_mid_line(data):
                tail = data.rstrip()[-30:].decode("ascii", "replace").split("\n")[-1]
                raise CalibError(
                    f"{path}: truncated ascii PCD: the last line '{tail}' has no end of line and its last number "
                    f"is narrower than those above it (cut off mid-number?)"
                )
            data = _normalise_text(data)
            _pcd_ascii_check(path, data, n_points, values_per_point)
    # pypcd4 only takes VERSION 0.7 headers: hand it a normalised one (the data layout is the same).
    normalised = "\n".join(
        [
            "VERSION 0.7",
            "FIELDS " + " ".join(info["names"]),
            "SIZE " + " ".join(map(str, info["sizes"])),
            "TYPE " + " ".join(info["types"]),
            "COUNT " + " ".join(map(str, info["counts"])),
            f"WIDTH {info['width']}",
            f"HEIGHT {info['height']}",
            "VIEWPOINT " + " ".join(map(repr, info["viewpoint"])),
            f"POINTS {n_points}",
            f"DATA {encoding}",
            "",
        ]
    ).encode()
    try:
        cloud = pypcd4.PointCloud.from_fileobj(io.BytesIO(normalised + data))
    except Exception as err:  # pypcd4, lzf and numpy raise many types; all mean "bad file"
        raise CalibError(f"{path}: unreadable {encoding} PCD data ({_one_line(err)})") from None
    if cloud.pc_data is None:
        raise CalibError(f"{path}: unreadable {encoding} PCD data")
    data = np.atleast_1d(cloud.pc_data)
    if len(data) != n_points:
        raise CalibError(f"{path}: truncated {encoding} PCD: header says {n_points} points, file holds {len(data)}")

    xyz = np.stack([data[axis].astype(np.float64) for axis in info["axes"]], axis=1) if n_points else np.zeros((0, 3))
    fields: dict[str, np.ndarray] = {}
    for name, count in zip(info["names"], info["counts"]):
        if name in info["axes"] or name == "_":
            continue  # "_" is PCL's padding
        if count == 1:
            fields[name] = np.ascontiguousarray(data[name]) if n_points else np.zeros(0)
        else:
            # pypcd4 splits COUNT > 1 fields into name__0000, name__0001, ...
            parts = [f"{name}__{i:04d}" for i in range(count)]
            fields[name] = np.stack([data[p] for p in parts], axis=1) if n_points else np.zeros((0, count))
    # A grid needs two dimensions: PCL writes unorganised lists as WIDTH N HEIGHT 1 and some writers
    # as WIDTH 1 HEIGHT N; both are flat.
    organized = (info["height"], info["width"]) if info["height"] > 1 and info["width"] > 1 else None
    meta: dict[str, Any] = {"format": "pcd", "encoding": encoding, "version": (header.get("VERSION") or ["0.7"])[0]}
    if info["viewpoint"] != [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]:
        # Recorded, not applied: the points are returned in the file's frame.
        meta["viewpoint"] = info["viewpoint"]
    return PointCloud(xyz=xyz, fields=fields, organized_shape=organized, meta=meta)


# --------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------

_PLY_SCALAR_BYTES = {
    "char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
    "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8,
}


def _ply_header(path: Path) -> tuple[str, list[tuple[str, int, int]], int]:
    """The PLY format, its elements as (name, count, smallest bytes per row) and the data offset."""
    elements: list[list] = []
    fmt = None
    offset = 0
    with open(path, "rb") as handle:
        if handle.read(4).rstrip(b"\r\n") != b"ply":
            raise CalibError(f"{path}: not a PLY file (it does not start with 'ply')")
        handle.seek(0)
        for _ in range(10_000):
            raw = handle.readline(4096)
            if not raw:
                break
            offset += len(raw)
            try:
                words = raw.decode("ascii").split()
            except UnicodeDecodeError:
                raise CalibError(f"{path}: not a PLY file (binary bytes before end_header)") from None
            if not words:
                continue
            if words[0] == "format" and len(words) >= 2:
                fmt = words[1]
            elif words[0] == "element" and len(words) != 3:
                raise CalibError(f"{path}: PLY header line '{' '.join(words)[:60]}' is not 'element NAME COUNT'")
            elif words[0] == "element":
                try:
                    count = int(words[2])
                except ValueError:
                    raise CalibError(f"{path}: PLY element '{words[1]}' has a non-integer count '{words[2][:20]}'") from None
                if count < 0:
                    raise CalibError(f"{path}: PLY element '{words[1]}' has a negative count")
                elements.append([words[1], count, 0])
            elif words[0] == "property" and elements:
                if len(words) >= 5 and words[1] == "list":
                    size = _PLY_SCALAR_BYTES.get(words[2])  # an empty list still stores its length
                else:
                    size = _PLY_SCALAR_BYTES.get(words[1]) if len(words) >= 3 else None
                if size is None:
                    raise CalibError(f"{path}: PLY property line '{' '.join(words)[:60]}' has an unknown type")
                elements[-1][2] += size
            elif words[0] == "end_header":
                if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                    raise CalibError(f"{path}: PLY format '{fmt}' is not ascii or binary")
                return fmt, [tuple(e) for e in elements], offset
    raise CalibError(f"{path}: not a PLY file (no end_header)")


def _read_ply(path: Path, max_points: int, **_) -> PointCloud:
    fmt, elements, data_offset = _ply_header(path)
    vertex = [e for e in elements if e[0] == "vertex"]
    if not vertex or vertex[0][1] == 0:
        raise CalibError(f"{path}: the point cloud is empty (PLY without vertices)")
    n_vertices = vertex[0][1]
    if n_vertices > max_points:
        raise _too_many(path, "PLY header declares", n_vertices, max_points)
    data_bytes = path.stat().st_size - data_offset
    # Smallest data the header's element counts need: binary rows as declared (lists empty),
    # ASCII rows one digit and a separator per value.
    smallest = sum(count * (row if fmt != "ascii" else 2) for _, count, row in elements)
    if data_bytes < smallest:
        counts = ", ".join(f"{count:,} {name}" for name, count, _ in elements)
        raise CalibError(f"{path}: truncated PLY: {data_bytes:,} data bytes cannot hold the declared {counts}")
    if fmt == "ascii" and _ends_mid_line(path.read_bytes()[data_offset:]):
        raise CalibError(
            f"{path}: truncated ascii PLY: the last line has no end of line and its last number is narrower "
            f"than those above it (cut off mid-number?)"
        )
    import trimesh  # after the checks: it takes a second to import

    try:
        # Vertices as stored: no texture re-indexing (which duplicates vertices), no texture file lookup.
        geometry = trimesh.load(str(path), file_type="ply", process=False, fix_texture=False, skip_materials=True)
    except Exception as err:  # trimesh raises ValueError, KeyError, IndexError, ... for bad files
        message = _one_line(err)
        if isinstance(err, KeyError):
            message = f"missing vertex property {message}"
        raise CalibError(f"{path}: unreadable PLY ({message})") from None
    vertices = getattr(geometry, "vertices", None)
    if vertices is None or len(vertices) == 0:
        raise CalibError(f"{path}: the point cloud is empty (PLY without vertices)")
    if len(vertices) != n_vertices:
        raise CalibError(f"{path}: PLY header declares {n_vertices} vertices, trimesh read {len(vertices)}")
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
    return PointCloud(xyz=xyz, fields=fields, meta={"format": "ply", "encoding": fmt})


# --------------------------------------------------------------------------
# LAS / LAZ
# --------------------------------------------------------------------------


def _read_las(path: Path, max_points: int, **_) -> PointCloud:
    import laspy

    try:
        with laspy.open(str(path)) as reader:
            header = reader.header
            expected = int(header.point_count)
            if expected > max_points:
                raise _too_many(path, "LAS header declares", expected, max_points)
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
        raise CalibError(f"{path}: unreadable LAS/LAZ ({kind}{_one_line(err)})") from None
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


# --------------------------------------------------------------------------
# .bin: float32 records of 3 to 64 values
# --------------------------------------------------------------------------


def _lag_spread(values: np.ndarray, lag: int) -> float:
    """Median change between values ``lag`` apart, on a log-like scale (asinh)."""
    if len(values) <= lag:
        return float("nan")
    squashed = np.arcsinh(values)
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
    spreads = {lag: _lag_spread(finite, lag) for lag in range(1, max(BIN_COLUMNS_DETECTED) + 1)}
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


def _read_bin(path: Path, max_points: int, bin_columns: int | None = None, **_) -> PointCloud:
    size = path.stat().st_size
    if size == 0:
        raise CalibError(f"{path}: the point cloud is empty (0 bytes)")
    if size % 4:
        raise CalibError(f"{path}: size {size} bytes is not a whole number of float32 values (a .bin holds float32 records)")
    n_values = size // 4
    if bin_columns is not None:
        if isinstance(bin_columns, bool) or not isinstance(bin_columns, (int, np.integer)) or not 3 <= bin_columns <= 64:
            raise CalibError(f"bin_columns must be an integer from 3 to 64, got {bin_columns!r}")
        columns, how = int(bin_columns), "given"
        if n_values % columns:
            raise CalibError(
                f"{path}: {n_values} float32 values do not split into records of {columns} (--bin-columns {columns})"
            )
    else:
        with open(path, "rb") as handle:
            head = np.frombuffer(handle.read(4 * 240_000), dtype="<f4")
        columns, spreads = detect_bin_columns(head)
        how = "detected"
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
        raise _too_many(path, "holds", n_points, max_points)
    data = np.fromfile(path, dtype="<f4").reshape(n_points, columns)
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


# --------------------------------------------------------------------------
# numpy files
# --------------------------------------------------------------------------


def _cloud_from_array(array: np.ndarray, path: Path, what: str) -> PointCloud:
    """A PointCloud from an array of the shapes documented for ``.npy``."""
    if array.dtype.names:
        axes = _xyz_names(path, array.dtype.names, what)
        flat = array.reshape(-1)
        if any(flat[axis].ndim != 1 or flat.dtype[axis].kind not in "biuf" for axis in axes):
            raise CalibError(f"{path}: {what}'s x, y, z fields must be single numbers")
        xyz = np.stack([flat[axis].astype(np.float64) for axis in axes], axis=1)
        fields = {n: flat[n].copy() for n in array.dtype.names if n not in axes and flat[n].ndim == 1}
        organized = tuple(array.shape) if array.ndim == 2 and min(array.shape) > 1 else None
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
        organized = (height, width) if min(height, width) > 1 else None
        return PointCloud(xyz=flat[:, :3].astype(np.float64), fields=fields, organized_shape=organized)
    raise CalibError(f"{path}: {what} has shape {array.shape}; expected (N, 3), (N, 4), (H, W, 3) or (H, W, 4)")


def _check_array_shape(path: Path, shape: tuple[int, ...], dtype: np.dtype, what: str) -> None:
    """The shapes :func:`_cloud_from_array` takes, checked from a header before loading."""
    if dtype.names:
        _xyz_names(path, dtype.names, what)
        return
    if dtype.kind not in "biuf":
        raise CalibError(f"{path}: {what} must be numeric, got dtype {dtype}")
    if not (len(shape) in (2, 3) and shape[-1] in (3, 4)):
        raise CalibError(f"{path}: {what} has shape {shape}; expected (N, 3), (N, 4), (H, W, 3) or (H, W, 4)")


def _array_points(shape: tuple[int, ...], dtype: np.dtype) -> int:
    """Points an array of this shape would give (its cells without the x/y/z axis)."""
    if dtype.names or len(shape) < 2:
        return math.prod(shape)
    return math.prod(shape[:-1])


def _read_npy(path: Path, max_points: int, **_) -> PointCloud:
    try:
        # Memory-mapped first: the header is checked against the file size without reading the data.
        mapped = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as err:  # ValueError (pickles, bad header, short file), OSError, EOFError
        raise CalibError(f"{path}: unreadable .npy ({_one_line(err)})") from None
    if not isinstance(mapped, np.ndarray):
        raise CalibError(f"{path}: holds several arrays; name it .npz")
    _check_array_shape(path, mapped.shape, mapped.dtype, "the array")
    count = _array_points(mapped.shape, mapped.dtype)
    if count > max_points:
        raise _too_many(path, "holds", count, max_points)
    array = np.array(mapped)
    del mapped
    cloud = _cloud_from_array(array, path, "the array")
    return dataclasses.replace(cloud, meta={"format": "npy"})


def _read_npz(path: Path, max_points: int, **_) -> PointCloud:
    members = npz_members(path)
    if "model" in members:
        depth = load_depth_npz(path, max_cells=max_points)
        return PointCloud(
            xyz=depth.points.reshape(-1, 3).copy(),
            organized_shape=depth.shape,
            meta={"format": "native_npz", "model": depth.meta.get("model")},
        )
    # Which arrays hold the points, decided from the headers alone.
    lower = {k.lower(): k for k in members}
    if all(axis in lower for axis in "xyz"):
        keys = [lower[axis] for axis in "xyz"]
        shapes = [members[k][0] for k in keys]
        if any(len(s) != 1 for s in shapes) or len(set(shapes)) != 1 or any(members[k][1].kind not in "biuf" for k in keys):
            raise CalibError(f"{path}: arrays x, y, z must be numeric and 1-D of one length")
        n = shapes[0][0]
        main_keys = keys
    else:
        main = next((k for k in ("points", "xyz") if k in members), None)
        if main is None:
            if len(members) != 1:
                raise CalibError(
                    f"{path}: .npz has neither 'model' (native scan), x/y/z nor 'points' arrays "
                    f"(keys: {', '.join(members) or 'none'})"
                )
            main = next(iter(members))
        shape, dtype = members[main]
        _check_array_shape(path, shape, dtype, f"array '{main}'")
        n = _array_points(shape, dtype)
        main_keys = [main]
    if n > max_points:
        raise _too_many(path, "holds", n, max_points)
    extra = [
        k for k, (shape, dtype) in members.items()
        if k not in main_keys and shape == (n,) and dtype.kind in "biuf"
    ]
    budget = max_points * 64
    if sum(math.prod(members[k][0]) * members[k][1].itemsize for k in main_keys + extra) > budget:
        raise CalibError(f"{path}: the arrays hold more than {budget:,} bytes (raise the limit with {MAX_CELLS_OPTION})")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in main_keys + extra}
    except Exception as err:  # BadZipFile, CRC errors, ValueError, OSError, EOFError
        raise CalibError(f"{path}: unreadable .npz ({_one_line(err)})") from None
    fields = {k: v for k, v in arrays.items() if k in extra}
    if len(main_keys) == 3:
        xyz = np.stack([arrays[k] for k in main_keys], axis=1).astype(np.float64)
        return PointCloud(xyz=xyz, fields=fields, meta={"format": "npz"})
    cloud = _cloud_from_array(arrays[main_keys[0]], path, f"array '{main_keys[0]}'")
    return dataclasses.replace(cloud, fields={**cloud.fields, **fields}, meta={"format": "npz"})


_READERS = {
    ".pcd": _read_pcd,
    ".ply": _read_ply,
    ".las": _read_las,
    ".laz": _read_las,
    ".bin": _read_bin,
    ".npy": _read_npy,
    ".npz": _read_npz,
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
    finite = np.isfinite(xyz)
    infinite = np.isinf(xyz).any(axis=1)
    if infinite.any():
        raise CalibError(f"{path}: {int(infinite.sum())} of {len(xyz)} points have an infinite coordinate")
    good = finite.all(axis=1)
    n_good = int(good.sum())
    if len(xyz) == 0:
        raise CalibError(f"{path}: the point cloud is empty")
    if n_good == 0:
        raise CalibError(f"{path}: all {len(xyz)} points are NaN or inf")
    if n_good < MIN_POINTS:
        raise CalibError(f"{path}: only {n_good} finite point(s); a scan needs at least {MIN_POINTS}")
    largest = float(np.max(np.abs(xyz[good])))
    if largest > MAX_ABS_COORDINATE_M:
        raise CalibError(f"{path}: a coordinate of {largest:.3g}: not metres in a sensor frame")


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
            raise CalibError(f"{path}: cannot read ({err.strerror or _one_line(err)}){said.suffix()}") from None
        except MemoryError:
            raise CalibError(f"{path}: not enough memory to read the file{said.suffix()}") from None
    _check_points(path, cloud)
    return dataclasses.replace(cloud, meta={**cloud.meta, "source": str(path)})


# --------------------------------------------------------------------------

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
    organize : str
        How the cloud becomes a grid:

        * ``"auto"`` -- an organized cloud keeps its grid; else the ring
          field if present; else elevation clustering when ``beams`` is
          given; else a spherical projection (default resolution:
          :func:`default_spherical_resolution_deg`, recorded in meta);
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
    bin_columns : int, optional
        Float32 values per point of a ``.bin`` file; see :func:`read_point_cloud`.
    max_points : int
        Cap on the points (or cells) read from the file; see :func:`read_point_cloud`.

    Returns
    -------
    DepthMatrix
        Lidar frame, metres.  ``meta`` holds ``source``, ``format``,
        ``organize`` (the method used) and the method's parameters and
        counts; for clouds, ``point_index`` ((H, W) index of each cell's
        point in the file, -1 where empty) and ``field_images`` (per-cell
        images of the 1-D fields, e.g. intensity, NaN where empty).

    Raises
    ------
    CalibError
        Bad file or options; see :func:`read_point_cloud`.
    """
    if organize not in ORGANIZE_METHODS:
        raise CalibError(f"unknown organize method '{organize}' (one of {', '.join(ORGANIZE_METHODS)})")
    method = "firing_order" if organize == "firing" else organize
    max_points = _check_max_points(max_points)
    path = _check_path(path, max_points)
    if _is_native_npz(path):
        depth = load_depth_npz(path, max_cells=max_points)
        return dataclasses.replace(depth, meta={**depth.meta, "source": str(path), "format": "native_npz", "organize": "native"})

    cloud = read_point_cloud(path, bin_columns=bin_columns, max_points=max_points)
    if beams is not None and (isinstance(beams, bool) or not isinstance(beams, (int, np.integer)) or beams < 1):
        raise CalibError(f"beams must be a positive integer, got {beams!r}")
    ring = cloud.ring_field()
    if method == "auto":
        if cloud.organized_shape is not None:
            method = "organized"
        elif ring is not None:
            method = "ring"
        elif beams is not None:
            method = "elevation"
        else:
            method = "spherical"

    extra: dict[str, Any] = {}
    try:
        if method == "organized":
            if cloud.organized_shape is None:
                raise CalibError("the cloud is not organized (it has no WIDTH x HEIGHT grid)")
            depth = organize_grid(cloud.xyz.reshape(*cloud.organized_shape, 3), wrap_cols=wrap_cols)
        elif method == "ring":
            if ring is None:
                raise CalibError(f"no ring field (fields: {', '.join(cloud.fields) or 'none'}); try beams=...")
            depth = organize_by_ring(cloud.xyz, ring, n_cols=n_cols)
        elif method in ("elevation", "firing_order"):
            if beams is None:
                raise CalibError(f"organize='{method}' needs the number of beams (beams=...)")
            organizer = organize_by_elevation if method == "elevation" else organize_by_firing_order
            depth = organizer(cloud.xyz, beams, n_cols=n_cols)
        else:
            if v_res_deg is None or h_res_deg is None:
                default = default_spherical_resolution_deg(cloud.xyz)
                extra["spherical_resolution"] = (
                    f"default {default} deg: the typical azimuth step; pass beams=... for one row per beam"
                )
                v_res_deg = default if v_res_deg is None else v_res_deg
                h_res_deg = default if h_res_deg is None else h_res_deg
            depth = organize_spherical(cloud.xyz, v_res_deg, h_res_deg, v_range_deg)
    except CalibError as err:
        raise CalibError(f"{path}: {err}") from None

    meta = {**depth.meta, **extra, "source": str(path), "format": cloud.meta.get("format")}
    meta["field_images"] = _field_images(cloud, meta["point_index"])
    return dataclasses.replace(depth, meta=meta)
