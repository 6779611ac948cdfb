"""By-eye frictions of runs 5 and 6 (docs/by_eye.md), driven through :class:`app_driver.AppDriver` on the committed
sample: Escape (Cancel pair) with nothing pending, a skipped lone marking proposal, the pair bar's Guided line."""

from __future__ import annotations

import numpy as np

from calib_core.synthetic import simulate_pairs

from app_driver import AppDriver


def test_cancel_pair_with_nothing_pending_gives_no_warning(app, scene):
    d = AppDriver(app)
    # Nothing at all: Escape / Cancel pair changes nothing and says nothing (run 6: a red "Not accepted").
    assert d.press_pair_action("Cancel pair") == [] and len(app.state.picks) == 0 and app.state.selected is None
    pair = simulate_pairs(scene, 1, np.random.default_rng(3), pixel_noise_px=0.0)[0]
    assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    done = app.state.picks
    assert len(done) == 1 and app.state.pending() is None
    # A finished pair and no selection: still nothing to cancel, still silent, the pair stays.
    assert d.press_pair_action("Cancel pair") == [] and app.state.picks == done
    # A half-made pair is still dropped, a selection still ended.
    assert d.click_camera(330.0, 250.0) == [] and app.state.pending() is not None
    assert d.press_pair_action("Cancel pair") == [] and app.state.picks == done
    app.state.select(done[0].id)
    assert d.press_pair_action("Cancel pair") == [] and app.state.selected is None and app.state.picks == done


def test_skipped_proposals_do_not_come_straight_back(app, scene):
    d = AppDriver(app)
    for pair in simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=0.0):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    assert d.guide_proposal is not None
    skipped: list[tuple[int, int]] = []
    for _ in range(60):  # at most 20 proposals, each skipped once
        p = d.guide_proposal
        if p is None:
            break
        cell = tuple(int(v) for v in p.laser_rc)
        # Run 6: "Skipped the marking. Proposal 1 of 1" showed the cell just skipped again.
        assert cell not in skipped, f"skipped cell {cell} offered again before any new pair"
        if p.replaces is None:
            skipped.append(cell)
        assert d.press_guide("Skip") == [] and d.wait_guide()
    assert d.guide_proposal is None and skipped
    assert app.state.pending() is None  # the guided half pick of the last skipped cell went with it
    assert "No other proposal is left" in app.guide.text
    assert app.pairs_panel.bar.guide_status == "**Guided:** no other proposal left; go on by hand"
    # Next pair shows a skipped one again, on request.
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    assert d.guide_proposal is not None and tuple(int(v) for v in d.guide_proposal.laser_rc) in skipped


def test_the_pair_bar_keeps_guided_to_one_short_line(app, scene):
    """Run 6: the bar repeated the Guided folder's text and grew to about 300 px; it now holds one short line."""
    d = AppDriver(app)
    for pair in simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=0.0):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    seen_kinds = set()
    for step in range(6):
        p = d.guide_proposal
        assert p is not None
        bar = app.pairs_panel.bar.guide_status
        n, i = len(app.guide.proposals), app.guide.proposals.index(p)
        assert bar.startswith("**Guided:** ") and "\n" not in bar and len(bar) <= 100, bar
        assert f"proposal {i + 1} of {n}" in bar
        # The full text stays in the Guided picking folder.
        assert f"Proposal {i + 1} of {n}: cell (row {p.laser_rc[0]}, col {p.laser_rc[1]})" in d.guide_panel
        assert "Predicted pixel" in d.guide_panel and "Predicted pixel" not in bar
        if p.replaces is None and app.state.pending() is not None:
            assert f"click pair {app.state.pending().id}'s corner in the camera loupe" in bar
        seen_kinds.add(p.replaces is None)
        assert d.press_guide("Skip") == [] and d.wait_guide()
    assert True in seen_kinds
