"""Camera models against OpenCV, hand-computed values and real intrinsic files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from calib_core.cameras import (
    CAMERA_MODELS,
    CameraModel,
    FisheyeCamera,
    OCamCamera,
    PinholeCamera,
    camera_from_dict,
    load_camera,
    save_camera_yaml,
)
from calib_core.errors import CalibError
from repo_paths import SAMPLE

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
PJLAB = DATA / "pjlab_opencalib_lidar2camera"

K_PIN = np.array([[800.0, 0.0, 640.5], [0.0, 790.0, 360.25], [0.0, 0.0, 1.0]])
DISTS = {
    0: [],
    4: [-0.28, 0.09, 0.0012, -0.0009],
    5: [-0.28, 0.09, 0.0012, -0.0009, -0.012],
    8: [0.21, -0.08, 0.0011, 0.0018, 0.011, 0.31, -0.05, 0.021],
    12: [0.21, -0.08, 0.0011, 0.0018, 0.011, 0.31, -0.05, 0.021, 0.0012, 0.0021, -0.0011, 0.0005],
    14: [0.21, -0.08, 0.0011, 0.0018, 0.011, 0.31, -0.05, 0.021, 0.0012, 0.0021, -0.0011, 0.0005, 0.012, -0.021],
}
K_FISH = np.array([[310.0, 0.0, 640.0], [0.0, 305.0, 480.0], [0.0, 0.0, 1.0]])
D_FISH = [0.05, -0.012, 0.0021, -0.0004]


def small_ocam() -> OCamCamera:
    """A synthetic catadioptric-like camera: rays reach beyond 90 deg."""
    return OCamCamera([-100.0, 0.0, 0.002], None, 239.5, 319.5, 1.0, 0.0, 0.0, 640, 480)


# -- every registered model (as COLMAP's camera-model tests do) ------------------------------
#: Representative instances of each registered model, by its ``model:`` name.  A model added to the registry
#: needs an entry here, or :func:`test_registered_model_round_trips` fails for it.
CAMERA_FACTORIES = {
    "pinhole": lambda: [PinholeCamera(K_PIN, DISTS[n], 1280, 720) for n in sorted(DISTS)],
    "fisheye": lambda: [FisheyeCamera(K_FISH, D_FISH, 1280, 960)],
    "ocam": lambda: [small_ocam(), load_camera(SAMPLE / "camera.yaml")],  # synthetic (rays past 90 deg), the sample's
}


def test_every_factory_is_for_a_registered_model():
    assert {"pinhole", "fisheye", "ocam"} <= set(CAMERA_MODELS)
    assert set(CAMERA_FACTORIES) <= set(CAMERA_MODELS)


def _pixel_grid(cam, n_u: int = 41, n_v: int = 31) -> np.ndarray:
    """A grid over the whole image, out to 1e-6 px from its edges (exactly on an edge, round-off may step outside)."""
    margin = 0.5 - 1e-6
    u, v = np.meshgrid(np.linspace(-margin, cam.width - 1 + margin, n_u),
                       np.linspace(-margin, cam.height - 1 + margin, n_v))
    return np.stack([u.ravel(), v.ravel()], axis=1)


@pytest.mark.parametrize("model", sorted(CAMERA_MODELS))
def test_registered_model_round_trips(model):
    """``project(bearing(pixels)) == pixels`` over a grid of pixels inside the image, and
    ``bearing(project(points))`` parallel to ``points`` for points all around the camera."""
    assert model in CAMERA_FACTORIES, f"camera model {model!r} is registered but has no factory in this test"
    rng = np.random.default_rng(5)
    for cam in CAMERA_FACTORIES[model]():
        assert isinstance(cam, CameraModel) and CAMERA_MODELS[cam.model] is type(cam)
        uv = _pixel_grid(cam)
        rays = cam.bearing(uv)
        has_ray = np.isfinite(rays).all(axis=1)
        # Pixels without a ray (beyond the model's field of view) are each model's own test; most of the image has one.
        assert has_ray.mean() > 0.5 and np.isnan(rays[~has_ray]).all()
        np.testing.assert_allclose(np.linalg.norm(rays[has_ray], axis=1), 1.0, atol=1e-12)
        back, valid = cam.project(rays[has_ray] * rng.uniform(0.5, 50.0, (int(has_ray.sum()), 1)))
        assert valid.all()
        assert np.max(np.abs(back - uv[has_ray])) < 1e-6

        directions = rng.normal(size=(20000, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        pixels, valid = cam.project(directions * rng.uniform(0.5, 50.0, (len(directions), 1)))
        assert valid.sum() > 200  # the sphere's share the camera sees (5 % or more here)
        assert np.isfinite(pixels[valid]).all()
        np.testing.assert_allclose(cam.bearing(pixels[valid]), directions[valid], atol=1e-9)


# -- pinhole ------------------------------------------------------------------------
@pytest.mark.parametrize("n_dist", sorted(DISTS))
def test_pinhole_matches_cv2_project_points(n_dist):
    dist = np.array(DISTS[n_dist])
    cam = PinholeCamera(K_PIN, dist, 1280, 720)
    rng = np.random.default_rng(n_dist)
    points = rng.uniform([-0.8, -0.5, 1.0], [0.8, 0.5, 2.0], (500, 3))
    pixels, valid = cam.project(points)
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K_PIN, dist)
    assert np.isfinite(pixels).all()
    np.testing.assert_allclose(pixels, expected[:, 0], atol=1e-7)
    inside = (expected[:, 0, 0] >= -0.5) & (expected[:, 0, 0] <= 1279.5)
    inside &= (expected[:, 0, 1] >= -0.5) & (expected[:, 0, 1] <= 719.5)
    np.testing.assert_array_equal(valid, inside)


def test_pinhole_hand_computed():
    # x = 1/2, r2 = 1/4, radial = 1 + 0.1/4 = 1.025 -> u = 100 * 0.5125 + 50
    cam = PinholeCamera([[100, 0, 50], [0, 100, 40], [0, 0, 1]], [0.1, 0, 0, 0], 200, 100)
    pixels, valid = cam.project([[1.0, 0.0, 2.0]])
    np.testing.assert_allclose(pixels, [[101.25, 40.0]], atol=1e-12)
    assert valid.all()


def test_pinhole_rejects_behind_camera():
    cam = PinholeCamera(K_PIN, DISTS[5], 1280, 720)
    pixels, valid = cam.project([[0.1, 0.1, 1.0], [-0.1, -0.1, -1.0], [0.1, 0.1, 0.0]])
    assert valid.tolist() == [True, False, False]
    assert np.isnan(pixels[1:]).all()


def test_pinhole_rejects_points_past_the_fold():
    # rd = r (1 - 0.5 r^2) increases until r = sqrt(2/3); beyond it the
    # mapping folds back: r = 1.2 lands at rd = 0.336, well inside the image.
    K = [[500.0, 0.0, 400.0], [0.0, 500.0, 300.0], [0.0, 0.0, 1.0]]
    cam = PinholeCamera(K, [-0.5, 0.0, 0.0, 0.0], 800, 600)
    r_fold = math.sqrt(2.0 / 3.0)
    far = np.array([[1.2, 0.0, 1.0]])
    folded, _ = cv2.projectPoints(far, np.zeros(3), np.zeros(3), np.array(K), np.array([-0.5, 0.0, 0.0, 0.0]))
    assert 0 <= folded[0, 0, 0] < 800  # OpenCV wraps it back into the image
    pixels, valid = cam.project(np.array([[r_fold - 0.01, 0.0, 1.0], [r_fold + 0.01, 0.0, 1.0], [1.2, 0.0, 1.0]]))
    assert valid.tolist() == [True, False, False]
    assert np.isnan(pixels[1:]).all()


def test_pinhole_valid_needs_pixel_inside_image():
    cam = PinholeCamera([[100, 0, 50], [0, 100, 40], [0, 0, 1]], [], 100, 80)
    # u = 100 X / Z + 50: right edge u = 99.5 at X = 0.495; v = 100 Y / Z + 40: bottom v = 79.5 at Y = 0.395
    _, valid = cam.project([[0.494, 0, 1], [0.496, 0, 1], [-0.504, 0, 1], [-0.506, 0, 1], [0, 0.394, 1], [0, 0.396, 1]])
    assert valid.tolist() == [True, False, True, False, True, False]


def test_pinhole_bearing_matches_cv2_undistort():
    dist = np.array(DISTS[5])
    cam = PinholeCamera(K_PIN, dist, 1280, 720)
    uv = np.random.default_rng(3).uniform([0, 0], [1279, 719], (200, 2))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-14)
    xy = cv2.undistortPoints(uv[:, None], K_PIN, dist, None, None, None, criteria)[:, 0]
    expected = np.column_stack([xy, np.ones(len(xy))])
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(cam.bearing(uv), expected, atol=1e-9)


# -- fisheye ------------------------------------------------------------------------
@pytest.mark.parametrize("skew", [0.0, 2.5])
def test_fisheye_matches_cv2_fisheye(skew):
    K = K_FISH.copy()
    K[0, 1] = skew
    cam = FisheyeCamera(K, D_FISH, 1280, 960)
    rng = np.random.default_rng(1)
    points = rng.normal(size=(500, 3))
    points[:, 2] = np.abs(points[:, 2]) + 0.05
    pixels, valid = cam.project(points)
    expected, _ = cv2.fisheye.projectPoints(
        points[:, None], np.zeros(3), np.zeros(3), K_FISH, np.array(D_FISH), alpha=skew / K_FISH[0, 0]
    )
    np.testing.assert_allclose(pixels, expected[:, 0], atol=1e-7)
    assert valid.mean() > 0.9


def test_fisheye_hand_computed():
    # D = 0: equidistant, theta = 45 deg -> radius fx * pi/4 along +x.
    cam = FisheyeCamera([[200, 0, 320], [0, 200, 240], [0, 0, 1]], [0, 0, 0, 0], 640, 480)
    pixels, valid = cam.project([[1.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(pixels, [[320 + 200 * math.pi / 4, 240], [320, 240]], atol=1e-12)
    assert valid.all()


def test_fisheye_rejects_minus_p_unlike_cv2():
    cam = FisheyeCamera(K_FISH, D_FISH, 1280, 960)
    P = np.array([[0.3, -0.2, 1.0]])
    cv_p, _ = cv2.fisheye.projectPoints(P[:, None], np.zeros(3), np.zeros(3), K_FISH, np.array(D_FISH))
    cv_minus, _ = cv2.fisheye.projectPoints(-P[:, None], np.zeros(3), np.zeros(3), K_FISH, np.array(D_FISH))
    np.testing.assert_allclose(cv_p, cv_minus)  # the OpenCV pitfall
    pixels, valid = cam.project(np.vstack([P, -P, [[1.0, 0.0, 0.0]]]))
    assert valid.tolist() == [True, False, False]
    np.testing.assert_allclose(pixels[0], cv_p[0, 0], atol=1e-9)
    assert np.isnan(pixels[1:]).all()


def test_fisheye_bearing_stops_at_90_degrees_and_matches_cv2_undistort():
    cam = FisheyeCamera(K_FISH, D_FISH, 1280, 960)
    u, v = np.meshgrid(np.linspace(-0.5, 1279.5, 41), np.linspace(-0.5, 959.5, 31))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    rays = cam.bearing(uv)
    has_ray = np.isfinite(rays[:, 0])
    # corners of this 1280x960 image lie beyond 90 deg: no ray there (the round trip is the registry test's)
    assert 0.5 < has_ray.mean() < 1.0
    assert (rays[has_ray, 2] > 0).all()
    # Against OpenCV's own inverse, at moderate angles.
    near = uv[has_ray & (np.hypot(uv[:, 0] - 640, uv[:, 1] - 480) < 350)]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    xy = cv2.fisheye.undistortPoints(near[:, None], K_FISH, np.array(D_FISH), criteria=criteria)[:, 0]
    expected = np.column_stack([xy, np.ones(len(xy))])
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(cam.bearing(near), expected, atol=1e-8)


# -- ocam (synthetic; real data in test_ocam_real.py) ---------------------------------
def test_ocam_hand_computed():
    cam = small_ocam()
    # centre pixel: the optical axis, +Z in OpenCV
    np.testing.assert_allclose(cam.bearing([[319.5, 239.5]]), [[0.0, 0.0, 1.0]], atol=1e-15)
    # 100 px right of the centre: rho = 100, pol = -100 + 0.002 * 1e4 = -80
    # OCam ray (x, y, z) = (0, 100, -80) -> OpenCV (100, 0, 80)
    expected = np.array([100.0, 0.0, 80.0]) / math.hypot(100.0, 80.0)
    np.testing.assert_allclose(cam.bearing([[419.5, 239.5]]), [expected], atol=1e-15)
    # 250 px below the centre: pol = -100 + 125 = 25 -> OpenCV (0, 250, -25): behind the image plane
    expected = np.array([0.0, 250.0, -25.0]) / math.hypot(250.0, 25.0)
    np.testing.assert_allclose(cam.bearing([[319.5, 489.5]]), [expected], atol=1e-15)
    pixels, _ = cam.project([expected * 3.0])
    np.testing.assert_allclose(pixels, [[319.5, 489.5]], atol=1e-9)
    # max angle: corner radius hypot(320, 240) = 400, pol(400) = 220
    assert cam.max_angle_rad == pytest.approx(math.atan2(400.0, -220.0), abs=1e-12)


def test_ocam_rejects_outside_field_of_view_and_zero():
    cam = small_ocam()
    a = cam.max_angle_rad
    rays = np.array([[math.sin(a - 0.01), 0, math.cos(a - 0.01)], [math.sin(a + 0.01), 0, math.cos(a + 0.01)], [0, 0, 0]])
    pixels, valid = cam.project(rays)
    assert np.isfinite(pixels[0]).all()
    assert np.isnan(pixels[1:]).all() and not valid[1:].any()


def test_ocam_fitted_invpol_and_file_round_trip(tmp_path):
    cam = small_ocam()
    # the fitted invpol reproduces the exact root within the toolbox's 0.01 px
    alpha = np.linspace(0, cam.max_angle_rad, 300)
    rho_fit = np.polynomial.polynomial.polyval(alpha - np.pi / 2, cam.invpol)
    # exact root of -100 + 0.002 rho^2 - m rho = 0 with m = z/n = -cot(alpha)
    m = -1.0 / np.tan(np.maximum(alpha, 1e-12))
    rho_exact = (m + np.sqrt(m * m + 4 * 0.002 * 100.0)) / (2 * 0.002)
    rho_exact[0] = 0.0
    assert np.max(np.abs(rho_fit - rho_exact)) < 0.01
    path = tmp_path / "calib_results.txt"
    cam.write_calib_results(path)
    again = OCamCamera.from_calib_results(path)
    for name in ("pol", "invpol"):
        np.testing.assert_array_equal(getattr(again, name), getattr(cam, name))
    assert (again.xc, again.yc, again.c, again.d, again.e) == (cam.xc, cam.yc, cam.c, cam.d, cam.e)
    assert (again.width, again.height) == (cam.width, cam.height)


# -- YAML / ROS / PJLab files ---------------------------------------------------------
@pytest.mark.parametrize(
    "camera",
    [PinholeCamera(K_PIN, DISTS[8], 1280, 720), FisheyeCamera(K_FISH, D_FISH, 1280, 960), small_ocam()],
    ids=["pinhole", "fisheye", "ocam"],
)
def test_yaml_save_load_round_trip(tmp_path, camera):
    path = tmp_path / "cam" / "camera.yaml"
    path.parent.mkdir()
    save_camera_yaml(camera, path)
    doc = yaml.safe_load(path.read_text())
    assert doc["model"] == camera.model
    if camera.model == "ocam":
        assert doc["file"] == "calib_results.txt" and (path.parent / "calib_results.txt").exists()
    loaded = load_camera(path)
    assert type(loaded) is type(camera)
    assert (loaded.width, loaded.height) == (camera.width, camera.height)
    rng = np.random.default_rng(0)
    points = rng.normal(size=(200, 3)) + [0, 0, 2]
    np.testing.assert_array_equal(loaded.project(points)[0], camera.project(points)[0])
    # to_dict / camera_from_dict round trip as well (inline for ocam)
    again = camera_from_dict(camera.to_dict(None), tmp_path)
    np.testing.assert_array_equal(again.project(points)[0], camera.project(points)[0])


def test_own_yaml_hand_written(tmp_path):
    (tmp_path / "pin.yaml").write_text(
        "model: pinhole\nwidth: 200\nheight: 100\nK: [[100, 0, 50], [0, 100, 40], [0, 0, 1]]\ndist: [0.1, 0, 0, 0]\n"
    )
    cam = load_camera(tmp_path / "pin.yaml")
    np.testing.assert_allclose(cam.project([[1.0, 0.0, 2.0]])[0], [[101.25, 40.0]])
    sub = tmp_path / "sub"
    sub.mkdir()
    small_ocam().write_calib_results(sub / "my_ocam.txt")
    (tmp_path / "o.yml").write_text("model: ocam\nfile: sub/my_ocam.txt\n")
    cam = load_camera(tmp_path / "o.yml")
    assert cam.model == "ocam" and cam.pol.tolist() == [-100.0, 0.0, 0.002]
    assert cam.to_dict(tmp_path) == {"model": "ocam", "file": "sub/my_ocam.txt"}


ROS_PLUMB_BOB = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [430.215, 0, 306.691, 0, 430.531, 227.224, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.337591, 0.111947, 0.000433, -0.000404, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [377.1, 0, 304.4, 0, 0, 397.7, 227.8, 0, 0, 0, 1, 0]
"""


def test_ros_camera_info_plumb_bob(tmp_path):
    path = tmp_path / "ost.yaml"
    path.write_text(ROS_PLUMB_BOB)
    cam = load_camera(path)
    assert isinstance(cam, PinholeCamera) and (cam.width, cam.height) == (640, 480)
    np.testing.assert_array_equal(cam.K, [[430.215, 0, 306.691], [0, 430.531, 227.224], [0, 0, 1]])
    np.testing.assert_array_equal(cam.dist, [-0.337591, 0.111947, 0.000433, -0.000404, 0])


def test_ros_camera_info_rational_and_equidistant(tmp_path):
    rational = ROS_PLUMB_BOB.replace("plumb_bob", "rational_polynomial").replace(
        "cols: 5\n  data: [-0.337591, 0.111947, 0.000433, -0.000404, 0]",
        "cols: 8\n  data: [0.5, -0.1, 0.001, 0.002, 0.01, 0.8, -0.05, 0.02]",
    )
    (tmp_path / "r.yaml").write_text(rational)
    cam = load_camera(tmp_path / "r.yaml")
    assert isinstance(cam, PinholeCamera) and cam.dist.size == 8
    equidistant = ROS_PLUMB_BOB.replace("plumb_bob", "equidistant").replace(
        "cols: 5\n  data: [-0.337591, 0.111947, 0.000433, -0.000404, 0]",
        "cols: 4\n  data: [0.05, -0.01, 0.002, -0.0005]",
    )
    (tmp_path / "e.yaml").write_text(equidistant)
    cam = load_camera(tmp_path / "e.yaml")
    assert isinstance(cam, FisheyeCamera)
    np.testing.assert_array_equal(cam.D, [0.05, -0.01, 0.002, -0.0005])


@pytest.mark.realdata
@pytest.mark.skipif(not PJLAB.exists(), reason=f"real data not found at {PJLAB}")
def test_pjlab_intrinsic_json():
    auto = load_camera(PJLAB / "auto_calib" / "center_camera-intrinsic.json")
    assert isinstance(auto, PinholeCamera) and (auto.width, auto.height) == (1920, 1200)
    np.testing.assert_array_equal(auto.K, [[2117.31, 0, 924.681], [0, 2113.29, 656.457], [0, 0, 1]])
    np.testing.assert_array_equal(auto.dist, [-0.102933, -0.040925, 0.00057951, -0.00419933, 0.429959])
    manual_path = PJLAB / "manual_calib" / "center_camera-intrinsic.json"
    manual = load_camera(manual_path)
    assert (manual.width, manual.height) == (1920, 1080)  # what the file claims
    fixed = load_camera(manual_path, image_size=(1920, 1200))
    assert (fixed.width, fixed.height) == (1920, 1200)
    np.testing.assert_array_equal(fixed.K, [[2109.75, 0, 949.828], [0, 2071.72, 576.237], [0, 0, 1]])
    assert fixed.dist.size == 4
    # a pixel in the bottom rows of the real 1200-row image is valid only with the fix
    ray = fixed.bearing([[960.0, 1150.0]])
    assert fixed.project(ray)[1][0] and not manual.project(ray)[1][0]


def test_txt_image_size_override(tmp_path):
    small_ocam().write_calib_results(tmp_path / "calib_results.txt")
    cam = load_camera(tmp_path / "calib_results.txt", image_size=(800, 600))
    assert (cam.width, cam.height) == (800, 600)
    assert cam.max_angle_rad > small_ocam().max_angle_rad  # the larger image reaches further out


# -- malformed input ------------------------------------------------------------------
BAD_YAML = {
    "missing_key.yaml": ("model: pinhole\nwidth: 10\nheight: 10\n", "missing key 'K'"),
    "bad_shape.yaml": ("model: pinhole\nwidth: 10\nheight: 10\nK: [[1, 0, 5], [0, 1, 5]]\ndist: []\n", "3x3"),
    "unknown.yaml": ("model: kannala\nwidth: 10\nheight: 10\n", "unknown camera model"),
    "nan.yaml": ("model: fisheye\nwidth: 10\nheight: 10\nK: [[1, 0, 5], [0, .nan, 5], [0, 0, 1]]\nD: [0, 0, 0, 0]\n", "finite"),
    "dist_len.yaml": ("model: pinhole\nwidth: 10\nheight: 10\nK: [[1, 0, 5], [0, 1, 5], [0, 0, 1]]\ndist: [0, 0, 0]\n", "coefficients"),
    "size.yaml": ("model: pinhole\nwidth: -3\nheight: 10\nK: [[1, 0, 5], [0, 1, 5], [0, 0, 1]]\n", "width"),
    "text.yaml": ("model: pinhole\nwidth: 10\nheight: 10\nK: [[a, 0, 5], [0, 1, 5], [0, 0, 1]]\n", "numbers"),
    "syntax.yaml": ("model: [pinhole\n", "malformed YAML"),
    "list.yaml": ("- 1\n- 2\n", "mapping"),
    "nothing.yaml": ("foo: 1\n", "not a camera description"),
    "ros_bad.yaml": (ROS_PLUMB_BOB.replace("cols: 3\n  data: [430.215, 0,", "cols: 3\n  data: ["), "rows x cols"),
    "ros_model.yaml": (ROS_PLUMB_BOB.replace("plumb_bob", "mei"), "distortion_model"),
    "ocam_missing.yaml": ("model: ocam\nfile: nowhere.txt\n", "not found"),
    "ocam_a0.yaml": ("model: ocam\npol: [100, 0, 0.001]\nxc: 1\nyc: 1\nc: 1\nd: 0\ne: 0\nwidth: 4\nheight: 4\n", "a0"),
}


@pytest.mark.parametrize("name", sorted(BAD_YAML))
def test_malformed_yaml_raises_calib_error(tmp_path, name):
    text, problem = BAD_YAML[name]
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(CalibError) as info:
        load_camera(path)
    message = str(info.value)
    assert name in message and problem in message and "\n" not in message


BAD_TXT = {
    "truncated.txt": ("5 -206.3 0 0.002 -4e-06 1.8e-08\n\n3 290 150 -11\n\n241 385\n\n1 0 0\n", "ends early"),
    "letters.txt": ("5 -206.3 0 0.002 -4e-06 abc\n", "not a number"),
    "extra.txt": ("1 -206.3\n\n1 290\n\n241 385\n\n1 0 0\n\n480 748\n\n7\n", "unexpected"),
    "badlen.txt": ("2.5 -206.3 0\n", "bad length"),
}


@pytest.mark.parametrize("name", sorted(BAD_TXT))
def test_malformed_calib_results_raises_calib_error(tmp_path, name):
    text, problem = BAD_TXT[name]
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(CalibError) as info:
        load_camera(path)
    assert name in str(info.value) and problem in str(info.value)


def test_other_bad_inputs(tmp_path):
    with pytest.raises(CalibError, match="not found"):
        load_camera(tmp_path / "missing.yaml")
    (tmp_path / "cam.ini").write_text("x")
    with pytest.raises(CalibError, match="unsupported camera file type"):
        load_camera(tmp_path / "cam.ini")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(CalibError, match="bad.json: malformed JSON"):
        load_camera(tmp_path / "bad.json")
    (tmp_path / "nok.json").write_text(json.dumps({"a": {"param": {"cam_K": {"data": [[1, 0], [0, 1]]}, "img_dist_w": 4, "img_dist_h": 4}}}))
    with pytest.raises(CalibError, match="nok.json: cam_K.data must be 3x3"):
        load_camera(tmp_path / "nok.json")
    with pytest.raises(CalibError, match="skew"):
        PinholeCamera([[100, 1, 50], [0, 100, 40], [0, 0, 1]], [], 100, 80)
    with pytest.raises(CalibError, match="points must be an"):
        PinholeCamera(K_PIN, [], 1280, 720).project(np.zeros((3, 2)))


# -- bulk float32 points (the colouring path) ---------------------------------------------
def _bulk_points(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points in front of the camera, with unprojectable rows (NaN, inf, behind, zero)
    at and around the 256-point chunk boundaries; returns the points and the bad rows."""
    points = rng.uniform([-0.8, -0.5, 1.0], [0.8, 0.5, 2.0], (n, 3))
    bad = np.array([0, 255, 256, 257, 511, 512, n - 1])
    points[bad] = [[np.nan, 0, 1], [0.1, 0.1, -1.0], [0, 0, 0], [np.inf, 0, 1], [0.2, 0.0, -3.0], [0, np.nan, 1],
                   [0.0, 0.0, -1.0]]
    return points, bad


@pytest.mark.parametrize("n_dist", [5, 14])
def test_pinhole_bulk_float32_matches_cv2(n_dist):
    dist = np.array(DISTS[n_dist])
    cam = PinholeCamera(K_PIN, dist, 1280, 720)
    points, bad = _bulk_points(np.random.default_rng(7), 1000)
    p32 = np.asfortranarray(points, dtype=np.float32)  # column-major, as colorize_points passes them
    pixels, valid = cam.project(p32)
    assert pixels.dtype == np.float32 and pixels.shape == (1000, 2)
    good = np.setdiff1d(np.arange(1000), bad)
    expected, _ = cv2.projectPoints(p32[good].astype(np.float64), np.zeros(3), np.zeros(3), K_PIN, dist)
    np.testing.assert_allclose(pixels[good], expected[:, 0], atol=5e-4)  # float32 storage of ~1000 px
    assert np.isnan(pixels[bad]).all() and not valid[bad].any()
    inside = (expected[:, 0, 0] >= -0.5) & (expected[:, 0, 0] <= 1279.5)
    inside &= (expected[:, 0, 1] >= -0.5) & (expected[:, 0, 1] <= 719.5)
    np.testing.assert_array_equal(valid[good], inside)


def test_fisheye_bulk_float32_matches_cv2_fisheye():
    cam = FisheyeCamera(K_FISH, D_FISH, 1280, 960)
    points, bad = _bulk_points(np.random.default_rng(8), 1000)
    p32 = np.asfortranarray(points, dtype=np.float32)
    pixels, valid = cam.project(p32)
    assert pixels.dtype == np.float32
    good = np.setdiff1d(np.arange(1000), bad)
    expected, _ = cv2.fisheye.projectPoints(p32[good].astype(np.float64)[:, None], np.zeros(3), np.zeros(3), K_FISH,
                                            np.array(D_FISH))
    np.testing.assert_allclose(pixels[good], expected[:, 0], atol=5e-4)
    assert valid[good].all()
    assert np.isnan(pixels[bad]).all() and not valid[bad].any()
