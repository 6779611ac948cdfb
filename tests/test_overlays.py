"""Colouring with the occlusion test, and PLY export, on a hand-built scene."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from calib_core.errors import CalibError
from calib_core.overlays import colorize_points, export_colored_ply
from repo_paths import SAMPLE


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


def test_colour_is_bilinear_between_pixel_centres(scene):
    image, _, _ = scene
    # The image's red is u and green is v, so bilinear sampling returns the
    # projected position itself, rounded: (130.25, 60.75) -> (130, 61); the
    # blue channel is 7 everywhere.
    pts = np.array([[0.3025 * 2, -0.3925 * 2, 2.0]])
    colors, has = colorize_points(pts, image, _Pinhole(), np.eye(4), occlusion=False)
    assert has.all()
    np.testing.assert_array_equal(colors, [[130, 61, 7]])


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


def _box_room_depth(noise_m=0.0, seed=0):
    """A 6 x 4 x 3 m room around a sensor at (0.5, -0.3, 0.2), ranges cast by hand."""
    from calib_core.lidar.spherical import spherical_depth

    el = np.radians(np.arange(60, -60, -1.0))
    az = np.radians(np.arange(-180, 180, 0.5))
    E, A = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1)
    origin = np.array([0.5, -0.3, 0.2])
    lo, hi = np.array([-3.0, -2.0, -1.5]), np.array([3.0, 2.0, 1.5])
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, (hi - origin) / d, (lo - origin) / d)
    rng_m = np.min(np.where(np.isfinite(t) & (t > 0), t, np.inf), axis=-1)
    rng_m = rng_m + np.random.default_rng(seed).normal(0, noise_m, rng_m.shape)
    return spherical_depth(rng_m, el, az, wrap_cols=True), origin, lo, hi


def _distance_to_box_edges(points, lo, hi):
    """Distance of each point to the nearest of the box's 12 edges (points on the box surface)."""
    # On an edge two coordinates sit on a bound; the distance is over those two.
    dist_to_bound = np.minimum(np.abs(points - lo), np.abs(points - hi))
    two_smallest = np.sort(dist_to_bound, axis=1)[:, :2]
    return np.linalg.norm(two_smallest, axis=1)


def test_ba_edges_lie_on_the_rooms_edges():
    from calib_core.bearing_angle import bearing_angle_images
    from calib_core.overlays import ba_edge_points_consensus

    depth, origin, lo, hi = _box_room_depth(noise_m=0.003)
    pts_sensor, rc = ba_edge_points_consensus(bearing_angle_images(depth), depth)
    assert len(pts_sensor) > 500
    pts_world = pts_sensor + origin
    near = _distance_to_box_edges(pts_world, lo, hi) < 0.15
    all_points, _ = depth.valid_points()
    baseline = (_distance_to_box_edges(all_points + origin, lo, hi) < 0.15).mean()
    assert baseline < 0.15, "the test room must not be all edges"
    assert near.mean() > 0.9, f"only {near.mean():.0%} of the edge points lie near a wall intersection"
    # Edges are found at every vertical corner of the room, not only one.
    for cx, cy in [(lo[0], lo[1]), (lo[0], hi[1]), (hi[0], lo[1]), (hi[0], hi[1])]:
        assert (np.hypot(pts_world[:, 0] - cx, pts_world[:, 1] - cy) < 0.15).sum() > 5
    np.testing.assert_array_equal(depth.points[rc[:, 0], rc[:, 1]], pts_sensor)


def test_no_edges_where_beams_are_closer_than_the_noise():
    from calib_core.overlays import trace_spacing_ok

    depth, _, _, _ = _box_room_depth()
    ok = trace_spacing_ok(depth, "horizontal", min_spacing_m=0.025)
    # Horizontal neighbours are 0.5 deg apart times cos(elevation): at 60 deg
    # elevation and under 2.86 m range they are closer than 2.5 cm.
    spacing = depth.range_m * np.radians(0.5) * np.cos(np.radians(np.arange(60, -60, -1.0)))[:, None]
    np.testing.assert_array_equal(ok[:, 1:], (spacing >= 0.025)[:, 1:])
    assert not ok[:, 0].any() or depth.meta.get("wrap_cols")


def _reference_colours(points, image, camera, T, cell, tol=0.05):
    """colorize_points written out the plain way, in float64: project, z-buffer per
    ``cell``-pixel cell, 3x3 minimum, depth test, bilinear sampling rounded half up."""
    from scipy.ndimage import minimum_filter

    xyz = points @ T[:3, :3].T + T[:3, 3]
    uv, valid = camera.project(xyz)
    dist = np.linalg.norm(xyz, axis=1)
    h, w = image.shape[:2]
    gh, gw = -(-h // cell), -(-w // cell)
    col = np.minimum(np.floor(uv[valid, 0] + 0.5) // cell, gw - 1).astype(int)
    row = np.minimum(np.floor(uv[valid, 1] + 0.5) // cell, gh - 1).astype(int)
    zbuf = np.full((gh, gw), np.inf)
    np.minimum.at(zbuf, (row, col), dist[valid])
    limit = minimum_filter(zbuf, size=3, mode="nearest") * (1 + tol) + 0.05
    visible = valid.copy()
    visible[valid] = dist[valid] <= limit[row, col]
    u = np.clip(uv[:, 0], 0, w - 1)
    v = np.clip(uv[:, 1], 0, h - 1)
    c0 = np.floor(np.nan_to_num(u)).astype(int)
    r0 = np.floor(np.nan_to_num(v)).astype(int)
    c1, r1 = np.minimum(c0 + 1, w - 1), np.minimum(r0 + 1, h - 1)
    fu, fv = (u - c0)[:, None], (v - r0)[:, None]
    img = image.astype(float)
    top = img[r0, c0] * (1 - fu) + img[r0, c1] * fu
    bottom = img[r1, c0] * (1 - fu) + img[r1, c1] * fu
    colours = np.floor(top * (1 - fv) + bottom * fv + 0.5)
    colours[~visible] = 0
    return colours.astype(np.uint8), visible, dist, limit, row, col, valid


@pytest.mark.parametrize("cell, n", [(2, 250_000), (3, 60_000), (4, 60_000)])
def test_matches_a_plain_computation_on_the_ocam_sample(cell, n):
    """Against an independent float64 computation on the sample's OCam camera, image and scan,
    seen from the true pose, with the scan points in random order plus jitter (as a dense cloud);
    250k points are coloured on two threads."""
    from calib_core.synthetic import load_sample

    sc = load_sample(SAMPLE)
    rng = np.random.default_rng(3)
    pts = sc.depth.points[sc.depth.valid]
    pts = pts[rng.integers(0, len(pts), n)] + rng.normal(0, 0.01, (n, 3))
    colours, has = colorize_points(pts, sc.image, sc.camera, sc.T_camera_lidar, cell_px=cell)
    ref, visible, dist, limit, row, col, valid = _reference_colours(pts, sc.image, sc.camera, sc.T_camera_lidar, cell)
    assert 0.2 < visible.mean() < 0.98, "the scene must have both visible and hidden points"
    # float32 inside colorize_points: decisions may differ only for points at the depth limit
    # or on a cell border (pixels within about 1e-3 px of the float64 ones).
    differ = has != visible
    assert differ.sum() <= 0.001 * len(pts), f"{differ.sum()} points decided differently"
    same = has & visible
    delta = np.abs(colours[same].astype(int) - ref[same])
    assert delta.max() <= 1 and (delta > 0).any(axis=1).mean() < 0.01
    assert not colours[~has].any(), "points without colour are zero"
