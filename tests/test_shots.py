"""Several shots, one calibration (issue 21): the joint solve, leave-one-shot-out, the disagreeing shot,
proposals across shots, and the two PJLab road scenes of one rig.

Truth: the synthetic generator's ground truth (the sample's ``T_camera_lidar`` shared by the rooms of
seeds 0 and 1, one rig); independent solves of the concatenated pairs made here with
``solve_extrinsics``; and the published calibration of the PJLab two-scene data (read here from its
``calib.txt``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.shots import Shot, propose_shots, solve_shots
from calib_core.solve import calibrate, solve_extrinsics
from calib_core.synthetic import load_sample, make_sample_scene, simulate_pairs
from calib_core.synthetic.picks import CIRCLE_MARGIN_PX, MAX_LASER_PICK_ERROR_M, laser_picks
from calib_core.synthetic.render import image_circle_mask
from calib_core.synthetic.sample import IMAGE_CIRCLE_RADIUS_PX
from calib_core.transforms import rotation_angle_deg, transform_points
from repo_paths import REPO, SAMPLE

TWO_SCENES = REPO.parent / "shared" / "data" / "pjlab_opencalib_two_scenes"


# ----------------------------------------------------------------------------- one rig, two rooms


def _on_rig(scene, T_rig):
    """The scene seen with the rig's pose: corners the rig's camera sees inside its image circle."""
    scene = dataclasses.replace(scene, T_camera_lidar=T_rig.copy())
    corners = np.asarray(scene.corners_lidar, dtype=np.float64)
    pix, ok = scene.camera.project(transform_points(T_rig, corners))
    ok &= np.all(np.isfinite(pix), axis=1)
    ok[ok] &= image_circle_mask(scene.camera, pix[ok], IMAGE_CIRCLE_RADIUS_PX - CIRCLE_MARGIN_PX)
    ok &= laser_picks(scene.depth, corners)[1] <= MAX_LASER_PICK_ERROR_M
    return dataclasses.replace(scene, corners_lidar=corners[ok])


@pytest.fixture(scope="module")
def rooms():
    """Room 0 (the committed sample) and room 1 (seed 1), both seen by the sample's rig."""
    sample = load_sample(SAMPLE)
    return [_on_rig(sample, sample.T_camera_lidar), _on_rig(make_sample_scene(1), sample.T_camera_lidar)]


def _half(scene, part):
    """The scene's corners whose picked cell has an even (part 0) or odd (part 1) column: two shots of one
    room that share no laser cell."""
    rc, _ = laser_picks(scene.depth, scene.corners_lidar)
    return dataclasses.replace(scene, corners_lidar=scene.corners_lidar[rc[:, 1] % 2 == part])


def _up(scene) -> np.ndarray:
    """The room's vertical axis in the lidar frame."""
    return np.linalg.inv(scene.T_world_lidar[:3, :3]) @ np.array([0.0, 0.0, 1.0])


def _rotation(axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def _shot(scene, n, rng, rotate_deg=0.0, name=""):
    pairs = simulate_pairs(scene, n, rng)
    shot = Shot.from_pairs(pairs, scene.depth, scene.camera, name=name)
    if rotate_deg:  # the scan taken while the rig had turned: its points turned about the vertical
        R = _rotation(_up(scene), rotate_deg)
        shot.points_lidar = shot.points_lidar @ R.T
        shot.laser_cov_m2 = R @ shot.laser_cov_m2 @ R.T
    return shot


def _errors(T, T_true):
    return rotation_angle_deg(T[:3, :3], T_true[:3, :3]), float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


# ----------------------------------------------------------------------------- one shot


def _assert_same_result(a, b, tol=1e-12):
    for key in ("T_camera_lidar", "covariance_6x6", "sigma_translation_m", "sigma_rpy_deg", "residual_deg"):
        np.testing.assert_allclose(getattr(a, key), getattr(b, key), rtol=0, atol=tol, err_msg=key)
    np.testing.assert_allclose(a.residual_px, b.residual_px, rtol=0, atol=tol, equal_nan=True)
    np.testing.assert_allclose(a.check_residual_px, b.check_residual_px, rtol=0, atol=tol, equal_nan=True)
    np.testing.assert_allclose(a.check_residual_deg, b.check_residual_deg, rtol=0, atol=tol)
    assert a.outliers == b.outliers and a.outlier_ids == b.outlier_ids
    assert a.quality == b.quality and a.warnings == b.warnings
    assert a.pair_positions == b.pair_positions and a.check_positions == b.check_positions
    assert a.check_ids == b.check_ids


def test_one_shot_equals_the_one_shot_solve():
    sample = load_sample(SAMPLE)
    from calib_core.pairs import load_pairs_yaml

    pairs = load_pairs_yaml(SAMPLE / "pairs.yaml")
    for variant in ("plain", "tagged"):
        if variant == "tagged":  # ids, precisions, a check pair, a laser_xyz pair and a gross outlier
            p = [dataclasses.replace(q, id=10 + i, precision_px=0.5 + 0.1 * i) for i, q in enumerate(pairs)]
            p[2] = dataclasses.replace(p[2], check=True)
            xyz = sample.depth.points[p[3].laser_rc[0], p[3].laser_rc[1]]
            p[3] = dataclasses.replace(p[3], laser_rc=None, laser_xyz=tuple(float(v) for v in xyz))
            p[5] = dataclasses.replace(p[5], pixel=(p[5].pixel[0] + 40.0, p[5].pixel[1] - 30.0))
        else:
            p = pairs
        one = calibrate(p, sample.depth, sample.camera)
        joint = solve_shots([Shot.from_pairs(p, sample.depth, sample.camera)], sample.camera)
        _assert_same_result(joint.result, one)
        assert joint.leave_one_shot_out == [] and joint.disagreeing == []
        if variant == "tagged":
            assert one.outlier_ids == [15]  # the robust path ran in both
            assert joint.shots[0].outliers == [5]


def test_too_few_pairs_in_all_is_one_clear_error(rooms):
    rng = np.random.default_rng(1)
    shots = [_shot(rooms[0], 2, rng), _shot(rooms[1], 1, rng)]
    with pytest.raises(CalibError, match="3 fit pairs in all"):
        solve_shots(shots, rooms[0].camera)
    with pytest.raises(CalibError, match="no shots"):
        solve_shots([], rooms[0].camera)


# ----------------------------------------------------------------------------- two shots, the truth


def test_two_shots_solve_to_the_truth_as_one_concatenated_solve(rooms):
    rng = np.random.default_rng(11)
    T_true = rooms[0].T_camera_lidar
    cam = rooms[0].camera
    shots = [_shot(rooms[0], 12, rng), _shot(rooms[1], 12, rng)]
    joint = solve_shots(shots, cam)
    res = joint.result
    rot, trans = _errors(res.T_camera_lidar, T_true)
    print(f"two shots x 12 pairs: rotation error {rot:.3f} deg, translation error {100 * trans:.2f} cm; "
          f"sigma rpy {np.round(res.sigma_rpy_deg, 3)} deg, t {np.round(100 * res.sigma_translation_m, 2)} cm")
    assert rot <= 0.5 and trans <= 0.03
    assert res.quality.status == "ok" and joint.disagreeing == [] and joint.undecided == []
    # Independent: the same pairs stacked by hand, each shot's points in its own lidar frame.
    by_hand = solve_extrinsics(
        np.concatenate([s.points_lidar for s in shots]), np.concatenate([s.bearings for s in shots]),
        camera=cam, pixels=np.concatenate([s.pixels for s in shots]),
        laser_cov_m2=np.concatenate([s.laser_cov_m2 for s in shots]))
    np.testing.assert_allclose(res.T_camera_lidar, by_hand.T_camera_lidar, atol=1e-12)
    np.testing.assert_allclose(res.covariance_6x6, by_hand.covariance_6x6, atol=1e-12)
    # Rows are named by position in all shots' pairs; each shot's report uses its own rows.
    assert res.pair_positions == list(range(24))
    assert joint.row_shot.tolist() == [0] * 12 + [1] * 12
    for k, rep in enumerate(joint.shots):
        assert rep.n_pairs == rep.n_fit == 12 and rep.in_fit
        np.testing.assert_allclose(rep.mean_px, np.nanmean(res.residual_px[12 * k:12 * (k + 1)]), atol=1e-12)


def test_leave_one_shot_out_fits_the_other_shots_and_reports(rooms):
    rng = np.random.default_rng(12)
    cam = rooms[0].camera
    T_true = rooms[0].T_camera_lidar
    shots = [_shot(rooms[0], 10, rng), _shot(rooms[1], 10, rng), _shot(rooms[1], 10, rng)]
    shots[2] = _shot(_half(rooms[1], 1), 10, rng)
    shots[1] = _shot(_half(rooms[1], 0), 10, rng)
    joint = solve_shots(shots, cam)
    assert [e.shot for e in joint.leave_one_shot_out] == [0, 1, 2]
    for e in joint.leave_one_shot_out:
        others = [s for j, s in enumerate(shots) if j != e.shot]
        alone = solve_extrinsics(np.concatenate([s.points_lidar for s in others]),
                                 np.concatenate([s.bearings for s in others]), camera=cam,
                                 pixels=np.concatenate([s.pixels for s in others]),
                                 laser_cov_m2=np.concatenate([s.laser_cov_m2 for s in others]))
        rot = rotation_angle_deg(e.T_camera_lidar[:3, :3], alone.T_camera_lidar[:3, :3])
        assert rot < 1e-6 and np.allclose(e.T_camera_lidar[:3, 3], alone.T_camera_lidar[:3, 3], atol=1e-8)
        # Its errors, computed here by projecting the held-out shot's points.
        s = shots[e.shot]
        uv, _ = cam.project(transform_points(e.T_camera_lidar, s.points_lidar))
        np.testing.assert_allclose(e.mean_px, np.linalg.norm(uv - s.pixels, axis=1).mean(), atol=1e-9)
        assert 0.3 < e.mean_px < 4.0 and 0.1 < e.mean_deg < 2.0
        assert _errors(e.T_camera_lidar, T_true)[0] < 1.0
    with pytest.raises(CalibError, match="shot 0 pair 0 and shot 1 pair 0 use the same laser point"):
        solve_shots([shots[0], shots[0]], cam)


# ----------------------------------------------------------------------------- the disagreeing shot


def test_a_rotated_shot_is_named_and_left_out(rooms):
    rng = np.random.default_rng(13)
    cam = rooms[0].camera
    T_true = rooms[0].T_camera_lidar
    shots = [_shot(_half(rooms[0], 0), 20, rng), _shot(rooms[1], 20, rng, rotate_deg=2.0),
             _shot(_half(rooms[0], 1), 20, rng)]
    joint = solve_shots(shots, cam)
    assert joint.disagreeing == [1]
    res = joint.result
    assert res.quality.status != "ok"
    reason = res.quality.reasons[0]
    assert reason.startswith("shot 1 disagrees with the others by ") and "not taken at the same instant" in reason
    named = {t.shot: t for t in joint.tests}[1]
    print(f"rotated 2 deg: named with estimated rotation {named.rotation_deg:.2f} deg, p = {named.p_value:.1e}")
    assert 1.5 < named.rotation_deg < 2.5
    # Left out of the fit: the result is the solve of shots 0 and 2 alone.
    kept = solve_shots([shots[0], shots[2]], cam, detect=False).result
    np.testing.assert_allclose(res.T_camera_lidar, kept.T_camera_lidar, atol=1e-12)
    assert not joint.shots[1].in_fit and joint.row_shot.tolist() == [0] * 20 + [2] * 20
    assert _errors(res.T_camera_lidar, T_true)[0] < 0.5
    # Without the test, the rotated shot pulls the pose.
    assert _errors(solve_shots(shots, cam, detect=False).result.T_camera_lidar, T_true)[0] > _errors(
        res.T_camera_lidar, T_true)[0]


def test_clean_shots_and_a_stray_click_are_not_named(rooms):
    cam = rooms[0].camera
    named = 0
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        shots = [_shot(rooms[0], 10, rng), _shot(_half(rooms[1], 0), 10, rng), _shot(_half(rooms[1], 1), 10, rng)]
        if seed == 0:  # one pair of shot 2 clicked 25 px off: a pair outlier, not a disagreeing shot
            shots[2].pixels[4] += [25.0, -10.0]
            shots[2].bearings[4] = cam.bearing(shots[2].pixels[4:5])[0]
        joint = solve_shots(shots, cam)
        named += bool(joint.disagreeing or joint.undecided)
        if seed == 0:
            assert joint.disagreeing == [] and joint.shots[2].outliers == [4]
    assert named == 0


def test_two_shots_that_disagree_are_both_named_unreliable(rooms):
    rng = np.random.default_rng(14)
    shots = [_shot(rooms[0], 20, rng), _shot(rooms[1], 20, rng, rotate_deg=3.0)]
    joint = solve_shots(shots, rooms[0].camera)
    assert joint.undecided == [0, 1] and joint.disagreeing == []
    assert joint.result.quality.status == "unreliable"
    assert joint.result.quality.reasons[0].startswith("shots 0 and 1 disagree by ")


# ----------------------------------------------------------------------------- proposals across shots


def test_proposals_across_shots_have_valid_shots_and_calibrated_ellipses(rooms):
    cam = rooms[0].camera
    T_true = rooms[0].T_camera_lidar
    inside = total = 0
    seen = set()
    for seed in (21, 22, 23):
        rng = np.random.default_rng(seed)
        shots = [_shot(rooms[0], 6, rng), _shot(rooms[1], 6, rng)]
        props, state = propose_shots(shots, cam, 15)
        assert len(props) == 15 and state.n_pairs == 12
        gains = [p.proposal.gain for p in props]
        assert all(g > 0 for g in gains)
        for sp in props:
            assert sp.shot in (0, 1)
            seen.add(sp.shot)
            p = sp.proposal
            # The proposed cell exists in that shot's scan, and its point is that cell's.
            np.testing.assert_allclose(p.laser_xyz, shots[sp.shot].depth.points[p.laser_rc], atol=0)
            true_px, _ = cam.project(transform_points(T_true, p.laser_xyz[None]))
            d = true_px[0] - p.pixel
            inside += float(d @ np.linalg.solve(p.pixel_cov, d)) <= 9.0
            total += 1
    print(f"proposals across two shots: {inside} of {total} true projections inside their 3-sigma ellipse")
    assert seen == {0, 1}
    assert inside >= 0.9 * total


# ----------------------------------------------------------------------------- PJLab: two road scenes, one rig


@pytest.mark.realdata
@pytest.mark.skipif(not (TWO_SCENES / "scene1" / "calib.pcd").is_file(), reason=f"no data at {TWO_SCENES}")
def test_pjlab_two_scenes_three_pairs_each_solve_together_not_alone():
    from bench.shots import load_two_scenes, rough_pairs

    scenes, rule = load_two_scenes()
    T_pub = scenes[0][2]
    np.testing.assert_allclose(scenes[1][2], T_pub)  # one rig: one published calibration
    camera = scenes[0][1]
    rot, trans = [], []
    # 3 pairs per scene: the first three of the rule's farthest-point order, pixel = projection with the
    # published T + N(0, 1 px) from default_rng(seed); 40 noise draws.  The target holds for the distribution,
    # not every draw (a single draw with seeds 21 and 22 gave 0.16 deg and 11.5 cm), hence the share asserted.
    for draw in range(40):
        shots = []
        for k, ((depth, cam, _), pairs) in enumerate(zip(scenes, rough_pairs(scenes, rule, draw))):
            if draw == 0:  # neither scene alone can be solved from its three pairs
                with pytest.raises(CalibError, match="at least 4 pairs"):
                    calibrate(pairs, depth, cam)
            shots.append(Shot.from_pairs(pairs, depth, cam, name=f"scene{k + 1}"))
        joint = solve_shots(shots, camera)
        assert joint.result.quality.status != "unreliable"
        r, t = _errors(joint.result.T_camera_lidar, T_pub)
        rot.append(r)
        trans.append(100 * t)
        if draw == 0:  # each held-out scene's 3 pairs cannot determine a pose: said, not hidden
            assert all(e.T_camera_lidar is None and "do not determine" in e.note for e in joint.leave_one_shot_out)
    rot, trans = np.array(rot), np.array(trans)
    within = np.mean((rot <= 0.5) & (trans <= 10.0))
    print(f"PJLab two scenes, 3 + 3 pairs, 40 noise draws: rotation median {np.median(rot):.3f} deg "
          f"(max {rot.max():.3f}), translation median {np.median(trans):.2f} cm (max {trans.max():.2f}); "
          f"within 0.5 deg / 10 cm: {100 * within:.0f} %")
    assert within >= 0.95 and np.median(trans) <= 5.0 and rot.max() <= 0.5
