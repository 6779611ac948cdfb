"""Guided picking across shots in the app (issue 21): proposals ranked over every shot (the same ranking as
``ba-calib propose --shot``: :func:`calib_core.shots.propose_shots`), the page switching to the next proposal's
shot by itself and the guided session going on there, and guided picking offered when the shown shot has
fewer than 4 pairs but all shots together have 4.

Truth: :func:`calib_core.shots.propose_shots` called here on the same pairs, and the ground truth of the
synthetic rig (the sample and room 1 seen with the sample's ``T_camera_lidar``): the simulated person clicks
each proposed laser point's true projection plus 0.3 px noise.
"""

from __future__ import annotations

import dataclasses
import queue

import numpy as np
import pytest
from app_driver import AppDriver
from shots_helpers import sample_shot_server

from calib_core.io.images import load_image_rgb
from calib_core.shots import Shot, propose_shots
from calib_core.synthetic import simulate_pairs
from calib_core.transforms import rotation_angle_deg, transform_points
from repo_paths import SAMPLE

CLICK_SIGMA_PX = 0.3


@pytest.fixture(scope="module")
def two_shots(second_shot):
    return second_shot  # shots_helpers.write_second_shot, made once per test process (tests/conftest.py)


def _true_click(camera, truth, proposal, rng) -> np.ndarray:
    pix, ok = camera.project(transform_points(truth, np.asarray(proposal.laser_xyz, dtype=float)[None]))
    assert ok[0]
    return np.asarray(pix[0], dtype=float) + rng.normal(0.0, CLICK_SIGMA_PX, 2)


def test_guided_picking_ranks_across_shots_and_switches_shot_by_itself(tmp_path, two_shots):
    s0, s1, scan1, image1 = two_shots
    truth = s0.T_camera_lidar
    server = sample_shot_server(tmp_path / "session.yaml", (scan1, image1))
    rng = np.random.default_rng(4)
    pairs0, pairs1 = simulate_pairs(s0, 5, rng), simulate_pairs(s1, 2, rng)
    try:
        server.state.import_pairs(pairs0)
        server.state.set_active_shot(1)
        server.state.import_pairs(pairs1)
        app = server.load(1)  # the shown shot has 2 pairs; all shots together have 7
        d = AppDriver(app)
        assert d.wait_idle() and len(app.state.complete_picks()) == 2
        assert d.press_guide("Next pair") == [] and d.wait_guide()
        assert app.guide.proposals, app.guide.text
        # The ranking is propose_shots' on the same pairs (same screen), over both shots.
        ids = [[p.id for p in app.state.all_picks if p.shot == k] for k in (0, 1)]
        shots = [Shot.from_pairs([dataclasses.replace(p, id=i) for p, i in zip(pairs, ids[k])], s.depth, s.camera)
                 for k, (pairs, s) in enumerate(((pairs0, s0), (pairs1, s1)))]
        images = {0: load_image_rgb(SAMPLE / "image.png"), 1: load_image_rgb(image1)}
        here, _ = propose_shots(shots, s0.camera, 20, images=images,
                                shot_options={k: {"screen": app.guide.screen} for k in (0, 1)})
        shown = [(k, tuple(p.laser_rc)) for k, p in zip(app.guide._prop_shots, app.guide.proposals)]
        assert shown == [(sp.shot, tuple(sp.proposal.laser_rc)) for sp in here][:len(shown)]
        assert {k for k, _ in shown} == {0, 1}, "proposals from one shot only"

        switches, picked = 0, {0: 0, 1: 0}
        for _ in range(8):
            try:
                k = server.requests.get(timeout=0.5)  # the guided session asked for another shot
            except queue.Empty:
                k = None
            if k is not None:
                assert app.guide.text.count("Next proposal is in shot") == 1
                switches += 1
                app = server.load(k)
                d = AppDriver(app)
                assert d.wait_guide() and d.wait_idle()
            p = d.guide_proposal
            assert p is not None, app.guide.text
            assert app.guide.shot_of(p) == app.active_shot  # a shown proposal is always in the shown shot
            if p.replaces is not None:
                assert d.press_guide("Skip") == [] and d.wait_guide()
                continue
            half = app.state.pending()
            assert half is not None and half.source == "guided" and half.laser_rc == tuple(p.laser_rc)
            assert d.click_loupe_camera(*_true_click(app.camera, truth, p, rng)) == [] and d.wait_guide()
            assert app.state.get(half.id).complete
            picked[app.active_shot] += 1
        assert switches >= 1 and picked[0] and picked[1], (switches, picked)
        assert d.wait_idle()
        T = app.result.T_camera_lidar
        print(f"\n{switches} switches, guided pairs per shot {picked}: "
              f"{rotation_angle_deg(T[:3, :3], truth[:3, :3]):.3f} deg from the truth")
    finally:
        server.stop()


def test_auto_accept_is_refused_across_shots_with_one_line(tmp_path, two_shots):
    _, _, scan1, image1 = two_shots
    server = sample_shot_server(tmp_path / "session.yaml", (scan1, image1))
    try:
        app = server.load(0)
        d = AppDriver(app)
        notes = d.set_auto_accept(True)
        assert len(notes) == 1 and "several shots" in " ".join(notes[0]), notes
        assert app.guide._auto is False
    finally:
        server.stop()
