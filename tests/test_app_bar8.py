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


def test_a_shift_click_on_a_markers_number_label_selects_that_pair(app, scene):
    """Run 7: a Shift+click on the "2" label beside marker 2 said "No pair within 18 px"."""
    d = AppDriver(app)
    _pairs(d, app, scene, 3)
    cam = d.tab.camera
    # The tab zoomed out (as a person sees the whole scan): a label's few screen pixels span many image pixels.
    cam.position = (cam.position[0], cam.position[1], cam.look_at[2] - 40.0)
    dist = cam.look_at[2] - cam.position[2]
    f = (cam.image_height / 2) / np.tan(cam.fov / 2)  # canvas px per world unit at the plane, times dist

    def world_of_screen(x: float, y: float) -> np.ndarray:  # the inverse of FakeCamera.screen_of on the plane
        return np.array([cam.position[0] + (x - cam.image_width / 2) * dist / f,
                         cam.position[1] + (y - cam.image_height / 2) * dist / f, 0.0])

    for key in (app.ba_keys[0], d.camera_key):
        slot = app.slot_of(key)
        for pick in app.state.picks:
            name = f"/annot/labels/{key}/{pick.id}"
            text, pos = app.nodes.drawn[name][1][1:]
            assert text == str(pick.id)
            # The middle of the digit: viser draws a label anchored bottom-left at its position, 9.6 CSS px per em
            # (12 px x font_screen_scale 0.8), padded by 0.2 line heights: about 5 px right of and 8 px above it.
            ax, ay = cam.screen_of(pos)
            uv = tuple(slot.pixel_from_world(world_of_screen(ax + 5.0, ay - 8.0)[None])[0])
            marker = np.array(d.marker_display_pixel(key, pick.id))
            ring_px = np.hypot(*(np.array(uv) - marker))
            m_reach = 2.5 * max(1.5 * max(slot.units_per_px, slot.units_per_px_y), 0.03) / slot.units_per_px
            assert ring_px > m_reach, (key, ring_px, m_reach)  # beyond the marker's own reach
            assert d.shift_click(key, uv) == [] and app.state.selected == pick.id, (key, pick.id, d.pair_status)
            assert "No pair within" not in d.pair_status
            assert d.press_pair_action("Cancel pair") == [] and app.state.selected is None
    # Well beside every label and marker: still no pair.
    key = app.ba_keys[0]
    marker = np.array(d.marker_display_pixel(key, app.state.picks[0].id))
    far = [marker + np.array(s) for s in ((-60.0, 60.0), (60.0, 60.0), (-60.0, -60.0), (60.0, -60.0))]
    others = np.array([d.marker_display_pixel(key, p.id) for p in app.state.picks])
    spot = max(far, key=lambda q: np.hypot(*(others - q).T).min())
    assert d.shift_click(key, tuple(spot)) == [] and app.state.selected is None and "No pair within" in d.pair_status


def test_the_refit_notice_shows_the_latest_refit_and_goes_with_the_next_pair(app, scene):
    """Run 7: after a later refit the bar still read "Pose refitted from 2 pairs: turned 0.8 deg"."""
    from scipy.spatial.transform import Rotation

    d = AppDriver(app)
    bar = app.pairs_panel.bar
    made = simulate_pairs(scene, 4, np.random.default_rng(5), pixel_noise_px=0.0)
    key = app.ba_keys[0]
    for pair in made[:2]:
        assert d.click_cell(key, *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle() and "(pose refitted from 2 pairs)" in bar.pose_note, bar.pose_note
    # The next pair started (its laser end clicked): the notice of the old refit goes.
    assert d.click_cell(key, *made[2].laser_rc) == [] and d.wait_idle()
    assert bar.pose_note == "", bar.pose_note
    # The pair made: the bar names this refit (its turn computed here from the two poses), or nothing.
    def latest_refit_shown(before: np.ndarray, n: int) -> None:
        after = d.rough_pose.copy()
        if np.allclose(before, after):
            assert bar.pose_note == "", bar.pose_note
        else:
            turned = np.degrees(Rotation.from_matrix(before[:3, :3].T @ after[:3, :3]).magnitude())
            assert f"the render turned {turned:.1f} deg (pose refitted from {n} pairs)" in bar.pose_note, bar.pose_note

    T = d.rough_pose.copy()
    assert d.click_camera(*made[2].pixel) == [] and d.wait_idle()
    latest_refit_shown(T, 3)
    # Undo takes the 3rd pair's camera end back: 2 pairs again, refitted to them (or not): the bar says which.
    T = d.rough_pose.copy()
    assert d.press_pair_action("Undo") == [] and d.wait_idle()
    latest_refit_shown(T, 2)
    # The 4th pair: the solve replaces the rough pose, and no notice stays.
    assert d.click_camera(*made[2].pixel) == [] and d.wait_idle()
    assert d.click_cell(key, *made[3].laser_rc) == [] and d.click_camera(*made[3].pixel) == [] and d.wait_idle()
    assert app.result is not None and bar.pose_note == ""


def test_the_live_line_counts_the_pairs_before_the_first_solve(app, scene):
    """Run 7: with 1-3 pairs the live line showed nothing."""
    d = AppDriver(app)
    bar = app.pairs_panel.bar
    assert d.wait_idle() and bar.live_line.replace("*", "") == "0 pairs · 4 more to solve", bar.live_line
    made = simulate_pairs(scene, 4, np.random.default_rng(5), pixel_noise_px=0.0)
    key = app.ba_keys[0]
    for n, pair in enumerate(made[:3], start=1):
        before = d.rough_pose
        assert d.click_cell(key, *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == [] and d.wait_idle()
        after = d.rough_pose  # refitted to these pairs when it changed
        turned = after is not None and (before is None or not np.allclose(before, after))
        want = [f"{n} pair{'s' if n > 1 else ''}"] + (["rough pose turned to fit them"] if turned else []) + [
            f"{4 - n} more to solve"]
        assert bar.live_line.replace("*", "") == " · ".join(want), (n, bar.live_line)
    assert n == 3 and "rough pose turned to fit them" in bar.live_line  # 2-3 pairs turn it (issue 20)
    assert d.click_cell(key, *made[3].laser_rc) == [] and d.click_camera(*made[3].pixel) == [] and d.wait_idle()
    assert app.result is not None and "4 pairs · mean" in bar.live_line and "more to solve" not in bar.live_line


def test_the_bar_gives_guided_pickings_reason_when_it_has_no_proposal(app, scene):
    """Run 7: the bar said only "Guided: no proposal; see Guided picking"; the reason was a long scroll away."""
    import re

    from calib_core.guide.evidence import ProposalScreen

    d = AppDriver(app)
    _pairs(d, app, scene, 4)
    app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=app.guide.screen.max_ellipse_px)  # none passes
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    for _ in range(12):  # the re-clicks of the 4 pairs, each skipped for good
        if d.guide_proposal is None:
            break
        assert d.press_guide("Skip") == [] and d.wait_guide()
    assert d.guide_proposal is None
    # The Guided folder's reason, with its count of candidates left out (the folder's own full text) ...
    m = re.search(r"No new corner to propose here; pick the next pairs by hand: of (\d+) corner-like spots? in "
                  r"the scan, most \((\d+)\) ([^;\n.]+)",
                  d.guide_panel.replace("\\", ""))
    assert m and int(m.group(1)) > 0, d.guide_panel
    # ... is in the pair bar's one line.
    bar = app.pairs_panel.bar.guide_status
    assert "\n" not in bar and bar.replace("\\", "") == (
        "**Guided:** n" + m.group(0)[1:]), bar


def test_the_bar_says_when_the_pairs_left_out_as_outliers_change(app, scene):
    """Run 7: at 6 pairs pair 2 was left out as an outlier; adding pair 7 put it back and left out pair 3, unsaid."""
    d = AppDriver(app)
    bar = app.pairs_panel.bar
    key = app.ba_keys[0]
    made = simulate_pairs(scene, 9, np.random.default_rng(11), pixel_noise_px=0.3)
    for pair in made[:6]:
        assert d.click_cell(key, *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle() and list(app.result.outlier_ids) == [] and bar.outlier_note == ""

    def add(pair, off_px: float) -> int:
        assert d.click_cell(key, *pair.laser_rc) == [] and d.click_camera(pair.pixel[0] + off_px, pair.pixel[1]) == []
        assert d.wait_idle()
        return app.state.picks[-1].id

    bad = add(made[6], 60.0)  # a click 60 px off: a gross outlier
    assert list(app.result.outlier_ids) == [bad], app.result.outlier_ids
    assert f"Pair {bad} now left out as an outlier." in bar.outlier_note, bar.outlier_note
    # It goes with the next pair started.
    assert d.click_cell(key, *made[7].laser_rc) == [] and d.wait_idle() and bar.outlier_note == ""
    assert d.press_pair_action("Cancel pair") == [] and d.wait_idle()
    # Pair `bad` re-clicked where it belongs (selected, then its camera end moved): back in the fit.
    app.state.select(bad)
    assert d.click_camera(*made[6].pixel) == [] and d.wait_idle()
    assert list(app.result.outlier_ids) == [] and f"Pair {bad} back in the fit." in bar.outlier_note, bar.outlier_note
    assert f"Changed with this solve: Pair {bad} back in the fit." in app.calibration_panel.result_text
    # Two more pairs, one of them 60 px off: only it is named.
    add(made[7], 0.0)
    assert list(app.result.outlier_ids) == [] and bar.outlier_note == ""  # nothing changed: nothing said
    second = add(made[8], -60.0)
    assert list(app.result.outlier_ids) == [second], app.result.outlier_ids
    assert bar.outlier_note.endswith(f"Pair {second} now left out as an outlier."), bar.outlier_note
    assert f"Left out of the fit: pair {second}  \nChanged with this solve: Pair {second} now left out as an outlier." \
        in app.calibration_panel.result_text
    # Deleting the outlier: it is not "back in".
    app.state.select(second)
    assert d.press_edit("Delete") == [] and d.wait_idle()
    assert list(app.result.outlier_ids) == [] and "back in" not in bar.outlier_note


def test_the_outlier_change_note_names_who_went_out_and_who_came_back():
    """The run-7 case in words: pair 2 was out; with pair 7 pair 3 went out and pair 2 came back."""
    from app.ui_common import outlier_change_note

    assert outlier_change_note([2], [3], [1, 2, 3, 4, 5, 6, 7]) == "Pair 3 now left out as an outlier; pair 2 back in the fit."
    assert outlier_change_note([], [3, 5], [3, 5, 6]) == "Pairs 3, 5 now left out as outliers."
    assert outlier_change_note([2, 4], [], [2, 4]) == "Pairs 2, 4 back in the fit."
    assert outlier_change_note([2], [], [1, 3]) == ""  # pair 2 deleted: not back in
    assert outlier_change_note([2], [2], [1, 2]) == ""
