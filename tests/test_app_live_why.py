"""Run 10's friction (docs/by_eye.md): leaving a pair out turned "Quality: ok" into "warning" and the live line
did not say why.  The live line now names the first reason, driven through :class:`app_driver.AppDriver` on the
committed sample."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np

from calib_core.synthetic import simulate_pairs

from app_driver import AppDriver


def _leave_out(d: AppDriver, key: str, pick_id: int) -> None:
    assert d.shift_click(key, d.marker_display_pixel(key, pick_id)) == [] and d.app.state.selected == pick_id
    panel = d.app.pairs_panel
    assert d._fire(d.app.guard(panel.on_leave_out), SimpleNamespace(client=d.tab, target=SimpleNamespace())) == []
    assert d.wait_idle()


def test_the_live_line_says_why_the_quality_is_not_ok(app, scene):
    d = AppDriver(app)
    for pair in simulate_pairs(scene, 6, np.random.default_rng(3), pixel_noise_px=0.5):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    line = app.pairs_panel.bar.live_line
    assert app.result.quality.status == "ok" and "Quality: ok**" in line and "why:" not in line, line

    second = app.state.picks[1]
    _leave_out(d, app.ba_keys[0], second.id)
    quality = app.result.quality
    line = app.pairs_panel.bar.live_line
    assert quality.status == "warning" and "Quality: warning**" in line, line
    m = re.search(r" · why: ([^·]+?)(?: · |$)", line)
    assert m, line
    # The words shown are how calib_core's first reason starts (5 pairs in the fit now: too few to check one another).
    shown = m.group(1).rstrip("…")
    assert len(shown) >= 10 and quality.reasons[0].startswith(shown), (shown, quality.reasons)
    assert "5 pairs in the fit" in " ".join(quality.reasons)

    _leave_out(d, app.ba_keys[0], second.id)  # put back: ok again, and the reason goes
    line = app.pairs_panel.bar.live_line
    assert app.result.quality.status == "ok" and "why:" not in line, line
