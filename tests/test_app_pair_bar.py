"""The pair bar at the top of the control panel during guided picking, and re-clicks that do not cycle (by-eye
frictions, issue 20), driven through :class:`app_driver.AppDriver` on the committed sample.

On PJLab the proposal screen left no new cell, and every proposal was "re-click of pair N", cycling back to the
same pair after a Skip or a Stop, while the guided status sat two wheel-scrolls down.  Here a screen that no cell
passes (nothing is within 0.5 m of the lidar on the sample) reproduces that state.
"""

from __future__ import annotations

import re

import numpy as np

from calib_core.guide.evidence import ProposalScreen
from calib_core.synthetic import simulate_pairs
from calib_core.transforms import transform_points

from app_driver import AppDriver


def click_pairs(d: AppDriver, scene, n: int, noise_px: float = 1.0, first: int = 0) -> None:
    """Click pairs ``first`` to ``n - 1`` of ``n`` spread corners, each pixel ``noise_px`` (per axis) off."""
    for pair in simulate_pairs(scene, n, np.random.default_rng(3), pixel_noise_px=noise_px)[first:]:
        assert d.click_cell(d.app.ba_keys[0], *pair.laser_rc) == []
        assert d.click_camera(*pair.pixel) == []
    assert d.wait_idle()


def test_reclicks_skipped_or_stopped_do_not_come_back_and_the_bar_says_why(app, scene):
    d = AppDriver(app)
    click_pairs(d, scene, 4)
    assert d.pairs_panel and app.pairs_panel.bar.guide_status == ""  # no guided session yet: nothing in the bar
    app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=app.guide.screen.max_ellipse_px)
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    shown, skipped = [], False
    for _ in range(12):  # at most 4 re-clicks (4 pairs); before the fix Skip cycled through them for ever
        p = d.guide_proposal
        if p is None:
            break
        assert p.replaces is not None  # no new cell passes this screen
        if skipped:  # run 4: after a Skip the next re-click's pair is not selected behind the person's back ...
            assert app.state.selected is None and "(selected)" not in app.pairs_panel.bar.guide_status
            if len(shown) == 1:  # ... so a plain click starts a pair and moves none (Cancel pair drops it)
                before = app.state.picks
                assert d.click_camera(330.0, 250.0) == [] and d.wait_idle()
                assert app.state.picks[:-1] == before and app.state.pending() is not None
                assert d.press_pair_action("Cancel pair") == [] and d.wait_idle() and app.state.picks == before
            assert d.press_pair_action("Next pair") == [] and d.wait_guide()  # Next pair selects it
            assert d.guide_proposal == p
        rid = app.state.selected
        assert rid is not None
        shown.append(rid)
        # The pair bar, at the top, says which proposal and what to click (not only the Guided folder).
        bar = app.pairs_panel.bar.guide_status
        assert f"re-click pair {rid} (selected)" in bar and "\n" not in bar  # one short line (run 6)
        assert f"Pair {rid} (selected)" in d.guide_panel and "No new corner to propose here" in d.guide_panel
        if len(shown) == 1:  # Cancel pair ends the selection and skips this re-click (run 5: Next pair re-offered it)
            assert d.press_pair_action("Cancel pair") == [] and d.wait_guide() and app.state.selected is None
            bar = app.pairs_panel.bar.guide_status
            assert f"re-click pair {rid}" not in bar and "(selected)" not in bar, bar
            skipped = True
            continue
        if len(shown) == 2:  # Stop declines it too; Next pair then shows another pair
            assert d.press_guide("Stop") == [] and d.wait_guide()
            assert app.pairs_panel.bar.guide_status == ""
            assert d.press_pair_action("Next pair") == [] and d.wait_guide()
        else:
            assert d.press_guide("Skip") == [] and d.wait_guide()
        skipped = len(shown) != 2
    assert len(shown) == len(set(shown)) and 1 <= len(shown) <= 4, shown
    assert d.guide_proposal is None
    panel = d.guide_panel.replace("\\", "")  # markdown escapes
    m = re.search(r"No new corner to propose here; pick the next pairs by hand: of (\d+) corner-like spots? in "
                  r"the scan, most \(\d+\) are too far away to place",
                  panel)
    assert m and int(m.group(1)) > 0, panel
    # The bar gives the reason itself in its one line (run 7).
    assert app.pairs_panel.bar.guide_status.replace("\\", "") == "**Guided:** n" + m.group(0)[1:]


def test_the_live_line_shows_the_solve_figures_at_the_top(app, scene):
    d = AppDriver(app)
    click_pairs(d, scene, 7)
    undone = 0
    while len(app.state.pairs()) > 4 or app.state.pending() is not None:  # back to 4 pairs: no error figure yet
        assert app.state.undo()
        undone += 1
    assert d.wait_idle() and len(app.state.pairs()) == 4
    assert "4 pairs · mean: no error estimate yet · Quality:" in app.pairs_panel.bar.live_line
    for _ in range(undone):
        assert app.state.redo()
    assert d.wait_idle() and len(app.state.pairs()) == 7
    r = app.result
    line = app.pairs_panel.bar.live_line
    m = re.fullmatch(r"\*\*(\d+) pairs · mean ([0-9.]+) px · left out ([0-9.]+) px \(warning above 6\) · "
                     r"Quality: (ok|warning|UNRELIABLE)"
                     r"\*\*( · worst: pair \d+ [0-9.]+ px)?( · why: [^·]+)?", line)  # tests/test_app_live_why.py
    assert m, line
    pairs = app.state.pairs()
    assert int(m.group(1)) == len(pairs)
    # The mean is the pairs' pixel error under the solved pose, computed here from the clicks and the scan.
    pts = np.array([app.depth.points[p.laser_rc] for p in pairs])
    uv, ok = app.camera.project(transform_points(r.T_camera_lidar, pts))
    mine = float(np.mean(np.linalg.norm(np.asarray(uv) - np.array([p.pixel for p in pairs]), axis=1)))
    assert ok.all() and abs(float(m.group(2)) - mine) <= 0.01, (line, mine)
    assert float(m.group(3)) >= float(m.group(2))  # a pair the pose did not see lands farther off than a fitted one
    assert m.group(4) == {"unreliable": "UNRELIABLE"}.get(r.quality.status, r.quality.status)
