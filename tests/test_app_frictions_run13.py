"""By-eye frictions recorded in run 13 (docs/by_eye.md, issue 20), driven through :class:`app_driver.AppDriver` on
the committed sample (one test per friction)."""

from __future__ import annotations

import numpy as np

from app_driver import AppDriver


def test_after_a_skipped_reclick_the_loupes_show_the_next_proposal(app, scene):
    """Runs 12 and 13: after Skip on a re-click, the Guided line named the next re-click but both loupes still
    showed the skipped pair until Next pair was pressed again.  The next re-click is not selected behind the
    person's back (run 4), but the loupes go to it."""
    from calib_core.guide.evidence import ProposalScreen
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    for pair in simulate_pairs(scene, 6, np.random.default_rng(3), pixel_noise_px=2.0):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=app.guide.screen.max_ellipse_px)  # re-clicks only
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    first = d.guide_proposal
    assert first is not None and first.replaces is not None and app.state.selected is not None  # its pair
    assert d.press_guide("Skip") == [] and d.wait_guide()
    nxt = d.guide_proposal
    assert nxt is not None and nxt.replaces is not None and nxt.replaces != first.replaces
    assert app.state.selected is None  # not selected: Next pair selects it
    ba, cam = d.loupe_view("ba"), d.loupe_view("camera")
    assert tuple(ba["center"]) == tuple(int(x) for x in nxt.laser_rc), (ba, nxt.laser_rc)
    assert np.hypot(cam["center"][0] - nxt.pixel[0], cam["center"][1] - nxt.pixel[1]) <= 1.0, (cam, nxt.pixel)


def test_guided_picking_before_four_pairs_names_both_conditions(app, scene):
    """Run 13: at 1 pair Next pair said "starts after 4 pairs"; at 4 pairs it then said it waits for a reliable
    calibration.  The first refusal names both."""
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    pair = simulate_pairs(scene, 1, np.random.default_rng(4), pixel_noise_px=0.5)[0]
    assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    notes = d.press_pair_action("Next pair")
    assert len(notes) == 1, notes
    text = " ".join(notes[0]).lower()
    assert "4 pairs" in text and "reliable" in text, notes
