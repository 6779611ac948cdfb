"""Issue 23, cameras: PJLab's OCam JSON, a KITTI calib file given as the camera, the --image-size hint.

The PJLab model is checked against its own projection (PJLab SensorsCalibration,
``surround-camera/manual_calib/src/run_avm.cpp``, ``world2cam``), written out below; the KITTI camera
against the calib file's ``P2`` and KITTI's published projection ``x = P2 @ R0_rect @ Tr_velo_to_cam @ X``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from calib_core.cameras import load_camera
from calib_core.errors import CalibError
from repo_paths import REPO, SAMPLE
from cli_helpers import one_error_line, run_cli

DATA = REPO.parent / "shared" / "data"
OCAM_JSON = DATA / "other_tools_files" / "cam" / "pjlab_surround_ocam_Front.json"
KITTI = DATA / "kitti_object_000002"
needs_ocam = pytest.mark.skipif(not OCAM_JSON.is_file(), reason=f"{OCAM_JSON} not found (shared data)")
needs_kitti = pytest.mark.skipif(not KITTI.is_dir(), reason=f"{KITTI} not found (shared data)")


# --------------------------------------------------------------------------
# PJLab's OCam intrinsic JSON
# --------------------------------------------------------------------------


def pjlab_world2cam(points: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """PJLab's projection (run_avm.cpp): the point (X, Y, Z) of the OpenCV camera frame goes in as
    (X, Y, -Z); ``theta = atan(-Z / hypot(X, Y))``, ``rho = sum_i D[i] theta^i``, then
    ``u = x K00 + y K01 + K02`` (its remap's x: the column) and ``v = x K10 + y + K12`` (the row)."""
    X, Y, Z = points.T
    norm = np.hypot(X, Y)
    theta = np.arctan(-Z / norm)
    rho = sum(c * theta**i for i, c in enumerate(D))
    x, y = X / norm * rho, Y / norm * rho
    return np.stack([x * K[0, 0] + y * K[0, 1] + K[0, 2], x * K[1, 0] + y + K[1, 2]], axis=1)


@needs_ocam
def test_pjlab_ocam_json_projects_as_pjlab_does():
    param = json.loads(OCAM_JSON.read_text())["front_camera-intrinsic"]["param"]
    K, D = np.array(param["cam_K"]["data"]), np.array(param["cam_dist"]["data"][0])
    camera = load_camera(OCAM_JSON)
    assert camera.model == "ocam" and (camera.width, camera.height) == (param["img_dist_w"], param["img_dist_h"])
    rng = np.random.default_rng(0)
    points = rng.normal(size=(200_000, 3)) * rng.uniform(0.5, 20.0, (200_000, 1))  # every direction, any range
    expected = pjlab_world2cam(points, K, D)
    inside = (expected >= -0.5).all(axis=1) & (expected[:, 0] <= camera.width - 0.5) & (expected[:, 1] <= camera.height - 0.5)
    angle = np.degrees(np.arccos(points[:, 2] / np.linalg.norm(points, axis=1)))
    assert inside.sum() > 50_000 and angle[inside].max() > 105.0  # the whole image, beyond 90 deg from the axis
    pixels, valid = camera.project(points[inside])
    assert valid.mean() > 0.9999
    error = np.linalg.norm(pixels[valid] - expected[inside][valid], axis=1)
    assert error.max() < 0.01, error.max()
    # And back: the ray of PJLab's pixel is the point's direction.
    rays = camera.bearing(expected[inside])
    unit = points[inside] / np.linalg.norm(points[inside], axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(np.sum(rays * unit, axis=1), -1.0, 1.0))).max() < 0.01


@needs_ocam
def test_the_pjlab_ocam_camera_solves_a_calibration(tmp_path):
    """End to end: pairs made with PJLab's own projection and a known pose are solved back to that pose."""
    param = json.loads(OCAM_JSON.read_text())["front_camera-intrinsic"]["param"]
    K, D = np.array(param["cam_K"]["data"]), np.array(param["cam_dist"]["data"][0])
    rng = np.random.default_rng(3)
    lidar = np.column_stack([rng.uniform(2, 12, 12), rng.uniform(-6, 6, 12), rng.uniform(-1.5, 2.0, 12)])
    # Camera looking along the lidar's +x: x_cam = -y_lidar, y_cam = -z_lidar, z_cam = x_lidar; then 0.1 m up.
    R = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    t = np.array([0.05, 0.1, -0.2])
    pixels = pjlab_world2cam(lidar @ R.T + t, K, D)
    pairs = tmp_path / "pairs.yaml"
    pairs.write_text("pairs:\n" + "".join(f"  - {{laser_xyz: {list(map(float, p))}, pixel: {list(map(float, q))}}}\n"
                                          for p, q in zip(lidar, pixels)))
    out = tmp_path / "e.yaml"
    run = run_cli("solve", "--camera", str(OCAM_JSON), "--pairs", str(pairs), "-o", str(out))
    assert run.returncode == 0, run.stderr
    from calib_core.io.extrinsics import load_extrinsics_yaml

    T = load_extrinsics_yaml(out)["T_camera_lidar"]
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-4)
    np.testing.assert_allclose(T[:3, 3], t, atol=1e-4)


# --------------------------------------------------------------------------
# A KITTI calib file as the camera
# --------------------------------------------------------------------------


def kitti_rows() -> dict[str, np.ndarray]:
    text = (KITTI / "calib" / "000002.txt").read_text()
    return {ln.split(":")[0]: np.array(ln.split(":")[1].split(), dtype=float) for ln in text.splitlines() if ":" in ln}


@needs_kitti
def test_a_kitti_calib_file_is_the_rectified_camera_2_by_default(tmp_path):
    rows = kitti_rows()
    path = KITTI / "calib" / "000002.txt"
    camera = load_camera(path, image_size=(1242, 375))
    assert camera.model == "pinhole" and (camera.width, camera.height) == (1242, 375)
    np.testing.assert_array_equal(camera.K, rows["P2"].reshape(3, 4)[:, :3])
    assert camera.to_dict()["dist"] == []
    for n in (0, 1, 3):
        np.testing.assert_array_equal(load_camera(path, image_size=(1242, 375), kitti_camera=n).K,
                                      rows[f"P{n}"].reshape(3, 4)[:, :3])
    with pytest.raises(CalibError) as excinfo:
        load_camera(path)  # KITTI states no image size
    assert "000002.txt" in str(excinfo.value) and "--image-size" in str(excinfo.value)

    # A damaged P2 is one line naming the file and the key.
    broken = [ln.replace("7.215377000000e+02", "7.2x", 1) if ln.startswith("P2:") else ln
              for ln in (KITTI / "calib" / "000002.txt").read_text().splitlines()]
    bad = tmp_path / "000002.txt"
    bad.write_text("\n".join(broken) + "\n")
    with pytest.raises(CalibError) as excinfo:
        load_camera(bad, image_size=(1242, 375))
    assert str(bad) in str(excinfo.value) and "'P2:'" in str(excinfo.value) and "\n" not in str(excinfo.value)


@needs_kitti
def test_colorize_with_a_kitti_calib_camera_takes_the_size_from_the_image(tmp_path):
    """The colours the CLI gives the Velodyne points are the image's at KITTI's own projection."""
    import trimesh

    rows = kitti_rows()
    P2 = rows["P2"].reshape(3, 4)
    R0, Tr = np.eye(4), np.vstack([rows["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]])
    R0[:3, :3] = rows["R0_rect"].reshape(3, 3)
    T = np.linalg.solve(np.vstack([np.c_[P2[:, :3], [0, 0, 0]], [0, 0, 0, 1]]),
                        np.vstack([P2, [0, 0, 0, 1]])) @ R0 @ Tr  # [I | K^-1 p4] @ R0 @ Tr
    extrinsics = tmp_path / "kitti_extrinsics.yaml"
    extrinsics.write_text(json.dumps({"T_camera_lidar": {"matrix": T.tolist()}}))
    out = tmp_path / "coloured.ply"
    run = run_cli("colorize", "--scan", str(KITTI / "velodyne" / "000002.bin"), "--image", str(KITTI / "image_2" / "000002.png"),
                  "--camera", str(KITTI / "calib" / "000002.txt"), "--extrinsics", str(extrinsics), "--no-occlusion",
                  "-o", str(out))
    assert run.returncode == 0, run.stderr
    cloud = trimesh.load(out)
    xyz = np.asarray(cloud.vertices, dtype=np.float64)
    rgb = np.asarray(cloud.colors[:, :3], dtype=np.float64)
    image = np.asarray(Image.open(KITTI / "image_2" / "000002.png").convert("RGB"), dtype=np.float64)
    projected = (P2 @ R0 @ Tr @ np.c_[xyz, np.ones(len(xyz))].T).T
    in_front = projected[:, 2] > 1.0
    uv = projected[in_front, :2] / projected[in_front, 2:]
    # Well inside the image (bilinear sampling at the border differs), at a pixel whose colour is smooth.
    inside = (uv[:, 0] > 2) & (uv[:, 0] < 1239) & (uv[:, 1] > 2) & (uv[:, 1] < 372)
    u, v = np.rint(uv[inside]).astype(int).T
    patch = np.stack([image[v + dv, u + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)])
    smooth = patch.std(axis=0).max(axis=1) < 3.0
    assert smooth.sum() > 1000
    got = rgb[in_front][inside][smooth]
    assert np.abs(got - image[v, u][smooth]).max() <= 6.0  # a bilinear sample of a smooth patch


# --------------------------------------------------------------------------
# An image whose size is not the camera file's
# --------------------------------------------------------------------------


def test_an_image_of_another_size_names_the_image_size_option(tmp_path):
    small = tmp_path / "small.png"
    Image.open(SAMPLE / "image.png").resize((320, 240)).save(small)
    line = one_error_line(run_cli("colorize", "--scan", str(SAMPLE / "scan.npz"), "--image", str(small),
                                  "--camera", str(SAMPLE / "camera.yaml"), "--extrinsics", str(SAMPLE / "ground_truth.yaml"),
                                  "-o", str(tmp_path / "c.ply")))
    assert "small.png" in line and "320x240" in line and "640x480" in line and "--image-size 320 240" in line
    # serve says it before the server starts.
    line = one_error_line(run_cli("serve", "--scan", str(SAMPLE / "scan.npz"), "--image", str(small),
                                  "--camera", str(SAMPLE / "camera.yaml"), "--port", "0", "--session", str(tmp_path / "s.yaml")))
    assert "small.png" in line and "--image-size 320 240" in line
