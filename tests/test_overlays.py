"""Colouring with the occlusion test, and PLY export, on a hand-built scene."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from calib_core.errors import CalibError
from calib_core.overlays import colorize_points, export_colored_ply


class _Pinhole:
    """200x200, f = 100 px, principal point (100, 100), no distortion."""

    model = "test"
    width = height = 200

    def project(self, points):
        p = np.asarray(points, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = 100.0 * p[:, :2] / p[:, 2:3] + 100.0
        valid = (p[:, 2] > 0) & (uv >= -0.5).all(axis=1) & (uv <= 199.5).all(axis=1)
        return uv, valid


def _grid(half, z, step):
    xs = np.arange(-half, half + 1e-9, step)
    x, y = np.meshgrid(xs, xs)
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)


@pytest.fixture
def scene():
    # Image: colour encodes the pixel, so the sampled colour says where a point landed.
    v, u = np.mgrid[0:200, 0:200]
    image = np.stack([u, v, np.full_like(u, 7)], axis=-1).astype(np.uint8)
    front = _grid(0.4, 2.0, 0.02)  # a square 2 m ahead: pixels 80..120
    back = _grid(4.0, 5.0, 0.05)  # a wall 5 m ahead, partly hidden by the square
    return image, front, back


def test_background_behind_an_object_gets_no_colour(scene):
    image, front, back = scene
    pts = np.concatenate([front, back])
    colors, has = colorize_points(pts, image, _Pinhole(), np.eye(4))
    nf = len(front)
    assert has[:nf].all(), "every point of the visible square is coloured"
    uv_back = 100.0 * back[:, :2] / 5.0 + 100.0
    hidden = (np.abs(uv_back - 100.0) < 18).all(axis=1)  # well inside the square's silhouette (80..120)
    visible = (np.abs(uv_back - 100.0) > 24).any(axis=1) & (uv_back >= 0).all(axis=1) & (uv_back <= 199).all(axis=1)
    assert hidden.sum() > 100 and visible.sum() > 1000
    assert not has[nf:][hidden].any(), "occluded wall points must not take the square's colour"
    assert has[nf:][visible].all()
    # Without the depth test the hidden points would be painted.
    _, has_no_test = colorize_points(pts, image, _Pinhole(), np.eye(4), occlusion=False)
    assert has_no_test[nf:][hidden].all()


def test_colour_is_sampled_where_the_point_projects(scene):
    image, _, _ = scene
    # Points that land exactly on pixel centres (u, v) = (130, 60) and (100, 100).
    pts = np.array([[0.3 * 2, -0.4 * 2, 2.0], [0.0, 0.0, 3.0]])
    colors, has = colorize_points(pts, image, _Pinhole(), np.eye(4), occlusion=False)
    assert has.all()
    np.testing.assert_array_equal(colors, [[130, 60, 7], [100, 100, 7]])


def test_points_behind_outside_or_nan_get_no_colour(scene):
    image, _, _ = scene
    pts = np.array([[0, 0, -2.0], [50.0, 0, 1.0], [np.nan, 0, 1.0], [0, 0, 1.0]])
    _, has = colorize_points(pts, image, _Pinhole(), np.eye(4))
    np.testing.assert_array_equal(has, [False, False, False, True])


def test_extrinsics_are_applied(scene):
    image, _, _ = scene
    # Lidar frame shifted 1 m along camera x: lidar origin is camera (1, 0, 0).
    T = np.eye(4)
    T[0, 3] = 1.0
    colors, has = colorize_points(np.array([[-1.0, 0.0, 2.0]]), image, _Pinhole(), T, occlusion=False)
    assert has[0]
    np.testing.assert_array_equal(colors[0], [100, 100, 7])


def test_image_size_must_match_camera(scene):
    image, front, _ = scene
    with pytest.raises(CalibError, match="200x200"):
        colorize_points(front, image[:100], _Pinhole(), np.eye(4))


def test_ply_round_trip(tmp_path):
    pts = np.array([[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [np.nan, 0, 0]])
    colors = np.array([[255, 0, 0], [0, 0, 0], [1, 2, 3]], np.uint8)
    path = tmp_path / "c.ply"
    export_colored_ply(path, pts, colors, has_color=np.array([True, False, True]))
    cloud = trimesh.load(path)
    np.testing.assert_allclose(cloud.vertices, pts[:2])
    np.testing.assert_array_equal(cloud.colors[:, :3], [[255, 0, 0], [128, 128, 128]])
