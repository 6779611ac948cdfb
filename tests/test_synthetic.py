"""The synthetic sample scene: the committed files agree with each other and
with the scene geometry.

Independent references: trimesh's own ray/triangle intersector (the sample is
rendered with calib_core's caster), the analytic window rectangle, the
paper's Table I numbers, and the image itself (the ground truth must be the
pose at which the scan's surfaces best explain the image's colours).
"""

from __future__ import annotations


import numpy as np
import pytest
from trimesh.ray.ray_triangle import RayMeshIntersector

from calib_core.errors import CalibError
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.lidar import rotating_scanner_beams
from calib_core.pairs import load_pairs_yaml
from calib_core.synthetic import load_sample, make_sample_scene, simulate_pairs, write_sample
from calib_core.synthetic.render import image_circle_mask, shade
from calib_core.synthetic.sample import FILES, IMAGE_CIRCLE_RADIUS_PX
from calib_core.synthetic.scene import build_room
from calib_core.transforms import (
    R_from_rpy_deg,
    invert_T,
    make_T,
    rotation_angle_deg,
    rpy_deg_from_R,
    transform_points,
)
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


@pytest.fixture(scope="module")
def intersector(scene):
    return RayMeshIntersector(scene.mesh)


def first_hit_points(intersector, origins, directions):
    """trimesh's (pure-python) first hits; NaN rows for misses, face -1."""
    loc, ray, tri = intersector.intersects_location(origins, directions, multiple_hits=False)
    points = np.full((len(origins), 3), np.nan)
    points[ray] = loc
    faces = np.full(len(origins), -1)
    faces[ray] = tri
    return points, faces


def beam_origins_world(scene, rows, cols):
    meta = scene.depth.meta
    H, W = scene.depth.shape
    theta = np.broadcast_to(meta["theta_rad"], (H, W))[rows, cols]
    phi = np.broadcast_to(meta["phi_rad"], (H, W))[rows, cols]
    origins, directions = rotating_scanner_beams(theta, phi, meta["dx_m"], meta["dz_m"])
    T = scene.T_world_lidar
    return transform_points(T, origins), directions @ T[:3, :3].T


def smooth_cells(depth, rng, n):
    """n random valid cells whose 3x3 neighbourhood is valid and free of range jumps."""
    r = depth.range_m
    H, W = r.shape
    pad = np.pad(r, 1, mode="edge")
    stack = np.stack([pad[1 + i:H + 1 + i, 1 + j:W + 1 + j] for i in (-1, 0, 1) for j in (-1, 0, 1)])
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(stack), axis=0) & (np.max(np.abs(stack - r), axis=0) < 0.05 * r)
    rows, cols = np.nonzero(ok)
    k = rng.choice(len(rows), n, replace=False)
    return rows[k], cols[k]


# --- the committed files -------------------------------------------------------------

def test_committed_sample_loads_with_the_promised_rig(scene):
    assert all((SAMPLE / name).is_file() for name in FILES)
    assert scene.depth.shape == (180, 720)
    assert scene.depth.meta["model"] == "rotating_2d" and scene.depth.meta["wrap_cols"]
    theta_deg = np.degrees(np.ravel(scene.depth.meta["theta_rad"]))
    phi_deg = np.degrees(np.ravel(scene.depth.meta["phi_rad"]))
    np.testing.assert_allclose(theta_deg, 89.5 - np.arange(180))
    np.testing.assert_allclose(np.abs(np.diff(phi_deg)), 0.5)
    assert abs(phi_deg[-1] - phi_deg[0]) == pytest.approx(359.5)
    assert (scene.depth.meta["dx_m"], scene.depth.meta["dz_m"]) == (0.05, 0.03)
    assert scene.image.shape == (480, 640, 3) and scene.image.dtype == np.uint8
    assert scene.camera.model == "ocam" and (scene.camera.width, scene.camera.height) == (640, 480)
    assert np.degrees(scene.camera.max_angle_rad) > 90.0  # field of view over 180 deg
    # Seed 0 is the paper's Table I pose.
    np.testing.assert_allclose(rpy_deg_from_R(scene.T_camera_lidar[:3, :3]), [0.64, -1.24, 166.95], atol=1e-9)
    np.testing.assert_allclose(scene.T_camera_lidar[:3, 3], [0.207, 0.042, 0.139], atol=1e-12)
    assert scene.seed == 0 and len(scene.corner_labels) == len(scene.corners_lidar) >= 40
    # The layout rebuilt from the seed is the one the files were made from.
    np.testing.assert_allclose(scene.room.T_world_lidar, scene.T_world_lidar, atol=1e-12)
    np.testing.assert_allclose(scene.room.T_camera_lidar, scene.T_camera_lidar, atol=1e-12)
    by_label = dict(zip(scene.room.corner_labels, scene.room.corners_world))
    corners_w = np.array([by_label[label] for label in scene.corner_labels])
    np.testing.assert_allclose(transform_points(scene.T_world_lidar, scene.corners_lidar), corners_w, atol=1e-9)


def matching_corners(scene, pairs):
    """For every pair, a corner whose true pixel is within 4.5 px of the click
    (1 px sigma per axis) and whose point is within 5 cm of the clicked cell's
    point (a whole-cell pick); -1 where there is none."""
    true_pix, _ = scene.camera.project(transform_points(scene.T_camera_lidar, scene.corners_lidar))
    out = []
    for p in pairs:  # ten pairs
        pix_err = np.abs(true_pix - np.asarray(p.pixel)).max(axis=1)
        laser_err = np.linalg.norm(scene.corners_lidar - scene.depth.points[p.laser_rc], axis=1)
        ok = np.flatnonzero((pix_err < 4.5) & (laser_err <= 0.05))
        out.append(int(ok[np.argmin(pix_err[ok])]) if ok.size else -1)
    return np.array(out), true_pix


def test_committed_pairs_are_clicks_near_true_corners(scene):
    pairs = load_pairs_yaml(SAMPLE / "pairs.yaml")
    assert len(pairs) == 10
    assert all(p.laser_rc is not None and scene.depth.valid[p.laser_rc] for p in pairs)
    corner, _ = matching_corners(scene, pairs)
    assert np.all(corner >= 0)


# --- geometry agrees: scan, mesh, camera, ground truth --------------------------------

def test_scan_points_lie_on_the_scene_surfaces(scene, intersector):
    rows, cols = np.nonzero(scene.depth.valid)
    k = np.random.default_rng(0).choice(len(rows), 1500, replace=False)
    rows, cols = rows[k], cols[k]
    origins, directions = beam_origins_world(scene, rows, cols)
    hits, _ = first_hit_points(intersector, origins, directions)
    points_w = transform_points(scene.T_world_lidar, scene.depth.points[rows, cols])
    err = np.linalg.norm(hits - points_w, axis=1)
    # Range noise sigma = 1 cm: median |N(0, 1 cm)| = 0.67 cm.
    assert np.isfinite(err).all()
    assert 0.004 < np.median(err) < 0.009
    assert err.max() < 0.05


def test_laser_points_project_onto_pixels_that_see_them(scene, intersector):
    rows, cols = smooth_cells(scene.depth, np.random.default_rng(1), 600)
    points_l = scene.depth.points[rows, cols]
    pix, valid = scene.camera.project(transform_points(scene.T_camera_lidar, points_l))
    valid &= image_circle_mask(scene.camera, np.nan_to_num(pix), IMAGE_CIRCLE_RADIUS_PX)
    assert valid.sum() > 300
    bearings = scene.camera.bearing(pix[valid])
    T_world_camera = scene.T_world_lidar @ invert_T(scene.T_camera_lidar)
    dirs = bearings @ T_world_camera[:3, :3].T
    origins = np.tile(T_world_camera[:3, 3], (len(dirs), 1))
    hits, _ = first_hit_points(intersector, origins, dirs)
    points_w = transform_points(scene.T_world_lidar, points_l[valid])
    err = np.linalg.norm(hits - points_w, axis=1)
    # Range noise and the odd laser point that the camera sees occluded.
    assert np.median(err) < 0.012
    assert np.mean(err < 0.03) > 0.95


def test_ground_truth_is_the_pose_that_explains_the_image(scene, intersector):
    """Colour the scan's surface points and compare with the image at their
    projection: the error is smallest at the ground truth, and clearly larger
    0.5 deg or 2 cm away from it on every axis."""
    import cv2

    rows, cols = np.nonzero(scene.depth.valid)
    k = np.random.default_rng(2).choice(len(rows), 3000, replace=False)
    rows, cols = rows[k], cols[k]
    origins, directions = beam_origins_world(scene, rows, cols)
    _, faces = first_hit_points(intersector, origins, directions)
    points_l = scene.depth.points[rows, cols]
    points_w = transform_points(scene.T_world_lidar, points_l)
    image = scene.image.astype(np.float32)

    def colour_error(T_camera_lidar):
        pix, valid = scene.camera.project(transform_points(T_camera_lidar, points_l))
        valid &= image_circle_mask(scene.camera, np.nan_to_num(pix), IMAGE_CIRCLE_RADIUS_PX - 6)
        centre = (scene.T_world_lidar @ invert_T(T_camera_lidar))[:3, 3]
        expected = 255.0 * shade(scene.room, faces[valid], points_w[valid], points_w[valid] - centre)
        p = pix[valid].astype(np.float32)
        seen = cv2.remap(image, p[:, :1], p[:, 1:], cv2.INTER_LINEAR)[:, 0, :]
        return float(np.mean(np.abs(seen - expected)))

    T = scene.T_camera_lidar
    at_truth = colour_error(T)
    assert at_truth < 8.0
    for axis in range(3):
        for sign in (-1, 1):
            rpy = np.zeros(3)
            rpy[axis] = 0.5 * sign
            rotated = make_T(R_from_rpy_deg(rpy) @ T[:3, :3], T[:3, 3])
            shift = np.zeros(3)
            shift[axis] = 0.02 * sign
            moved = make_T(T[:3, :3], T[:3, 3] + shift)
            assert colour_error(rotated) > at_truth + 0.4, (axis, sign)
            assert colour_error(moved) > at_truth + 0.4, (axis, sign)


def test_corners_are_seen_by_both_sensors(scene, intersector):
    points_c = transform_points(scene.T_camera_lidar, scene.corners_lidar)
    pix, valid = scene.camera.project(points_c)
    assert valid.all()
    assert image_circle_mask(scene.camera, pix, IMAGE_CIRCLE_RADIUS_PX).all()
    corners_w = transform_points(scene.T_world_lidar, scene.corners_lidar)
    for T_world_sensor in (scene.T_world_lidar @ invert_T(scene.T_camera_lidar), scene.T_world_lidar):
        origins = np.tile(T_world_sensor[:3, 3], (len(corners_w), 1))
        hits, _ = first_hit_points(intersector, origins, corners_w - origins)
        # Nothing in between: the first hit is at the corner (1 cm slack for
        # rays that graze a face meeting at it).
        dist = np.linalg.norm(corners_w - origins, axis=1)
        assert np.all(np.linalg.norm(hits - origins, axis=1) > dist - 0.011)
    corners_doc = SAMPLE / "corners.yaml"
    import yaml

    listed = yaml.safe_load(corners_doc.read_text())["corners"]
    np.testing.assert_allclose([c["pixel"] for c in listed], pix, atol=1e-6)


def test_invalid_cells_are_exactly_the_window(scene):
    """No return only where the beam passes through the window opening (the
    room is far smaller than the 30 m range, and nothing stands in front of
    the window that reaches its sill)."""
    H, W = scene.depth.shape
    rows, cols = np.mgrid[0:H, 0:W]
    origins, directions = beam_origins_world(scene, rows.ravel(), cols.ravel())
    win = scene.room.window

    def through_opening(x_plane):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (x_plane - origins[:, 0]) / directions[:, 0]
        p = origins + t[:, None] * directions
        return (t > 0) & (p[:, 1] > win.y_range_m[0]) & (p[:, 1] < win.y_range_m[1]) & \
            (p[:, 2] > win.z_range_m[0]) & (p[:, 2] < win.z_range_m[1])

    expected = (through_opening(win.x_inner_m) & through_opening(win.x_glass_m)).reshape(H, W)
    invalid = ~scene.depth.valid
    assert 0.002 < expected.mean() < 0.05
    assert abs(invalid.mean() - expected.mean()) < 2e-4
    assert np.mean(invalid == expected) > 0.9997  # at most a few grazing cells on the edge


# --- seeds, generation, clicks ---------------------------------------------------------

def test_seeds_change_layout_and_ground_truth():
    rooms = [build_room(seed) for seed in (0, 1, 2)]
    T0 = rooms[0].T_camera_lidar
    np.testing.assert_allclose(rpy_deg_from_R(T0[:3, :3]), [0.64, -1.24, 166.95], atol=1e-9)
    for other in rooms[1:]:
        T = other.T_camera_lidar
        assert 0.05 < rotation_angle_deg(T[:3, :3], T0[:3, :3]) < 6.0
        assert 0.001 < np.linalg.norm(T[:3, 3] - T0[:3, 3]) < 0.06
        assert not np.allclose(other.size_m, rooms[0].size_m)
        assert not np.allclose(other.T_world_lidar, rooms[0].T_world_lidar)
        assert not np.allclose(other.corners_world[:20], rooms[0].corners_world[:20])
    for bad in (-1, 1.5, "3"):
        with pytest.raises(CalibError, match="seed"):
            build_room(bad)
    # Same seed, same scene.
    again = build_room(1)
    np.testing.assert_array_equal(again.mesh.vertices, rooms[1].mesh.vertices)
    np.testing.assert_array_equal(again.T_camera_lidar, rooms[1].T_camera_lidar)


def test_write_sample_files_are_present_and_reload(tmp_path):
    written = write_sample(tmp_path, seed=3, image_scale=8, scan_step=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(FILES)
    loaded = load_sample(tmp_path)
    assert loaded.seed == 3
    assert loaded.depth.shape == (90, 360) and loaded.image.shape == (60, 80, 3)
    np.testing.assert_array_equal(loaded.image, written.image)
    np.testing.assert_array_equal(loaded.depth.valid, written.depth.valid)
    np.testing.assert_allclose(loaded.depth.points[loaded.depth.valid], written.depth.points[written.depth.valid])
    np.testing.assert_allclose(loaded.T_camera_lidar, written.T_camera_lidar, atol=1e-12)
    np.testing.assert_allclose(load_extrinsics_yaml(tmp_path / "ground_truth.yaml")["T_camera_lidar"],
                               build_room(3).T_camera_lidar, atol=1e-12)
    np.testing.assert_allclose(loaded.corners_lidar, written.corners_lidar, atol=1e-12)
    assert loaded.corner_labels == written.corner_labels
    assert len(load_pairs_yaml(tmp_path / "pairs.yaml")) == 10
    assert "ba-calib sample -o sample_data --seed 3" in (tmp_path / "README.md").read_text()


def test_make_sample_scene_thinned_scan_keeps_the_rig():
    scene = make_sample_scene(5, image_scale=16, scan_step=4)
    assert scene.depth.shape == (45, 180) and scene.image.shape == (30, 40, 3)
    assert 0 < (~scene.depth.valid).mean() < 0.05
    # The image has content inside the circle and black corners outside it.
    assert scene.image[15, 20].max() > 0 and scene.image[0, 0].max() == 0


def test_load_sample_names_a_missing_file(tmp_path):
    with pytest.raises(CalibError, match="scan"):
        load_sample(tmp_path)
    with pytest.raises(CalibError, match="not found"):
        load_sample(tmp_path / "nowhere")


def test_simulated_pairs_are_spread_realistic_clicks(scene):
    rng = np.random.default_rng(7)
    pairs = simulate_pairs(scene, 10, rng, pixel_noise_px=1.0)
    assert len(pairs) == 10 and len({p.laser_rc for p in pairs}) == 10
    corner, true_pix = matching_corners(scene, pairs)
    assert np.all(corner >= 0)
    clicked = np.array([p.pixel for p in pairs])
    assert 0.2 < np.sqrt(np.mean((clicked - true_pix[corner]) ** 2)) < 2.0
    # Spread over the view: the clicked rays are far apart.
    b = scene.camera.bearing(clicked)
    cos = b @ b.T - 2 * np.eye(10)
    assert np.degrees(np.arccos(cos.max())) > 15.0
    # Noise-free clicks land on the true projection.
    exact = simulate_pairs(scene, 10, np.random.default_rng(7), pixel_noise_px=0.0)
    exact_pix = np.array([p.pixel for p in exact])
    assert np.min(np.linalg.norm(true_pix[None] - exact_pix[:, None], axis=2), axis=1).max() < 1e-9
    # Same generator state, same clicks.
    again = simulate_pairs(scene, 10, np.random.default_rng(7), pixel_noise_px=1.0)
    assert again == pairs
    with pytest.raises(CalibError, match="pairs"):
        simulate_pairs(scene, 10_000, rng)
