"""PLY files: the vertices as stored, with their properties (decoded with trimesh).

The header's element counts are checked against the file size before trimesh
is imported, so a header declaring 10^12 vertices is refused at once.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import CalibError, one_line
from .cloud import PointCloud, normalise_text, too_many_points, values_per_line


_PLY_SCALAR_BYTES = {
    "char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
    "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8,
}


def _ply_header(path: Path) -> tuple[str, list[tuple[str, int, int, bool, int]], int]:
    """The PLY format, its elements as (name, count, smallest bytes per row, has a list, properties) and the
    data offset."""
    elements: list[list] = []
    fmt = None
    offset = 0
    with open(path, "rb") as handle:
        # The magic line is "ply"; writers add trailing blanks or a CR (PDAL's test files: "ply ").
        if handle.readline(64).rstrip(b" \t\r\n") != b"ply":
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
                elements.append([words[1], count, 0, False, 0])
            elif words[0] == "property" and elements:
                if len(words) >= 5 and words[1] == "list":
                    size = _PLY_SCALAR_BYTES.get(words[2])  # an empty list still stores its length
                    elements[-1][3] = True
                else:
                    size = _PLY_SCALAR_BYTES.get(words[1]) if len(words) >= 3 else None
                if size is None:
                    raise CalibError(f"{path}: PLY property line '{' '.join(words)[:60]}' has an unknown type")
                elements[-1][2] += size
                elements[-1][4] += 1
            elif words[0] == "end_header":
                if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                    raise CalibError(f"{path}: PLY format '{fmt}' is not ascii or binary")
                return fmt, [tuple(e) for e in elements], offset
    raise CalibError(f"{path}: not a PLY file (no end_header)")


def _check_ascii_rows(path: Path, text: bytes, layout: list, counts: str) -> None:
    """One line per element row, and the declared number of values on every row without a list.

    A missing final newline is no truncation: a cut file loses lines or values.
    """
    per_line = values_per_line(text) if text else np.zeros(0, dtype=np.int64)
    per_line = per_line[per_line > 0]
    if len(per_line) != sum(count for _, count, _, _, _ in layout):
        raise CalibError(f"{path}: ascii PLY declares {counts} rows but holds {len(per_line):,} lines")
    start = 0
    for name, count, _, listed, n_properties in layout:
        rows = per_line[start : start + count]
        wrong = np.flatnonzero(rows != n_properties) if not listed else np.zeros(0, dtype=np.int64)
        if len(wrong):
            raise CalibError(
                f"{path}: ascii PLY {name} {wrong[0]} has {rows[wrong[0]]} values, the header declares {n_properties}"
                + (" (truncated?)" if start + wrong[0] == len(per_line) - 1 and rows[wrong[0]] < n_properties else "")
            )
        start += count


def read_ply(path: Path, max_points: int, **_) -> PointCloud:
    """A PLY file's vertices as stored, with their numeric properties as fields."""
    fmt, elements, data_offset = _ply_header(path)
    has_lists = any(listed for _, _, _, listed, _ in elements)
    layout = elements
    elements = [(name, count, row) for name, count, row, _, _ in layout]
    vertex = [e for e in elements if e[0] == "vertex"]
    if not vertex or vertex[0][1] == 0:
        raise CalibError(f"{path}: the point cloud is empty (PLY without vertices)")
    n_vertices = vertex[0][1]
    if n_vertices > max_points:
        raise too_many_points(path, "PLY header declares", n_vertices, max_points)
    data_bytes = path.stat().st_size - data_offset
    # Smallest data the header's element counts need: binary rows as declared (lists empty),
    # ASCII rows one digit and a separator per value.
    smallest = sum(count * (row if fmt != "ascii" else 2) for _, count, row in elements)
    if data_bytes < smallest:
        counts = ", ".join(f"{count:,} {name}" for name, count, _ in elements)
        raise CalibError(f"{path}: truncated PLY: {data_bytes:,} data bytes cannot hold the declared {counts}")
    counts = ", ".join(f"{count:,} {name}" for name, count, _ in elements)
    if fmt == "ascii":
        text = path.read_bytes()[data_offset:]
        _check_ascii_rows(path, normalise_text(text) if text.strip() else b"", layout, counts)
    elif not has_lists and data_bytes - smallest >= max(1, min(row for _, _, row in elements)):
        raise CalibError(f"{path}: binary PLY holds {data_bytes - smallest:,} bytes more than its declared {counts}")
    import trimesh  # after the checks: it takes a second to import

    try:
        # Vertices as stored: no texture re-indexing (which duplicates vertices), no texture file lookup.
        geometry = trimesh.load(str(path), file_type="ply", process=False, fix_texture=False, skip_materials=True)
    except Exception as err:  # trimesh raises ValueError, KeyError, IndexError, ... for bad files
        message = one_line(err)
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
