"""Select a pair (Shift+click or dropdown), move it, re-solve: no error (issue 11, "Broken")."""

from __future__ import annotations


import numpy as np
import pytest

from calib_core.pairs import load_pairs_yaml
from browser_helpers import start_sample_app
from repo_paths import SAMPLE


@pytest.fixture
def driver(tmp_path):
    app, d = start_sample_app(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml")[:6])
    try:
        yield d
    finally:
        app.stop()


def no_errors(notes):
    return [n for n in notes if n[0] in ("Internal error", "Not accepted")] == []


def test_shift_click_selects_shows_in_dropdown_then_move_and_resolve(driver):
    app = driver.app
    pid = app.state.picks[2].id
    key = driver.camera_key
    uv = driver.marker_display_pixel(key, pid)
    notes = driver.shift_click(key, uv)
    assert no_errors(notes), notes
    assert app.state.selected == pid
    assert driver.dropdown_value == f"#{pid}"  # the selection shows in the dropdown
    assert f"Pair {pid} selected" in driver.pairs_panel
    assert driver.selection_drawn(key) > 0 and driver.selection_drawn("horizontal") > 0
    # Move its camera end 3 px right with a plain click: the pair moves, the solve reruns without error.
    u, v = app.state.get(pid).pixel
    before = app.result
    notes = driver.click_camera(u + 3.0, v)
    assert no_errors(notes), notes
    assert driver.wait_idle()
    assert app.state.get(pid).pixel[0] == pytest.approx(u + 3.0, abs=0.05)
    assert len(app.state.picks) == 6  # moved, not added
    assert app.result is not None and app.result is not before
    assert "Solve failed" not in driver.result_panel
    # Deselect: the ring goes, the dropdown follows.
    assert no_errors(driver.press_edit("Deselect"))
    assert driver.dropdown_value == "none" and driver.selection_drawn(key) == 0


def test_dropdown_selects_and_a_ba_click_moves_the_laser_end(driver):
    app = driver.app
    pid = app.state.picks[4].id
    notes = driver.select_in_dropdown(pid)
    assert no_errors(notes), notes
    assert app.state.selected == pid and driver.selection_drawn("vertical") > 0
    row, col = app.state.get(pid).laser_rc
    valid = app.depth.valid
    new = next((r, c) for r, c in ((row, col + 1), (row + 1, col), (row, col - 1)) if valid[r, c])
    notes = driver.click_cell("horizontal", *new)
    assert no_errors(notes), notes
    assert driver.wait_idle()
    assert app.state.get(pid).laser_rc == new and len(app.state.picks) == 6
    assert app.result is not None and "Solve failed" not in driver.result_panel
    assert np.isfinite(app.result.mean_px)
    # Selecting another pair by Shift+click on a BA image switches the selection.
    other = app.state.picks[0].id
    notes = driver.shift_click("horizontal", driver.marker_display_pixel("horizontal", other))
    assert no_errors(notes) and app.state.selected == other and driver.dropdown_value == f"#{other}"


def test_snap_refines_ba_clicks_on_the_full_image_and_in_the_loupe_alike(driver):
    """With "Snap clicks to corners", a BA click lands on the strongest corner near it (calib_core's refinement of
    the grey image the pane shows), whether it is made on the full BA image or through the BA loupe."""
    from calib_core.panorama import refine_click_to_corner

    app = driver.app
    key = app.ba_keys[0]
    app.state.set_view(snap=True)
    assert driver.press_edit("Deselect") == []
    for row, col in [(45, 262), (83, 256), (105, 480)]:
        corner = refine_click_to_corner(app.laser_images.ba_display(key), (float(col), float(row)), 3.0)
        want = (int(round(corner[1])), int(round(corner[0])) % app.depth.shape[1])
        n = len(app.state.picks)
        assert driver.click_cell(key, row, col) == []
        full = app.state.picks[-1]
        assert len(app.state.picks) == n + 1 and full.laser_rc == want
        assert driver.press_edit("Undo") == []
        app.loupes.frame_ba(key, row, col)
        assert driver.click_loupe_cell(row, col) == []
        assert app.state.picks[-1].laser_rc == want
        assert driver.press_edit("Undo") == []
    app.state.set_view(snap=False)
    assert driver.click_cell(key, 45, 262) == [] and app.state.picks[-1].laser_rc == (45, 262)
