"""Frictions of by-eye run 4 (docs/by_eye.md, "Frictions recorded in run 4"), driven without a browser.

* A click in the laser loupe after a finished pair refines that pair's laser end (it showed the render's crop and
  started a new pair); a refining click that changes nothing says so ("same cell").
* The top Undo says which half of a pair it took back.
* The 2-D view is framed the same at any pixel ratio the tab reports (it re-framed itself small, top left).
* The selected pair can be left out of the fit (a check pair) and put back from the Pairs folder.
* A BA-edge dot covers at most 2 photo pixels (they covered small corners).

Truth: the clicks made here, the state's own pairs, the solve's fitted pairs, the camera-view render recomputed
here with :func:`calib_core.render.render_from_camera`, and the tab's camera projected here.  The browser half (the pinned pair bar, Delete and Ctrl+Z keys) is in
``tests/test_e2e_pair_bar_keys.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from browser_helpers import start_sample_app
from calib_core.pairs import load_pairs_yaml
from repo_paths import SAMPLE
from test_app_frictions import rendered, reset, return_pixel


@pytest.fixture(scope="module")
def driver(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("frictions4")
    app, d = start_sample_app(tmp, load_pairs_yaml(SAMPLE / "pairs.yaml")[:6])
    try:
        assert d.set_panorama(False) == []  # raw view: render pixels are original pixels
        assert d.wait_render()
        yield d
    finally:
        app.stop()


def test_a_laser_loupe_click_after_a_finished_pair_refines_it_and_same_cell_says_so(driver):
    d, app = driver, driver.app
    reset(d)
    cells = rendered(d)
    n = len(app.state.picks)
    u, v = return_pixel(cells, (420.0, 300.0))
    # Camera first, then the render: a finished pair, and the laser loupe shows the render's crop.
    assert d.click_camera(float(u) + 0.3, float(v) - 0.2) == []
    assert d.click_render(float(u), float(v)) == []
    pid = app.state.picks[-1].id
    assert app.state.get(pid).complete and app.state.pending() is None and len(app.state.picks) == n + 1
    assert app.loupes.shows_render
    crop = app.loupes.camera_crop
    # A click in the laser loupe, 3 px right: the finished pair's laser end moves there, no new pair.
    want = tuple(int(x) for x in cells[v, u + 3])
    assert want != app.state.get(pid).laser_rc
    assert d.click("loupe_ba", (u + 3.0 - crop.u0, v - crop.v0)) == []
    assert len(app.state.picks) == n + 1 and app.state.get(pid).laser_rc == want
    # The same cell again: nothing changes, and the person is told so.
    before = app.state.picks
    notes = d.click("loupe_ba", (u + 3.0 - crop.u0, v - crop.v0))
    assert app.state.picks == before
    assert len(notes) == 1 and "same cell" in notes[0][1].lower(), notes
    # The camera loupe likewise, at the same pixel.
    notes = d.click("loupe_camera", d.loupe_display_pixel("camera", app.state.get(pid).pixel))
    assert app.state.picks == before
    assert len(notes) == 1 and "same" in notes[0][1].lower(), notes
    app.state.delete(pid)
    reset(d)


def test_the_top_undo_says_which_half_of_a_pair_it_took_back(driver):
    d, app = driver, driver.app
    reset(d)
    cells = rendered(d)
    picks = app.state.picks
    u, v = return_pixel(cells, (200.0, 250.0))
    assert d.click_camera(float(u), float(v)) == [] and d.click_render(float(u), float(v)) == []
    pid = app.state.picks[-1].id
    assert app.state.get(pid).complete
    # The render click completed the pair: Undo takes back its laser end; the camera point waits.
    assert d.press_pair_action("Undo") == [] and d.wait_idle()
    half = app.state.pending()
    assert half.id == pid and half.pixel is not None and half.laser_rc is None
    assert f"Undone: pair {pid}'s laser end; its camera point waits" in d.pair_status, d.pair_status
    # Undo again: the half pair goes; the line names the pair.
    assert d.press_pair_action("Undo") == [] and d.wait_idle()
    assert app.state.picks == picks and f"Undone: pair {pid} (its last end)." in d.pair_status, d.pair_status
    # A moved camera point, undone; a deleted pair, brought back.
    first = picks[0]
    app.state.move_pixel(first.id, first.pixel[0] + 2.0, first.pixel[1])
    assert d.press_pair_action("Undo") == [] and app.state.picks == picks
    assert f"Undone: the move of pair {first.id}'s camera point." in d.pair_status, d.pair_status
    app.state.delete(first.id)
    assert d.press_pair_action("Undo") == [] and app.state.picks == picks
    assert f"Undone: the removal of pair {first.id}." in d.pair_status, d.pair_status
    # The next change clears the line.
    app.state.select(first.id)
    assert d.wait_idle() and "Undone" not in d.pair_status
    reset(d)


def canvas_fraction(tab, bounds) -> np.ndarray:
    """``(x0, y0, x1, y1)`` of world rectangle ``bounds`` as fractions of the tab's canvas (the fake camera looks
    along +z as the app sets it)."""
    cam = tab.camera
    (a, b), (c, e) = cam.screen_of((bounds[0], bounds[1])), cam.screen_of((bounds[2], bounds[3]))
    return np.array([a / cam.image_width, b / cam.image_height, c / cam.image_width, e / cam.image_height])


def test_the_page_is_framed_the_same_whatever_pixel_ratio_the_tab_reports(driver):
    """Run 4: after a pair the 2-D view re-framed itself, everything smaller at the top left.  viser reports the
    canvas scaled down while the page renders slowly (same shape, rounded); framing with that size drew the page
    small.  The page must take the same share of the canvas at any pixel ratio, and a scaled-down report is no
    resize (the view stays)."""
    import asyncio

    from app_driver.fakes import FakeTab

    app = driver.app
    tab = FakeTab()
    tab.camera.client = tab
    app.view.set_view(tab, "all")
    report = tab.camera.update_callbacks[-1]
    asyncio.run(report(tab.camera))  # the tab's first report: 1400 x 900
    app.view.set_view(tab, "all")
    page = app.view.camera_slot().bounds()
    full = canvas_fraction(tab, page)
    assert 0.0 < full[0] < full[2] < 1.0 and 0.0 < full[1] < full[3] < 1.0
    pose = (tab.camera.position, tab.camera.look_at)
    # The page renders slowly: viser halves the resolution, and rounds a small one (1.4 % off the shape).
    for size in ((700, 450), (281, 178)):
        tab.camera.image_width, tab.camera.image_height = size
        asyncio.run(report(tab.camera))
        assert driver.wait_idle()
        assert (tab.camera.position, tab.camera.look_at) == pose, size  # no re-framing: not a resize
        np.testing.assert_allclose(canvas_fraction(tab, page), full, atol=0.01)
        app.view.set_view(tab, "all")  # framed again at this ratio (e.g. View -> All): the same share
        np.testing.assert_allclose(canvas_fraction(tab, page), full, atol=0.01)
    app.view.forget_tab(tab.client_id)


def test_leave_the_selected_pair_out_of_the_fit_and_put_it_back(driver):
    from types import SimpleNamespace

    from calib_core.solve.quality import pairs_in_fit

    d, app = driver, driver.app
    reset(d)
    press = lambda: d._fire(app.guard(app.pairs_panel.on_leave_out),  # noqa: E731
                            SimpleNamespace(client=d.tab, target=SimpleNamespace(value=None)))
    notes = press()
    assert len(notes) == 1 and "select a pair first" in notes[0][1]
    assert d.wait_idle()
    n = len(app.state.complete_picks())
    assert pairs_in_fit(app.result) == n
    pid = app.state.picks[2].id
    app.state.select(pid)
    assert press() == [] and d.wait_idle()
    assert app.state.get(pid).check and pairs_in_fit(app.result) == n - 1
    assert f"left out (check pairs): #{pid} ·" in d.pairs_panel
    app.state.select(pid)  # the press ended the selection (run 7): select it again to put it back
    assert press() == [] and d.wait_idle()
    assert not app.state.get(pid).check and pairs_in_fit(app.result) == n
    assert "left out (check pairs)" not in d.pairs_panel
    reset(d)


@pytest.mark.parametrize("width_px", [640, 1280, 1920, 4096])
def test_edge_dots_cover_at_most_two_photo_pixels(width_px):
    """Run 4: with 4+ pairs the blue BA-edge dots (2.9 px squares on a 1920 px photo) covered small corners."""
    from app.layout import CAMERA_WIDTH
    from app.overlay_drawing import edge_dot_size

    units_per_px = CAMERA_WIDTH / width_px  # the photo is drawn CAMERA_WIDTH world units wide
    size_px = edge_dot_size(units_per_px) / units_per_px
    assert 1.6 - 1e-9 <= size_px <= 2.0 + 1e-9, size_px
