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


def test_the_render_loupe_stretches_grey_shading_over_its_crop():
    """PJLab check before run 15: a lane line's paint on the near rings was about 20-30 grey levels above the
    asphalt in the render loupe (Intensity), too faint to find.  Its grey returns are stretched over the crop;
    depth-edge lines (white), no-return pixels (alpha 0) and coloured pixels stay as they are, and so does a crop
    whose grey levels already spread widely (KITTI's mixed objects, as runs 1-14 read them)."""
    from app.shown_render import STRETCH_MIN_GREY, stretched_grey

    rgba = np.zeros((10, 10, 4), np.uint8)
    rgba[..., 3] = 255
    rgba[:, :5, :3] = 40  # asphalt
    rgba[:, 5:, :3] = 70  # paint
    rgba[0, 0] = (255, 255, 255, 255)  # a depth-edge line
    rgba[0, 1] = (10, 10, 10, 0)  # no return
    rgba[0, 2] = (200, 30, 30, 255)  # colour: not a grey shading
    out = stretched_grey(rgba)
    assert out[5, 0, 0] == STRETCH_MIN_GREY and out[5, 9, 0] == 255  # 40 -> the floor, 70 -> white
    assert (out[5, 0, :3] == out[5, 0, 0]).all()  # still grey
    assert tuple(out[0, 0]) == (255, 255, 255, 255) and tuple(out[0, 1]) == (10, 10, 10, 0)
    assert tuple(out[0, 2]) == (200, 30, 30, 255)
    flat = np.full((10, 10, 4), 90, np.uint8)
    flat[..., 3] = 255
    assert (stretched_grey(flat) == flat).all()  # no spread: left alone
    mixed = rgba.copy()
    mixed[:, 5:, :3] = 200  # a crop of mixed objects, already 160 levels apart: left as it is
    assert (stretched_grey(mixed) == mixed).all()


def test_delete_without_a_selection_takes_the_pair_just_made_and_refined(app, scene):
    """Run 15: right after a pair was made and its photo end refined in the loupe, nothing is selected and Delete
    did nothing; removing the bad pair took three Undos.  Delete now takes the newest pair the loupes show, and
    only that one."""
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    pairs = simulate_pairs(scene, 2, np.random.default_rng(6), pixel_noise_px=0.5)
    for pair in pairs:
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    first, newest = [p.id for p in app.state.complete_picks()]
    u, v = pairs[1].pixel
    assert d.click_loupe_camera(u + 1.0, v) == []  # refines the newest pair's photo end
    assert app.state.selected is None
    assert d.press_edit("Delete") == []
    assert [p.id for p in app.state.complete_picks()] == [first]
    assert f"Deleted pair {newest}" in d.pair_status
    # The loupes no longer show a pair (theirs is gone): Delete asks for a selection and removes nothing.
    notes = d.press_edit("Delete")
    assert notes and "select a pair first" in " ".join(notes[0]).lower(), notes
    assert [p.id for p in app.state.complete_picks()] == [first]


def test_a_second_photo_click_on_a_half_pair_moves_its_photo_point_and_the_bar_says_so(app, scene):
    """Run 15: a second photo click while the laser end was pending moved the pending photo point instead of
    starting a pair; useful, but nothing said so."""
    d = AppDriver(app)
    assert d.click_camera(300.0, 200.0) == []
    half = app.state.pending()
    assert "a photo click moves its photo point" in d.pair_status, d.pair_status
    assert d.click_camera(310.0, 205.0) == []
    (moved,) = app.state.picks
    assert moved.id == half.id and np.allclose(moved.pixel, (310.0, 205.0), atol=1e-6) and moved.laser_rc is None
