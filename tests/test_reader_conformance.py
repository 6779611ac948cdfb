"""Reader conformance with files written by other software.

Every scan file in ``../shared/data/other_tools_files/`` (PCL, PDAL, laspy,
trimesh, mmdetection3d, PJLab) either reads exactly as an independent decoder
of its documented layout reads it, or is refused with one line; reading never
prints anything.  The independent decoders here follow the format documents
(PCL's PCD header semantics, the LAS 1.2/1.4 header table, the PLY header,
KITTI's and nuScenes' float32 records) and use numpy only.  A few small text
files from PCL, PDAL and trimesh, copied here from their repositories, add
header variants the shared folder lacks.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.io.scan_readers import load_scan, read_point_cloud

OTHER = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "other_tools_files"
KITTI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti_object_000002"
needs_other = pytest.mark.skipif(not OTHER.is_dir(), reason=f"files from other tools not found at {OTHER}")

SCAN_SUFFIXES = (".pcd", ".ply", ".las", ".laz", ".bin", ".npy", ".npz")


# --------------------------------------------------------------------------
# Independent decoders, from the format documents
# --------------------------------------------------------------------------

_PCD_NUMPY = {"F": "f", "U": "u", "I": "i"}


def pcd_reference(path: Path) -> tuple[dict[str, list[str]], np.ndarray]:
    """Header and records of a PCD, per PCL's file-format page.

    ascii: one point per line, values split on blanks (PDAL also commas);
    binary: the records packed row after row; binary_compressed: uint32
    compressed and uncompressed sizes, then LZF of the data stored field
    after field.
    """
    raw = path.read_bytes()
    header: dict[str, list[str]] = {}
    offset = 0
    while "DATA" not in header:
        end = raw.index(b"\n", offset) + 1
        line = raw[offset:end].decode().strip()
        offset = end
        if line and not line.startswith("#"):
            key, *values = line.split()
            header[key] = values
    counts = [int(c) for c in header.get("COUNT", ["1"] * len(header["FIELDS"]))]
    dtype = np.dtype(
        [
            (name, f"<{_PCD_NUMPY[t]}{s}", (c,)) if c > 1 else (name, f"<{_PCD_NUMPY[t]}{s}")
            for name, s, t, c in zip(header["FIELDS"], header["SIZE"], header["TYPE"], counts)
        ]
    )
    n = int(header["POINTS"][0]) if "POINTS" in header else int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
    encoding = header["DATA"][0]
    if encoding == "binary":
        return header, np.frombuffer(raw, dtype=dtype, count=n, offset=offset)
    if encoding == "binary_compressed":
        import lzf

        compressed, uncompressed = struct.unpack_from("<II", raw, offset)
        data = lzf.decompress(raw[offset + 8 : offset + 8 + compressed], uncompressed)
        records = np.zeros(n, dtype=dtype)
        start = 0
        for name in dtype.names:
            size = dtype[name].itemsize * n
            records[name] = np.frombuffer(data[start : start + size], dtype=dtype[name].base).reshape(records[name].shape)
            start += size
        return header, records
    text = raw[offset:].replace(b",", b" ").decode()
    values = np.array(text.split(), dtype=np.float64).reshape(n, -1)
    records = np.zeros(n, dtype=dtype)
    column = 0
    for name in dtype.names:
        width = int(np.prod(dtype[name].shape or (1,)))
        records[name] = values[:, column : column + width].reshape(records[name].shape).astype(dtype[name].base)
        column += width
    return header, records


def las_reference(path: Path) -> np.ndarray:
    """Scaled x, y, z of an uncompressed LAS, from the LAS 1.2 / 1.4 header table."""
    raw = path.read_bytes()
    assert raw[:4] == b"LASF"
    major, minor = raw[24], raw[25]
    (offset,) = struct.unpack_from("<I", raw, 96)
    (record_length,) = struct.unpack_from("<H", raw, 105)
    (count,) = struct.unpack_from("<I", raw, 107)
    if (major, minor) >= (1, 4) and count == 0:
        (count,) = struct.unpack_from("<Q", raw, 247)
    scale = np.array(struct.unpack_from("<3d", raw, 131))
    origin = np.array(struct.unpack_from("<3d", raw, 155))
    records = np.frombuffer(
        raw,
        dtype=np.dtype({"names": ["X", "Y", "Z"], "formats": ["<i4"] * 3, "offsets": [0, 4, 8], "itemsize": record_length}),
        count=count,
        offset=offset,
    )
    return np.stack([records[a] for a in "XYZ"], axis=1) * scale + origin


def ply_reference_vertices(path: Path) -> np.ndarray:
    """The vertex block of a binary little-endian PLY whose vertex properties are scalars."""
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode().splitlines()
    assert "format binary_little_endian 1.0" in header
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "char": "i1", "ushort": "<u2", "short": "<i2", "int": "<i4", "uint": "<u4"}
    n, props, in_vertex = 0, [], False
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            n, in_vertex = int(words[2]), True
        elif words and words[0] == "element":
            in_vertex = False
        elif in_vertex and words[0] == "property":
            props.append((words[2], types[words[1]]))
    return np.frombuffer(raw, dtype=np.dtype(props), count=n, offset=end)


def assert_one_line(excinfo, path: Path) -> str:
    message = str(excinfo.value)
    assert "\n" not in message and path.name in message, message
    return message


# --------------------------------------------------------------------------
# The shared folder, file by file
# --------------------------------------------------------------------------


def scan_files() -> list[Path]:
    if not OTHER.is_dir():
        return []
    return sorted(p for p in OTHER.rglob("*") if p.is_file() and p.suffix.lower() in SCAN_SUFFIXES)


@needs_other
def test_every_scan_file_is_covered_below():
    """The per-file checks below name every scan file in the folder (a new file must get a check)."""
    covered = set(EXPECTED)
    found = {p.relative_to(OTHER).as_posix() for p in scan_files()}
    assert found == covered, f"unchecked files: {sorted(found - covered)}; missing: {sorted(covered - found)}"


def check_pcd(path: Path, cloud) -> None:
    header, records = pcd_reference(path)
    names = header["FIELDS"]
    axes = [a if a in names else a.upper() for a in "xyz"]
    np.testing.assert_array_equal(cloud.xyz, np.stack([records[a].astype(np.float64) for a in axes], axis=1))
    for name in names:
        if name not in axes and name != "_":
            np.testing.assert_array_equal(cloud.fields[name], records[name])
    width, height = int(header["WIDTH"][0]), int(header.get("HEIGHT", ["1"])[0])
    # PCL: a cloud is organised only when both dimensions exceed 1.
    assert cloud.organized_shape == ((height, width) if width > 1 and height > 1 else None)


def check_bunny(path, cloud):
    check_pcd(path, cloud)
    assert len(cloud) == 397 and cloud.meta["version"] == ".5"


def check_colored(path, cloud):
    check_pcd(path, cloud)  # WIDTH 1 HEIGHT 1000: a flat list
    assert len(cloud) == 1000 and cloud.organized_shape is None


def check_office(path, cloud):
    check_pcd(path, cloud)
    assert cloud.organized_shape == (480, 640)
    assert np.isnan(cloud.xyz).any()  # a Kinect frame has cells without depth


def check_autzen_pcd(path, cloud):
    check_pcd(path, cloud)  # upper-case X Y Z
    assert len(cloud) == 1065 and "Intensity" in cloud.fields


def check_pjlab(path, cloud):
    check_pcd(path, cloud)
    ring = cloud.ring_field()
    assert ring is not None and ring.min() == 0 and ring.max() == 63


def check_pdal_npy(path, cloud):
    # PDAL wrote the raw LAS integers of laspy's simple.las: compare with our own LAS decoding.
    las = OTHER / "las" / "laspy_simple.las"
    scaled = las_reference(las)
    np.testing.assert_allclose(cloud.xyz * 0.01, scaled, atol=1e-9)  # simple.las scale 0.01, offset 0
    assert {"intensity", "gps_time", "red"} <= set(cloud.fields)


def check_las(path, cloud):
    np.testing.assert_allclose(cloud.xyz, las_reference(path), rtol=0, atol=1e-9)


def check_laz(path, cloud):
    # laspy's simple.laz is simple.las compressed.
    np.testing.assert_allclose(cloud.xyz, las_reference(OTHER / "las" / "laspy_simple.las"), rtol=0, atol=1e-9)


def check_kitti_bin(path, cloud):
    records = np.fromfile(path, dtype="<f4").reshape(-1, 4)  # KITTI: x, y, z, reflectance
    assert cloud.meta["bin_columns"] == 4 and len(cloud) == 17238
    np.testing.assert_array_equal(cloud.xyz, records[:, :3])
    np.testing.assert_array_equal(cloud.fields["intensity"], records[:, 3])


def check_nuscenes_bin(path, cloud):
    records = np.fromfile(path, dtype="<f4").reshape(-1, 5)  # nuScenes: x, y, z, intensity, ring index
    assert cloud.meta["bin_columns"] == 5 and len(cloud) == 34688
    np.testing.assert_array_equal(cloud.xyz, records[:, :3])
    np.testing.assert_array_equal(cloud.fields["intensity"], records[:, 3])
    np.testing.assert_array_equal(cloud.ring_field(), records[:, 4])
    assert sorted(set(cloud.ring_field().tolist())) == list(range(32))  # the HDL-32E's 32 lasers


def check_ply_points(path, cloud):
    vertices = ply_reference_vertices(path)
    assert len(cloud) == len(vertices) == 5
    np.testing.assert_array_equal(cloud.xyz, np.stack([vertices[a] for a in "xyz"], axis=1).astype(np.float64))


def check_fuze(path, cloud):
    vertices = ply_reference_vertices(path)
    assert len(cloud) == len(vertices) == 502  # as stored; texture seams are not split into copies
    np.testing.assert_array_equal(cloud.xyz, np.stack([vertices[a] for a in "xyz"], axis=1).astype(np.float64))
    np.testing.assert_array_equal(cloud.fields["red"], vertices["red"])


#: relative path -> check of a successful read, or the words a refusal must contain.
EXPECTED = {
    "pcd/pcl_bunny.pcd": check_bunny,
    "pcd/pcl_colored_cloud.pcd": check_colored,
    "pcd/pcl_office1.pcd": check_office,
    "pcd/pdal_autzen-utm.pcd": check_autzen_pcd,
    "pcd/pjlab_circle_449.pcd": check_pjlab,
    "npy/pdal_1.2-with-color.npy": check_pdal_npy,
    "las/laspy_simple.las": check_las,
    "las/laspy_test1_4.las": check_las,
    "las/laspy_simple.laz": check_laz,
    "las/pdal_simple-laszip-compressor-version-1.2r0.laz": ("LAZ",),
    "bin/mmdet3d_kitti_000008.bin": check_kitti_bin,
    "bin/mmdet3d_nuscenes_LIDAR_TOP.pcd.bin": check_nuscenes_bin,
    "ply/trimesh_points_bin.ply": check_ply_points,
    "ply/trimesh_fuze.ply": check_fuze,
}


@needs_other
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_file_reads_like_an_independent_decoder_or_is_refused(name, capfd):
    path = OTHER / name
    if not path.is_file():
        pytest.skip(f"{path} not present")
    expected = EXPECTED[name]
    capfd.readouterr()
    if callable(expected):
        cloud = read_point_cloud(path)
        expected(path, cloud)
    else:
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path)
        message = assert_one_line(excinfo, path)
        for word in expected:
            assert word in message, message
    out, err = capfd.readouterr()
    assert out == "" and err == "", f"the reader printed: {(out + err)[:300]!r}"


@needs_other
def test_cli_on_the_panicking_laz_prints_one_error_line(tmp_path):
    import subprocess
    import sys

    path = OTHER / "las" / "pdal_simple-laszip-compressor-version-1.2r0.laz"
    run = subprocess.run(
        [sys.executable, "-m", "app.cli", "ba-images", "--scan", str(path), "-o", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parents[1],
    )
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "LAZ" in lines[0], run.stderr


@needs_other
def test_nuscenes_ring_column_organises_by_ring():
    depth = load_scan(OTHER / "bin" / "mmdet3d_nuscenes_LIDAR_TOP.pcd.bin")
    assert depth.meta["organize"] == "ring" and depth.shape[0] == 32


@pytest.mark.skipif(not (KITTI / "velodyne").is_dir(), reason=f"KITTI frame not found at {KITTI}")
def test_full_kitti_frame_is_detected_as_four_columns():
    path = next((KITTI / "velodyne").glob("*.bin"))
    records = np.fromfile(path, dtype="<f4").reshape(-1, 4)
    cloud = read_point_cloud(path)
    assert cloud.meta["bin_columns"] == 4
    np.testing.assert_array_equal(cloud.xyz, records[:, :3])


# --------------------------------------------------------------------------
# .bin layouts: detected by plausibility, or refused naming --bin-columns
# --------------------------------------------------------------------------


def sweep(n_points: int = 6000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic 32-laser sweep in firing order (points, ring): smooth along the order."""
    rng = np.random.default_rng(seed)
    n_lasers = 32
    firing = np.arange(n_points)
    ring = firing % n_lasers
    azimuth = (firing // n_lasers) * np.radians(0.2)
    elevation = np.radians(-30.0 + ring * (40.0 / (n_lasers - 1)))
    distance = 8.0 + 3.0 * np.sin(3 * azimuth) + rng.normal(0, 0.02, n_points)
    xyz = np.stack(
        [distance * np.cos(elevation) * np.cos(azimuth), distance * np.cos(elevation) * np.sin(azimuth), distance * np.sin(elevation)],
        axis=1,
    )
    return xyz, ring


def test_bin_layouts_are_detected(tmp_path):
    xyz, ring = sweep(6000)  # 6000 points: sizes divisible by 16, 20 and 24 alike
    rng = np.random.default_rng(1)
    intensity = rng.uniform(0, 255, len(xyz)).round()
    layouts = {
        4: np.column_stack([xyz, intensity / 255]),  # KITTI: reflectance in [0, 1]
        5: np.column_stack([xyz, intensity, ring]),  # nuScenes: intensity, ring index
        6: np.column_stack([xyz, rng.uniform(0, 1, (len(xyz), 3))]),  # SUN RGB-D: r, g, b in [0, 1]
    }
    for columns, records in layouts.items():
        path = tmp_path / f"c{columns}.bin"
        records.astype("<f4").tofile(path)
        cloud = read_point_cloud(path)
        assert cloud.meta["bin_columns"] == columns, columns
        np.testing.assert_array_equal(cloud.xyz, records[:, :3].astype("<f4"))
        if columns == 5:
            np.testing.assert_array_equal(cloud.ring_field(), ring)


def test_shuffled_bins_are_still_detected(tmp_path):
    # SUN RGB-D subsamples points at random: no scan order to lean on, only the columns' kinds.
    xyz, ring = sweep(6000)
    rng = np.random.default_rng(2)
    order = rng.permutation(len(xyz))
    records = np.column_stack([xyz, rng.uniform(0, 1, (len(xyz), 3))])[order]
    path = tmp_path / "sunrgbd.bin"
    records.astype("<f4").tofile(path)
    assert read_point_cloud(path).meta["bin_columns"] == 6


def test_ambiguous_bin_is_refused_naming_the_option(tmp_path):
    # Every value of one kind: no column structure to detect.
    rng = np.random.default_rng(3)
    path = tmp_path / "noise.bin"
    rng.uniform(-50, 50, 6000 * 5).astype("<f4").tofile(path)
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path)
    assert "--bin-columns" in assert_one_line(excinfo, path)
    # The user can still say how the file is laid out.
    assert read_point_cloud(path, bin_columns=5).meta["bin_columns"] == 5


def test_bin_that_is_not_float_metres_is_refused(tmp_path):
    # Text saved as .bin repeats every 4 values, but as float32 its "points" are 1e-19 m from the sensor.
    path = tmp_path / "text.bin"
    path.write_bytes(b"1.0 2.0 3.0 4.0\n" * 64)
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path)
    assert "not points in metres" in assert_one_line(excinfo, path)


def test_given_bin_columns_that_contradict_the_data_are_refused(tmp_path):
    xyz, ring = sweep(8000)
    path = tmp_path / "kitti.bin"
    np.column_stack([xyz, np.full(len(xyz), 0.5)]).astype("<f4").tofile(path)
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path, bin_columns=5)
    assert "pass --bin-columns 4" in assert_one_line(excinfo, path)
    assert read_point_cloud(path, bin_columns=8).meta["bin_columns"] == 8  # a multiple of the period is the user's call


def test_five_column_bin_is_never_read_as_four(tmp_path):
    # The nuScenes failure: 43,360 "points" of 4 floats from 34,688 of 5.
    xyz, ring = sweep(8000)  # 8000 * 5 floats divide by 4 as well
    records = np.column_stack([xyz, np.full(len(xyz), 17.0), ring])
    path = tmp_path / "n.pcd.bin"
    records.astype("<f4").tofile(path)
    cloud = read_point_cloud(path)
    assert len(cloud) == 8000 and cloud.meta["bin_columns"] == 5


# --------------------------------------------------------------------------
# Small text files from other projects (copied verbatim from the repositories named)
# --------------------------------------------------------------------------

# PointCloudLibrary/pcl test/nhood_test.pcd @ 2af4bc4a (BSD-3-Clause), first 6 of its 36 points with
# the counts changed to 6; VERSION .5, no VIEWPOINT, and like the original no newline after the last line.
PCL_NHOOD = (
    "# .PCD v.5 - Point Cloud Data file format\nVERSION .5\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
    "COUNT 1 1 1 1\nWIDTH 6\nHEIGHT 1\nPOINTS 6\nDATA ascii\n"
    "-1.050570 -0.750850 1.527237 0.000000\n-1.059155 -0.756576 1.518478 0.000183\n"
    "-1.064163 -0.744050 1.521166 0.000268\n-1.035994 -0.753445 1.535901 0.000294\n"
    "-1.045383 -0.767850 1.522352 0.000340\n-1.052991 -0.732873 1.534287 0.000379"
)
# PointCloudLibrary/pcl test/octants.pcd @ 2d80ed77 (BSD-3-Clause), whole file.
PCL_OCTANTS = (
    "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
    "WIDTH 8\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 8\nDATA ascii\n-9.0 -9.0 -9.0\n-6.0 -9.0 -9.0\n-3.0 -9.0 -9.0\n"
    "-2.0 -9.0 -9.0\n1.0 -3.0 -3.0\n3.0 -3.0 -3.0\n6.0 -3.0 -3.0\n9.0 -3.0 -3.0\n"
)
_UTM17_POINTS = [
    ("289814.15", "4320978.61", "170.76"), ("289814.64", "4320978.84", "170.76"), ("289815.12", "4320979.06", "170.75"),
    ("289815.60", "4320979.28", "170.74"), ("289816.08", "4320979.50", "170.68"), ("289816.56", "4320979.71", "170.66"),
    ("289817.03", "4320979.92", "170.63"), ("289817.53", "4320980.16", "170.62"), ("289818.01", "4320980.38", "170.61"),
    ("289818.50", "4320980.59", "170.58"),
]
_UTM17_HEADER = (
    "VERSION 0.7\nFIELDS X Y Z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 10\nHEIGHT 1\n"
    "VIEWPOINT 0.0 0.0 0.0 1.0 0.0 0.0 0.0\nPOINTS 10\nDATA ascii\n"
)
# PDAL/PDAL test/data/pcd/utm17_tab.pcd @ cda458ac and utm17_comma.pcd @ 4c6f42e2 (BSD), whole files:
# upper-case fields, values separated by tabs / commas.
PDAL_UTM17_TAB = _UTM17_HEADER + "".join("\t".join(p) + "\n" for p in _UTM17_POINTS)
PDAL_UTM17_COMMA = _UTM17_HEADER + "".join(",".join(p) + "\n" for p in _UTM17_POINTS)
# mikedh/trimesh models/points_ascii.ply @ a8d0c7ba and points_ascii_with_lists.ply @ 2beb7d77 (MIT), whole files.
_TRIMESH_POINTS = (
    "-0.06325 0.0359793 0.0420873 \n-0.06275 0.0360343 0.0425949 \n-0.0645 0.0365101 0.0404362 \n"
    "-0.064 0.0366195 0.0414512 \n-0.0635 0.0367289 0.0424662 \n"
)
TRIMESH_POINTS_ASCII = (
    "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    + _TRIMESH_POINTS + "\n"
)
TRIMESH_POINTS_WITH_LISTS = (
    "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
    "element point_list 2\nproperty list uchar uint point_indices1\nproperty list uchar uint point_indices2\n"
    "property float some_float\nend_header\n" + _TRIMESH_POINTS + "3 10 11 12 2 13 14 1.1\n2 10 11 3 12 13 14 2.2\n"
)
# mikedh/trimesh models/emptyIO/ply_empty_header.ply @ 0c2656c5 (MIT), whole file.
TRIMESH_EMPTY_HEADER = "ply\nformat ascii 1.0\nend_header\n"

TRIMESH_XYZ = np.array([[float(v) for v in line.split()] for line in _TRIMESH_POINTS.splitlines()], dtype=np.float32)


@pytest.mark.parametrize(
    "name, text, n_points",
    [
        ("pcl_nhood_test.pcd", PCL_NHOOD, 6),
        ("pcl_octants.pcd", PCL_OCTANTS, 8),
        ("pdal_utm17_tab.pcd", PDAL_UTM17_TAB, 10),
        ("pdal_utm17_comma.pcd", PDAL_UTM17_COMMA, 10),
    ],
)
def test_small_pcds_from_other_projects(tmp_path, name, text, n_points):
    path = tmp_path / name
    path.write_text(text)
    cloud = read_point_cloud(path)
    _, records = pcd_reference(path)
    assert len(cloud) == n_points
    check_pcd(path, cloud)


def test_a_missing_final_newline_is_no_truncation_the_values_are_counted(tmp_path):
    # PCL nhood_test.pcd has no newline after its last line; cut inside its last number, the file still
    # holds every value (a shorter last number is a valid number): the values are counted, not their widths.
    path = tmp_path / "cut.pcd"
    path.write_text(PCL_NHOOD[:-3])
    np.testing.assert_array_equal(read_point_cloud(path).xyz[-1], np.float32([-1.052991, -0.732873, 1.534287]))
    # Cut so that the last point loses values, or lines: refused.
    for cut, name in ((PCL_NHOOD[: PCL_NHOOD.rindex(" ")], "short_last_line"), (PCL_NHOOD[:-40], "lost_line")):
        path = tmp_path / f"{name}.pcd"
        path.write_text(cut)
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path)
        assert "truncated" in assert_one_line(excinfo, path)


# PointCloudLibrary/pcl test/rops_cloud.pcd @ fd791e47 (BSD-3-Clause): its header, its first 7 and its 28th of
# 32,087 points, counts changed to 8; numbers of varying width (%g) and, like the original,
# no final newline.
PCL_ROPS_HEAD = (
    "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
    "WIDTH 8\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 8\nDATA ascii\n"
)
PCL_ROPS_POINTS = [
    (0.13058, 0.24871, -1.1732), (0.13169, 0.24871, -1.1732), (0.12191, 0.24796, -1.1749),
    (0.12285, 0.24763, -1.1733), (0.1239, 0.24752, -1.1728), (0.12489, 0.24729, -1.1717),
    (0.12595, 0.24721, -1.1713), (0.13794, 0.24583, -1.17),
]
# mikedh/trimesh models/metadata.ply @ ae499e5a (MIT), whole file: no newline after the last face.
TRIMESH_METADATA = (
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 2\nproperty list uchar int vertex_index\nproperty char face_type\nend_header\n"
    "-4 -4 0\n-4 4 0\n4 -4 0\n4 4 0\n3 0 2 1 12\n3 1 2 3 90"
)
# PDAL/PDAL test/data/ply/simple_text.ply @ 85360956 (BSD), whole file: "ply " with a trailing blank.
PDAL_SIMPLE_TEXT = (
    "ply \nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z \n"
    "end_header\n-1 0 0\n 0 1 0\n 1 0 0 \n"
)


def test_pcl_variable_width_pcd_without_a_final_newline(tmp_path):
    path = tmp_path / "rops_head.pcd"
    body = "\n".join(" ".join(f"{v:g}" for v in point) for point in PCL_ROPS_POINTS)
    path.write_text(PCL_ROPS_HEAD + body)  # no final newline
    cloud = read_point_cloud(path)
    np.testing.assert_array_equal(cloud.xyz, np.float32(PCL_ROPS_POINTS).astype(np.float64))
    check_pcd(path, cloud)


@pytest.mark.parametrize(
    "name, text, xyz",
    [
        ("metadata.ply", TRIMESH_METADATA, [[-4, -4, 0], [-4, 4, 0], [4, -4, 0], [4, 4, 0]]),
        ("simple_text.ply", PDAL_SIMPLE_TEXT, [[-1, 0, 0], [0, 1, 0], [1, 0, 0]]),
    ],
)
def test_ascii_plys_of_other_projects(tmp_path, name, text, xyz):
    path = tmp_path / name
    path.write_text(text)
    cloud = read_point_cloud(path)
    np.testing.assert_array_equal(cloud.xyz, np.array(xyz, dtype=np.float64))


def test_ascii_ply_rows_are_counted(tmp_path):
    # A vertex row cut short (and no list in the element): refused, naming the row.
    text = TRIMESH_POINTS_ASCII.rstrip()
    path = tmp_path / "cut.ply"
    path.write_text(text[: text.rindex(" ")])
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path)
    assert "vertex 4 has 2 values" in assert_one_line(excinfo, path)


@pytest.mark.parametrize("text", [TRIMESH_POINTS_ASCII, TRIMESH_POINTS_WITH_LISTS], ids=["points", "with_lists"])
def test_trimesh_ascii_plys(tmp_path, text):
    path = tmp_path / "points.ply"
    path.write_text(text)
    cloud = read_point_cloud(path)
    np.testing.assert_array_equal(cloud.xyz, TRIMESH_XYZ.astype(np.float64))


def test_trimesh_empty_ply_is_refused(tmp_path):
    path = tmp_path / "empty.ply"
    path.write_text(TRIMESH_EMPTY_HEADER)
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path)
    assert "empty" in assert_one_line(excinfo, path)
