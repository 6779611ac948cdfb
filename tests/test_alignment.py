"""The rough-alignment maths (calib_core.alignment) against hand-computed values and KITTI's calibration.

Truth: rotations written out by hand from the frame conventions (lidar x forward, y left, z up; camera
x right, y down, z forward), KITTI's published calibration parsed here from its text file, and a pinhole
projection written in the test.
"""

from __future__ import annotations


import numpy as np
import pytest

from calib_core.alignment import (
    MOUNTING_PRESETS,
    drag_to_rotation,
    focal_px_estimate,
    preset_T,
    rotate_about_camera,
    translate_in_camera,
    view_rotation,
)
from calib_core.cameras.fisheye import FisheyeCamera
from calib_core.cameras.io import load_camera
from calib_core.cameras.pinhole import PinholeCamera
from calib_core.errors import CalibError
from kitti_reference import KITTI_CALIB, kitti_K_T
from repo_paths import SAMPLE


def pinhole_pixel(K: np.ndarray, T: np.ndarray, p_lidar: np.ndarray) -> np.ndarray:
    """The test's own pinhole projection: K (R p + t), divided by depth."""
    q = K @ (T[:3, :3] @ p_lidar + T[:3, 3])
    return q[:2] / q[2]


def angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R_a.T @ R_b) - 1) / 2, -1, 1))))


# ------------------------------------------------------------------ presets
@pytest.mark.parametrize(
    "name, lidar_dir, right_dir",
    [
        ("+x", (1, 0, 0), (0, -1, 0)),  # forward: the vehicle's right (-y) is the image's right
        ("-y", (0, -1, 0), (-1, 0, 0)),  # facing right: image right is backward
        ("+y", (0, 1, 0), (1, 0, 0)),  # facing left: image right is forward
        ("-x", (-1, 0, 0), (0, 1, 0)),  # facing backward: image right is the vehicle's left
    ],
)
def test_preset_looks_along_its_axis_upright(name, lidar_dir, right_dir):
    T = preset_T(name)
    R = T[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_array_equal(T[:3, 3], 0.0)
    # A point 10 m along the axis is on the optical axis; lidar up is image up (camera -y); the stated right.
    np.testing.assert_allclose(R @ (10.0 * np.array(lidar_dir)), [0, 0, 10], atol=1e-12)
    np.testing.assert_allclose(R @ np.array([0, 0, 1.0]), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(R @ np.array(right_dir, float), [1, 0, 0], atol=1e-12)


def test_preset_aliases_copies_and_errors():
    np.testing.assert_array_equal(preset_T("forward"), MOUNTING_PRESETS["+x"])
    np.testing.assert_array_equal(preset_T("right"), MOUNTING_PRESETS["-y"])
    T = preset_T("+x")
    T[0, 0] = 99.0
    assert MOUNTING_PRESETS["+x"][0, 0] == 0.0
    with pytest.raises(CalibError, match="unknown mounting preset"):
        preset_T("up")


@pytest.mark.skipif(not KITTI_CALIB.is_file(), reason=f"KITTI calib not found at {KITTI_CALIB}")
def test_forward_preset_is_close_to_kitti_published_rotation():
    error = angle_deg(preset_T("+x")[:3, :3], kitti_K_T()[1][:3, :3])
    print(f"\n'+x' preset vs KITTI 000002 published rotation: {error:.2f} deg")
    assert error < 3.0
    for other in ("-y", "+y", "-x"):
        assert angle_deg(preset_T(other)[:3, :3], kitti_K_T()[1][:3, :3]) > 80.0


# ------------------------------------------------------------------ rotation about the camera
def test_view_rotation_hand_values():
    a = np.radians(30.0)
    # Yaw alone: the optical axis turns towards +x (right): (sin a, 0, cos a).
    np.testing.assert_allclose(view_rotation(a, 0.0) @ [0, 0, 1.0], [0.5, 0, np.sqrt(3) / 2], atol=1e-12)
    # Pitch alone: towards +y (down).
    np.testing.assert_allclose(view_rotation(0.0, a) @ [0, 0, 1.0], [0, 0.5, np.sqrt(3) / 2], atol=1e-12)
    # Roll alone: image right (+x) turns towards image down (+y): clockwise on the screen.
    np.testing.assert_allclose(view_rotation(0.0, 0.0, a) @ [1.0, 0, 0], [np.sqrt(3) / 2, 0.5, 0], atol=1e-12)


def test_rotate_about_camera_keeps_the_camera_centre():
    T = np.eye(4)
    T[:3, :3] = preset_T("-y")[:3, :3] @ view_rotation(0.1, -0.2, 0.3)
    T[:3, 3] = [0.2, -0.1, 0.4]
    centre = -T[:3, :3].T @ T[:3, 3]
    T2 = rotate_about_camera(T, 0.05, 0.07, -0.02)
    np.testing.assert_allclose(-T2[:3, :3].T @ T2[:3, 3], centre, atol=1e-12)
    np.testing.assert_allclose(T2[:3, :3] @ T2[:3, :3].T, np.eye(3), atol=1e-12)
    np.testing.assert_array_equal(T2[3], [0, 0, 0, 1])
    # Zero turn is the identity; the input is not modified.
    np.testing.assert_allclose(rotate_about_camera(T, 0, 0, 0), T, atol=1e-15)


@pytest.mark.parametrize("du, dv", [(40.0, 0.0), (0.0, -25.0), (-63.5, 31.25), (300.0, 150.0)])
@pytest.mark.parametrize("fx, fy", [(721.5377, 721.5377), (500.0, 650.0)])
def test_drag_moves_the_point_at_the_principal_point_by_the_drag(du, dv, fx, fy):
    K = np.array([[fx, 0, 609.5], [0, fy, 172.8], [0, 0, 1.0]])
    T = preset_T("+x")
    T[:3, 3] = [0.06, -0.08, -0.27]
    # A lidar point on the optical axis 12 m in front of the camera.
    centre = -T[:3, :3].T @ T[:3, 3]
    p = centre + 12.0 * T[:3, :3].T @ np.array([0, 0, 1.0])
    before = pinhole_pixel(K, T, p)
    np.testing.assert_allclose(before, [609.5, 172.8], atol=1e-9)
    yaw, pitch = drag_to_rotation(du, dv, (fx, fy))
    after = pinhole_pixel(K, rotate_about_camera(T, yaw, pitch, 0.0), p)
    np.testing.assert_allclose(after - before, [du, dv], atol=1e-6)
    # Hand formula: pitch = atan(dv / fy), yaw = atan(du / (fx sqrt(1 + (dv / fy)^2))).
    assert pitch == pytest.approx(np.arctan(dv / fy), abs=1e-15)
    assert yaw == pytest.approx(np.arctan(du / (fx * np.sqrt(1 + (dv / fy) ** 2))), abs=1e-15)


def test_drag_elsewhere_follows_to_first_order():
    f = 700.0
    K = np.array([[f, 0, 600.0], [0, f, 180.0], [0, 0, 1.0]])
    T = preset_T("+x")
    p = np.array([15.0, -3.0, 1.0])  # off-axis
    before = pinhole_pixel(K, T, p)
    yaw, pitch = drag_to_rotation(2.0, -1.5, f)
    moved = pinhole_pixel(K, rotate_about_camera(T, yaw, pitch), p) - before
    # 140 px off-axis a turn moves a point by (1 + (x / f)^2) = 1.04 times what it moves one on the axis.
    x_n = (before[0] - 600.0) / f
    assert abs(x_n) > 0.19
    np.testing.assert_allclose(moved, [2.0 * (1 + x_n**2), -1.5], rtol=0.03)


def test_drag_errors():
    with pytest.raises(CalibError, match="focal length"):
        drag_to_rotation(1.0, 1.0, 0.0)
    with pytest.raises(CalibError, match="drag"):
        drag_to_rotation(np.nan, 1.0, 500.0)


def test_translate_in_camera_moves_the_centre_along_camera_axes():
    T = preset_T("+x")
    T[:3, 3] = [0.1, 0.2, 0.3]
    centre = -T[:3, :3].T @ T[:3, 3]
    T2 = translate_in_camera(T, 0.5, 0.0, 0.0)  # half a metre to the camera's right: lidar -y for '+x'
    np.testing.assert_allclose(-T2[:3, :3].T @ T2[:3, 3], centre + [0, -0.5, 0], atol=1e-12)
    T3 = translate_in_camera(T, 0.0, -0.2, 1.0)  # up 0.2 m (lidar +z), forward 1 m (lidar +x)
    np.testing.assert_allclose(-T3[:3, :3].T @ T3[:3, 3], centre + [1.0, 0, 0.2], atol=1e-12)
    np.testing.assert_array_equal(T3[:3, :3], T[:3, :3])
    with pytest.raises(CalibError):
        translate_in_camera(T, np.inf, 0, 0)


# ------------------------------------------------------------------ focal length
def test_focal_estimate_pinhole_is_exact():
    cam = PinholeCamera(np.array([[800.0, 0, 300.2], [0, 760.0, 250.7], [0, 0, 1]]), np.zeros(0), 640, 480)
    assert focal_px_estimate(cam) == pytest.approx(780.0, rel=1e-9)


def test_focal_estimate_fisheye_and_ocam():
    # Kannala-Brandt: r = f * theta_d(theta), theta_d ~ theta near the axis: pixels per radian -> f there.
    cam = FisheyeCamera(np.array([[310.0, 0, 320], [0, 310.0, 240], [0, 0, 1]]), np.array([0.05, -0.01, 0, 0]),
                        640, 480)
    assert focal_px_estimate(cam) == pytest.approx(310.0, rel=1e-4)
    # OCam (the sample): its pixels-per-radian at the centre from the projection of two rays 1 mrad apart.
    ocam = load_camera(SAMPLE / "camera.yaml")
    px, ok = ocam.project(np.array([[0.0, 0.0, 1.0], [np.tan(1e-3), 0.0, 1.0], [0.0, np.tan(1e-3), 1.0]]))
    assert ok.all()
    scale = (np.linalg.norm(px[1] - px[0]) + np.linalg.norm(px[2] - px[0])) / 2 / 1e-3
    print(f"\nOCam sample: focal estimate {focal_px_estimate(ocam):.2f} px, 1 mrad projection {scale:.2f} px/rad")
    assert focal_px_estimate(ocam) == pytest.approx(scale, rel=2e-3)
