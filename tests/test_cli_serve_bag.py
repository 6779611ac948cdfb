"""``ba-calib serve --bag``: frames of bags written by rosbags' own writers (ROS 1, ROS 2 sqlite3, mcap).

The bags hold the committed sample (and, with ../shared/data, the PJLab
auto_calib scene); what the app shows is compared with the loose files, the
/tf_static extrinsic with the transform written into the bag.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from bag_helpers import CloudSpec, SceneBag, write_bag
from browser_helpers import free_port
from scipy.spatial.transform import Rotation

from app.serving import BagServer, BagSource
from app_driver import AppDriver
from calib_core.cameras import load_camera
from calib_core.errors import CalibError
from calib_core.io.extrinsic_formats import load_extrinsics_any
from calib_core.io.images import load_image_rgb
from calib_core.io.scan_readers import load_scan, read_point_cloud
from calib_core.pairs import load_pairs_yaml
from calib_core.solve import calibrate
from repo_paths import REPO, SAMPLE

AUTO = REPO.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"
KINDS = ["ros1", "sqlite3", "mcap"]

# lidar -> camera_optical through a body frame: TF edges parent -> child (T_parent_child).
T_LIDAR_BODY = np.eye(4)
T_LIDAR_BODY[:3, :3] = Rotation.from_euler("z", 12.0, degrees=True).as_matrix()
T_LIDAR_BODY[:3, 3] = [0.2, -0.05, 0.1]
T_BODY_OPTICAL = np.eye(4)
T_BODY_OPTICAL[:3, :3] = Rotation.from_euler("xyz", [-90.0, 0.5, -90.0], degrees=True).as_matrix()
T_BODY_OPTICAL[:3, 3] = [0.03, 0.01, -0.02]


@pytest.fixture(scope="module")
def sample_cloud():
    cloud = read_point_cloud(SAMPLE / "scan.npz")
    h, w = cloud.organized_shape
    return CloudSpec({a: cloud.xyz[:, i].copy() for i, a in enumerate("xyz")}, organized_shape=(h, w))


def _sample_bag(kind: str, tmp: Path, cloud: CloudSpec) -> tuple[Path, list[np.ndarray]]:
    image = load_image_rgb(SAMPLE / "image.png")
    images = [image, image[::-1].copy()]  # the second frame's image is told apart by its flip
    scene = SceneBag(clouds=[cloud, cloud], cloud_times=[50.0, 50.5], images=images, image_times=[50.01, 50.49],
                     lidar_frame="velodyne", camera_frame="camera_optical",
                     static_tf=[("velodyne", "base", T_LIDAR_BODY), ("base", "camera_optical", T_BODY_OPTICAL)])
    return write_bag(tmp / "bag", kind, scene), images


@pytest.mark.parametrize("kind", KINDS)
def test_serve_bag_shows_the_frame_and_switches_frames(kind, sample_cloud, tmp_path):
    bag, images = _sample_bag(kind, tmp_path, sample_cloud)
    source = BagSource(bag, camera=SAMPLE / "camera.yaml", frames_dir=tmp_path / "frames",
                       session=tmp_path / "session.yaml")
    server = BagServer(source, port=0)
    try:
        app = server.load()
        assert np.array_equal(app.image, images[0])
        loose = load_scan(SAMPLE / "scan.npz")
        assert app.depth.shape == loose.shape and int(app.depth.valid.sum()) == int(loose.valid.sum())
        assert app.session_path == tmp_path / "session.yaml"
        # /tf_static's chain velodyne -> base -> camera_optical, as T_camera_lidar.
        T_tf = load_extrinsics_any(server.frame.initial_extrinsics)
        expected = np.linalg.inv(T_LIDAR_BODY @ T_BODY_OPTICAL)
        assert np.abs(T_tf - expected).max() < 1e-9
        assert np.abs(app.pose() - expected).max() < 1e-9  # offered to the app: its pose before any pair
        assert "cloud 0 of 2" in server.frame.description
        port = app.port
        # The page's "Load this frame" asks for frame 1; serve() then restarts the app on it, on the same port.
        server.panel.request(1)
        app2 = server.load(server.requests.get_nowait())
        assert app2 is not app and app2.port == port
        assert np.array_equal(app2.image, images[1])
        assert app2.session_path == tmp_path / "session.frame1.yaml"
        # A frame that is not in the bag: one line, and the frame shown before keeps being served.
        with pytest.raises(CalibError, match="index 7"):
            server.load(7)
        assert server.app is app2 and server.frame.index == 1
    finally:
        server.stop()


def test_first_frame_by_time(sample_cloud, tmp_path):
    bag, images = _sample_bag("mcap", tmp_path, sample_cloud)
    source = BagSource(bag, camera=SAMPLE / "camera.yaml", frames_dir=tmp_path / "frames", time_s=0.45)
    frame = source.extract()
    assert frame.index == 1 and np.array_equal(load_image_rgb(frame.image), images[1])
    assert frame.session.name == "bag.frame1.ba-calib-session.yaml"


def _cli(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], capture_output=True, text=True, timeout=300,
                          cwd=kw.get("cwd", REPO))


def test_cli_serve_bag_runs_and_bad_options_are_one_line(sample_cloud, tmp_path):
    bag, _ = _sample_bag("mcap", tmp_path, sample_cloud)
    proc = _cli("serve", "--bag", str(bag), "--frames-dir", str(tmp_path / "f"))
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [
        f"error: {bag}: no CameraInfo topic; give the camera file with --camera"]
    proc = _cli("serve", "--bag", str(bag), "--scan", str(SAMPLE / "scan.npz"))
    assert proc.returncode == 2 and "leave out --scan and --image" in proc.stderr
    proc = _cli("serve", "--bag", str(bag), "--index", "1", "--time", "2")
    assert proc.returncode == 2
    proc = _cli("serve", "--index", "1")
    assert proc.returncode == 2 and proc.stderr.strip() == "error: --index choose(s) what to read from a bag: give --bag too"
    port = free_port()
    child = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--bag", str(bag), "--camera", str(SAMPLE / "camera.yaml"),
         "--index", "1", "--port", str(port), "--frames-dir", str(tmp_path / "f"), "--session", str(tmp_path / "s.yaml")],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        lines = []
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = child.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "open http://" in line:
                break
        url = next(ln for ln in lines if "open http://" in ln).split("open ")[1].split()[0]
        assert f":{port}" in url
        with urllib.request.urlopen(url, timeout=30) as resp:
            assert resp.status == 200
        assert (tmp_path / "f" / "frame_00001" / "scan.pcd").is_file()
    finally:
        child.send_signal(signal.SIGTERM)
        out, _ = child.communicate(timeout=60)
    assert child.returncode == 0, "".join(lines) + out


@pytest.fixture(scope="module")
def auto_calib():
    if not (AUTO / "calib.pcd").is_file():
        pytest.skip(f"PJLab auto_calib scene not found at {AUTO} (../shared/data)")
    cloud = read_point_cloud(AUTO / "calib.pcd")
    intr = json.loads((AUTO / "center_camera-intrinsic.json").read_text())
    param = next(iter(intr.values()))["param"]
    K = np.array(param["cam_K"]["data"], float)
    D = np.array(param["cam_dist"]["data"], float).ravel()
    pairs = load_pairs_yaml(REPO / "real_data" / "pairs" / "auto_calib_pairs.yaml")
    T_loose = calibrate(pairs, load_scan(AUTO / "calib.pcd"), load_camera(AUTO / "center_camera-intrinsic.json")).T_camera_lidar
    return cloud, load_image_rgb(AUTO / "calib.png"), K, D, T_loose


@pytest.mark.realdata
@pytest.mark.parametrize("kind", KINDS)
def test_auto_calib_bag_opens_in_the_app_and_calibrates_to_the_loose_pose(kind, auto_calib, tmp_path):
    cloud, image, K, D, T_loose = auto_calib
    cols = {a: cloud.xyz[:, i].astype(np.float32) for i, a in enumerate("xyz")}
    cols.update(cloud.fields)
    scene = SceneBag(clouds=[CloudSpec(cols, bigendian=kind == "ros1")], cloud_times=[1700000000.05], images=[image],
                     image_times=[1700000000.06], K=K, D=D, lidar_frame="top_center_lidar",
                     camera_frame="center_camera", compressed_images=kind == "mcap")
    bag = write_bag(tmp_path / "bag", kind, scene)
    server = BagServer(BagSource(bag, frames_dir=tmp_path / "frames", session=tmp_path / "s.yaml"), port=0)
    try:
        app = server.load()
        driver = AppDriver(app)
        driver.upload_pairs("auto_calib_pairs.yaml", (REPO / "real_data" / "pairs" / "auto_calib_pairs.yaml").read_bytes())
        assert driver.wait_idle()
        diff = float(np.abs(app.result.T_camera_lidar - T_loose).max())
        print(f"\nauto_calib {kind} bag in the app: max |T_app - T_loose| = {diff:.3g}")
        assert diff <= 1e-9
    finally:
        server.stop()
