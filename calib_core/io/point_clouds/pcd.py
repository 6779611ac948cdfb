"""PCL's PCD files: VERSION .5 to 0.7, ascii / binary / binary_compressed, decoded with pypcd4.

The header is parsed and checked here first (field table, declared counts
against the data size, the point cap), then pypcd4 decodes a normalised copy
(it only takes VERSION 0.7 and single-space ASCII).
"""

from __future__ import annotations

import io
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import CalibError, one_line
from .cloud import PointCloud, normalise_text, too_many_points, values_per_line, xyz_field_names


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
    axes = xyz_field_names(path, names, "PCD")
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
    """Every data line holds one point's values (normalised text; the last line needs no end of line)."""
    per_line = values_per_line(data)
    per_line = per_line[per_line > 0]
    if len(per_line) != n_points:
        raise CalibError(f"{path}: truncated or padded ascii PCD: header says {n_points} points, data has {len(per_line)} lines")
    wrong = np.flatnonzero(per_line != values_per_point)
    if len(wrong):
        raise CalibError(
            f"{path}: ascii PCD point {wrong[0] + 1} has {per_line[wrong[0]]} values, "
            f"the header declares {values_per_point} per point"
            + (" (truncated?)" if wrong[0] == n_points - 1 and per_line[wrong[0]] < values_per_point else "")
        )


def read_pcd(path: Path, max_points: int, **_) -> PointCloud:
    """A PCD file's points and fields; organized when WIDTH and HEIGHT both exceed 1."""
    import pypcd4

    header, data_offset = _pcd_header(path)
    info = _check_pcd_header(path, header)
    n_points = info["points"]
    if n_points > max_points:
        raise too_many_points(path, "PCD header declares", n_points, max_points)
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
            data = normalise_text(handle.read())
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
        raise CalibError(f"{path}: unreadable {encoding} PCD data ({one_line(err)})") from None
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
