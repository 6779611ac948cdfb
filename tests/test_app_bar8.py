"""By-eye frictions of run 7 (docs/by_eye.md), driven through :class:`app_driver.AppDriver` on the committed sample:
a left-out pair stayed selected, a marker's number label took no Shift+click, a stale refit notice, no live line
before 4 pairs, guided picking's reason out of view, outlier exclusions that changed unannounced."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from calib_core.synthetic import simulate_pairs

from app_driver import AppDriver


def _pairs(d: AppDriver, app, scene, n: int, seed: int = 3) -> list:
    made = simulate_pairs(scene, n, np.random.default_rng(seed), pixel_noise_px=0.0)
    for pair in made:
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    return made


def _press_leave_out(d: AppDriver) -> list:
    panel = d.app.pairs_panel
    return d._fire(d.app.guard(panel.on_leave_out), SimpleNamespace(client=d.tab, target=SimpleNamespace()))


def test_leaving_a_pair_out_ends_the_selection_so_the_next_click_does_not_move_it(app, scene):
    """Run 7: Shift+click marker 2, "Leave selected pair out", then a click on the image moved pair 2's laser end."""
    d = AppDriver(app)
    _pairs(d, app, scene, 3)
    key = app.ba_keys[0]
    second = app.state.picks[1]
    assert d.shift_click(key, d.marker_display_pixel(key, second.id)) == [] and app.state.selected == second.id
    assert _press_leave_out(d) == [] and d.wait_idle()
    assert app.state.get(second.id).check and app.state.selected is None
    assert f"Pair {second.id} left out of the fit; selection ended" in d.pair_status, d.pair_status
    # The next click starts a new pair: pair 2 keeps both its ends.
    before = app.state.get(second.id)
    far = (second.laser_rc[0], (second.laser_rc[1] + 40) % app.depth.shape[1])
    assert d.click_cell(key, *far) == [] and d.wait_idle()
    assert app.state.get(second.id) == before and app.state.pending() is not None
    assert app.state.pending().id != second.id
    assert d.press_pair_action("Cancel pair") == []
    # Putting it back also ends the selection, and says so.
    assert d.shift_click(key, d.marker_display_pixel(key, second.id)) == [] and app.state.selected == second.id
    assert _press_leave_out(d) == [] and d.wait_idle()
    assert not app.state.get(second.id).check and app.state.selected is None
    assert f"Pair {second.id} put back in the fit; selection ended" in d.pair_status, d.pair_status
