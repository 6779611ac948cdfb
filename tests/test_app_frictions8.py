"""By-eye frictions recorded in run 8 (docs/by_eye.md, issue 20), driven through :class:`app_driver.AppDriver` on
the committed sample (one test per friction)."""

from __future__ import annotations

from app_driver import AppDriver


def test_unticking_align_by_drag_hides_the_render_it_showed_over_the_photo(app):
    """Run 8: ticking "Align by drag" drew the render over the photo at 0.5, and unticking left it there; only the
    "Render over photo" slider cleared it.  A blend the person chose stays."""
    d = AppDriver(app)
    assert app.state.view.render_blend == 0.0
    assert d.set_align_by_drag(True) == [] and app.state.view.render_blend == 0.5
    assert d.set_align_by_drag(False) == [] and app.state.view.render_blend == 0.0

    # The person's own choice while aligning is kept when the tick goes.
    assert d.set_align_by_drag(True) == [] and d.set_render_blend(0.3) == []
    assert d.set_align_by_drag(False) == [] and abs(app.state.view.render_blend - 0.3) < 1e-9
    # And a tick that found the render already shown does not hide it afterwards.
    assert d.set_align_by_drag(True) == [] and d.set_align_by_drag(False) == []
    assert abs(app.state.view.render_blend - 0.3) < 1e-9


def test_a_render_loupe_click_during_a_reclick_makes_it_not_skips_it(app, scene):
    """Run 8: during a guided re-click, a click in the laser loupe moved the pair's laser end, but the bar said
    "Skipped the re-click of pair N" and Next pair offered the same pair again."""
    import numpy as np

    from calib_core.guide.evidence import ProposalScreen
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    for pair in simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=1.0):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=app.guide.screen.max_ellipse_px)  # re-clicks only
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    rid = app.state.selected
    assert rid is not None and d.guide_proposal.replaces is not None
    row, col = app.state.get(rid).laser_rc
    view = d.loupe_view("ba")
    # A neighbouring valid cell the laser loupe shows (one column over, the same row).
    target = next((row, c) for c in (col + 1, col - 1)
                  if app.depth.valid[row, c % app.depth.shape[1]] and d.loupe_display_pixel("ba", (float(c), float(row))) is not None)
    assert view is not None and d.click_loupe_cell(*target) == [] and d.wait_guide()
    assert app.state.get(rid).laser_rc == target  # the laser end moved
    assert "Skipped the re-click" not in app.pairs_panel.bar.guide_status.replace("\\", "")
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    assert app.state.selected != rid  # the same re-click is not offered again
