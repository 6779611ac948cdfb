"""Export formats: round trip, and the direction of each file checked independently.

The direction check parses every exported file here with json / yaml / xml /
plain string handling and SciPy, following each format's published convention
(TF and URDF: the transform from parent to child maps child points into the
parent frame; KITTI's Tr_velo_to_cam and OpenCalib's "<a>-to-<b>" matrix map
lidar points into the camera; direct_visual_lidar_calibration's T_lidar_camera
maps camera points into the lidar), then projects known lidar points with
``cv2.projectPoints`` and compares with the pixels of the true pose.
"""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from calib_core.errors import CalibError
from calib_core.io.extrinsic_formats import FORMATS, export_extrinsics, load_extrinsics_any, read_extrinsics_any
from repo_paths import REPO, SAMPLE

DATA = REPO.parent / "shared" / "data"

LIDAR, CAMERA = "velodyne", "camera_optical"
# A lidar with x forward, y left, z up and an OpenCV camera looking forward,
# a little turned and offset: the typical set-up, and one far from identity.
R_OPTICAL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # lidar x -> camera z
R_TRUE = Rotation.from_euler("xyz", [1.7, 0.8, -2.3], degrees=True).as_matrix() @ R_OPTICAL
T_TRUE = np.eye(4)
T_TRUE[:3, :3] = R_TRUE
T_TRUE[:3, 3] = [0.06, -0.31, -0.22]
K = np.array([[1000.0, 0.0, 960.0], [0.0, 1000.0, 600.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.1, 0.05, 0.001, -0.0005, 0.0])
# Lidar points ahead of the sensors (x forward), spread left/right and up/down.
rng = np.random.default_rng(3)
POINTS = np.column_stack([rng.uniform(5, 30, 40), rng.uniform(-6, 6, 40), rng.uniform(-1.5, 2.5, 40)])

CASES = [(fmt, parent, child) for fmt in FORMATS for parent, child in ((LIDAR, CAMERA), (CAMERA, LIDAR))]


def _T(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _inv(T) -> np.ndarray:
    return _T(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])


def _from_parent_child(T_parent_child, parent) -> np.ndarray:
    """TF: T_parent_child maps child points into the parent frame."""
    return _inv(T_parent_child) if parent == LIDAR else T_parent_child


def independent_T_camera_lidar(fmt: str, text: str, parent: str) -> np.ndarray:
    """T_camera_lidar from an exported file, following the format's own documentation."""
    code = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if fmt == "ros1-tf":
        args = code[0].split("static_transform_publisher")[1].split()
        x, y, z, qx, qy, qz, qw = map(float, args[:7])
        assert args[7:] == [parent, CAMERA if parent == LIDAR else LIDAR]
        return _from_parent_child(_T(Rotation.from_quat([qx, qy, qz, qw]).as_matrix(), [x, y, z]), args[7])
    if fmt == "ros2-tf":
        args = code[0].split("static_transform_publisher")[1].split()
        opt = dict(zip(args[0::2], args[1::2]))
        q = [float(opt[k]) for k in ("--qx", "--qy", "--qz", "--qw")]
        t = [float(opt[k]) for k in ("--x", "--y", "--z")]
        return _from_parent_child(_T(Rotation.from_quat(q).as_matrix(), t), opt["--frame-id"])
    if fmt == "urdf":
        joint = ET.fromstring(text[text.index("<joint") :])
        origin = joint.find("origin")
        rpy = [float(v) for v in origin.get("rpy").split()]
        t = [float(v) for v in origin.get("xyz").split()]
        # URDF rpy: roll about fixed x, then pitch about fixed y, then yaw about fixed z.
        R = Rotation.from_euler("xyz", rpy).as_matrix()
        return _from_parent_child(_T(R, t), joint.find("parent").get("link"))
    if fmt == "autoware":
        data = yaml.safe_load(text)
        (p, children), = data.items()
        (_, v), = children.items()
        R = Rotation.from_euler("xyz", [v["roll"], v["pitch"], v["yaw"]]).as_matrix()
        return _from_parent_child(_T(R, [v["x"], v["y"], v["z"]]), p)
    if fmt == "opencalib":
        (key, block), = json.loads(text).items()
        assert key == f"{LIDAR}-to-{CAMERA}-extrinsic"
        return np.array(block["param"]["sensor_calib"]["data"], dtype=float)
    if fmt == "dvlc":
        x, y, z, qx, qy, qz, qw = json.loads(text)["results"]["T_lidar_camera"]
        return _inv(_T(Rotation.from_quat([qx, qy, qz, qw]).as_matrix(), [x, y, z]))
    if fmt == "kitti":
        (line,) = [ln for ln in code if ln.startswith("Tr_velo_to_cam:")]
        M = np.eye(4)
        M[:3, :4] = np.array(line.split(":")[1].split(), dtype=float).reshape(3, 4)
        return M
    if fmt == "matrix":
        M = np.loadtxt(text.splitlines(), comments="#")
        return _from_parent_child(M, parent)
    raise AssertionError(fmt)


def project(T: np.ndarray) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))
    pixels, _ = cv2.projectPoints(POINTS, rvec, T[:3, 3].copy(), K, DIST)
    return pixels.reshape(-1, 2)


@pytest.mark.parametrize("fmt,parent,child", CASES)
def test_round_trip(fmt, parent, child, tmp_path):
    text = export_extrinsics(T_TRUE, fmt, parent, child)
    path = tmp_path / f"out{FORMATS[fmt].suffix}"
    path.write_text(text)
    parsed = read_extrinsics_any(path)
    assert parsed.format == fmt
    assert (parsed.lidar_frame, parsed.camera_frame) == (LIDAR, CAMERA)
    err = np.abs(parsed.T_camera_lidar - T_TRUE).max()
    assert err < 1e-9, f"{fmt} {parent}->{child}: round trip off by {err:.2e}"


@pytest.mark.parametrize("fmt,parent,child", CASES)
def test_direction_by_projection(fmt, parent, child):
    text = export_extrinsics(T_TRUE, fmt, parent, child)
    assert f"{LIDAR}" in text and "maps" in text, "the file must say which frame maps to which"
    T = independent_T_camera_lidar(fmt, text, parent)
    truth = project(T_TRUE)
    assert ((truth >= 0) & (truth < [1920, 1200])).all() and np.ptp(truth[:, 0]) > 300, "points spread over the image"
    gap = np.abs(project(T) - truth).max()
    assert gap < 1e-6, f"{fmt}: pixels off by {gap:.3g} px"
    # The check can fail: the inverse transform lands far away.
    assert np.nanmax(np.abs(project(_inv(T)) - truth)) > 50


def test_matrix_both_directions_differ():
    a = export_extrinsics(T_TRUE, "matrix", LIDAR, CAMERA)
    b = export_extrinsics(T_TRUE, "matrix", CAMERA, LIDAR)
    Ma, Mb = (np.loadtxt(t.splitlines(), comments="#") for t in (a, b))
    assert np.allclose(Ma @ Mb, np.eye(4), atol=1e-12) and not np.allclose(Ma, Mb)
    assert "X_velodyne = T_velodyne_camera_optical @ X_camera_optical" in a
    assert "X_camera_optical = T_camera_optical_velodyne @ X_velodyne" in b


def test_frames_whose_roles_cannot_be_told():
    with pytest.raises(CalibError, match="lidar-frame"):
        export_extrinsics(T_TRUE, "ros1-tf", "base", "sensor2")
    text = export_extrinsics(T_TRUE, "ros1-tf", "base", "sensor2", lidar_frame="sensor2")
    assert "X_base = T_base_sensor2 @ X_sensor2" in text
    # The marker lets it read back; without it the names tell nothing.
    assert np.allclose(load_extrinsics_any_text(text), T_TRUE, atol=1e-12)
    bare = "\n".join(ln for ln in text.splitlines() if not ln.startswith("#"))
    with pytest.raises(CalibError, match="lidar"):
        load_extrinsics_any_text(bare)


def load_extrinsics_any_text(text: str) -> np.ndarray:
    from calib_core.io.extrinsic_formats import parse_extrinsics

    return parse_extrinsics(text).T_camera_lidar


def test_foreign_ros1_euler_form():
    # static_transform_publisher x y z yaw pitch roll parent child: an identity camera 1 m ahead.
    text = "rosrun tf2_ros static_transform_publisher 1 0 0 0 0 0 base_lidar cam\n"
    T = load_extrinsics_any_text(text)
    assert np.allclose(T, _T(np.eye(3), [-1, 0, 0]))


@pytest.mark.realdata
@pytest.mark.skipif(not (DATA / "pjlab_opencalib_lidar2camera").is_dir(), reason="../shared/data PJLab scenes absent")
@pytest.mark.parametrize("scene", ["auto_calib", "manual_calib"])
def test_reads_the_published_opencalib_file(scene):
    path = DATA / "pjlab_opencalib_lidar2camera" / scene / "top_center_lidar-to-center_camera-extrinsic.json"
    published = np.array(
        json.loads(path.read_text())["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"]
    )
    got = read_extrinsics_any(path)
    assert got.format == "opencalib" and got.lidar_frame == "top_center_lidar"
    assert np.array_equal(got.T_camera_lidar, published)


@pytest.mark.realdata
@pytest.mark.skipif(not (DATA / "kitti_object_000002").is_dir(), reason="../shared/data KITTI frame absent")
def test_reads_a_kitti_calib_file():
    """A full KITTI calib file: the pose of the rectified camera whose image KITTI projects into with
    ``x = Pn @ R0_rect @ Tr_velo_to_cam @ X`` (camera 2 by default, the colour images)."""
    path = DATA / "kitti_object_000002" / "calib" / "000002.txt"
    rows = {ln.split(":")[0]: np.array(ln.split(":")[1].split(), dtype=float) for ln in path.read_text().splitlines() if ":" in ln}
    Tr, R0 = np.vstack([rows["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]]), np.eye(4)
    R0[:3, :3] = rows["R0_rect"].reshape(3, 3)
    points = np.random.default_rng(0).uniform([5, -10, -2], [40, 10, 2], (50, 3))  # Velodyne frame, ahead
    homogeneous = np.c_[points, np.ones(len(points))]
    for camera in (2, 0, 3):
        P = rows[f"P{camera}"].reshape(3, 4)
        got = read_extrinsics_any(path, kitti_camera=camera) if camera != 2 else read_extrinsics_any(path)
        assert got.format == "kitti"
        T = got.T_camera_lidar
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-5)  # a rotation (R0 is rounded)
        # KITTI's projection and K @ T give the same pixels.
        kitti = (P @ R0 @ Tr @ homogeneous.T).T
        ours = (P[:, :3] @ (T @ homogeneous.T)[:3]).T
        np.testing.assert_allclose(ours[:, :2] / ours[:, 2:], kitti[:, :2] / kitti[:, 2:], atol=1e-9)
        assert np.all(ours[:, 2] > 0)
    # Camera 0 has no baseline: its pose is R0_rect @ Tr_velo_to_cam.
    np.testing.assert_allclose(read_extrinsics_any(path, kitti_camera=0).T_camera_lidar, R0 @ Tr, atol=1e-12)


@pytest.mark.parametrize(
    "text,fragment",
    [
        ("hello world\n", "unrecognised"),
        ("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "direction"),
        ("Tr_velo_to_cam: 1 2 3\n", "kitti"),
        ('{"results": {"T_lidar_camera": [0, 0, 0, 0, 0, 0, 0]}}', "dvlc"),
        ("<joint><parent link='a'/></joint>", "urdf"),
        ("ros2 run tf2_ros static_transform_publisher --x 1 --frame-id lidar", "child-frame-id"),
    ],
)
def test_bad_files_name_the_format(text, fragment, tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(CalibError, match=fragment) as info:
        load_extrinsics_any(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], capture_output=True, text=True, timeout=120, cwd=REPO)


def test_cli_export_stdout_and_file(tmp_path):
    src = tmp_path / "extrinsics.yaml"
    src.write_text(yaml.safe_dump({"T_camera_lidar": {"matrix": T_TRUE.tolist()}}))
    proc = _cli("export", str(src), "--format", "urdf", "--parent-frame", CAMERA, "--child-frame", LIDAR)
    assert proc.returncode == 0, proc.stderr
    assert np.abs(independent_T_camera_lidar("urdf", proc.stdout, CAMERA) - T_TRUE).max() < 1e-9
    out = tmp_path / "tf.txt"
    proc = _cli("export", str(src), "--format", "kitti", "--parent-frame", LIDAR, "--child-frame", CAMERA, "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert np.abs(load_extrinsics_any(out) - T_TRUE).max() < 1e-12
    # A file in any format converts to another.
    proc = _cli("export", str(out), "--format", "dvlc")
    assert proc.returncode == 0, proc.stderr
    x, y, z, *q = json.loads(proc.stdout)["results"]["T_lidar_camera"]
    assert np.allclose(_inv(_T(Rotation.from_quat(q).as_matrix(), [x, y, z])), T_TRUE, atol=1e-12)


def test_cli_export_errors(tmp_path):
    proc = _cli("export", str(tmp_path / "none.yaml"), "--format", "kitti")
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and len(proc.stderr.strip().splitlines()) == 1
    src = tmp_path / "e.yaml"
    src.write_text(yaml.safe_dump({"T_camera_lidar": {"matrix": T_TRUE.tolist()}}))
    proc = _cli("export", str(src), "--format", "urdf", "--parent-frame", "a", "--child-frame", "b")
    assert proc.returncode == 2 and "--lidar-frame" in proc.stderr
    proc = _cli("export", str(src), "--format", "urdf", "-o", str(tmp_path))
    assert proc.returncode == 2 and "not a regular file" in proc.stderr


def test_cli_solve_starts_from_an_imported_extrinsic(tmp_path):
    truth = yaml.safe_load((SAMPLE / "ground_truth.yaml").read_text())["T_camera_lidar"]["matrix"]
    init = tmp_path / "init.urdf"
    # A start 2 deg and 10 cm off, written as a URDF joint (camera -> lidar direction).
    off = np.array(truth)
    off[:3, :3] = Rotation.from_euler("z", 2.0, degrees=True).as_matrix() @ off[:3, :3]
    off[:3, 3] += [0.1, 0.0, 0.0]
    init.write_text(export_extrinsics(off, "urdf", "lidar", "camera"))
    base = ["solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"), "--pairs", str(SAMPLE / "pairs.yaml")]
    plain = _cli(*base, "-o", str(tmp_path / "a.yaml"))
    started = _cli(*base, "--initial-extrinsics", str(init), "-o", str(tmp_path / "b.yaml"))
    assert plain.returncode == 0 and started.returncode == 0, started.stderr
    a = np.array(yaml.safe_load((tmp_path / "a.yaml").read_text())["T_camera_lidar"]["matrix"])
    b = np.array(yaml.safe_load((tmp_path / "b.yaml").read_text())["T_camera_lidar"]["matrix"])
    assert np.abs(a - b).max() < 1e-6, "the same optimum from the imported start"
    bad = tmp_path / "bad.txt"
    bad.write_text("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    proc = _cli(*base, "--initial-extrinsics", str(bad), "-o", str(tmp_path / "c.yaml"))
    assert proc.returncode == 2 and "direction" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_several_sensors_compose_the_chain_between_lidar_and_camera():
    from calib_core.io.extrinsic_formats import parse_extrinsics

    # base_link -> lidar_top and base_link -> cam_front_optical, as a real sensor kit file lists them.
    T_base_lidar = _T(Rotation.from_euler("xyz", [0.01, -0.02, 0.3]).as_matrix(), [1.1, 0.0, 1.9])
    T_base_cam = _T(Rotation.from_euler("xyz", [-1.57, 0.02, -1.6]).as_matrix(), [1.6, 0.1, 1.5])
    expected = _inv(T_base_cam) @ T_base_lidar  # X_cam = inv(T_base_cam) T_base_lidar X_lidar

    def entry(T):
        r, p, y = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
        return {"x": float(T[0, 3]), "y": float(T[1, 3]), "z": float(T[2, 3]), "roll": float(r), "pitch": float(p), "yaw": float(y)}

    autoware = yaml.safe_dump({"base_link": {"lidar_top": entry(T_base_lidar), "cam_front_optical": entry(T_base_cam)}})
    got = parse_extrinsics(autoware, lidar_frame="lidar_top", camera_frame="cam_front_optical")
    assert np.abs(got.T_camera_lidar - expected).max() < 1e-12 and got.format == "autoware"
    with pytest.raises(CalibError, match="name the lidar and the camera frame"):
        parse_extrinsics(autoware)

    def joint(child, T):
        r, p, y = (float(a) for a in Rotation.from_matrix(T[:3, :3]).as_euler("xyz"))
        xyz = " ".join(repr(float(v)) for v in T[:3, 3])
        return f'<joint name="j_{child}" type="fixed"><parent link="base_link"/><child link="{child}"/><origin xyz="{xyz}" rpy="{r!r} {p!r} {y!r}"/></joint>'

    urdf = f'<robot name="car"><link name="base_link"/>{joint("lidar_top", T_base_lidar)}{joint("cam_front_optical", T_base_cam)}</robot>'
    got = parse_extrinsics(urdf, lidar_frame="lidar_top", camera_frame="cam_front_optical")
    assert np.abs(got.T_camera_lidar - expected).max() < 1e-12 and got.format == "urdf"
    with pytest.raises(CalibError, match="no chain"):
        parse_extrinsics(urdf, lidar_frame="lidar_top", camera_frame="cam_rear")


def test_the_nine_exports_round_trip_and_point_the_right_way(tmp_path):
    """Target of issue 13, printed: the 8 formats, ``matrix`` in both directions (9 exports), each with
    both frame orders for the TF-like ones: round trip error and the cv2.projectPoints direction gap."""
    truth = project(T_TRUE)
    cases = [(f, LIDAR, CAMERA) for f in FORMATS if f != "matrix"] + [("matrix", LIDAR, CAMERA), ("matrix", CAMERA, LIDAR)]
    assert len(cases) == 9
    lines = []
    for fmt, parent, child in cases:
        text = export_extrinsics(T_TRUE, fmt, parent, child)
        path = tmp_path / f"{fmt}-{parent}{FORMATS[fmt].suffix}"
        path.write_text(text)
        trip = float(np.abs(read_extrinsics_any(path).T_camera_lidar - T_TRUE).max())
        gap = float(np.abs(project(independent_T_camera_lidar(fmt, text, parent)) - truth).max())
        lines.append(f"  {fmt:10} parent {parent:15} round trip {trip:.2e}   direction gap {gap:.2e} px")
        assert trip < 1e-9 and gap < 1e-6
    print("\n" + "\n".join(lines))
