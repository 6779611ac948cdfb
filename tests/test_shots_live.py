"""The live joint solve of several shots (issue 21, speed): the joint fit is shown first, the shots' checks
(leave-one-shot-out, the disagreeing-shot test) follow in the solver's next job, and the status is never
``ok`` before they ran.

Truth: :func:`calib_core.shots.solve_shots` with its checks, called here on the same pairs, and the ground
truth of the synthetic rig (the sample and room 1 seen with the sample's ``T_camera_lidar``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from shots_helpers import sample_shot_server

from calib_core.shots import UNCHECKED_REASON, Shot, solve_shots
from calib_core.synthetic import simulate_pairs
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def two_shots(second_shot):
    return second_shot  # shots_helpers.write_second_shot, made once per test process (tests/conftest.py)


def _shots(two_shots, n=6, seed=0):
    s0, s1, _, _ = two_shots
    rng = np.random.default_rng(seed)
    return [Shot.from_pairs(simulate_pairs(s, n, rng), s.depth, s.camera, name=f"shot {k}")
            for k, s in enumerate((s0, s1))]


def test_the_joint_fit_without_checks_is_the_checked_fit_and_never_ok(two_shots):
    shots = _shots(two_shots)
    camera = two_shots[0].camera
    full = solve_shots(shots, camera)
    fast = solve_shots(shots, camera, checks=False)
    assert full.checked and not fast.checked
    assert full.result.quality.status == "ok" and not full.disagreeing  # clean shots: the checks find nothing
    # No shot left out: the same fit to the last bit, the same per-shot errors.
    np.testing.assert_array_equal(fast.result.T_camera_lidar, full.result.T_camera_lidar)
    assert [r.mean_px for r in fast.shots] == [r.mean_px for r in full.shots]
    # ... but nothing checked, and said so: never "ok".
    assert fast.leave_one_shot_out == [] and fast.tests == [] and len(full.leave_one_shot_out) == 2
    assert fast.result.quality.status == "warning" and UNCHECKED_REASON in fast.result.quality.reasons
    assert UNCHECKED_REASON not in full.result.quality.reasons
    # One shot has nothing to check: the same as with checks.
    one = solve_shots(shots[:1], camera, checks=False)
    assert one.checked and one.result.quality.status == solve_shots(shots[:1], camera).result.quality.status


def test_the_app_shows_the_joint_fit_then_the_checked_one(tmp_path, two_shots):
    s0, s1, scan1, image1 = two_shots
    server = sample_shot_server(tmp_path / "session.yaml", (scan1, image1))
    rng = np.random.default_rng(3)
    pairs0, pairs1 = simulate_pairs(s0, 6, rng), simulate_pairs(s1, 6, rng)
    try:
        server.state.import_pairs(pairs0)
        app = server.load(1)
        assert app.wait_idle(120)
        shown = []
        original = app.calibration_panel.show
        app.calibration_panel.show = lambda bundle, *a, **k: (shown.append(bundle), original(bundle, *a, **k))[1]
        app.state.import_pairs(pairs1)
        assert app.wait_idle(120)
        solved = [b for b in shown if b is not None]
        firsts = [b for b in solved if not b.shots.solved.checked]
        assert firsts, "the joint fit alone was never shown"
        assert all(b.result.quality.status != "ok" for b in firsts)
        text = [app.calibration_panel.md_result.content]
        last = app.solve_bundle
        assert last is solved[-1] and last.shots.solved.checked and len(last.shots.solved.leave_one_shot_out) == 2
        assert UNCHECKED_REASON not in " ".join(text)
        # The checked result is solve_shots of the same pairs, with its checks.
        ids = [[p.id for p in app.state.all_picks if p.shot == k] for k in (0, 1)]
        here = solve_shots([Shot.from_pairs([dataclasses.replace(p, id=i) for p, i in zip(pairs, ids[k])], s.depth,
                                            s.camera) for k, (pairs, s) in enumerate(((pairs0, s0), (pairs1, s1)))],
                           s0.camera)
        np.testing.assert_allclose(last.result.T_camera_lidar, here.result.T_camera_lidar, rtol=0, atol=1e-12)
        assert last.result.quality.status == here.result.quality.status
        for mine, theirs in zip(last.shots.solved.leave_one_shot_out, here.leave_one_shot_out):
            assert mine.mean_px == pytest.approx(theirs.mean_px, rel=1e-9)
        # The first showing is what is timed; the checks' showing is timed apart, later.
        assert app.live.last_checks_shown() >= app.live.last_click_to_update() > 0
    finally:
        server.stop()


def test_the_3d_pane_labels_every_pair_with_its_shot(tmp_path, two_shots):
    """Every shot's pairs are marked in the 3-D pane at their laser point (the cell's point in that shot's
    scan, lidar frame), labelled ``S<shot>·<id>``; a pair of fewer than 4 (no solve yet) too."""
    from calib_core.io.scan_readers import load_scan

    s0, s1, scan1, image1 = two_shots
    server = sample_shot_server(tmp_path / "session.yaml", (scan1, image1))
    rng = np.random.default_rng(8)
    scans = [load_scan(SAMPLE / "scan.npz"), load_scan(scan1)]
    try:
        server.state.import_pairs(simulate_pairs(s0, 2, rng))
        app = server.load(1)
        assert app.wait_idle(120)
        assert app.live.bundle is None  # 2 pairs: no solve, but marked
        want = {f"S0\u00b7{p.id}": scans[0].points[p.laser_rc] for p in app.state.all_picks}
        assert set(app.cloud.pair_labels) == set(want)
        app.state.import_pairs(simulate_pairs(s1, 3, rng))
        assert app.wait_idle(120) and app.live.bundle is not None
        want = {f"S{p.shot}\u00b7{p.id}": scans[p.shot].points[p.laser_rc] for p in app.state.all_picks}
        labels = app.cloud.pair_labels
        assert set(labels) == set(want) and len(want) == 5
        for text, xyz in want.items():
            np.testing.assert_allclose(labels[text], xyz, atol=1e-6)
        app.state.undo()  # shot 1's three pairs go: so do their marks
        assert app.wait_idle(120) and set(app.cloud.pair_labels) == {t for t in want if t.startswith("S0")}
    finally:
        server.stop()


def test_the_rough_pose_is_kept_when_switching_shots_before_any_solve(tmp_path, two_shots):
    s0, _, scan1, image1 = two_shots
    server = sample_shot_server(tmp_path / "session.yaml", (scan1, image1))
    try:
        app = server.load(0)
        server.state.import_pairs(simulate_pairs(s0, 1, np.random.default_rng(2)))  # one pair: no solve
        rough = s0.T_camera_lidar.copy()
        rough[:3, 3] += 0.05
        app.align.adopt(rough)  # as Align's buttons do
        assert app.wait_idle(60)
        app = server.load(1)
        assert app.wait_idle(60) and app.live.bundle is None
        T, source = app.pose_source.view_pose()
        assert source == "rough"
        np.testing.assert_array_equal(T, rough)
        app = server.load(0)
        assert app.wait_idle(60)
        np.testing.assert_array_equal(app.pose_source.view_pose()[0], rough)
    finally:
        server.stop()
