"""Issue 23, scans: valid files refused and hostile inputs not handled cleanly.

* an indoor RGB-D frame in the camera's frame (SUN RGB-D as mmdetection3d stores it) is organised by default;
* 2-D data stored as a point cloud (PCL's lena.pcd: pixel x, y and z = 0) is not a 3-D scan;
* a native ``.npz`` whose deflate stream is damaged is one ``error:`` line naming the file, exit 2;
* a native scan too small for a BA image (a 1 x 1 or 1 x N rotating scan) is refused;
* a pairs file whose ``laser_xyz`` is the lidar origin is refused, naming the pair.

The files are made here from each format's description; the expected values come from the
geometry that generated them, not from the code under test.
"""

from __future__ import annotations

import io
import zipfile
import zlib

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import load_pairs_yaml
from repo_paths import SAMPLE
from cli_helpers import one_error_line, run_cli


# --------------------------------------------------------------------------
# An indoor RGB-D frame in the camera's frame
# --------------------------------------------------------------------------


def rgbd_frame(n_points: int = 40_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A SUN RGB-D-like frame: a pinhole depth camera (730 x 530 px, f = 529.5 px) at the origin looks into a
    box-shaped room; ``n_points`` of its pixels are drawn at random (mmdetection3d subsamples the frame), in
    SUN RGB-D's depth coordinates (x right, y forward, z up), tilted 10 deg down.

    Returns the (N, 6) float32 records x, y, z, r, g, b (colours in 0..1) and the unit viewing ray of each
    point (depth coordinates), from which the points were made.
    """
    rng = np.random.default_rng(seed)
    width, height, focal = 730, 530, 529.5
    u, v = rng.uniform(0, width, n_points), rng.uniform(0, height, n_points)
    ray = np.stack([(u - width / 2) / focal, (v - height / 2) / focal, np.ones(n_points)], axis=1)  # x right, y down
    distance = np.full(n_points, np.inf)
    # Walls of the room (camera frame): back z = 4.5, sides x = +-2.2, floor y = 1.3, ceiling y = -1.4.
    for axis, plane in ((2, 4.5), (0, 2.2), (0, -2.2), (1, 1.3), (1, -1.4)):
        with np.errstate(divide="ignore"):
            t = plane / ray[:, axis]
        distance = np.where((t > 0) & (t < distance), t, distance)
    # A cupboard: its front face z = 2.0 for -0.6 < x < 0.4, 0.1 < y (down to the floor).
    t = 2.0 / ray[:, 2]
    front = (ray[:, 0] * t > -0.6) & (ray[:, 0] * t < 0.4) & (ray[:, 1] * t > 0.1) & (t < distance)
    distance = np.where(front, t, distance)
    camera = ray * distance[:, None]
    tilt = np.radians(-10.0)
    rotation = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    to_depth = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # x right, y forward, z up
    xyz = camera @ to_depth.T @ rotation.T
    colours = rng.uniform(0.0, 1.0, (n_points, 3))
    return np.hstack([xyz, colours]).astype(np.float32), xyz / np.linalg.norm(xyz, axis=1, keepdims=True)


def test_an_rgbd_frame_in_the_camera_frame_is_organised_by_default(tmp_path):
    records, _ = rgbd_frame()
    path = tmp_path / "000017.bin"
    records.tofile(path)
    depth = load_scan(path)
    report = depth.organize_report
    assert report.method == "spherical" and "narrow field" in report.reason
    assert report.kept_share >= 0.55 and report.valid_share >= 0.5, report.line()
    # Every cell holds a point of the file, unchanged.
    rows, cols = np.nonzero(depth.valid)
    index = depth.meta["point_index"][rows, cols]
    np.testing.assert_array_equal(depth.points[rows, cols], records[index, :3].astype(np.float64))
    # The columns are cut to the camera's field: the frame's azimuth extent (about 75 deg here), not 360.
    azimuth = np.degrees(np.arctan2(records[:, 1], records[:, 0]).astype(np.float64))
    field = azimuth.max() - azimuth.min()  # the frame looks along +y: no wrap at +-180 deg
    cell = depth.meta["h_res_deg"]
    assert field / cell <= depth.shape[1] <= field / cell + 2 and depth.meta["wrap_cols"] is False
    run = run_cli("ba-images", "--scan", str(path), "-o", str(tmp_path / "ba"))
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("organised by spherical") and "narrow field" in run.stdout.splitlines()[0]


def test_a_see_through_cloud_over_a_narrow_field_is_still_refused(tmp_path):
    # A solid block of random points 5-9 m ahead: many points lie behind nearer ones, no view from the origin.
    rng = np.random.default_rng(1)
    block = np.column_stack([rng.uniform(5, 9, 30_000), rng.uniform(-2, 2, 30_000), rng.uniform(-1.5, 1.5, 30_000)])
    path = tmp_path / "block.npy"
    np.save(path, block)
    with pytest.raises(CalibError, match="does not look like a scan seen from the lidar origin"):
        load_scan(path)


# --------------------------------------------------------------------------
# 2-D data stored as a point cloud
# --------------------------------------------------------------------------


def test_an_image_stored_as_a_pcd_is_not_a_3d_scan(tmp_path):
    # As PCL's lena.pcd: an organised grid whose x, y are the pixel's column and row and z = 0.
    height, width = 48, 64
    rows, cols = np.mgrid[0:height, 0:width]
    grey = (rows * 5 + cols * 3) % 256
    header = (
        "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
        f"WIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {width * height}\nDATA ascii\n"
    )
    body = "".join(f"{c} {r} 0 {g}\n" for c, r, g in zip(cols.ravel(), rows.ravel(), grey.ravel()))
    path = tmp_path / "lena.pcd"
    path.write_text(header + body)
    with pytest.raises(CalibError) as excinfo:
        load_scan(path)
    message = str(excinfo.value)
    assert "not a 3-D scan" in message and "z = 0" in message and str(path) in message and "\n" not in message
    line = one_error_line(run_cli("ba-images", "--scan", str(path), "-o", str(tmp_path / "ba")))
    assert "lena.pcd" in line and "not a 3-D scan" in line


# --------------------------------------------------------------------------
# Native scans: a damaged deflate stream, too small for BA images
# --------------------------------------------------------------------------


def rotating_scan(rows: int, cols: int) -> dict[str, np.ndarray]:
    """A native rotating-scanner scan (paper eq. 3), ranges 2-3 m."""
    rng = np.random.default_rng(rows * 1000 + cols)
    return {
        "model": np.array("rotating_2d"),
        "range_m": 2.0 + rng.random((rows, cols)),
        "theta_rad": np.linspace(-0.5, 0.5, rows)[:, None],
        "phi_rad": np.linspace(0.0, 3.0, cols)[None, :],
        "dx_m": np.array(0.0),
        "dz_m": np.array(0.0),
    }


def zlib_damaged_npz(arrays: dict[str, np.ndarray]) -> bytes:
    """``np.savez_compressed(arrays)`` with one bit flipped in ``range_m``'s deflate stream, chosen (by zlib
    itself) so that decompressing it fails with a zlib error after the .npy header, not a CRC mismatch."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    data = bytearray(buffer.getvalue())
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as archive:
        info = archive.getinfo("range_m.npy")
    # The member's data follow its local header: 30 bytes, then its name and extra field (their lengths at 26, 28).
    name_len, extra_len = (int.from_bytes(data[info.header_offset + k : info.header_offset + k + 2], "little") for k in (26, 28))
    start = info.header_offset + 30 + name_len + extra_len
    stream = bytes(data[start : start + info.compress_size])
    for offset in range(info.compress_size // 2, info.compress_size):
        for bit in range(8):
            damaged = bytearray(stream)
            damaged[offset] ^= 1 << bit
            try:  # as zipfile reads it: at most the member's size of output
                zlib.decompressobj(-15).decompress(bytes(damaged), info.file_size)
            except zlib.error:
                data[start + offset] ^= 1 << bit
                return bytes(data)
    raise AssertionError("no bit flip made a zlib error")


def test_a_native_npz_with_a_damaged_deflate_stream_is_one_error_line(tmp_path):
    path = tmp_path / "damaged.npz"
    path.write_bytes(zlib_damaged_npz(rotating_scan(40, 80)))
    with pytest.raises(CalibError, match="damaged.npz"):
        load_scan(path)
    line = one_error_line(run_cli("ba-images", "--scan", str(path), "-o", str(tmp_path / "ba")))
    assert str(path) in line and "range_m" in line


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (5, 1)])
def test_a_native_scan_too_small_for_bearing_angle_images_is_refused(tmp_path, shape):
    path = tmp_path / f"tiny_{shape[0]}x{shape[1]}.npz"
    np.savez(path, **rotating_scan(*shape))
    line = one_error_line(run_cli("ba-images", "--scan", str(path), "-o", str(tmp_path / "ba")))
    assert str(path) in line and ("too small for Bearing Angle images" in line or "valid cell" in line)
    assert not (tmp_path / "ba").exists() or not any((tmp_path / "ba").iterdir())


# --------------------------------------------------------------------------
# A laser point at the lidar origin
# --------------------------------------------------------------------------


def test_a_pair_at_the_lidar_origin_is_refused_naming_it(tmp_path):
    pairs = tmp_path / "pairs.yaml"
    pairs.write_text(
        "pairs:\n"
        "  - {laser_xyz: [2.0, 1.0, 0.5], pixel: [100, 120]}\n"
        "  - {laser_xyz: [0, 0, 0], pixel: [200, 220], id: 7}\n"
    )
    with pytest.raises(CalibError) as excinfo:
        load_pairs_yaml(pairs)
    assert "pair 1" in str(excinfo.value) and "id 7" in str(excinfo.value) and "origin" in str(excinfo.value)
    line = one_error_line(run_cli("solve", "--camera", str(SAMPLE / "camera.yaml"), "--pairs", str(pairs),
                                  "-o", str(tmp_path / "e.yaml")))
    assert "pairs.yaml: pair 1" in line and "lidar origin" in line
    assert not (tmp_path / "e.yaml").exists()


# --------------------------------------------------------------------------
# The azimuth resolution the error asks for is an option that exists
# --------------------------------------------------------------------------


def test_too_few_azimuth_steps_name_the_option_that_gives_them(tmp_path):
    # Three rings of three points each: 6 azimuth steps, too few to estimate the columns.
    elevation, azimuth = np.radians([2.0, 0.0, -2.0]), np.radians([12.0, 23.0, 34.0])
    rows = [(5 * np.cos(e) * np.cos(a), 5 * np.cos(e) * np.sin(a), 5 * np.sin(e), ring)
            for ring, e in enumerate(elevation) for a in azimuth]
    header = "VERSION 0.7\nFIELDS x y z ring\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 9\nHEIGHT 1\nPOINTS 9\nDATA ascii\n"
    path = tmp_path / "three_rings.pcd"
    path.write_text(header + "".join(f"{x:.6f} {y:.6f} {z:.6f} {ring}\n" for x, y, z, ring in rows))
    line = one_error_line(run_cli("ba-images", "--scan", str(path), "-o", str(tmp_path / "ba")))
    assert "azimuth resolution" in line and "--h-res-deg" in line and "pass n_cols" not in line
    # The option named works: 10 deg columns, column c centred on azimuth 180 - 10 (c + 0.5) deg.
    depth = load_scan(path, h_res_deg=10.0)
    assert depth.shape == (3, 36)
    assert sorted({int(c) for c in np.nonzero(depth.valid)[1]}) == [int((180 - a) // 10) for a in (34, 23, 12)]
    assert run_cli("ba-images", "--scan", str(path), "--h-res-deg", "10", "-o", str(tmp_path / "ba")).returncode == 0
