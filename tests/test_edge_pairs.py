"""Edge pairs: a laser point whose pixel lies on a straight image edge and may slide along it.

Checked against independent truth: synthetic images of hand-known edges (``edge_at``), the hand-built
anisotropic click covariance (the whitening), the sample's ground truth (the solve), files written and read.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.image_edges import EDGE_COHERENCE, edge_at
from calib_core.io.session_file import parse_session
from calib_core.pairs import Pair, load_pairs_yaml, save_pairs_yaml, tag_fields
from calib_core.shots import Shot, solve_shots
from calib_core.solve import calibrate, solve_extrinsics
from calib_core.solve.edges import EDGE_SLIDE, edge_tangent_jacobian
from calib_core.solve.kernels import tangent_probes
from calib_core.solve.whiten import tangent_to_pixel, whitening
from calib_core.synthetic import load_sample
from repo_paths import SAMPLE


# ----------------------------------------------------------------------------------------------------------------
# edge_at on synthetic images
# ----------------------------------------------------------------------------------------------------------------

H, W = 200, 240
VV, UU = np.mgrid[0:H, 0:W].astype(np.float64)
CENTRE = np.array([120.3, 100.7])


def _unit(angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    a = math.radians(angle_deg)
    t = np.array([math.cos(a), math.sin(a)])
    return t, np.array([-t[1], t[0]])


def _signed_distance(angle_deg: float) -> np.ndarray:
    """Distance (px) of every pixel from the line through CENTRE at ``angle_deg``, along its normal."""
    _, n = _unit(angle_deg)
    return (UU - CENTRE[0]) * n[0] + (VV - CENTRE[1]) * n[1]


def _angle_diff(a: float, b: float) -> float:
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


@pytest.mark.parametrize("angle", [0.0, 30.0, 90.0, 135.0])
def test_edge_at_finds_a_step_edge_direction(angle):
    rng = np.random.default_rng(int(angle))
    # A step of 80 grey levels, one pixel of ramp (area sampling of a sharp edge), 2 grey levels of noise.
    img = 60 + 80 * np.clip(0.5 + _signed_distance(angle), 0, 1) + rng.normal(0, 2, (H, W))
    _, n = _unit(angle)
    for click in (CENTRE, CENTRE + 2.5 * n, CENTRE - 3.0 * _unit(angle)[0]):
        found = edge_at(img, click)
        assert found.ok and found.coherence >= EDGE_COHERENCE
        assert found.radius_px == 4  # the smallest window already holds the edge
        assert _angle_diff(found.angle_deg, angle) < 1.0, found
        assert 0.0 <= found.angle_deg < 180.0


def test_edge_at_a_wide_bar_clicked_in_its_middle_uses_a_window_that_reaches_both_sides():
    rng = np.random.default_rng(5)
    angle = 30.0
    img = 60 + 100 * np.clip(20.5 - np.abs(_signed_distance(angle)), 0, 1) + rng.normal(0, 2, (H, W))  # 41 px wide
    found = edge_at(img, CENTRE)
    assert found.ok
    assert found.radius_px >= 16  # inside the bar, 20 px from either side: a small window sees only noise
    assert _angle_diff(found.angle_deg, angle) < 1.0, found
    inside_only = edge_at(img, CENTRE, radii=(4, 8))
    assert not inside_only.ok


def test_edge_at_a_corner_is_not_coherent_and_noise_has_no_direction():
    rng = np.random.default_rng(6)
    corner = 60 + 100 * ((UU > CENTRE[0]) & (VV > CENTRE[1])) + rng.normal(0, 2, (H, W))
    found = edge_at(corner, CENTRE)
    assert not found.ok and found.coherence < 0.3
    noise = 60 + rng.normal(0, 2, (H, W))
    found = edge_at(noise, CENTRE)
    assert not found.ok and math.isnan(found.angle_deg) and found.coherence == 0.0


def test_edge_at_refuses_a_click_outside_the_image():
    img = np.zeros((H, W))
    for uv in ((-3.0, 10.0), (W + 0.0, 10.0), (10.0, H + 5.0), (math.nan, 3.0)):
        with pytest.raises(CalibError, match="edge_at"):
            edge_at(img, uv)


# ----------------------------------------------------------------------------------------------------------------
# the whitening: M^-1 A gives the anisotropic click covariance
# ----------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


def _frames(bearings: np.ndarray) -> np.ndarray:
    """Rows e1, e2, b of each bearing (an orthonormal tangent basis; any one will do for the claim)."""
    b = bearings / np.linalg.norm(bearings, axis=1, keepdims=True)
    helper = np.where(np.abs(b[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(helper, b)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(b, e1)
    return np.stack([e1, e2, b], axis=1)


def test_edge_whitening_equals_the_hand_built_anisotropic_covariance(scene):
    cam = scene.camera
    rng = np.random.default_rng(3)
    pixels = np.column_stack([rng.uniform(200, 440, 6), rng.uniform(150, 330, 6)])
    frames = _frames(cam.bearing(pixels))
    A, ok = tangent_to_pixel(cam, frames)
    assert ok.all()
    angles = np.array([0.0, 30.0, 90.0, 135.0, np.nan, 170.0])
    sigma = np.array([1.0, 0.5, 2.0, 1.0, 1.0, 0.3])
    laser = np.array([np.diag([1e-5, 3e-5]) + 1e-6 for _ in range(6)])  # rad^2
    W, unit = whitening(6, camera=cam, frames=frames, pixel_sigma=sigma, laser_tangent_cov=laser,
                        tangent=(edge_tangent_jacobian(A, angles), ok))
    assert unit == "sigma"
    for i in range(6):
        # The click's covariance in px^2, built by hand: sigma^2 (n n^T + k^2 t t^T), isotropic for the corner pair.
        if np.isnan(angles[i]):
            S_px = sigma[i] ** 2 * np.eye(2)
        else:
            t, n = _unit(angles[i])
            S_px = sigma[i] ** 2 * (np.outer(n, n) + EDGE_SLIDE**2 * np.outer(t, t))
        A_inv = np.linalg.inv(A[i])
        C = A_inv @ S_px @ A_inv.T + laser[i]  # the residual's covariance in the tangent plane, rad^2
        # Whitened residual z = W r has covariance W C W^T = I.
        np.testing.assert_allclose(W[i] @ C @ W[i].T, np.eye(2), atol=1e-9)
    # Without a laser term W = M^-1 A / sigma; sampled click errors through it come out white.
    W0, _ = whitening(6, camera=cam, frames=frames, pixel_sigma=sigma, tangent=(edge_tangent_jacobian(A, angles), ok))
    t, n = _unit(30.0)
    dm = sigma[1] * (rng.normal(size=(200_000, 1)) * n + EDGE_SLIDE * rng.normal(size=(200_000, 1)) * t)
    z = (W0[1] @ np.linalg.inv(A[1]) @ dm.T).T
    np.testing.assert_allclose(np.cov(z.T), np.eye(2), atol=0.02)


# ----------------------------------------------------------------------------------------------------------------
# the solve on the sample
# ----------------------------------------------------------------------------------------------------------------

CORNER_NOISE_PX, ACROSS_NOISE_PX = 0.5, 0.5


def _pose_errors(T, T_true) -> tuple[float, np.ndarray]:
    dR = T[:3, :3] @ T_true[:3, :3].T
    angle = math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
    return angle, T[:3, 3] - T_true[:3, 3]


def _edge_scene(scene, seed: int = 1, n_corner: int = 6, n_edge: int = 8):
    """Corner pairs at the true projections of sample corners plus noise, and edge pairs whose pixel is moved
    15-35 px along a known edge direction (plus noise across it)."""
    T = scene.T_camera_lidar
    P = scene.corners_lidar
    uv, ok = scene.camera.project(P @ T[:3, :3].T + T[:3, 3])
    uv, ok = np.asarray(uv), np.asarray(ok, bool)
    rng = np.random.default_rng(seed)
    usable = np.flatnonzero(ok & (uv[:, 0] > 60) & (uv[:, 0] < 580) & (uv[:, 1] > 60) & (uv[:, 1] < 420))
    rng.shuffle(usable)
    pairs, truth = [], []
    for k, i in enumerate(usable[:n_corner]):
        pairs.append(Pair(None, tuple(P[i]), tuple(uv[i] + rng.normal(0, CORNER_NOISE_PX, 2)), id=k))
    for k, i in enumerate(usable[n_corner:n_corner + n_edge]):
        angle = float(rng.uniform(0, 180))
        t, n = _unit(angle)
        pixel = uv[i] + rng.normal(0, ACROSS_NOISE_PX) * n + rng.choice([-1, 1]) * rng.uniform(15, 35) * t
        pairs.append(Pair(None, tuple(P[i]), tuple(pixel), id=100 + k, edge_deg=angle))
    return pairs


def test_edge_pairs_recover_the_true_pose_and_the_same_pairs_as_corners_do_not(scene):
    pairs = _edge_scene(scene)
    T_true = scene.T_camera_lidar
    res = calibrate(pairs, None, scene.camera, shared_ratio=0.0)
    assert res.quality.status != "unreliable" and not res.outliers
    angle, dt = _pose_errors(res.T_camera_lidar, T_true)
    # Tolerance from the noise: the solve's own 1-sigma (from its residuals, Student-t, no shared part: the
    # simulated clicks are independent), 4 sigma per axis.  With 0.5 px of noise on this 640x480 fisheye of a
    # small room the sigmas are 2-7 mm and 0.02-0.1 deg.
    assert np.all(np.abs(dt) < 4 * res.sigma_translation_m), (dt, res.sigma_translation_m)
    assert angle < 4 * float(np.linalg.norm(res.sigma_rpy_deg))

    # The reported pixel error of an edge pair is across its edge, computed here independently.
    T = res.T_camera_lidar
    pts = np.array([p.laser_xyz for p in pairs])
    proj = np.asarray(scene.camera.project(pts @ T[:3, :3].T + T[:3, 3])[0])
    for i, p in enumerate(pairs):
        d = proj[i] - np.array(p.pixel)
        want = np.linalg.norm(d) if p.edge_deg is None else abs(d @ _unit(p.edge_deg)[1])
        assert res.residual_px[i] == pytest.approx(want, abs=1e-6)
    assert res.mean_px < 2.0  # across: the 15-35 px along the edges are no error
    loo = res.quality.leave_one_out
    assert loo is not None and np.nanmax(loo.loo_px) < 5.0

    # The same pairs solved as corner pairs: the slid pixels pull the pose away (all pairs kept), or the robust
    # solve drops every edge pair as an outlier.
    plain = [dataclasses.replace(p, edge_deg=None) for p in pairs]
    forced = calibrate(plain, None, scene.camera, shared_ratio=0.0, robust=False)
    angle_p, dt_p = _pose_errors(forced.T_camera_lidar, T_true)
    assert np.linalg.norm(dt_p) > 3 * max(np.linalg.norm(dt), 0.01) and angle_p > 3 * max(angle, 0.1)
    robust = calibrate(plain, None, scene.camera, shared_ratio=0.0)
    assert set(range(6, 14)) <= set(robust.outliers) or robust.quality.status == "unreliable"


def test_a_check_edge_pair_reports_its_across_edge_error(scene):
    pairs = _edge_scene(scene, seed=2)
    pairs[-1] = dataclasses.replace(pairs[-1], check=True)
    res = calibrate(pairs, None, scene.camera, shared_ratio=0.0)
    T = res.T_camera_lidar
    p = pairs[-1]
    d = np.asarray(scene.camera.project(np.array([p.laser_xyz]) @ T[:3, :3].T + T[:3, 3])[0])[0] - np.array(p.pixel)
    assert res.check_residual_px[0] == pytest.approx(abs(d @ _unit(p.edge_deg)[1]), abs=1e-6)
    assert abs(d @ _unit(p.edge_deg)[0]) > 10  # the along-edge part, not counted


def test_the_multi_shot_solve_takes_edge_pairs_as_calibrate_does(scene):
    pairs = _edge_scene(scene, seed=3)
    one = calibrate(pairs, None, scene.camera)
    shots = solve_shots([Shot.from_pairs(pairs, None, scene.camera)], scene.camera)
    np.testing.assert_allclose(shots.result.T_camera_lidar, one.T_camera_lidar, atol=1e-9)
    np.testing.assert_allclose(shots.result.residual_px, one.residual_px, atol=1e-9)
    assert shots.shots[0].mean_px == pytest.approx(one.mean_px, abs=1e-9)


def test_edge_pairs_need_four_corner_pairs_unless_a_start_is_given(scene):
    pairs = _edge_scene(scene, seed=4, n_corner=3, n_edge=9)
    with pytest.raises(CalibError, match="edge pairs need at least 4 corner pairs"):
        calibrate(pairs, None, scene.camera)
    T0 = scene.T_camera_lidar.copy()
    T0[:3, 3] += [0.02, -0.01, 0.015]
    res = calibrate(pairs, None, scene.camera, shared_ratio=0.0, initial_T_camera_lidar=T0)
    angle, dt = _pose_errors(res.T_camera_lidar, scene.T_camera_lidar)
    assert np.all(np.abs(dt) < 4 * res.sigma_translation_m) and angle < 4 * float(np.linalg.norm(res.sigma_rpy_deg))
    pts = np.array([p.laser_xyz for p in pairs])
    with pytest.raises(CalibError, match="cost='angular'"):
        solve_extrinsics(pts, scene.camera.bearing(np.array([p.pixel for p in pairs])), camera=scene.camera,
                         cost="pixel", pixels=np.array([p.pixel for p in pairs]),
                         pixel_edge_deg=[np.nan if p.edge_deg is None else p.edge_deg for p in pairs])


# ----------------------------------------------------------------------------------------------------------------
# files
# ----------------------------------------------------------------------------------------------------------------


def test_pairs_yaml_round_trip_with_edge_deg(tmp_path):
    pairs = [Pair((3, 4), None, (10.5, 20.25), id=1), Pair(None, (1.0, 2.0, 3.0), (5.0, 6.0), id=2, edge_deg=30.0),
             Pair((5, 6), None, (7.0, 8.0), id=3, edge_deg=0.0, precision_px=0.5, check=True)]
    path = tmp_path / "pairs.yaml"
    save_pairs_yaml(path, pairs)
    assert load_pairs_yaml(path) == pairs
    text = path.read_text()
    assert text.count("edge_deg") == 2  # written only where set: a corner pair's entry is as before
    assert "edge_deg" not in str(pairs[0].to_dict())
    assert tag_fields("clicked", None, False) == {}
    assert tag_fields("clicked", None, False, edge_deg=200.0) == {"edge_deg": 20.0}
    # An angle outside [0, 180) names the same line.
    path.write_text("pairs:\n  - {laser_rc: [1, 2], pixel: [3, 4], edge_deg: -30}\n")
    assert load_pairs_yaml(path)[0].edge_deg == 150.0


@pytest.mark.parametrize("bad", [".nan", ".inf", "'steep'", "true", "[1, 2]"])
def test_a_bad_edge_deg_is_one_clear_line_naming_the_pair(tmp_path, bad):
    path = tmp_path / "pairs.yaml"
    path.write_text("pairs:\n  - {laser_rc: [1, 2], pixel: [3, 4]}\n"
                    f"  - {{laser_rc: [1, 3], pixel: [3, 5], id: 9, edge_deg: {bad}}}\n")
    with pytest.raises(CalibError) as err:
        load_pairs_yaml(path)
    message = str(err.value)
    assert "\n" not in message and "pair 1" in message and "id 9" in message and "edge_deg" in message


def test_a_pair_object_with_a_bad_edge_deg_is_refused_by_the_solve(scene):
    pairs = _edge_scene(scene, seed=5)
    pairs[7] = dataclasses.replace(pairs[7], edge_deg=math.inf)
    with pytest.raises(CalibError, match=f"pair {pairs[7].id}: edge_deg"):
        calibrate(pairs, None, scene.camera)


def test_the_session_file_accepts_edge_deg_and_refuses_a_bad_one():
    doc = {"format": "ba-calib-session", "version": 1,
           "pairs": [{"id": 1, "laser_rc": [1, 2], "pixel": [3.0, 4.0], "edge_deg": 45.0}]}
    assert len(parse_session(doc, "s.yaml").picks) == 1
    doc["pairs"][0]["edge_deg"] = float("nan")
    with pytest.raises(CalibError, match="pair 0 edge_deg"):
        parse_session(doc, "s.yaml")


def test_edge_pairs_on_cells_take_the_laser_pick_term(scene):
    """Cells of the scan (the whole-cell pick covariance enters the whitening, re-whitened in the LM): the sample's
    10 clicked corner pairs plus 10 edge pairs on random cells, their pixels 15-35 px along a known direction."""
    corners = load_pairs_yaml(SAMPLE / "pairs.yaml")
    T = scene.T_camera_lidar
    depth = scene.depth
    rng = np.random.default_rng(7)
    rows, cols = np.nonzero(np.asarray(depth.valid))
    P = np.asarray(depth.points)[rows, cols]
    uv, ok = scene.camera.project(P @ T[:3, :3].T + T[:3, 3])
    uv, ok = np.asarray(uv), np.asarray(ok, bool)
    usable = np.flatnonzero(ok & (np.hypot(uv[:, 0] - 320, uv[:, 1] - 240) < 180))
    edges = []
    for k, i in enumerate(rng.choice(usable, 10, replace=False)):
        angle = float(rng.uniform(0, 180))
        t, n = _unit(angle)
        pixel = uv[i] + rng.normal(0, 0.5) * n + rng.choice([-1, 1]) * rng.uniform(15, 35) * t
        edges.append(Pair((int(rows[i]), int(cols[i])), None, tuple(pixel), edge_deg=angle))
    res = calibrate(corners + edges, depth, scene.camera, shared_ratio=0.0)
    assert not res.outliers and res.quality.status != "unreliable"
    angle_err, dt = _pose_errors(res.T_camera_lidar, T)
    assert np.all(np.abs(dt) < 4 * res.sigma_translation_m), (dt, res.sigma_translation_m)
    assert angle_err < 4 * float(np.linalg.norm(res.sigma_rpy_deg))
    assert np.all(res.residual_px[len(corners):] < 4.0)  # across the edge: the along offsets are no error
    plain = calibrate(corners + [dataclasses.replace(p, edge_deg=None) for p in edges], depth, scene.camera,
                      shared_ratio=0.0, robust=False)
    assert np.linalg.norm(_pose_errors(plain.T_camera_lidar, T)[1]) > 3 * max(np.linalg.norm(dt), 0.01)


def test_the_guides_pose_covariance_counts_an_edge_pair_only_across_its_edge(scene):
    """Guided picking's pose state (``pose_state_of_fit``): an edge pair informs less than the same pair as a
    corner and more than no pair (Loewner order of the covariances), and moving its pixel along its edge changes
    nothing (the residual variance factor stays 1), while moving a corner's does."""
    from calib_core.guide.pose_state import pose_state_of_fit
    from calib_core.transforms import transform_points

    rng = np.random.default_rng(21)
    idx = rng.choice(len(scene.corners_lidar), 8, replace=False)
    points = np.asarray(scene.corners_lidar, np.float64)[idx]
    uv, ok = scene.camera.project(transform_points(scene.T_camera_lidar, points))
    assert np.all(ok)
    pixels = np.asarray(uv, np.float64)
    T, sig, laser = scene.T_camera_lidar, np.ones(8), np.zeros((8, 3, 3))
    edges = np.full(8, np.nan)
    edges[5:] = [0.0, 60.0, 120.0]

    def cov(px, e, keep=slice(None)):
        state = pose_state_of_fit(scene.camera, T, points[keep], px[keep], sig[keep], laser[keep], "test",
                                  edge_deg=None if e is None else e[keep])
        return state.covariance, state.variance_factor

    corners, f0 = cov(pixels, None)
    with_edges, f1 = cov(pixels, edges)
    without, _ = cov(pixels, None, slice(0, 5))
    assert f0 == f1 == 1.0
    assert np.linalg.eigvalsh(with_edges - corners).min() > -1e-12 and np.trace(with_edges) > 1.01 * np.trace(corners)
    assert np.linalg.eigvalsh(without - with_edges).min() > -1e-12
    a = np.radians(edges[5:])
    slid = pixels.copy()
    slid[5:] += 30.0 * np.stack([np.cos(a), np.sin(a)], axis=1)
    moved, f2 = cov(slid, edges)
    assert f2 == 1.0 and np.allclose(moved, with_edges)
    _, f3 = cov(slid, None)
    assert f3 > 10.0


def test_an_edge_pairs_laser_end_has_no_row_offset(scene):
    """The laser end of an edge pair is the measured point where its ring crosses the photo's line: only which
    cell along the ring (the column) is a guess, plus the range; a corner's cell also guesses the row.  Hand-built
    from the depth matrix's directions (central differences) and ranges."""
    from calib_core.solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M, pairs_pick_covariance

    depth = scene.depth
    valid = np.argwhere(np.asarray(depth.valid))
    r, c = (int(x) for x in valid[len(valid) // 2])
    corner = Pair((r, c), None, (10.0, 10.0))
    edge = dataclasses.replace(corner, edge_deg=35.0)
    xyz = Pair(None, (3.0, 0.5, 0.2), (12.0, 10.0), edge_deg=35.0)
    cov = pairs_pick_covariance([corner, edge, xyz], depth)
    dirs, rho = np.asarray(depth.directions, np.float64), float(depth.range_m[r, c])
    W = depth.shape[1]
    g_row = (dirs[r + 1, c] - dirs[r - 1, c]) / 2
    g_col = (dirs[r, (c + 1) % W] - dirs[r, (c - 1) % W]) / 2
    beam = dirs[r, c]
    s_row, s_col = PICK_CELL_SIGMA
    along = PICK_RANGE_SIGMA_M**2 * np.outer(beam, beam)
    assert np.allclose(cov[0], rho**2 * (s_row**2 * np.outer(g_row, g_row) + s_col**2 * np.outer(g_col, g_col)) + along)
    assert np.allclose(cov[1], rho**2 * s_col**2 * np.outer(g_col, g_col) + along)
    assert np.all(cov[2] == 0)
    assert pairs_pick_covariance([xyz], depth) is None
