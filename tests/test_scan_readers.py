"""Scan readers: every format against files written by hand per its spec, real PCDs
against an independent decoding, and one-line errors for bad or truncated input."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.io.scan_readers import PointCloud, load_scan, read_point_cloud

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "pjlab_opencalib_lidar2camera"
AUTO_PCD = DATA / "auto_calib" / "calib.pcd"
AUTO_DECODED = DATA / "auto_calib" / "calib_pcd_decoded.npz"
MANUAL_PCD = DATA / "manual_calib" / "0.pcd"
needs_data = pytest.mark.skipif(not AUTO_PCD.is_file(), reason=f"real data not found at {DATA}")


# --------------------------------------------------------------------------
# Writers per format spec (independent of the readers under test)
# --------------------------------------------------------------------------

# x y z intensity ring time: F4 F4 F4 F4 U2 F8
RECORD = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f8")])


def sample_records(n: int = 12, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rec = np.zeros(n, dtype=RECORD)
    rec["x"] = rng.uniform(-20, 20, n)
    rec["y"] = rng.uniform(-20, 20, n)
    rec["z"] = rng.uniform(-2, 2, n)
    rec["intensity"] = rng.integers(0, 255, n)
    rec["ring"] = rng.integers(0, 64, n)
    rec["time"] = 1.6e9 + rng.uniform(0, 0.1, n)
    return rec


def pcd_header(encoding: str, width: int, height: int = 1, points: int | None = None, fields: str | None = None) -> bytes:
    lines = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        fields or "FIELDS x y z intensity ring time",
        "SIZE 4 4 4 4 2 8",
        "TYPE F F F F U F",
        "COUNT 1 1 1 1 1 1",
        f"WIDTH {width}",
        f"HEIGHT {height}",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {width * height if points is None else points}",
        f"DATA {encoding}",
    ]
    return ("\n".join(lines) + "\n").encode()


def lzf_literal(data: bytes) -> bytes:
    """LZF stream made only of literal runs (control byte = run length - 1, runs <= 32)."""
    out = bytearray()
    for start in range(0, len(data), 32):
        chunk = data[start : start + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def pcd_bytes(rec: np.ndarray, encoding: str, height: int = 1) -> bytes:
    width = len(rec) // height
    head = pcd_header(encoding, width, height)
    if encoding == "ascii":
        body = "".join(
            f"{r['x']!r} {r['y']!r} {r['z']!r} {r['intensity']!r} {r['ring']} {r['time']!r}\n"
            for r in rec.tolist()
            for r in [dict(zip(RECORD.names, r))]
        ).encode()
    elif encoding == "binary":
        body = rec.tobytes()
    else:  # binary_compressed: field after field (structure of arrays), LZF
        raw = b"".join(np.ascontiguousarray(rec[name]).tobytes() for name in RECORD.names)
        packed = lzf_literal(raw)
        body = struct.pack("<II", len(packed), len(raw)) + packed
    return head + body


def write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def assert_one_line_error(excinfo, path: Path, *words: str) -> None:
    message = str(excinfo.value)
    assert "\n" not in message
    assert str(path) in message or path.name in message
    for word in words:
        assert word.lower() in message.lower(), message


# --------------------------------------------------------------------------
# PCD
# --------------------------------------------------------------------------


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_pcd_encodings_keep_all_fields(tmp_path, encoding):
    rec = sample_records()
    path = write(tmp_path / f"c_{encoding}.pcd", pcd_bytes(rec, encoding))
    cloud = read_point_cloud(path)
    assert isinstance(cloud, PointCloud)
    assert cloud.organized_shape is None
    assert cloud.xyz.dtype == np.float64 and cloud.xyz.shape == (len(rec), 3)
    np.testing.assert_array_equal(cloud.xyz, np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64))
    assert set(cloud.fields) == {"intensity", "ring", "time"}
    for name in ("intensity", "ring", "time"):
        assert cloud.fields[name].dtype == RECORD[name]
        np.testing.assert_array_equal(cloud.fields[name], rec[name])
    np.testing.assert_array_equal(cloud.ring_field(), rec["ring"])


def test_organized_pcd_has_its_grid(tmp_path):
    rec = sample_records(12)
    path = write(tmp_path / "org.pcd", pcd_bytes(rec, "binary", height=3))
    cloud = read_point_cloud(path)
    assert cloud.organized_shape == (3, 4)
    # Row-major: row 1, column 2 is record 1 * 4 + 2.
    np.testing.assert_array_equal(cloud.xyz.reshape(3, 4, 3)[1, 2], [rec["x"][6], rec["y"][6], rec["z"][6]])


def test_pcd_count_field_and_padding(tmp_path):
    head = (
        "VERSION 0.7\nFIELDS x y z normal _\nSIZE 4 4 4 4 1\nTYPE F F F F U\nCOUNT 1 1 1 3 2\n"
        "WIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n"
    )
    body = "1 2 3 0.1 0.2 0.3 0 0\n4 5 6 0.4 0.5 0.6 0 0\n7 8 9 0.7 0.8 0.9 1 1\n"
    cloud = read_point_cloud(write(tmp_path / "n.pcd", (head + body).encode()))
    np.testing.assert_array_equal(cloud.xyz, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert set(cloud.fields) == {"normal"}
    np.testing.assert_array_equal(cloud.fields["normal"], np.float32([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6], [0.7, 0.8, 0.9]]))


def test_bad_pcds_raise_one_line_errors(tmp_path):
    rec = sample_records(10)
    good_binary = pcd_bytes(rec, "binary")
    good_compressed = pcd_bytes(rec, "binary_compressed")
    good_ascii = pcd_bytes(rec, "ascii")
    cases = {
        "short_binary_mid_point": (good_binary[:-5], ["truncated"]),
        "short_binary_whole_points": (good_binary[: -2 * RECORD.itemsize], ["truncated"]),
        "short_compressed": (good_compressed[:-7], ["truncated"]),
        "corrupt_compressed_size": (
            good_compressed[: len(pcd_header("binary_compressed", 10))]
            + struct.pack("<II", 10, 99)
            + good_compressed[len(pcd_header("binary_compressed", 10)) + 8 :],
            ["corrupt"],
        ),
        "ascii_missing_lines": (b"".join(good_ascii.splitlines(keepends=True)[:-3]), ["truncated"]),
        "ascii_short_line": (good_ascii.rstrip(b"\n").rsplit(b" ", 2)[0] + b"\n", ["pcd"]),
        "no_xyz": (good_ascii.replace(b"FIELDS x y z", b"FIELDS a b c"), ["no x/y/z field"]),
        "no_fields": (good_ascii.replace(b"FIELDS x y z intensity ring time\n", b""), ["lacks FIELDS"]),
        "size_count_mismatch": (good_ascii.replace(b"SIZE 4 4 4 4 2 8", b"SIZE 4 4 4 4 2"), ["SIZE"]),
        "points_mismatch": (good_ascii.replace(b"POINTS 10", b"POINTS 11"), ["POINTS"]),
        "bad_data": (good_ascii.replace(b"DATA ascii", b"DATA zip"), ["zip"]),
        "garbage": (b"\x89PNG\r\n\x1a\n\x00\x00 not a cloud", ["not a PCD"]),
        "text_garbage": (b"hello world\n", ["not a PCD"]),
        "empty": (pcd_header("ascii", 0), ["empty"]),
    }
    for name, (data, words) in cases.items():
        path = write(tmp_path / f"{name}.pcd", data)
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path)
        assert_one_line_error(excinfo, path, *words)


def test_all_nan_cloud_is_rejected(tmp_path):
    rec = sample_records(4)
    rec["x"] = np.nan
    path = write(tmp_path / "nan.pcd", pcd_bytes(rec, "binary"))
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path)
    assert_one_line_error(excinfo, path, "NaN")


@needs_data
def test_real_binary_compressed_pcd_matches_independent_decoding():
    cloud = read_point_cloud(AUTO_PCD)
    with np.load(AUTO_DECODED) as truth:
        assert len(cloud) == len(truth["x"]) == 85546
        for axis, name in enumerate("xyz"):
            np.testing.assert_array_equal(cloud.xyz[:, axis], truth[name].astype(np.float64))
        assert set(cloud.fields) == {"intensity", "ring", "timestamp"}
        for name in ("intensity", "ring", "timestamp"):
            assert cloud.fields[name].dtype == truth[name].dtype
            np.testing.assert_array_equal(cloud.fields[name], truth[name])
    assert cloud.organized_shape is None
    assert cloud.meta["encoding"] == "binary_compressed"


@needs_data
def test_real_ascii_pcd_matches_numpy_text_parse():
    cloud = read_point_cloud(MANUAL_PCD)
    truth = np.loadtxt(MANUAL_PCD, skiprows=11, dtype=np.float32)  # 11 header lines, fields x y z intensity
    assert truth.shape == (78238, 4) and len(cloud) == 78238
    np.testing.assert_array_equal(cloud.xyz, truth[:, :3].astype(np.float64))
    np.testing.assert_array_equal(cloud.fields["intensity"], truth[:, 3])
    assert cloud.ring_field() is None
    # First data line of the file, read by eye: 21.647913 0.19822195 -1.8524752 11
    np.testing.assert_array_equal(cloud.xyz[0], np.float32([21.647913, 0.19822195, -1.8524752]))


# --------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------


def ply_header(fmt: str, n: int, props: str = "x y z intensity") -> bytes:
    lines = ["ply", f"format {fmt} 1.0", f"element vertex {n}"]
    lines += [f"property float {p}" for p in props.split()]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode()


def test_ply_ascii_and_binary(tmp_path):
    xyzi = np.float32([[1.5, 2, 3, 10], [4, 5, 6.25, 20], [-7, 8, 9, 30]])
    ascii_path = write(tmp_path / "a.ply", ply_header("ascii", 3) + b"".join(b"%r %r %r %r\n" % tuple(map(float, r)) for r in xyzi))
    binary_path = write(tmp_path / "b.ply", ply_header("binary_little_endian", 3) + xyzi.astype("<f4").tobytes())
    for path in (ascii_path, binary_path):
        cloud = read_point_cloud(path)
        np.testing.assert_array_equal(cloud.xyz, xyzi[:, :3].astype(np.float64))
        np.testing.assert_array_equal(cloud.fields["intensity"], xyzi[:, 3])


def test_bad_plys(tmp_path):
    xyzi = np.float32(np.arange(12).reshape(3, 4))
    cases = {
        "truncated": ply_header("binary_little_endian", 3) + xyzi.tobytes()[:-6],
        "truncated_whole_vertex": ply_header("binary_little_endian", 3) + xyzi.tobytes()[:-16],
        "no_x": ply_header("ascii", 1, "a y z") + b"1 2 3\n",
        "garbage": b"not a ply at all\n",
        "empty": ply_header("ascii", 0, "x y z"),
    }
    for name, data in cases.items():
        path = write(tmp_path / f"{name}.ply", data)
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path)
        assert_one_line_error(excinfo, path)


# --------------------------------------------------------------------------
# LAS / LAZ
# --------------------------------------------------------------------------


def write_las(path: Path, xyz: np.ndarray, intensity: np.ndarray, ring: np.ndarray, gps_time: np.ndarray) -> None:
    import laspy

    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.zeros(3)
    header.add_extra_dim(laspy.ExtraBytesParams(name="ring", type=np.uint16))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.intensity = intensity
    las.gps_time = gps_time
    las.ring = ring
    las.write(str(path))


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_and_laz(tmp_path, suffix):
    xyz = np.array([[1.0, 2.0, 3.0], [-4.5, 5.25, -0.125], [10.001, 0.0, 2.5]])
    path = tmp_path / f"scan{suffix}"
    write_las(path, xyz, np.uint16([7, 8, 9]), np.uint16([0, 5, 63]), np.array([0.0, 0.05, 0.1]))
    cloud = read_point_cloud(path)
    np.testing.assert_allclose(cloud.xyz, xyz, atol=5e-4)  # LAS stores millimetre integers
    np.testing.assert_array_equal(cloud.fields["intensity"], [7, 8, 9])
    np.testing.assert_array_equal(cloud.ring_field(), [0, 5, 63])
    np.testing.assert_array_equal(cloud.fields["gps_time"], [0.0, 0.05, 0.1])


def test_truncated_las_and_laz(tmp_path):
    xyz = np.arange(30, dtype=float).reshape(10, 3)
    for suffix in (".las", ".laz"):
        good = tmp_path / f"good{suffix}"
        write_las(good, xyz, np.zeros(10, np.uint16), np.zeros(10, np.uint16), np.zeros(10))
        data = good.read_bytes()
        cuts = [len(data) - 40, 100] if suffix == ".laz" else [len(data) - 2 * 30, len(data) - 7, 100]
        for cut in cuts:  # 30 bytes per point: format 1 (28) + 2 extra bytes
            path = write(tmp_path / f"cut{cut}{suffix}", data[:cut])
            with pytest.raises(CalibError) as excinfo:
                read_point_cloud(path)
            assert_one_line_error(excinfo, path)


# --------------------------------------------------------------------------
# KITTI .bin, .npy, .npz
# --------------------------------------------------------------------------


def test_kitti_bin_with_given_columns(tmp_path):
    data = np.float32([[1, 2, 3, 0.5], [4, 5, 6, 0.25], [7, 8, 9, 0.0]])
    cloud = read_point_cloud(write(tmp_path / "000000.bin", data.tobytes()), bin_columns=4)
    np.testing.assert_array_equal(cloud.xyz, data[:, :3])
    np.testing.assert_array_equal(cloud.fields["intensity"], data[:, 3])
    assert cloud.meta["bin_columns"] == 4 and cloud.meta["bin_columns_how"] == "given"
    cases = [
        ("odd.bin", data.tobytes()[:-2], {}, "float32"),
        ("cut.bin", data.tobytes()[:-4], {"bin_columns": 4}, "--bin-columns 4"),
        ("empty.bin", b"", {}, "empty"),
        # Three points are too few to see a period in: refused, naming the option.
        ("short.bin", data.tobytes(), {}, "--bin-columns"),
    ]
    for name, raw, options, word in cases:
        path = write(tmp_path / name, raw)
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path, **options)
        assert_one_line_error(excinfo, path, word)
    with pytest.raises(CalibError, match="bin_columns must be"):
        read_point_cloud(tmp_path / "000000.bin", bin_columns=2)


def test_npy_shapes(tmp_path):
    pts = np.arange(12, dtype=np.float32).reshape(4, 3) + 1
    np.save(tmp_path / "n3.npy", pts)
    np.save(tmp_path / "n4.npy", np.c_[pts, [9, 8, 7, 6]])
    np.save(tmp_path / "hw3.npy", pts.reshape(2, 2, 3))
    assert read_point_cloud(tmp_path / "n3.npy").organized_shape is None
    np.testing.assert_array_equal(read_point_cloud(tmp_path / "n3.npy").xyz, pts)
    np.testing.assert_array_equal(read_point_cloud(tmp_path / "n4.npy").fields["intensity"], [9, 8, 7, 6])
    grid = read_point_cloud(tmp_path / "hw3.npy")
    assert grid.organized_shape == (2, 2)
    np.testing.assert_array_equal(grid.xyz, pts)
    structured = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("ring", "u2")])
    structured["x"], structured["ring"] = [1, 2, 3], [4, 5, 6]
    np.save(tmp_path / "s.npy", structured)
    cloud = read_point_cloud(tmp_path / "s.npy")
    np.testing.assert_array_equal(cloud.xyz[:, 0], [1, 2, 3])
    np.testing.assert_array_equal(cloud.ring_field(), [4, 5, 6])

    np.save(tmp_path / "bool.npy", np.ones((4, 3), bool))
    refuse(tmp_path / "bool.npy", "integer or float coordinates")
    np.save(tmp_path / "n5.npy", np.zeros((4, 5)))
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    write(tmp_path / "trunc.npy", (tmp_path / "n3.npy").read_bytes()[:-8])
    np.save(tmp_path / "empty.npy", np.zeros((0, 3)))
    np.save(tmp_path / "nan.npy", np.full((3, 3), np.nan))
    for name, word in [("n5", "shape"), ("obj", "unreadable"), ("trunc", "unreadable"), ("empty", "empty"), ("nan", "NaN")]:
        path = tmp_path / f"{name}.npy"
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path)
        assert_one_line_error(excinfo, path, word)


def test_npz_variants(tmp_path):
    x, y, z = np.float32([1, 2]), np.float32([3, 4]), np.float32([5, 6])
    np.savez(tmp_path / "xyz.npz", x=np.r_[x, 7], y=np.r_[y, 8], z=np.r_[z, 9], ring=np.uint16([1, 0, 2]), note=np.zeros(7))
    cloud = read_point_cloud(tmp_path / "xyz.npz")
    np.testing.assert_array_equal(cloud.xyz, [[1, 3, 5], [2, 4, 6], [7, 8, 9]])
    assert set(cloud.fields) == {"ring"}
    np.savez(tmp_path / "points.npz", points=np.float32([[1, 2, 3], [4, 5, 6], [7, 8, 9]]), intensity=np.float32([0.5, 1, 2]))
    cloud = read_point_cloud(tmp_path / "points.npz")
    np.testing.assert_array_equal(cloud.xyz, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    np.testing.assert_array_equal(cloud.fields["intensity"], [0.5, 1, 2])
    np.savez(tmp_path / "bad.npz", a=np.zeros(3), b=np.zeros(3))
    write(tmp_path / "zip.npz", b"PK\x03\x04 broken zip")
    for name, word in [("bad", "keys: a, b"), ("zip", "unreadable")]:
        path = tmp_path / f"{name}.npz"
        with pytest.raises(CalibError) as excinfo:
            read_point_cloud(path)
        assert_one_line_error(excinfo, path, word)


def test_native_npz_goes_through_the_model(tmp_path):
    # A spherical scan written by hand per npz_format's key table.
    range_m = np.array([[1.0, np.nan], [2.0, 4.0]])
    elevation = np.radians([10.0, -10.0])
    azimuth = np.radians([30.0, -30.0])
    path = tmp_path / "scan.npz"
    np.savez(path, model=np.array("spherical"), range_m=range_m, elevation_rad=elevation, azimuth_rad=azimuth, wrap_cols=np.array(False))
    depth = load_scan(path, organize="auto", beams=64)
    assert depth.meta["organize"] == "native" and depth.shape == (2, 2)
    expected = 4.0 * np.array([np.cos(elevation[1]) * np.cos(azimuth[1]), np.cos(elevation[1]) * np.sin(azimuth[1]), np.sin(elevation[1])])
    np.testing.assert_allclose(depth.points[1, 1], expected, atol=1e-12)
    cloud = read_point_cloud(path)
    assert cloud.organized_shape == (2, 2) and np.isnan(cloud.xyz[1]).all()


def test_unknown_and_missing_files(tmp_path):
    path = write(tmp_path / "scan.xyz", b"1 2 3\n")
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path)
    assert_one_line_error(excinfo, path, "unknown scan file type", ".xyz")
    with pytest.raises(CalibError, match="not found"):
        load_scan(tmp_path / "nope.pcd")
    (tmp_path / "dir.pcd").mkdir()
    with pytest.raises(CalibError, match="is a folder"):
        read_point_cloud(tmp_path / "dir.pcd")


# --------------------------------------------------------------------------
# load_scan: choosing the organisation
# --------------------------------------------------------------------------


def ring_cloud(n_rings: int = 4, n_cols: int = 90, drop_every: int | None = 7) -> np.ndarray:
    """Records on an exact ring x azimuth grid (column centres), some cells dropped."""
    step = 2 * np.pi / n_cols
    rows, cols = np.meshgrid(np.arange(n_rings), np.arange(n_cols), indexing="ij")
    keep = np.ones(rows.size, bool) if drop_every is None else (np.arange(rows.size) % drop_every) != 3
    rows, cols = rows.ravel()[keep], cols.ravel()[keep]
    elevation = np.radians(np.array([5.0, 1.0, -2.0, -11.0]))[rows]  # row 0 highest
    azimuth = np.pi - (cols + 0.5) * step
    rng = 4.0 + (rows * n_cols + cols) % 13
    rec = np.zeros(len(rows), dtype=RECORD)
    rec["x"] = rng * np.cos(elevation) * np.cos(azimuth)
    rec["y"] = rng * np.cos(elevation) * np.sin(azimuth)
    rec["z"] = rng * np.sin(elevation)
    rec["ring"] = n_rings - 1 - rows  # ring 0 = lowest beam, as most drivers number them
    rec["intensity"] = rows * 1000 + cols
    return rec


def test_load_scan_picks_ring_then_scan_order_then_elevation(tmp_path):
    rec = ring_cloud()
    with_ring = write(tmp_path / "ring.pcd", pcd_bytes(rec, "binary"))
    depth = load_scan(with_ring)
    assert depth.meta["organize"] == "ring" and depth.shape == (4, 90)
    assert depth.meta["source"] == str(with_ring)
    # The intensity encodes the true cell: row * 1000 + column.
    rows, cols = np.nonzero(depth.valid)
    np.testing.assert_array_equal(depth.meta["field_images"]["intensity"][rows, cols], rows * 1000 + cols)
    assert depth.valid.sum() == len(rec)

    # Without a ring field, points stored ring after ring are a firing order (issue 10).
    no_ring = tmp_path / "noring.npy"
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=1)
    np.save(no_ring, xyz)
    def rows_of_points(d, order=None):
        """Each row's set of file points (as indices into ``rec``): the recovered lasers."""
        index = d.meta["point_index"]
        return [sorted((index[r][index[r] >= 0] if order is None else order[index[r][index[r] >= 0]]).tolist()) for r in range(d.shape[0])]

    in_order = load_scan(no_ring)
    assert in_order.meta["organize"] == "firing_order" and in_order.shape == (4, 90)
    assert in_order.valid.sum() == len(rec)
    assert rows_of_points(in_order) == rows_of_points(depth)
    # Shuffled, the order says nothing: elevation clustering, with or without --beams, says why.
    shuffled = tmp_path / "shuffled.npy"
    perm = np.random.default_rng(0).permutation(len(xyz))
    np.save(shuffled, xyz[perm])
    for kwargs in ({}, {"beams": 4}):
        by_elevation = load_scan(shuffled, **kwargs)
        assert by_elevation.meta["organize"] == "elevation" and by_elevation.shape == (4, 90)
        assert by_elevation.valid.sum() == len(rec)
        assert rows_of_points(by_elevation, perm) == rows_of_points(depth)
        assert "not beams stored in firing order" in by_elevation.meta["organize_report"].line()
    spherical = load_scan(shuffled, organize="spherical")
    assert spherical.meta["organize"] == "spherical"
    assert spherical.meta["h_res_deg"] == pytest.approx(4.0)  # the 90-column azimuth step

    with pytest.raises(CalibError) as excinfo:
        load_scan(no_ring, organize="ring")
    assert_one_line_error(excinfo, no_ring, "no ring field")
    with pytest.raises(CalibError) as excinfo:
        load_scan(no_ring, organize="elevation")
    assert_one_line_error(excinfo, no_ring, "beams")
    with pytest.raises(CalibError, match="unknown organize"):
        load_scan(no_ring, organize="magic")
    with pytest.raises(CalibError, match="beams"):
        load_scan(no_ring, beams=0)


def test_load_scan_firing_alias(tmp_path):
    rec = ring_cloud(drop_every=None)
    # Ring after ring, each a clockwise sweep starting behind the sensor: the storage order above.
    path = tmp_path / "fire.npy"
    np.save(path, np.stack([rec["x"], rec["y"], rec["z"]], axis=1))
    depth = load_scan(path, organize="firing", beams=4)
    assert depth.meta["organize"] == "firing_order" and depth.shape == (4, 90) and depth.valid.all()


def test_load_scan_organized_pcd_is_turned_upright(tmp_path):
    # A 2 x 3 grid whose FIRST row is the LOWER beam, azimuth decreasing to the right.
    elevation = np.radians([[-5.0], [5.0]])
    azimuth = np.radians([[60.0, 0.0, -60.0]])
    rng = np.array([[2.0, 3.0, 4.0], [5.0, 6.0, 7.0]])
    xyz = np.stack(np.broadcast_arrays(rng * np.cos(elevation) * np.cos(azimuth), rng * np.cos(elevation) * np.sin(azimuth), rng * np.sin(elevation)), axis=-1)
    rec = np.zeros(6, dtype=RECORD)
    rec["x"], rec["y"], rec["z"] = (xyz.reshape(-1, 3)[:, i] for i in range(3))
    rec["x"][1] = np.nan  # one missing return
    path = write(tmp_path / "org.pcd", pcd_bytes(rec, "binary", height=2))
    depth = load_scan(path)
    assert depth.meta["organize"] == "organized" and depth.meta["flipped_rows"] and not depth.meta["flipped_cols"]
    assert depth.meta["wrap_cols"] is False
    np.testing.assert_allclose(depth.range_m, [[5.0, 6.0, 7.0], [2.0, np.nan, 4.0]], rtol=1e-6)
    np.testing.assert_array_equal(depth.meta["point_index"], [[3, 4, 5], [0, -1, 2]])
    # The missing cell still has a direction: lower row's elevation, middle column's azimuth.
    np.testing.assert_allclose(depth.directions[1, 1], [np.cos(np.radians(5.0)), 0.0, -np.sin(np.radians(5.0))], atol=1e-6)


# --------------------------------------------------------------------------
# Hostile files: bounded before reading, refused in one line, quietly
# --------------------------------------------------------------------------


def refuse(path: Path, *words: str, capfd=None, **options) -> str:
    """Read ``path``, expect a one-line CalibError containing ``words`` and (with capfd) nothing printed."""
    if capfd is not None:
        capfd.readouterr()
    with pytest.raises(CalibError) as excinfo:
        read_point_cloud(path, **options)
    assert_one_line_error(excinfo, path, *words)
    if capfd is not None:
        out, err = capfd.readouterr()
        assert out == "" and err == "", (out + err)[:300]
    return str(excinfo.value)


def test_non_regular_files_are_refused_without_blocking(tmp_path):
    import os

    fifo = tmp_path / "scan.pcd"
    os.mkfifo(fifo)  # opening a FIFO for reading would block until a writer comes
    refuse(fifo, "not a regular file")
    with pytest.raises(CalibError, match="not a regular file"):
        load_scan("/dev/zero")


def test_ascii_pcd_without_a_final_newline_is_read_a_cut_that_loses_values_is_refused(tmp_path):
    rec = sample_records(10)
    good = pcd_bytes(rec, "ascii")
    # Without its final newline the file is whole: every point holds its values (issue 23: PCL's rops_cloud.pcd).
    cloud = read_point_cloud(write(tmp_path / "no_newline.pcd", good[:-1]))
    np.testing.assert_array_equal(cloud.fields["time"], rec["time"])
    # Cut inside the last line so that its last value is lost: refused.
    last_blank = good.rstrip().rindex(b" ")
    refuse(write(tmp_path / "cut.pcd", good[:last_blank]), "truncated", "point 10 has 5 values")
    # A whole file still reads, with the last number intact.
    cloud = read_point_cloud(write(tmp_path / "whole.pcd", good))
    np.testing.assert_array_equal(cloud.fields["time"], rec["time"])


def test_pcd_count_on_xyz_and_declared_counts(tmp_path):
    head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 3 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n"
    refuse(write(tmp_path / "count3.pcd", (head + "1 2 3 4 5\n" * 3).encode()), "COUNT 3")
    rec = sample_records(10)
    ascii_data = pcd_bytes(rec, "ascii")
    # More records than POINTS declares (binary; binary_compressed files from PCL carry slack after their block).
    refuse(write(tmp_path / "more.pcd", pcd_bytes(rec, "binary") + rec[:3].tobytes()), "after the 10 points")
    assert len(read_point_cloud(write(tmp_path / "newline.pcd", pcd_bytes(rec, "binary") + b"\n"))) == 10
    # More lines than POINTS declares.
    refuse(write(tmp_path / "extra.pcd", ascii_data + ascii_data.splitlines(keepends=True)[-1]), "10 points", "11 lines")
    # 10^12 points declared, one held: refused from the sizes, before anything is allocated.
    huge = pcd_bytes(rec[:1], "binary").replace(b"WIDTH 1\n", b"WIDTH 1000000000000\n").replace(b"POINTS 1\n", b"POINTS 1000000000000\n")
    refuse(write(tmp_path / "huge.pcd", huge), "1,000,000,000,000 points", "--max-points")
    small_cap = pcd_bytes(rec, "binary")
    refuse(write(tmp_path / "cap.pcd", small_cap), "--max-points", max_points=5)


def test_pcd_headers_written_by_other_software(tmp_path):
    rec = sample_records(12)
    # VERSION .6 (PCL before 1.0) and upper-case X Y Z (PDAL).
    data = pcd_bytes(rec, "binary").replace(b"VERSION 0.7", b"VERSION .6").replace(b"FIELDS x y z", b"FIELDS X Y Z")
    cloud = read_point_cloud(write(tmp_path / "v6.pcd", data))
    np.testing.assert_array_equal(cloud.xyz[:, 2], rec["z"])
    assert cloud.meta["version"] == ".6"
    # An unorganised list written as WIDTH 1 HEIGHT N is flat, not an N x 1 grid.
    flat = pcd_bytes(rec, "binary").replace(b"WIDTH 12\nHEIGHT 1\n", b"WIDTH 1\nHEIGHT 12\n")
    assert read_point_cloud(write(tmp_path / "tall.pcd", flat)).organized_shape is None
    refuse(write(tmp_path / "v9.pcd", data.replace(b"VERSION .6", b"VERSION 9.1")), "VERSION 9.1")


def test_too_few_points_and_absurd_coordinates(tmp_path):
    np.save(tmp_path / "two.npy", np.float32([[1, 2, 3], [4, 5, 6]]))
    refuse(tmp_path / "two.npy", "only 2 finite point")
    one = np.full((5, 3), np.nan)
    one[2] = [1, 2, 3]
    np.save(tmp_path / "one.npy", one)
    refuse(tmp_path / "one.npy", "only 1 finite point")
    big = np.float64([[1, 2, 3], [4, 5, 6], [1e300, 0, 0]])
    np.save(tmp_path / "big.npy", big)
    refuse(tmp_path / "big.npy", "1e+300")
    rec = sample_records(6)
    rec["y"][3] = np.inf
    refuse(write(tmp_path / "inf.pcd", pcd_bytes(rec, "binary")), "1 of 6 points have an infinite coordinate")
    # 1e300 written into a float32 PCD field overflows to inf: refused, and numpy's overflow warning is not printed.
    head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n"
    refuse(write(tmp_path / "e300.pcd", (head + "1 2 3\n4 5 6\n1e300 0 0\n").encode()), "infinite")


def test_ply_declared_counts_must_match_the_data(tmp_path, capfd):
    xyz = np.float32([[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    header = ply_header("binary_little_endian", 10**12, "x y z")
    refuse(write(tmp_path / "huge.ply", header + xyz[:1].tobytes()), "1,000,000,000,000", capfd=capfd)
    refuse(write(tmp_path / "huge_ascii.ply", ply_header("ascii", 10**12, "x y z") + b"1 2 3\n"), "1,000,000,000,000", capfd=capfd)
    faces = ply_header("binary_little_endian", 3, "x y z").replace(
        b"end_header", b"element face 1000000000\nproperty list uchar int vertex_indices\nend_header"
    )
    refuse(write(tmp_path / "faces.ply", faces + xyz.tobytes()), "1,000,000,000 face", capfd=capfd)
    body = b"1.5 2 3\n4 5 6.25\n7 8 9.125"  # no final newline, but every row holds its 3 values: whole
    np.testing.assert_array_equal(read_point_cloud(write(tmp_path / "whole.ply", ply_header("ascii", 3, "x y z") + body)).xyz,
                                  [[1.5, 2, 3], [4, 5, 6.25], [7, 8, 9.125]])
    cut = body[: body.rindex(b" ")]  # the last row lost its z
    refuse(write(tmp_path / "cut.ply", ply_header("ascii", 3, "x y z") + cut), "truncated", "vertex 2 has 2 values", capfd=capfd)


def test_ply_rows_beyond_the_declared_counts_are_refused(tmp_path):
    xyz = np.float32([[1, 2, 3], [4, 5, 6], [7, 8, 9], [1, 1, 1]])
    ascii_body = b"".join(b"%r %r %r\n" % tuple(map(float, r)) for r in xyz)
    refuse(write(tmp_path / "fewer.ply", ply_header("ascii", 3, "x y z") + ascii_body), "3 vertex rows but holds 4 lines")
    refuse(write(tmp_path / "fewer_bin.ply", ply_header("binary_little_endian", 3, "x y z") + xyz.tobytes()), "12 bytes more")


def test_textured_ply_keeps_vertices_as_stored_quietly(tmp_path, capfd):
    # Two triangles sharing an edge, with per-corner texture coordinates and a texture file that does not exist.
    vertices = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    header = (
        "ply\nformat ascii 1.0\ncomment TextureFile missing.png\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
    )
    body = "".join(f"{x} {y} {z}\n" for x, y, z in vertices.tolist())
    body += "3 0 1 2 6 0 0 1 0 0 1\n3 1 3 2 6 0.5 0 0.5 0.5 0 0.5\n"
    capfd.readouterr()
    cloud = read_point_cloud(write(tmp_path / "tex.ply", (header + body).encode()))
    assert capfd.readouterr() == ("", "")
    np.testing.assert_array_equal(cloud.xyz, vertices)


def test_las_declaring_more_points_than_it_holds(tmp_path):
    good = tmp_path / "good.las"
    write_las(good, np.arange(30, dtype=float).reshape(10, 3), np.zeros(10, np.uint16), np.zeros(10, np.uint16), np.zeros(10))
    data = bytearray(good.read_bytes())
    struct.pack_into("<I", data, 107, 4_000_000_000)  # legacy point count (LAS 1.2 header, byte 107)
    refuse(write(tmp_path / "huge.las", bytes(data)), "4,000,000,000", "--max-points")
    struct.pack_into("<I", data, 107, 11)
    refuse(write(tmp_path / "eleven.las", bytes(data)), "truncated")


def _zip_bomb(path: Path, name: str, header: bytes, zero_bytes: int, **small) -> None:
    """An .npz member of ``zero_bytes`` zeros after ``header``, deflated (a few kB on disk), plus ``small`` arrays."""
    import io
    import zipfile

    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for key, value in small.items():
            buffer = io.BytesIO()
            np.save(buffer, value)
            archive.writestr(f"{key}.npy", buffer.getvalue())
        with archive.open(name, "w", force_zip64=True) as member:
            member.write(header)
            chunk = bytes(1 << 20)
            for start in range(0, zero_bytes, len(chunk)):
                member.write(chunk[: min(len(chunk), zero_bytes - start)])


def _npy_header(shape, dtype="<f8") -> bytes:
    import io

    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, {"descr": dtype, "fortran_order": False, "shape": shape})
    return buffer.getvalue()


def test_npz_zip_bomb_is_refused_from_the_central_directory(tmp_path):
    n = 6_000_000  # 6 M points of float64 x 3: 144 MB once decompressed, under 1 MB on disk
    path = tmp_path / "bomb.npz"
    _zip_bomb(path, "points.npy", _npy_header((n, 3)), n * 24)
    assert path.stat().st_size < 1_000_000
    refuse(path, "6,000,000 points", "--max-points")
    native = tmp_path / "native_bomb.npz"
    _zip_bomb(
        native, "range_m.npy", _npy_header((3000, 2000)), 3000 * 2000 * 8,
        model=np.array("spherical"), elevation_rad=np.zeros(3000), azimuth_rad=np.zeros(2000),
    )
    with pytest.raises(CalibError, match="6,000,000 cells.*--max-points"):
        load_scan(native)
    single = tmp_path / "single_bomb.npz"
    _zip_bomb(single, "grid.npy", _npy_header((3000, 2000)), 3000 * 2000 * 8)
    refuse(single, "shape (3000, 2000)")


def test_npz_member_header_must_match_its_size(tmp_path):
    import zipfile

    path = tmp_path / "liar.npz"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("points.npy", _npy_header((10**9, 3)) + np.zeros((3, 3)).tobytes())
    refuse(path, "declares shape (1000000000, 3)")


def test_native_npz_without_a_valid_cell_is_refused(tmp_path):
    path = tmp_path / "blank.npz"
    np.savez(path, model=np.array("organized"), points=np.full((4, 5, 3), np.nan))
    with pytest.raises(CalibError) as excinfo:
        load_scan(path)
    assert_one_line_error(excinfo, path, "no valid cell")
    far = tmp_path / "far.npz"
    points = np.ones((2, 2, 3))
    points[0, 0] = [1e300, 0, 0]
    np.savez(far, model=np.array("organized"), points=points)
    with pytest.raises(CalibError, match="key 'points' holds 1 value.*1e\\+300"):
        load_scan(far)


def test_max_points_is_validated():
    with pytest.raises(CalibError, match="max_points"):
        read_point_cloud("x.pcd", max_points=0)


# --------------------------------------------------------------------------
# Images
# --------------------------------------------------------------------------


def _png(width: int, height: int, rows: int) -> bytes:
    """An 8-bit RGB PNG declaring width x height but holding ``rows`` rows of pixels."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    pixels = zlib.compress(b"".join(b"\0" + bytes(3 * width) for _ in range(rows)))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", pixels) + chunk(b"IEND", b"")


def test_images_checked_from_the_header_and_quiet(tmp_path, capfd):
    import os

    from calib_core.io.images import image_header_size, load_image_rgb

    good = write(tmp_path / "good.png", _png(40, 30, 30))
    assert image_header_size(good) == (40, 30)
    image = load_image_rgb(good)
    assert image.shape == (30, 40, 3) and image.dtype == np.uint8
    cases = {
        "huge.png": (_png(30000, 30000, 1), "pixels"),  # 900 MP declared: refused before decoding
        "short.png": (_png(100, 100, 10), "cannot decode"),  # libpng complains: folded into the line
        "empty.png": (b"", "empty"),
        "text.png": (b"hello, not an image\n", "not a readable image"),
    }
    for name, (data, word) in cases.items():
        path = write(tmp_path / name, data)
        capfd.readouterr()
        with pytest.raises(CalibError) as excinfo:
            load_image_rgb(path)
        assert_one_line_error(excinfo, path, word)
        assert capfd.readouterr() == ("", ""), name
    with pytest.raises(CalibError, match="more than the 1,000 allowed"):
        load_image_rgb(good, max_pixels=1000)
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    with pytest.raises(CalibError, match="not a regular file"):
        load_image_rgb(fifo)


def test_fuzz_corpus_of_scans_is_complete(tmp_path):
    """The scan/image fuzz corpus: >= 200 hostile files over every format, >= 25 mutants, unique names."""
    from tests.fuzz.cases_scans import make_cases

    cases = make_cases(tmp_path)
    names = [case.name for case in cases]
    assert len(names) == len(set(names))
    mutants = [c for c in cases if c.name.startswith("mutant/")]
    hostile = [c for c in cases if not c.name.startswith("mutant/")]
    assert len(hostile) >= 200 and len(mutants) >= 25
    suffixes = {Path(c.argv[c.argv.index("--scan") + 1]).suffix for c in hostile if c.argv[0] == "ba-images"}
    assert {".pcd", ".ply", ".las", ".laz", ".bin", ".npy", ".npz"} <= suffixes
    images = {Path(c.argv[c.argv.index("--image") + 1]).suffix for c in hostile if c.argv[0] == "colorize"}
    assert {".png", ".jpg"} <= images
    for case in cases:
        for flag in ("--scan", "--image"):
            if flag in case.argv:
                target = Path(case.argv[case.argv.index(flag) + 1])
                assert target.exists() or target.is_symlink() or "missing" in case.name, case.name
