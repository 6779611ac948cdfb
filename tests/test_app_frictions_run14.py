"""By-eye frictions recorded in run 14 (docs/by_eye.md, issue 20), driven through :class:`app_driver.AppDriver` on
the committed sample."""

from __future__ import annotations

import numpy as np

from app_driver import AppDriver


def test_delete_says_in_the_bar_which_pair_it_removed(app, scene):
    """Run 14: Delete removed the selected pair with no word in the pair bar."""
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    for pair in simulate_pairs(scene, 2, np.random.default_rng(5), pixel_noise_px=0.5):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    ids = [p.id for p in app.state.complete_picks()]
    assert d.select_in_dropdown(ids[0]) == []
    assert d.press_edit("Delete") == []
    assert [p.id for p in app.state.complete_picks()] == ids[1:]
    status = d.pair_status
    assert f"Deleted pair {ids[0]}" in status and "Undo" in status, status
    assert d.press_pair_action("Undo") == []  # and it comes back
    assert [p.id for p in app.state.complete_picks()] == ids
