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
