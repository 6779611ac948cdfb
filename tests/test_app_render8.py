"""By-eye frictions of run 7 (docs/by_eye.md) in the camera-view render and its loupe, driven through
:class:`app_driver.AppDriver` on the committed sample (one test per friction)."""

from __future__ import annotations

import numpy as np

from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks
from calib_core.transforms import transform_points

from app_driver import AppDriver


def _clustered_corners(scene, n: int, around: int = 11) -> list[tuple[tuple[int, int], tuple[float, float]]]:
    """``n`` corners close together in the photo (distinct laser cells): ``((row, col), (u, v))`` from the ground
    truth.  Four such pairs fix the pose poorly: their solve is "unreliable"."""
    corners = np.asarray(scene.corners_lidar, np.float64).reshape(-1, 3)
    rc, err = laser_picks(scene.depth, corners)
    pts = transform_points(scene.T_camera_lidar, corners)
    uv, seen = scene.camera.project(pts)
    usable = np.flatnonzero((err <= MAX_LASER_PICK_ERROR_M) & seen & (pts[:, 2] > 0))
    start = usable[around]
    out, cells = [], set()
    for k in usable[np.argsort(np.hypot(*(uv[usable] - uv[start]).T))]:
        cell = (int(rc[k, 0]), int(rc[k, 1]))
        if cell not in cells:
            cells.add(cell)
            out.append((cell, (float(uv[k, 0]), float(uv[k, 1]))))
        if len(out) == n:
            break
    return out


def _spread_to(pose: np.ndarray, scene) -> float:
    """Median pixel distance, over every corner the camera sees, between ``pose``'s projection and the truth's."""
    corners = np.asarray(scene.corners_lidar, np.float64).reshape(-1, 3)
    truth, ok_t = scene.camera.project(transform_points(scene.T_camera_lidar, corners))
    mine, ok_m = scene.camera.project(transform_points(pose, corners))
    ok = ok_t & ok_m
    return float(np.median(np.hypot(*(truth[ok] - mine[ok]).T))) if ok.any() else float("inf")


def test_an_unreliable_solve_is_not_rendered_the_rough_pose_refitted_to_the_pairs_is(app, scene):
    """Run 7: the 4th pair's solve was unreliable (t 0.6 m off) and the render switched to it ("changed completely,
    hard to compare with the photo until pair 5")."""
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    for cell, pixel in _clustered_corners(scene, 4):
        assert d.click_cell(app.ba_keys[0], *cell) == [] and d.click_camera(*pixel) == []
    assert d.wait_idle() and d.wait_render()
    bundle = app.solve_bundle
    assert bundle is not None and bundle.result.quality.status == "unreliable"  # the situation of run 7
    shown = d.render_shown
    # The render and the predictions use the rough pose, and the title says why.
    assert not np.array_equal(shown.T_camera_lidar, bundle.result.T_camera_lidar)
    assert np.array_equal(shown.T_camera_lidar, d.rough_pose) and np.array_equal(app.pose(), d.rough_pose)
    assert "under the rough pose: the solve is unreliable" in app.render_pane.title()
    assert "solve is unreliable" in d.align_text
    # The rough pose is turned to fit the four pairs: it is the rough pose the 3-pair fit left, refitted ("4 pairs")
    # and it shows the scene as the truth does far better than the unreliable solve (every corner, not just the 4).
    assert "refitted from 4 pairs" in app.pose_source.last_turn.note()
    assert _spread_to(d.rough_pose, scene) < 0.25 * _spread_to(bundle.result.T_camera_lidar, scene)
    # The Align buttons still turn the rough pose (it is what the page shows).
    before = d.rough_pose.copy()
    assert d.press_turn("▶") == [] and d.wait_render() and not np.array_equal(d.rough_pose, before)
    assert np.array_equal(d.render_shown.T_camera_lidar, d.rough_pose)
    # Spread pairs until the solve is no longer unreliable: the render then uses the solve.
    for pair in simulate_pairs(scene, 12, np.random.default_rng(1), pixel_noise_px=0.0):
        if app.solve_bundle.result.quality.status != "unreliable":
            break
        if tuple(pair.laser_rc) in {tuple(p.laser_rc) for p in app.state.picks}:
            continue
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
        assert d.wait_idle()
    bundle = app.solve_bundle
    assert bundle.result.quality.status in ("ok", "warning")
    assert d.wait_render()
    assert np.array_equal(d.render_shown.T_camera_lidar, bundle.result.T_camera_lidar)
    assert np.array_equal(app.pose(), bundle.result.T_camera_lidar)
    assert "under the solved pose" in app.render_pane.title()


def test_the_render_loupe_stays_on_the_pairs_laser_end_while_its_photo_end_is_refined(app, scene):
    """Run 7: a refining click in the photo loupe refitted the rough pose (2 pairs) and the render loupe moved under
    the person: its title went r5 c982 -> r4 c981 -> r5 c986, a click planned on it landed elsewhere, and once it
    said "no return here" on the pair's cell."""
    from calib_core.synthetic import simulate_pairs

    import time

    from calib_core.alignment import rotate_about_camera

    from app.pose_source import REFIT_CLICK_GRACE_S

    d = AppDriver(app)
    app.pose_source.adopt_rough_pose(rotate_about_camera(scene.T_camera_lidar, 0.02, -0.015, 0.01))  # 1.5 deg off
    first, second = simulate_pairs(scene, 2, np.random.default_rng(5), pixel_noise_px=0.0)
    assert d.click_cell(app.ba_keys[0], *first.laser_rc) == [] and d.click_camera(*first.pixel) == []
    assert d.wait_idle() and d.wait_render()
    # The second pair: its laser end picked on the render (the loupe shows the render's crop), its photo end clicked.
    assert d.click_render(*second.pixel) == [] and app.loupes.shows_render
    assert d.click_camera(*second.pixel) == [] and d.wait_idle() and d.wait_render()
    pick = app.state.picks[-1]
    assert pick.complete and app.pose_source.last_turn.why == "refitted from 2 pairs"
    cell = pick.laser_rc
    # Refine the photo end in the photo loupe, twice, a few pixels each: each refits the rough pose.
    for du, dv in ((3.0, -2.0), (-5.0, 3.0)):
        turned = app.pose_source.last_turn
        where = d.loupe_display_pixel("ba", (cell[1], cell[0]))  # the laser end in the render loupe
        crop = app.loupes.render_crop
        assert where is not None
        u, v = app.state.picks[-1].pixel
        assert d.click_loupe_camera(u + du, v + dv) == [] and d.wait_idle() and d.wait_render()
        assert app.pose_source.last_turn is not turned  # the pose was refitted, the render is the new one
        assert d.render_shown.T_camera_lidar is not None and app.state.picks[-1].laser_rc == cell
        # The render loupe shows the laser end where it was (within a pixel of the rounding of its crop), redrawn
        # under the new pose: the crop moved with the end's pixel in the new render.
        now = d.loupe_display_pixel("ba", (cell[1], cell[0]))
        assert now is not None and np.hypot(now[0] - where[0], now[1] - where[1]) <= 1.0, (where, now)
        new_uv = app.render_pane.pixel_of_cells(np.array([cell]))[0]
        rc = app.loupes.render_crop
        assert np.hypot(new_uv[0] - rc.u0 - now[0], new_uv[1] - rc.v0 - now[1]) < 1e-9
        assert rc.n == crop.n
        # Its title names the pair's cell, not the crop centre's.
        assert f"r{cell[0]} c{cell[1]}" in d.loupe_title("ba"), d.loupe_title("ba")
        # A click on the pair's cell in the loupe takes that cell (no "no return here"), once the refit's grace for
        # clicks planned on the old render is over.
        time.sleep(max(0.0, d.render_shown.made_at + REFIT_CLICK_GRACE_S + 0.05 - time.monotonic()))
        x, y = np.floor(np.asarray(now) + 0.5)
        notes = d.click("loupe_ba", (float(x), float(y)))
        assert [t for t, _ in notes] in ([], ["No change"]), notes
        assert app.state.picks[-1].laser_rc == cell, (app.state.picks[-1].laser_rc, cell)
        assert d.wait_idle() and d.wait_render()


def test_the_render_controls_carry_no_tooltip_their_help_is_in_the_folder_text(app):
    """Run 7: the tooltips of "Render over photo" and "Render shading" stayed over the Turn / Move buttons after a
    click on them (viser's hints cannot be dismissed from the server): the page gets no hint for them, and what
    they said is in the Align folder's text.  Read from the messages a tab receives over the websocket."""
    import asyncio

    from viser_wire import WireClient

    async def run() -> dict:
        async with WireClient(app.port) as tab:
            found = {}
            for kind, label in (("GuiSliderMessage", "Render over photo"), ("GuiDropdownMessage", "Render shading")):
                m = await tab.wait_for(lambda m: m.get("type") == kind and m.get("props", {}).get("label") == label)
                found[label] = m["props"]
            texts = [m["props"].get("_markdown", "") for m in tab.messages if m.get("type") == "GuiMarkdownMessage"]
            return {"props": found, "texts": texts}

    got = asyncio.run(run())
    for label, props in got["props"].items():
        assert not props.get("hint"), (label, props.get("hint"))
    help_text = " ".join(t for t in got["texts"] if "Render over photo" in t)
    assert "Render shading" in help_text and "bearing angle" in help_text and "0: photo only" in help_text, help_text
