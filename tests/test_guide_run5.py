"""Guided re-clicks as the by-eye walkthrough run 5 met them (docs/by_eye.md), driven through
:class:`app_driver.AppDriver` on the committed sample.

In run 5 guided picking proposed only re-clicks of existing pairs; "Next pair" and "Cancel pair" then "Next pair"
showed the same re-click again, an accepted re-click selected the next proposal's pair by itself, one Ctrl+Z undid
only the precision the guide gave the click, and the counts said "0 guided" after 3 re-clicks.  A screen no new cell
passes (nothing is within 0.5 m of the lidar on the sample) reproduces the only-re-clicks state, as in
tests/test_app_pair_bar.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.guide.evidence import ProposalScreen
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.synthetic import simulate_pairs
from calib_core.transforms import transform_points

from app_driver import AppDriver
from repo_paths import SAMPLE


def only_reclicks(d: AppDriver, scene) -> None:
    """4 hand pairs, 1 px off their corners per axis; a screen that leaves only re-click proposals."""
    for pair in simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=1.0):
        assert d.click_cell(d.app.ba_keys[0], *pair.laser_rc) == []
        assert d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    d.app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=d.app.guide.screen.max_ellipse_px)


def reclicked_ids(app) -> set[int]:
    """The pairs the shown proposals offer to re-click, read from the proposals' cells and the pairs' cells."""
    by_cell = {p.laser_rc: p.id for p in app.state.picks}
    return {by_cell[tuple(p.laser_rc)] for p in app.guide.proposals if p.replaces is not None}


def test_next_pair_and_cancel_pair_move_on_from_a_reclick(app, scene):
    d = AppDriver(app)
    only_reclicks(d, scene)
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    first = app.state.selected
    assert first is not None and d.guide_proposal.replaces is not None
    assert app.state.get(first).laser_rc == tuple(d.guide_proposal.laser_rc)
    offered = reclicked_ids(app)
    assert first in offered and len(offered) >= 3, offered

    # Next pair while the re-click is started: it is skipped, the next re-click is started (its pair selected).
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    second = app.state.selected
    assert second is not None and second != first
    assert app.state.get(second).laser_rc == tuple(d.guide_proposal.laser_rc)
    assert first not in reclicked_ids(app)
    assert f"Skipped the re-click of pair {first}" in app.pairs_panel.bar.guide_status.replace("\\", "")  # md escapes

    # Cancel pair during a re-click ends its selection and skips it too: Next pair then shows another pair.
    assert d.press_pair_action("Cancel pair") == [] and d.wait_guide() and app.state.selected is None
    assert second not in reclicked_ids(app)
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    third = app.state.selected
    assert third is not None and third not in (first, second)

    # Neither comes back once the proposals are recomputed (a pair changed: the third re-click is made).
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    p = d.guide_proposal
    pix, ok = scene.camera.project(transform_points(truth, np.asarray(p.laser_xyz, dtype=float)[None]))
    assert ok[0] and d.click_loupe_camera(*pix[0]) == [] and d.wait_guide()
    assert np.allclose(app.state.get(third).pixel, pix[0], atol=0.05)
    assert not {first, second, third} & reclicked_ids(app)


def accept_a_reclick(d: AppDriver, scene) -> tuple:
    """Start guided picking on :func:`only_reclicks` and make the first re-click at its corner's true projection
    (the sample's ground truth) in the camera loupe; ``(its pair id, the picks before, the picks after)``."""
    only_reclicks(d, scene)
    app = d.app
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    rid = app.state.selected
    before = app.state.picks
    assert app.state.get(rid).precision_px is None and app.state.get(rid).source == "clicked"
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    pix, ok = scene.camera.project(transform_points(truth, np.asarray(d.guide_proposal.laser_xyz, float)[None]))
    assert ok[0] and d.click_loupe_camera(*pix[0]) == [] and d.wait_guide()
    done = app.state.get(rid)
    assert np.allclose(done.pixel, pix[0], atol=0.05) and done.precision_px == pytest.approx(0.3)
    assert done.source == "clicked"  # a hand pair stays "clicked"
    return rid, before, app.state.picks


def test_an_accepted_reclick_selects_nothing(app, scene):
    """The next proposal is another re-click; its pair is not selected by itself, so a plain click moves no pair
    (run 5: "Pair 4 selected: the next click moves it" right after a re-click).  Next pair selects it."""
    d = AppDriver(app)
    rid, _, after = accept_a_reclick(d, scene)
    p = d.guide_proposal
    assert p is not None and p.replaces is not None and tuple(p.laser_rc) != app.state.get(rid).laser_rc
    assert app.state.selected is None and "(selected)" not in app.pairs_panel.bar.guide_status
    assert "**Next pair** re-clicks pair" in app.pairs_panel.bar.guide_status
    assert d.click_camera(330.0, 250.0) == [] and d.wait_guide()
    assert app.state.picks[:-1] == after and app.state.pending() is not None  # a new pair started, none moved
    assert d.press_pair_action("Cancel pair") == [] and d.wait_guide() and app.state.picks == after
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    assert app.state.selected is not None and app.state.get(app.state.selected).laser_rc == tuple(p.laser_rc)


def test_one_undo_takes_back_a_whole_reclick(app, scene):
    """Pixel, precision and all in one Undo (run 5: the first Ctrl+Z took back only the precision), and the guide
    adds nothing after it; one Redo brings it back whole."""
    d = AppDriver(app)
    rid, before, after = accept_a_reclick(d, scene)
    assert d.press_pair_action("Undo") == [] and d.wait_guide()
    assert app.state.picks == before
    assert f"Undone: the move of pair {rid}'s camera point." in d.pair_status
    assert d.wait_idle() and app.state.picks == before and app.state.can_redo
    assert app.state.redo() and d.wait_guide() and d.wait_idle()
    assert app.state.picks == after


def test_reclicks_by_guidance_are_counted(app, scene):
    """A re-clicked hand pair stays "clicked" and is counted apart (run 5: "12 clicked, 0 guided" after 3)."""
    d = AppDriver(app)
    accept_a_reclick(d, scene)
    assert "Pairs: 4 clicked (1 re-clicked by guidance), 0 guided, 0 auto" in d.guide_panel
    assert d.press_pair_action("Undo") == [] and d.wait_guide()
    assert "Pairs: 4 clicked, 0 guided, 0 auto" in d.guide_panel


def test_same_step_joins_only_a_change_of_the_same_pick():
    """The state's side of one-step undo: a tag change ``same_step`` joins the newest step when that step moved the
    same pick, and makes its own step after a change of another pick."""
    from app.state import AnnotationState

    state = AnnotationState(np.ones((10, 20), dtype=bool), (100, 80))
    a = state.add_laser(1, 2)
    state.add_pixel(10.0, 20.0)
    b = state.add_laser(3, 4)
    state.add_pixel(30.0, 40.0)
    state.move_pixel(a, 11.0, 21.0)  # the click
    state.move_pixel(a, 11.0, 21.0, precision_px=0.3, same_step=True)  # the guide's tag on it
    assert state.get(a).precision_px == 0.3
    assert state.undo() and state.get(a).pixel == (10.0, 20.0) and state.get(a).precision_px is None
    assert state.redo() and state.get(a).pixel == (11.0, 21.0) and state.get(a).precision_px == 0.3
    state.move_pixel(b, 31.0, 41.0)  # another pick changed since: the tag is a step of its own
    state.move_pixel(a, 11.0, 21.0, precision_px=0.5, same_step=True)
    assert state.undo() and state.get(a).precision_px == 0.3 and state.get(b).pixel == (31.0, 41.0)
