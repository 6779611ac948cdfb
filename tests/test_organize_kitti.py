"""Organising clouds stored in scan order without a ring field (KITTI's HDL-64E).

Truth: a synthetic HDL-64E whose laser of every point is known; the KITTI
frame's README (64 beams, stored laser after laser) and its published
calibration (``calib/000002.txt``, parsed here independently of the code
under test); the point count of the ``.bin`` file read with numpy.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from app.cli import main as cli_main
from calib_core.errors import CalibError
from calib_core.io.kitti_calib import read_kitti_camera2
from calib_core.io.point_clouds.float_bin import read_float_records
from calib_core.io.scan_readers import load_scan
from calib_core.lidar.organize_cloud import organize_cloud

REPO = Path(__file__).resolve().parents[1]
KITTI = REPO.parent / "shared" / "data" / "kitti_object_000002"
KITTI_BIN = KITTI / "velodyne" / "000002.bin"
needs_kitti = pytest.mark.skipif(not KITTI_BIN.is_file(), reason=f"KITTI frame not found at {KITTI}")

REPORT = re.compile(
    r"organised by (\w+): (\d+) x (\d+), ([\d.]+) % of cells valid, ([\d.]+) % of points kept \((\d+) of (\d+)\)(.*)"
)


def kitti_points() -> np.ndarray:
    return read_float_records(KITTI_BIN, 4)  # x, y, z, reflectance


def parse_report(stdout: str) -> re.Match:
    match = next((m for m in map(REPORT.match, stdout.splitlines()) if m), None)
    assert match is not None, stdout
    return match


# --------------------------------------------------------------------------
# Synthetic HDL-64E
# --------------------------------------------------------------------------


def hdl64_cloud(seed: int = 0, n_firings: int = 2083, azimuth_offset_deg: float = 0.0):
    """A 64-laser scan stored laser after laser, each laser a sweep from encoder angle 0 upwards.

    Each laser has its own vertical angle (HDL-64E: upper block +2 to -8.33
    deg, lower block -8.83 to -24.33 deg), and its origin sits off the lidar
    origin by a vertical offset (upper block 0.19-0.22 m, lower block
    0.13-0.16 m, like the HDL-64E's calibration) and a horizontal (sideways)
    offset of up to 3 cm, so that elevation and azimuth seen from the origin
    drift with range.  With ``azimuth_offset_deg``, each laser also fires at
    its own azimuth offset (uniform within +-that, like the HDL-64E's
    rotational corrections), so its sweep starts that far off the encoder's
    zero.  Scene: ground 1.73 m below, a wall at 25 m, 12 poles 2-12 m
    away.  5 % of returns are dropped; lasers are stored in a shuffled order.
    Returns points (N, 3) and the laser of every point.
    """
    rng = np.random.default_rng(seed)
    vertical = np.radians(np.r_[np.linspace(2.0, -8.33, 32), np.linspace(-8.83, -24.33, 32)])
    v_offset = np.r_[rng.uniform(0.19, 0.22, 32), rng.uniform(0.13, 0.16, 32)]
    h_offset = rng.uniform(-0.03, 0.03, 64)
    rotation = np.radians(rng.uniform(-azimuth_offset_deg, azimuth_offset_deg, 64))
    encoder = np.arange(n_firings) * (2 * np.pi / n_firings) + rng.normal(0, np.radians(0.005), n_firings)
    poles = np.c_[rng.uniform(2, 12, 12) * np.cos(a := rng.uniform(0, 2 * np.pi, 12)), rng.uniform(2, 12, 12) * np.sin(a)]
    points, lasers = [], []
    for laser in rng.permutation(64):
        az = encoder + rotation[laser]
        cos_az, sin_az = np.cos(az), np.sin(az)
        origin = np.stack([-h_offset[laser] * sin_az, h_offset[laser] * cos_az, np.full_like(az, v_offset[laser])], axis=1)
        d = np.stack([np.cos(vertical[laser]) * cos_az, np.cos(vertical[laser]) * sin_az, np.full_like(az, np.sin(vertical[laser]))], axis=1)
        t = np.full(len(az), np.inf)
        if d[0, 2] < 0:
            t = np.minimum(t, (-1.73 - origin[:, 2]) / d[:, 2])
        # Wall: |o_xy + t d_xy| = 25.
        a2 = (d[:, :2] ** 2).sum(1)
        b = 2 * (origin[:, :2] * d[:, :2]).sum(1)
        c = (origin[:, :2] ** 2).sum(1) - 25.0**2
        t = np.minimum(t, (-b + np.sqrt(b * b - 4 * a2 * c)) / (2 * a2))
        for px, py in poles:
            oc = origin[:, :2] - [px, py]
            b = 2 * (oc * d[:, :2]).sum(1)
            c = (oc**2).sum(1) - 0.15**2
            disc = b * b - 4 * a2 * c
            with np.errstate(invalid="ignore"):
                hit = (-b - np.sqrt(disc)) / (2 * a2)
            hit = np.where((disc > 0) & (hit > 0), hit, np.inf)
            z_hit = origin[:, 2] + hit * d[:, 2]
            t = np.minimum(t, np.where(z_hit < 3.0, hit, np.inf))
        keep = np.isfinite(t) & (t < 80) & (rng.random(len(az)) > 0.05)
        points.append(origin[keep] + t[keep, None] * d[keep])
        lasers.append(np.full(keep.sum(), laser))
    return np.concatenate(points), np.concatenate(lasers)


@pytest.mark.parametrize("azimuth_offset_deg", [0.0, 4.0])
def test_synthetic_hdl64_organises_into_its_64_lasers(azimuth_offset_deg):
    points, lasers = hdl64_cloud(azimuth_offset_deg=azimuth_offset_deg)
    # The offsets really do defeat plain elevation: beams overlap as seen from the origin.
    elevation = np.degrees(np.arcsin(points[:, 2] / np.linalg.norm(points, axis=1)))
    spans = np.array([np.ptp(elevation[lasers == k]) for k in range(64)])
    assert np.median(spans) > 0.5  # wider than the 0.33 / 0.5 deg beam spacing

    # A spurious wrap: one point in the middle of a sweep thrown across the seam.
    points = points.copy()
    mid = np.flatnonzero(lasers == lasers[len(lasers) // 2])[500]
    r = np.hypot(points[mid, 0], points[mid, 1])
    points[mid, :2] = r * np.cos(np.radians(-0.3)), r * np.sin(np.radians(-0.3))
    # Seam jitter: the last point of some sweeps a little past the cut.
    ends = np.flatnonzero(np.diff(lasers))[::5]
    r = np.hypot(points[ends, 0], points[ends, 1])
    points[ends, 0], points[ends, 1] = r * np.cos(np.radians(0.04)), r * np.sin(np.radians(0.04))

    depth = organize_cloud(points)
    report = depth.meta["organize_report"]
    assert report.method == "firing_order" and depth.shape[0] == 64
    assert report.points_in - report.points_kept <= 0.01 * len(points)
    rows, cols = np.nonzero(depth.valid)
    laser_of_cell = lasers[depth.meta["point_index"][rows, cols]]
    # Every row holds exactly one laser, and each laser has its own row.
    per_row = [np.unique(laser_of_cell[rows == r]) for r in range(64)]
    assert all(len(u) == 1 for u in per_row)
    assert sorted(int(u[0]) for u in per_row) == list(range(64))
    # Rows top-down: the lasers' vertical angles decrease down the image.
    vertical = np.r_[np.linspace(2.0, -8.33, 32), np.linspace(-8.83, -24.33, 32)]
    assert np.all(np.diff(vertical[[int(u[0]) for u in per_row]]) < 0)
    # Columns at the firing resolution (2083 firings per turn).
    assert abs(depth.shape[1] - 2083) <= 10


def test_synthetic_hdl64_with_beams_and_forced_method():
    points, lasers = hdl64_cloud(seed=1)
    depth = organize_cloud(points, organize="firing", beams=64)
    assert depth.shape[0] == 64
    with pytest.raises(CalibError, match="found 64 azimuth sweeps"):
        organize_cloud(points, organize="firing", beams=32)


# --------------------------------------------------------------------------
# KITTI 000002
# --------------------------------------------------------------------------


@needs_kitti
def test_kitti_through_the_cli_with_default_options(tmp_path, capsys):
    n_points = len(kitti_points())
    assert cli_main(["ba-images", "--scan", str(KITTI_BIN), "-o", str(tmp_path / "ba")]) == 0
    match = parse_report(capsys.readouterr().out)
    method, rows, cols = match.group(1), int(match.group(2)), int(match.group(3))
    kept, total = int(match.group(6)), int(match.group(7))
    assert method == "firing_order" and rows == 64  # the README's 64 beams
    assert total == n_points and kept >= 0.99 * n_points
    assert 2000 <= cols <= 2300  # ~0.17 deg: an HDL-64E at 10 Hz
    assert len(list((tmp_path / "ba").glob("ba_*.png"))) == 4

    depth = load_scan(KITTI_BIN)
    # Valid cells below the horizon (cell direction below the x-y plane).
    below = depth.directions[..., 2] < 0
    assert depth.valid[below].mean() >= 0.85
    # Laser after laser: every row's points form one block of the file.
    rows_, cols_ = np.nonzero(depth.valid)
    index = depth.meta["point_index"][rows_, cols_]
    first = np.array([index[rows_ == r].min() for r in range(64)])
    last = np.array([index[rows_ == r].max() for r in range(64)])
    order = np.argsort(first)
    assert np.all(last[order][:-1] < first[order][1:])


@needs_kitti
def test_kitti_shuffled_takes_the_fallback_and_says_so(tmp_path, capsys):
    cloud = kitti_points()
    shuffled = tmp_path / "shuffled.bin"
    cloud[np.random.default_rng(0).permutation(len(cloud))].tofile(shuffled)
    assert cli_main(["ba-images", "--scan", str(shuffled), "-o", str(tmp_path / "ba")]) == 0
    match = parse_report(capsys.readouterr().out)
    assert match.group(1) == "spherical"
    assert "fallback" in match.group(8) and "azimuth neighbours" in match.group(8)
    depth = load_scan(shuffled, beams=64)
    report = depth.meta["organize_report"]
    assert report.method == "elevation" and depth.shape[0] == 64 and "fallback" in report.reason


@needs_kitti
def test_kitti_cropped_to_the_camera_view_keeps_64_rows(tmp_path):
    # Like KITTI's velodyne_reduced: only points in front, within the camera's 90 deg.
    cloud = kitti_points()
    azimuth = np.degrees(np.arctan2(cloud[:, 1], cloud[:, 0]))
    cropped = tmp_path / "reduced.bin"
    inside = (np.abs(azimuth) < 41.0) & (cloud[:, 0] > 0)
    cloud[inside].tofile(cropped)
    depth = load_scan(cropped, beams=64)
    assert depth.shape[0] == 64 and depth.meta["organize"] == "firing_order"
    assert depth.meta["organize_report"].kept_share >= 0.99
    # Default options give the same grid (every laser sees into this crop).
    default = load_scan(cropped)
    assert default.shape[0] == 64
    np.testing.assert_array_equal(default.valid, depth.valid)
    # The same laser lands in the same row as in the full scan.
    full = load_scan(KITTI_BIN)
    rows_full = np.full(len(cloud), -1)
    r, c = np.nonzero(full.valid)
    rows_full[full.meta["point_index"][r, c]] = r
    r, c = np.nonzero(depth.valid)
    original = np.flatnonzero(inside)[depth.meta["point_index"][r, c]]
    known = rows_full[original] >= 0
    assert np.mean(rows_full[original][known] == r[known]) >= 0.999

    # As KITTI's velodyne_reduced is made: the points the published calibration
    # projects into the 1242 x 375 image.  The lowest lasers see below it.
    P = read_kitti_camera2(KITTI / "calib" / "000002.txt")[1]
    K = np.array([[721.5377, 0.0, 609.5593], [0.0, 721.5377, 172.854], [0.0, 0.0, 1.0]])  # calib P2[:, :3]
    camera_points = cloud[:, :3].astype(float) @ P[:3, :3].T + P[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = camera_points @ K.T
        u, v = uv[:, 0] / uv[:, 2], uv[:, 1] / uv[:, 2]
    in_view = (camera_points[:, 2] > 0) & (u >= 0) & (u < 1242) & (v >= 0) & (v < 375)
    reduced = tmp_path / "reduced_by_camera.bin"
    cloud[in_view].tofile(reduced)
    depth = load_scan(reduced)
    report = depth.meta["organize_report"]
    assert depth.shape[0] == 64 and report.points_kept == in_view.sum()
    assert depth.meta["n_sweeps"] < 64 and "cropped" in report.reason
    r, c = np.nonzero(depth.valid)
    original = np.flatnonzero(in_view)[depth.meta["point_index"][r, c]]
    known = rows_full[original] >= 0
    assert np.mean(rows_full[original][known] == r[known]) >= 0.999


MMDET3D_REDUCED = REPO.parent / "shared" / "data" / "other_tools_files" / "bin" / "mmdet3d_kitti_000008.bin"


@pytest.mark.skipif(not MMDET3D_REDUCED.is_file(), reason=f"{MMDET3D_REDUCED} not found")
def test_kitti_velodyne_reduced_from_mmdetection3d_has_64_rows(tmp_path, capsys):
    # KITTI 000008 as mmdetection3d ships it: only the points in the camera's view.
    cloud = read_float_records(MMDET3D_REDUCED, 4)
    azimuth = np.arctan2(cloud[:, 1], cloud[:, 0])
    assert np.ptp(np.degrees(azimuth)) < 90.0  # cropped to the camera
    # Independent count of the sweeps: this file's sweeps all start at azimuth 0.
    n_sweeps = 1 + int(np.count_nonzero((azimuth[:-1] < 0) & (azimuth[1:] >= 0)))
    assert cli_main(["ba-images", "--scan", str(MMDET3D_REDUCED), "-o", str(tmp_path / "ba")]) == 0
    match = parse_report(capsys.readouterr().out)
    assert match.group(1) == "firing_order" and match.group(2) == "64" and match.group(6) == match.group(7)
    depth = load_scan(MMDET3D_REDUCED)
    report = depth.meta["organize_report"]
    assert report.method == "firing_order" and depth.shape[0] == 64
    assert depth.meta["n_sweeps"] == n_sweeps and report.points_kept == len(cloud)
    assert np.all(~depth.valid[n_sweeps:])  # the rows added below hold nothing


def test_clouds_that_are_not_one_sensors_view_are_refused(tmp_path):
    # An object scan: a ball of points 2 m across, 5 m away, seen from the origin.
    rng = np.random.default_rng(4)
    ball = rng.normal(size=(1065, 3))
    ball = ball / np.linalg.norm(ball, axis=1, keepdims=True) + [5.0, 0.0, 0.0]
    path = tmp_path / "ball.npy"
    np.save(path, ball)
    with pytest.raises(CalibError, match="does not look like a scan seen from the lidar origin"):
        load_scan(path)
    assert cli_main(["ba-images", "--scan", str(path), "-o", str(tmp_path / "ba")]) == 2


def test_sensor_origin_moves_a_world_frame_scan_to_the_lidar(tmp_path, capsys):
    points, _ = hdl64_cloud(seed=2)
    origin = np.array([1000.0, -250.0, 31.5])
    path = tmp_path / "world.npy"
    np.save(path, points + origin)
    with pytest.raises(CalibError, match="sensor-origin"):
        load_scan(path)
    depth = load_scan(path, sensor_origin=origin)
    assert depth.shape[0] == 64 and depth.meta["organize_report"].kept_share >= 0.99
    rows, cols = np.nonzero(depth.valid)
    np.testing.assert_allclose(depth.points[rows, cols], points[depth.meta["point_index"][rows, cols]], atol=1e-9)
    args = ["ba-images", "--scan", str(path), "--sensor-origin", *map(str, origin), "-o", str(tmp_path / "ba")]
    assert cli_main(args) == 0
    assert parse_report(capsys.readouterr().out).group(2) == "64"
    with pytest.raises(CalibError, match="sensor origin"):
        load_scan(path, sensor_origin=[1.0, 2.0])


# --------------------------------------------------------------------------
# Solve from pairs on the KITTI frame
# --------------------------------------------------------------------------


@needs_kitti
def test_kitti_solve_from_pairs_agrees_with_published_calibration(tmp_path, capsys):
    import yaml

    out = tmp_path / "extrinsics.yaml"
    args = [
        "solve", "--scan", str(KITTI_BIN), "--camera", str(REPO / "real_data" / "kitti_000002_camera.yaml"),
        "--pairs", str(REPO / "real_data" / "pairs" / "kitti_000002_pairs.yaml"), "-o", str(out),
    ]  # fmt: skip
    assert cli_main(args) == 0
    stdout = capsys.readouterr().out
    assert parse_report(stdout).group(2) == "64"
    written = yaml.safe_load(out.read_text())
    T = np.array(written["T_camera_lidar"]["matrix"], dtype=float)
    T_ref = read_kitti_camera2(KITTI / "calib" / "000002.txt")[1]
    cos_angle = (np.trace(T_ref[:3, :3].T @ T[:3, :3]) - 1.0) / 2.0
    rotation_deg = float(np.degrees(np.arccos(np.clip(cos_angle, -1.0, 1.0))))
    translation_m = float(np.linalg.norm(T[:3, 3] - T_ref[:3, 3]))
    sigma = [float(x) for x in re.findall(r"t[xyz] \[m\]\s+\S+\s+(\S+)", stdout)]
    print(f"\nKITTI 000002: rotation error {rotation_deg:.3f} deg, translation error {100 * translation_m:.2f} cm, "
          f"predicted 1-sigma {100 * np.linalg.norm(sigma):.2f} cm")  # fmt: skip
    assert rotation_deg < 0.5
    # 11 pairs with 1 px clicks on a 1242 x 375 image: the solver predicts about 2-3 cm per axis (1 sigma),
    # strongly correlated between x and z (depth and lateral shift trade off).  The error against the
    # published calibration must be consistent with the solve's own translation covariance: its Mahalanobis
    # distance squared within the 99 % quantile of chi-square with 3 dof (11.34), and under 10 cm.
    assert len(sigma) == 3 and translation_m < 0.10
    from scipy.stats import chi2

    from calib_core.cameras import load_camera
    from calib_core.pairs import load_pairs_yaml
    from calib_core.solve import calibrate

    result = calibrate(load_pairs_yaml(REPO / "real_data" / "pairs" / "kitti_000002_pairs.yaml"),
                       load_scan(KITTI_BIN), load_camera(REPO / "real_data" / "kitti_000002_camera.yaml"))
    np.testing.assert_allclose(result.T_camera_lidar, T, atol=1e-6)  # the CLI's solve, as written
    np.testing.assert_allclose(np.sqrt(np.diag(result.covariance_6x6)[3:]), sigma, atol=5e-5)  # printed to 0.1 mm
    error = T[:3, 3] - T_ref[:3, 3]
    mahalanobis2 = float(error @ np.linalg.solve(result.covariance_6x6[3:, 3:], error))
    print(f"translation error {np.round(100 * error, 2)} cm, Mahalanobis^2 {mahalanobis2:.2f} (3 dof)")
    assert mahalanobis2 < chi2.ppf(0.99, 3)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q", "-s"]))
