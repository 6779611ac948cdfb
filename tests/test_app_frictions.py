"""Frictions of the by-eye runs 1 and 2 (docs/by_eye.md, "Frictions recorded"), driven without a browser.

* A pair moved while selected is deselected: the next click starts (or continues) a new pair.
* "Cancel pair" at the top of the panel drops a half-made pair in one undoable step; re-clicks of a half pair's
  end are not undo steps of their own.
* The loupes keep their crops after a refining click inside them; a click on the full image frames them again.
* A click just beside the render's outline (within 2 screen pixels) takes the nearest laser return.

Truth: the sample's clicks made here, the state's own pairs (laser cells and pixels set by the test), and the
camera-view render recomputed here with :func:`calib_core.render.render_from_camera` plus a brute-force
nearest-pixel search written here.  The browser half (notifications, the panel's top, Escape) is in
``tests/test_e2e_frictions.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.state import AnnotationState
from browser_helpers import start_sample_app
from calib_core.pairs import load_pairs_yaml
from calib_core.render import render_from_camera
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def driver(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("frictions")
    app, d = start_sample_app(tmp, load_pairs_yaml(SAMPLE / "pairs.yaml")[:6])
    try:
        assert d.set_panorama(False) == []  # raw view: render pixels are original pixels
        assert d.wait_render()
        yield d
    finally:
        app.stop()


def rendered(d) -> np.ndarray:
    """``cell_rc`` of the render of the pose the pane shows, recomputed here."""
    assert d.wait_idle() and d.wait_render()
    shown = d.render_shown
    return render_from_camera(d.app.depth, d.app.camera, shown.T_camera_lidar).cell_rc


def return_pixel(cells: np.ndarray, near: tuple[float, float]) -> tuple[int, int]:
    """The pixel ``(u, v)`` with a return nearest ``near`` whose 7 x 7 neighbourhood all has returns."""
    has = cells[..., 0] >= 0
    h, w = has.shape
    full = np.zeros_like(has)
    full[3:-3, 3:-3] = np.all([np.roll(np.roll(has, dv, 0), du, 1)[3:-3, 3:-3] for dv in range(-3, 4)
                               for du in range(-3, 4)], axis=0)
    vs, us = np.nonzero(full)
    k = int(np.argmin(np.hypot(us - near[0], vs - near[1])))
    return int(us[k]), int(vs[k])


def reset(d) -> None:
    """No half pair, no selection (the module's app is shared by the tests)."""
    app = d.app
    while app.state.pending() is not None:
        app.state.delete(app.state.pending().id)
    app.state.select(None)
    app.forget_last_picks()


def test_a_pair_moved_while_selected_is_deselected_and_the_next_click_starts_a_new_pair(driver):
    d, app = driver, driver.app
    reset(d)
    pid = app.state.picks[1].id
    before = app.state.get(pid)
    assert d.shift_click(d.camera_key, d.marker_display_pixel(d.camera_key, pid)) == []
    assert app.state.selected == pid
    u, v = before.pixel
    assert d.click_camera(u + 5.0, v - 2.0) == []
    moved = app.state.get(pid)
    assert moved.pixel == pytest.approx((u + 5.0, v - 2.0)) and moved.laser_rc == before.laser_rc
    assert app.state.selected is None and d.dropdown_value == "none"
    # The next click on the render starts a new pair; the moved pair's laser end stays where it was.
    n = len(app.state.picks)
    cells = rendered(d)
    pu, pv = return_pixel(cells, (200.0, 200.0))
    assert d.click_render(float(pu), float(pv)) == []
    assert len(app.state.picks) == n + 1 and app.state.get(pid) == moved
    assert app.state.pending().laser_rc == tuple(int(x) for x in cells[pv, pu])
    reset(d)


def test_cancel_pair_drops_a_half_pair_in_one_undoable_step(driver):
    d, app = driver, driver.app
    reset(d)
    picks = app.state.picks
    # A camera click, then two re-clicks of the same half pair (moving its pixel).
    for uv in ((300.0, 250.0), (304.0, 251.0), (306.5, 249.0)):
        assert d.click_camera(*uv) == []
    half = app.state.pending()
    assert half.pixel == pytest.approx((306.5, 249.0)) and len(app.state.picks) == len(picks) + 1
    assert f"Pair {half.id} waits for a BA click" in d.pair_status and "Cancel pair" in d.pair_status
    # Cancel pair: the half pair is gone, the complete pairs are as they were, the status line is empty.
    assert d.press_pair_action("Cancel pair") == []
    assert app.state.picks == picks and app.state.pending() is None and d.pair_status == ""
    # One undo brings the half pair back as it was last clicked ...
    assert d.press_pair_action("Undo") == []
    assert app.state.pending() == half
    # ... and one more undo drops it whole: the re-clicks were not steps of their own.
    assert d.press_pair_action("Undo") == []
    assert app.state.picks == picks
    # With nothing to cancel: nothing changes and nothing is shown (run 6: a red warning there was noise).
    assert d.press_pair_action("Cancel pair") == []
    assert app.state.picks == picks and app.state.pending() is None and app.state.selected is None
    # With a pair selected, Cancel pair ends the selection.
    pid = picks[0].id
    assert d.select_in_dropdown(pid) == [] and app.state.selected == pid
    assert f"Pair {pid} selected" in d.pair_status
    assert d.press_pair_action("Cancel pair") == [] and app.state.selected is None
    assert app.state.picks == picks


def test_re_clicks_of_a_half_pair_join_its_undo_step_but_nothing_else_does():
    valid = np.ones((10, 20), bool)
    s = AnnotationState(valid, (320, 240))
    s.add_laser(1, 1)
    s.add_pixel(10.0, 10.0)  # pair 1 complete
    s.add_laser(2, 2)
    s.add_laser(3, 3)  # a re-click of pair 2's laser end
    s.add_laser(4, 4)
    assert s.pending().laser_rc == (4, 4)
    assert s.undo() and [p.id for p in s.picks] == [1]  # the half pair goes in one step
    assert s.redo() and s.pending().laser_rc == (4, 4)
    s.add_pixel(20.0, 20.0)  # completes pair 2: its own step
    assert s.undo() and s.pending().laser_rc == (4, 4) and s.pending().pixel is None
    # Moving a complete pair's end is its own step, each time.
    s.add_pixel(20.0, 20.0)
    s.move_pixel(1, 11.0, 11.0)
    s.move_pixel(1, 12.0, 12.0)
    assert s.undo() and s.get(1).pixel == (11.0, 11.0)
    assert s.undo() and s.get(1).pixel == (10.0, 10.0)
    # A half pair started after another change: its re-clicks join its own step, not the change before.
    s.delete(2)
    s.add_pixel(30.0, 30.0)
    s.add_pixel(31.0, 30.0)
    assert s.undo() and [p.id for p in s.picks] == [1] and s.pending() is None
    assert s.undo() and [p.id for p in s.picks] == [1, 2]


def test_the_loupes_keep_their_crops_after_refining_clicks(driver):
    d, app = driver, driver.app
    reset(d)
    cells = rendered(d)
    u, v = return_pixel(cells, (420.0, 300.0))
    assert d.click_render(float(u), float(v)) == []  # a new pair: the loupes frame it
    pid = app.state.pending().id
    assert app.loupes.shows_render
    crop = app.loupes.camera_crop
    assert crop.center == pytest.approx((u, v))
    ba_texture = d.loupe_texture("ba").copy()
    # A refining click in the laser loupe (it shows the render's crop), 3 px off: the laser end moves ...
    assert d.click("loupe_ba", (u + 3.0 - crop.u0, v + 2.0 - crop.v0)) == []
    assert app.state.get(pid).laser_rc == tuple(int(x) for x in cells[v + 2, u + 3])
    # ... and neither loupe moves.
    assert app.loupes.camera_crop == crop and np.array_equal(d.loupe_texture("ba"), ba_texture)
    # Another look, another refinement: still where it was.
    assert d.click("loupe_ba", (u - 2.0 - crop.u0, v - 1.0 - crop.v0)) == []
    assert app.state.get(pid).laser_rc == tuple(int(x) for x in cells[v - 1, u - 2])
    assert app.loupes.camera_crop == crop and np.array_equal(d.loupe_texture("ba"), ba_texture)
    # The camera end in the camera loupe, 5 px off its centre: the pair is complete, the loupes stay.
    assert d.click_loupe_camera(u - 5.0, v + 4.0) == []
    assert app.state.get(pid).pixel == pytest.approx((u - 5.0, v + 4.0)) and app.state.get(pid).complete
    assert d.wait_idle() and d.wait_render() and app.loupes.camera_crop == crop
    # A click on the full image (a new spot, a new pair) frames the loupes there.
    u2, v2 = return_pixel(cells, (u + 120.0, v))
    assert d.click_render(float(u2), float(v2)) == []
    assert app.loupes.camera_crop.center == pytest.approx((u2, v2)) and app.state.pending().id != pid
    reset(d)
    app.state.delete(pid)  # the module's app is shared


def nearest_return(cells: np.ndarray, u: int, v: int) -> tuple[float, set]:
    """Distance (render px) from pixel ``(u, v)`` to the nearest pixels with a return, and their cells."""
    vs, us = np.nonzero(cells[..., 0] >= 0)
    if not len(vs):
        return math.inf, set()
    dist = np.hypot(us - u, vs - v)
    best = dist == dist.min()
    return float(dist.min()), {tuple(int(x) for x in cells[v_, u_]) for v_, u_ in zip(vs[best], us[best])}


def test_a_click_just_beside_the_renders_outline_takes_the_nearest_return(driver):
    d, app = driver, driver.app
    reset(d)
    cells = rendered(d)
    has = cells[..., 0] >= 0
    per_px = app.view.slots["render"].units_per_px
    # The tab shows the pane small: 4 render pixels per screen pixel (as a 1920-wide photo shown 480 px wide).
    cam = d.tab.camera
    old = cam.position
    cam.position = (0.0, 0.0, -(4.0 * per_px) * cam.image_height / (2.0 * math.tan(cam.fov / 2.0)))
    try:
        # Empty pixels whose nearest return is 5-7 render px away (under 2 screen px) and 9-12 px (over).
        vs, us = np.nonzero(~has)
        rng = np.random.default_rng(1)
        near, far = [], []
        for k in rng.permutation(len(vs))[:4000]:
            u, v = int(us[k]), int(vs[k])
            if not (12 < u < has.shape[1] - 13 and 12 < v < has.shape[0] - 13):
                continue
            dist, cell = nearest_return(cells[v - 12:v + 13, u - 12:u + 13], 12, 12)
            if 5.0 <= dist <= 7.0 and len(near) < 3:
                near.append((u, v, cell))
            elif 9.0 <= dist <= 12.0 and not np.any(has[v - 8:v + 9, u - 8:u + 9]) and len(far) < 1:
                far.append((u, v))
        assert len(near) == 3 and far, (near, far)
        n = len(app.state.picks)
        for u, v, cell in near:
            assert d.click_render(float(u), float(v)) == [], (u, v)
            assert app.state.pending().laser_rc in cell
        # Farther than 2 screen pixels: still refused, in one line.
        notes = d.click_render(float(far[0][0]), float(far[0][1]))
        assert [t for t, _ in notes] == ["Not accepted"] and "no laser return here" in notes[0][1]
        # Seen large (1 render pixel per screen pixel) the render's own radius of 4 px applies: 5-7 px is refused.
        cam.position = (0.0, 0.0, -per_px * cam.image_height / (2.0 * math.tan(cam.fov / 2.0)))
        notes = d.click_render(float(near[0][0]), float(near[0][1]))
        assert [t for t, _ in notes] == ["Not accepted"]
        assert len(app.state.picks) == n + 1
    finally:
        cam.position = old
        reset(d)


def shown_widths(camera_size, ba_size, cell_aspect, canvas=(1000, 900)):
    """Screen widths (px) of the photo and of one BA pane when the whole page (photo, render, BA panes, loupes) is
    fitted into ``canvas`` (the part left of the control panel), and the number of BA columns."""
    from app.layout import bounds_of, layout_with_render, loupe_areas

    keys = ("horizontal", "vertical", "diag_pos45", "diag_neg45")
    slots = layout_with_render({"raw": camera_size}, "raw", ba_size, keys, cell_aspect)
    main = bounds_of(list(slots.values()))
    x0, y0, x1, y1 = main
    for area in loupe_areas(main).values():
        x1, y1 = max(x1, area.x0 + area.width), max(y1, area.y0 + area.height)
    scale = min(canvas[0] / (x1 - x0), canvas[1] / (y1 - y0))  # screen px per world unit
    n_cols = len({round(slots[k].center[0], 6) for k in keys})
    return slots["raw"].render_width * scale, slots[keys[0]].render_width * scale, n_cols


def test_a_small_window_gives_the_photo_and_the_render_the_room():
    # PJLab manual_calib at 1400 x 900 (1000 px left of the panel): 1920 x 1200 photo, the 272 columns facing it.
    photo, ba, n_cols = shown_widths((1920, 1200), (272, 64), 3.3)
    assert photo >= 0.5 * 1000, (photo, ba, n_cols)  # by-eye run: about 390 px
    assert ba >= 100 and n_cols == 4
    # A wide, short photo (KITTI) keeps the 2 x 2 BA panes: the photo is wide already.
    photo, ba, n_cols = shown_widths((1242, 375), (520, 64), 2.53)
    assert photo >= 0.55 * 1000 and n_cols == 2
    # A whole 360 deg strip is never cut into slivers 1 x 4 (each a quarter of the photo's width).
    photo, ba, n_cols = shown_widths((1920, 1200), (1800, 64), 3.24)
    assert n_cols in (1, 2) and ba >= 0.45 * photo


def test_after_a_ba_loupe_click_the_camera_loupe_moves_only_if_the_prediction_leaves_its_middle(driver):
    from calib_core.transforms import transform_points

    d, app = driver, driver.app
    reset(d)
    assert d.wait_idle() and app.result is not None
    T = app.result.T_camera_lidar

    def predicted(cell) -> np.ndarray:  # the solved pose's projection of the cell, computed here
        uv, ok = app.camera.project(transform_points(T, app.depth.cell_points(np.array([cell]))))
        assert ok[0]
        return uv[0]

    key = app.ba_keys[0]
    valid = app.depth.valid
    cols = app.ba_window.columns
    row, col = next((r, int(c)) for r in range(60, 120) for c in cols[200:400] if valid[r, c] and valid[r, c + 1])
    assert d.click_cell(key, row, col) == []  # the full BA image: both loupes framed
    pid = app.state.pending().id
    crop = app.loupes.camera_crop
    assert crop.center == pytest.approx(tuple(predicted((row, col))), abs=0.01)
    # The next cell, in the BA loupe: its prediction stays in the camera loupe's middle, which does not move.
    near = predicted((row, col + 1)) - [crop.u0, crop.v0]
    assert np.all((0.15 * crop.n <= near) & (near <= 0.85 * crop.n - 1)), near
    assert d.click_loupe_cell(row, col + 1) == [] and app.state.get(pid).laser_rc == (row, col + 1)
    assert app.loupes.camera_crop == crop
    # A cell farther off in the BA loupe whose prediction leaves the camera loupe's middle: the camera loupe frames it.
    ba = app.loupes.ba_crop

    def off_middle(cell) -> bool:
        xy = predicted(cell) - [crop.u0, crop.v0]
        return not np.all((0.15 * crop.n <= xy) & (xy <= 0.85 * crop.n - 1))

    far = next((r, c) for c in range(ba.col0 + 1, ba.col0 + ba.n_cols - 1)
               for r in range(ba.row0 + 1, ba.row0 + ba.n_rows - 1) if valid[r, c] and off_middle((r, c)))
    assert d.click_loupe_cell(*far) == [] and app.state.get(pid).laser_rc == far
    assert app.loupes.camera_crop.center == pytest.approx(tuple(predicted(far)), abs=0.01)
    reset(d)
