"""Unwrapped panorama: its geometry, its resampling, and corner snapping."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calib_core.cameras import FisheyeCamera, OCamCamera
from calib_core.errors import CalibError
from calib_core.panorama import Panorama, refine_click_to_corner


def ocam_200deg() -> OCamCamera:
    # pol(rho) = -300 + 0.001552 rho^2: the ray at rho = 500 px is 100 deg off
    # the axis (pol(500) = 88 = 500 / -tan(100 deg)), a > 180 deg fisheye.
    return OCamCamera([-300.0, 0.0, 0.001552], None, 300.0, 400.0, 1.0, 0.0, 0.0, 800, 600)


def kb_fisheye() -> FisheyeCamera:
    K = [[300.0, 0.0, 399.5], [0.0, 300.0, 299.5], [0.0, 0.0, 1.0]]
    return FisheyeCamera(K, [0.02, -0.01, 0.0, 0.0], 800, 600)


def test_hand_computed_geometry():
    # 180 x 90 deg panorama, 2 pixels per degree, upright camera (up = -y).
    pano = Panorama.for_camera(
        ocam_200deg(), 360, 180, azimuth_range_rad=(-np.pi / 2, np.pi / 2), elevation_range_rad=(-np.pi / 4, np.pi / 4)
    )
    px = np.array(
        [
            [179.5, 89.5],  # centre: azimuth 0, elevation 0 -> straight ahead
            [-0.5, 89.5],  # left border: azimuth -90 deg -> camera -x
            [359.5, 89.5],  # right border: +90 deg -> +x
            [179.5, -0.5],  # top border: elevation +45 deg -> up (-y) and ahead
            [269.5, 179.5],  # azimuth +45 deg, elevation -45 deg
        ]
    )
    s = np.sqrt(0.5)
    expected = np.array([[0, 0, 1], [-1, 0, 0], [1, 0, 0], [0, -s, s], [0.5, s, 0.5]])
    np.testing.assert_allclose(pano.bearing(px), expected, atol=1e-12)
    back, valid = pano.project(expected * 7.0)  # any length
    np.testing.assert_allclose(back, px, atol=1e-9)
    assert valid.all()
    # Outside the panorama: no bearing, and projections flagged invalid.
    assert np.isnan(pano.bearing([[360.0, 10.0]])).all()
    assert not pano.project([[0.0, 0.0, -1.0]])[1][0]


def test_custom_axis_for_a_camera_looking_up():
    # Cylinder axis = optical axis: azimuth runs around the image centre.
    pano = Panorama.for_camera(
        ocam_200deg(), 360, 90, up_camera=(0, 0, 1), forward_camera=(1, 0, 0),
        azimuth_range_rad=(-np.pi, np.pi), elevation_range_rad=(-np.pi / 4, np.pi / 4),
    )
    # right = forward x up = x cross z = -y.
    np.testing.assert_allclose(pano.right_camera, [0, -1, 0])
    np.testing.assert_allclose(pano.bearing([[269.5, 44.5]])[0], [0, -1, 0], atol=1e-12)
    # A full turn has no seam: directions just either side of azimuth 180 deg map to both ends.
    eps = 1e-6
    px, valid = pano.project([[-1.0, eps, 0.0], [-1.0, -eps, 0.0]])
    assert valid.all() and px[0, 0] < 0 and px[1, 0] > 359


@pytest.mark.parametrize("make_camera", [ocam_200deg, kb_fisheye])
def test_round_trips(make_camera):
    cam = make_camera()
    pano = Panorama.for_camera(cam)
    rng = np.random.default_rng(1)
    px = rng.uniform([-0.5, -0.5], [pano.width - 0.5, pano.height - 0.5], size=(500, 2))
    b = pano.bearing(px)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-12)
    back, valid = pano.project(b)
    assert valid.all()
    np.testing.assert_allclose(back, px, atol=1e-8)
    # Original image -> panorama -> original image.
    seen = pano.seen[np.clip(np.round(px[:, 1]).astype(int), 0, pano.height - 1), np.clip(np.round(px[:, 0]).astype(int), 0, pano.width - 1)]
    raw, ok = pano.to_camera_pixels(px[seen])
    ok &= np.isfinite(raw).all(axis=1)
    again, ok2 = pano.from_camera_pixels(raw[ok])
    assert ok2.all()
    np.testing.assert_allclose(again, px[seen][ok], atol=1e-6)


def test_default_extent_covers_a_wider_than_180_view():
    pano = Panorama.for_camera(ocam_200deg())
    az0, az1 = np.rad2deg(pano.azimuth_range_rad)
    el0, el1 = np.rad2deg(pano.elevation_range_rad)
    # The image circle reaches 100 deg off the axis at radius 500 px (within the 800 x 600
    # image horizontally), so the horizon spans more than +-90 deg.
    assert az0 < -95 and az1 > 95
    assert el0 >= -80 - 1e-9 and el1 <= 80 + 1e-9
    # Square pixels at the camera's own resolution at the centre (1/300 rad per pixel).
    assert pano.width == pytest.approx(np.deg2rad(az1 - az0) * 300, rel=0.02)
    assert pano.height == pytest.approx(np.deg2rad(el1 - el0) * 300, rel=0.02)


@pytest.mark.parametrize("make_camera", [ocam_200deg, kb_fisheye])
def test_panorama_pixel_shows_the_raw_pixel_its_bearing_projects_to(make_camera):
    cam = make_camera()
    pano = Panorama.for_camera(cam, 600, 300)
    # A raw image whose two channels are its own pixel coordinates: bilinear
    # sampling of a linear function is exact, so the panorama shows exactly
    # which raw position each of its pixels was sampled from.
    us, vs = np.meshgrid(np.arange(cam.width, dtype=np.float32), np.arange(cam.height, dtype=np.float32))
    coords = np.dstack([us, vs])
    shown = pano.render(coords)
    rng = np.random.default_rng(2)
    idx = np.flatnonzero(pano.seen)
    pick = rng.choice(idx, 300, replace=False)
    v, u = np.divmod(pick, pano.width)
    raw, ok = cam.project(pano.bearing(np.stack([u, v], axis=1).astype(float)))
    inner = ok & (raw[:, 0] > 1) & (raw[:, 0] < cam.width - 2) & (raw[:, 1] > 1) & (raw[:, 1] < cam.height - 2)
    assert inner.sum() > 200
    # cv2.remap interpolates at 1/32 px steps, so up to 1/64 px off.
    np.testing.assert_allclose(shown[v, u][inner], raw[inner], atol=0.02)
    # Where the camera sees nothing, the panorama is black.
    assert (pano.render(np.full((cam.height, cam.width, 3), 255, np.uint8))[~pano.seen] == 0).all()


def test_panorama_colours_follow_scene_directions():
    # Paint the raw image with a function of each pixel's own ray (camera.bearing):
    # the panorama pixel must then show the same function of the panorama's bearing.
    cam = ocam_200deg()
    us, vs = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    rays = cam.bearing(np.stack([us.ravel(), vs.ravel()], axis=1))
    paint = (128 + 100 * np.nan_to_num(rays)).reshape(cam.height, cam.width, 3).astype(np.float32)
    pano = Panorama.for_camera(cam, 400, 200)
    shown = pano.render(paint)
    uu, vv = np.meshgrid(np.arange(400, dtype=float), np.arange(200, dtype=float))
    expected = (128 + 100 * pano.bearing(np.stack([uu.ravel(), vv.ravel()], axis=1))).reshape(200, 400, 3)
    ok = pano.seen & cv2.erode(pano.seen.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    # Linear interpolation of a smooth function: errors well under one grey level.
    assert np.abs(shown[ok] - expected[ok]).max() < 1.0


def test_bad_parameters_raise():
    cam = kb_fisheye()
    with pytest.raises(CalibError, match="up_camera"):
        Panorama.for_camera(cam, up_camera=(0, 0, 0))
    with pytest.raises(CalibError, match="not parallel"):
        Panorama.for_camera(cam, up_camera=(0, 0, 1), forward_camera=(0, 0, 2))
    with pytest.raises(CalibError, match="elevation range"):
        Panorama.for_camera(cam, 100, 50, azimuth_range_rad=(-1, 1), elevation_range_rad=(0.5, -0.5))
    pano = Panorama.for_camera(cam, 100, 50)
    with pytest.raises(CalibError, match="camera model is 800x600"):
        pano.render(np.zeros((10, 10, 3), np.uint8))


def _quadrant_image() -> np.ndarray:
    img = np.full((100, 120), 20, np.uint8)
    img[40:, 50:] = 200  # one bright quadrant: an L corner at (u, v) = (49.5, 39.5)
    return img


def test_snap_to_corner():
    img = _quadrant_image()
    for click in [(47.0, 37.0), (52.0, 42.0), (53.0, 36.0)]:
        np.testing.assert_allclose(refine_click_to_corner(img, click, 4.0), [49.5, 39.5], atol=0.2)
    # A checkerboard saddle is located exactly.
    board = img.copy()
    board[:40, :50] = 200
    board = cv2.GaussianBlur(board, (0, 0), 1.0)
    np.testing.assert_allclose(refine_click_to_corner(board, (51.3, 41.0), 4.0), [49.5, 39.5], atol=0.02)


def test_snap_leaves_clicks_without_a_corner_alone():
    flat = np.full((100, 120), 20, np.uint8)
    np.testing.assert_array_equal(refine_click_to_corner(flat, (47.0, 37.0), 4.0), [47.0, 37.0])
    noise = np.random.default_rng(0).normal(100, 3, (100, 120)).clip(0, 255).astype(np.uint8)
    np.testing.assert_array_equal(refine_click_to_corner(noise, (48.0, 37.0), 4.0), [48.0, 37.0])
    # The corner is 10 px away: out of reach.
    np.testing.assert_array_equal(refine_click_to_corner(_quadrant_image(), (39.5, 39.5), 4.0), [39.5, 39.5])
    with pytest.raises(CalibError):
        refine_click_to_corner(np.zeros((10, 10, 3)), (1, 1))


def test_image_mask_limits_the_extent_and_oversample_sets_the_size():
    cam = ocam_200deg()
    rows, cols = np.mgrid[0:600, 0:800]
    disk = np.hypot(rows - 300.0, cols - 400.0) <= 300.0  # lens circle of radius 300 px
    pano = Panorama.for_camera(cam, image_mask=disk)
    # At rho = 300 px, pol = -300 + 0.001552 * 300^2 = -160.32, so the ray is
    # atan2(300, 160.32) = 61.88 deg off the axis; the extent adds a 1 deg margin.
    # The field of view is sampled on a 256 x 256 grid (2.3 px ~ 0.5 deg steps here).
    half = np.degrees(np.arctan2(300.0, 300.0 - 0.001552 * 300.0**2)) + 1.0
    np.testing.assert_allclose(np.degrees(pano.azimuth_range_rad), [-half, half], atol=0.75)
    np.testing.assert_allclose(np.degrees(pano.elevation_range_rad), [-half, half], atol=0.75)
    twice = Panorama.for_camera(cam, image_mask=disk, oversample=2.0)
    assert twice.width == pytest.approx(2 * pano.width, abs=2)
    with pytest.raises(CalibError, match="image_mask shape"):
        Panorama.for_camera(cam, image_mask=disk[:10])
