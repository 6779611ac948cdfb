"""The camera-view laser render and the rough alignment (issue 20, items 1-4), through the app's test driver.

Truth: a pinhole projection written here with numpy from the KITTI camera file's K (KITTI's published calibration
for the far end of the drag tests), the render recomputed here with :func:`calib_core.render.render_from_camera`,
and the mounting presets' definition (camera axes in the lidar frame, from the module's docstring).
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calib_core.alignment import preset_T
from calib_core.io.kitti_calib import read_kitti_camera2
from calib_core.render import render_from_camera
from calib_core.transforms import invert_T, rotation_angle_deg
from repo_paths import SAMPLE

ROOT = Path(__file__).resolve().parents[1]
KITTI = ROOT.parent / "shared" / "data" / "kitti_object_000002"
CAMERA_YAML = ROOT / "real_data" / "kitti_000002_camera.yaml"
needs_kitti = pytest.mark.skipif(not (KITTI / "velodyne" / "000002.bin").is_file(),
                                 reason=f"KITTI frame not found at {KITTI} (../shared/data)")
# The KITTI camera file's K, written out here (rectified: no distortion).
FX, CX, CY, W, H = 721.5377, 609.5593, 172.854, 1242, 375


def kitti_app(tmp_path: Path, session: Path | None = None, **kwargs):
    from app.server import CalibrationApp
    from app_driver import AppDriver

    app = CalibrationApp(KITTI / "velodyne" / "000002.bin", KITTI / "image_2" / "000002.png", CAMERA_YAML,
                         session_path=session or tmp_path / "session.yaml", port=0, **kwargs)
    return app, AppDriver(app)


def project(T: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole pixels ``(N, 2)`` of lidar points under ``T`` and which lie in front of the camera."""
    p = points @ T[:3, :3].T + T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([FX * p[:, 0] / p[:, 2] + CX, FX * p[:, 1] / p[:, 2] + CY], axis=1)
    return uv, p[:, 2] > 0.1


def ray_point(T: np.ndarray, uv: tuple[float, float], depth_m: float = 50.0) -> np.ndarray:
    """The lidar-frame point ``depth_m`` in front of the camera that ``T`` shows at pixel ``uv``."""
    p_cam = np.array([(uv[0] - CX) / FX, (uv[1] - CY) / FX, 1.0]) * depth_m
    return (invert_T(T) @ np.append(p_cam, 1.0))[:3]


def columns_seen(app, T: np.ndarray) -> np.ndarray:
    """Scan columns with a point the camera shows under ``T`` (independent of the app's window code)."""
    rows, cols = np.nonzero(app.depth.valid)
    uv, front = project(T, app.depth.points[rows, cols])
    inside = front & (uv[:, 0] >= -0.5) & (uv[:, 0] <= W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= H - 0.5)
    return np.unique(cols[inside])


@needs_kitti
def test_the_render_pane_a_click_on_it_and_the_ba_columns_before_any_pair(tmp_path):
    from app.render_pane import RENDER_KEY

    app, d = kitti_app(tmp_path)
    try:
        assert d.wait_render()
        # The pane: the camera image's size and framing, right below it, same size on the page.
        shown = d.render_shown
        assert shown.source == "default" and np.array_equal(shown.T_camera_lidar, preset_T("+x"))
        # KITTI's .bin has reflectance: the render starts shaded by it (the sample has none: range, below).
        assert shown.mode == "intensity" and app.state.view.render_mode == "intensity"
        raw, slot = app.slots["raw"], app.slots[RENDER_KEY]
        assert (slot.width_px, slot.height_px) == (W, H) == (raw.width_px, raw.height_px)
        assert (slot.render_width, slot.render_height) == (raw.render_width, raw.render_height)
        assert slot.center[0] == raw.center[0] and slot.bounds()[1] > raw.bounds()[3]
        assert d.render_texture().shape == (H, W, 3)
        assert d.ba_columns_choice == "Facing the camera"
        # Before any pose the BA panes show the columns the '+x' preset puts in the camera, not 360 degrees.
        n_cols = app.depth.shape[1]
        seen = columns_seen(app, preset_T("+x"))
        assert app.ba_window.display_cols(seen)[1].all() and app.ba_window.width < 0.35 * n_cols

        # A preset is a rough pose: predictions use it; the BA columns follow it (camera looking right).
        assert d.press_preset("-y") == []
        assert np.array_equal(d.rough_pose, preset_T("-y")) and app.pose() is not None
        seen_right = columns_seen(app, preset_T("-y"))
        assert app.ba_window.display_cols(seen_right)[1].all() and app.ba_window.width < 0.35 * n_cols
        assert not app.ba_window.display_cols(seen)[1].any()  # the columns ahead are gone
        assert d.press_preset("+x") == [] and d.wait_render()
        assert d.render_shown.source == "rough"

        # A click on the render picks the cell it draws there (the render recomputed here).
        expected = render_from_camera(app.depth, app.camera, preset_T("+x"))
        has = expected.cell_rc[..., 0] >= 0
        assert np.array_equal(has, d.render_shown.render.cell_rc[..., 0] >= 0)
        vs, us = np.nonzero(has)
        targets = [(300.0, 260.0), (640.0, 200.0), (1000.0, 300.0)]
        for goal in targets:
            k = int(np.argmin(np.hypot(us - goal[0], vs - goal[1])))
            u, v = float(us[k]), float(vs[k])
            assert d.click_render(u + 0.3, v - 0.2) == []
            pick = app.state.picks[-1]
            assert pick.laser_rc == tuple(int(x) for x in expected.cell_rc[int(v), int(u)])
            # ... a cell whose point the pose puts near the click (its footprint covers a few pixels).
            uv, front = project(preset_T("+x"), app.depth.points[pick.laser_rc][None])
            assert front[0] and np.hypot(uv[0, 0] - u, uv[0, 1] - v) < 12.0
            # The laser loupe shows the render's crop of the camera loupe's pixels, centred on the click.
            assert app.loupes.shows_render and d.loupe_view("camera")["center"] == pytest.approx((u + 0.3, v - 0.2))
            crop = app.loupes.camera_crop
            tex = d.loupe_texture("ba")
            k_tex = tex.shape[0] // crop.n
            # (its grey shading stretched over the crop: app.shown_render.stretched_grey, checked on its own)
            from app.shown_render import pane_texture, stretched_grey

            part = d.render_shown.rgba[crop.v0:crop.v0 + crop.n, crop.u0:crop.u0 + crop.n]
            assert np.array_equal(tex[::k_tex, ::k_tex], pane_texture(stretched_grey(part)))
        # Two laser clicks in a row replace the laser end: one pick, an ordinary laser_rc end ...
        assert len(app.state.picks) == 1
        # ... which a camera click completes into an ordinary pair.
        assert d.click_camera(700.0, 180.0) == []
        (pair,) = app.state.pairs()
        assert pair.laser_rc == app.state.picks[-1].laser_rc and pair.laser_xyz is None
        assert pair.pixel == pytest.approx((700.0, 180.0))

        # Where the render shows no return, within 4 px: the nearest rendered pixel; farther: refused, one line.
        empty_v, empty_u = np.nonzero(~has)
        top = (5.0, 5.0)
        assert not has[5, 5]
        notes = d.click_render(*top)
        assert [t for t, _ in notes] == ["Not accepted"] and "no laser return here" in notes[0][1]
        # A pixel whose only rendered pixel within 2 px is 2 px to its right.
        gap = next(((u, v) for v, u in zip(empty_v, empty_u) if 2 < v < H - 3 and 2 < u < W - 3
                    and has[v, u + 2] and not has[v - 2:v + 3, u - 2:u + 2].any()), None)
        assert gap is not None
        assert d.click_render(float(gap[0]), float(gap[1])) == []
        assert app.state.picks[-1].laser_rc == tuple(int(x) for x in expected.cell_rc[gap[1], gap[0] + 2])

        # A BA click: the laser loupe shows the BA image again.
        col = int(app.ba_window.columns[10])
        row = int(np.flatnonzero(app.depth.valid[:, col])[0])
        assert d.click_cell("horizontal", row, col) == []
        assert not app.loupes.shows_render and d.loupe_view("ba")["center"] == (row, col)
    finally:
        app.stop()


@needs_kitti
def test_dragging_turns_the_view_so_the_grabbed_point_follows_the_mouse(tmp_path):
    from app.render_pane import RENDER_KEY

    session = tmp_path / "session.yaml"
    app, d = kitti_app(tmp_path, session)
    try:
        assert d.press_preset("+x") == [] and d.set_align_by_drag(True) == []
        assert app.state.view.render_blend == 0.5  # the render shows over the photo while aligning
        T0 = d.rough_pose.copy()
        # Grab the render at the principal point and drag it 40 px right and 25 px down: the scene point under
        # the cursor must follow it (exact for a point on the optical axis).
        grab, drop = (CX, CY), (CX + 40.0, CY + 25.0)
        far = ray_point(T0, grab)
        handlers = app.align.drag_callbacks(RENDER_KEY, None)
        slot = app.slots[RENDER_KEY]

        def event(phase: str, uv) -> SimpleNamespace:
            return SimpleNamespace(client=d.tab, target=None, phase=phase, modifier=None, button="left",
                                   start_position=tuple(slot.world_from_pixel(np.array([grab]))[0]),
                                   end_position=tuple(slot.world_from_pixel(np.array([uv]))[0]),
                                   start_screen_pos=(0.5, 0.5), end_screen_pos=(0.6, 0.6))

        for phase, uv in (("start", (CX + 5.0, CY)), ("update", (CX + 20.0, CY + 10.0))):
            for h in handlers:
                d._fire(h, event(phase, uv))
        # Mid-drag only the render follows; the rough pose (and all that uses it) waits for the drop.
        assert d.wait_render() and d.render_shown.source == "drag"
        uv_mid, _ = project(d.render_shown.T_camera_lidar, far[None])
        np.testing.assert_allclose(uv_mid[0], (CX + 20.0, CY + 10.0), atol=1e-6)
        assert np.array_equal(d.rough_pose, T0)
        for h in handlers:
            d._fire(h, event("end", drop))
        assert d.wait_render() and d.render_shown.source == "rough"
        uv_end, _ = project(d.rough_pose, far[None])
        np.testing.assert_allclose(uv_end[0], drop, atol=1e-6)
        # The camera turned about its centre: it did not move.
        np.testing.assert_allclose(invert_T(d.rough_pose)[:3, 3], invert_T(T0)[:3, 3], atol=1e-12)

        # Shift+drag on the camera image rolls about the principal point: 100 px right of it -> 100 px below.
        T1 = d.rough_pose.copy()
        side = ray_point(T1, (CX + 100.0, CY))
        assert d.drag("raw", (CX + 100.0, CY), (CX, CY + 100.0), shift=True) == []
        uv_roll, _ = project(d.rough_pose, np.array([side, ray_point(T1, (CX, CY))]))
        np.testing.assert_allclose(uv_roll, [[CX, CY + 100.0], [CX, CY]], atol=1e-6)
        assert rotation_angle_deg(d.rough_pose[:3, :3], T1[:3, :3]) == pytest.approx(90.0)
        assert d.press_align_undo() == [] and np.allclose(d.rough_pose, T1)

        # The buttons: a turn moves the render by 0.5 deg, a move steps the camera 5 cm along its own axis.
        assert d.press_turn("▶") == []
        uv_step, _ = project(d.rough_pose, ray_point(T1, (CX, CY))[None])
        np.testing.assert_allclose(uv_step[0], (CX + FX * math.tan(math.radians(0.5)), CY), atol=1e-6)
        T2 = d.rough_pose.copy()
        assert d.press_move("z+") == []
        step = invert_T(d.rough_pose)[:3, 3] - invert_T(T2)[:3, 3]
        np.testing.assert_allclose(step, 0.05 * T2[2, :3], atol=1e-12)  # camera z axis in the lidar frame
        T3 = d.rough_pose.copy()
        # The drop is an ordinary initial extrinsic: a pending laser pick is predicted where it projects.
        assert d.set_align_by_drag(False) == []
        col = int(app.ba_window.columns[len(app.ba_window.columns) // 2])
        row = int(np.flatnonzero(app.depth.valid[:, col])[len(np.flatnonzero(app.depth.valid[:, col])) // 2])
        assert d.click_cell("horizontal", row, col) == []
        uv_cell, _ = project(T3, app.depth.points[row, col][None])
        assert app.pose_source.predict_pixel(row, col) == pytest.approx(tuple(uv_cell[0]), abs=1e-6)
        assert "from '+x'" in d.align_text
    finally:
        app.stop()
    # The rough pose is in the session: a restart keeps it.
    app, d = kitti_app(tmp_path, session)
    try:
        np.testing.assert_allclose(d.rough_pose, T3, atol=1e-12)
        assert d.wait_render() and d.render_shown.source == "rough"
    finally:
        app.stop()


def test_an_imported_extrinsic_is_the_start_the_rough_pose_is_refused_once_solved(tmp_path):
    """On the sample: the file given at start is the rough pose and "Back to the imported extrinsic" returns to it;
    with 4+ pairs solved the render shows the solve and the Align actions say why they do nothing."""
    from app.server import CalibrationApp
    from app_driver import AppDriver
    from calib_core.io.extrinsics import load_extrinsics_yaml

    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=0,
                         initial_extrinsics_path=SAMPLE / "ground_truth.yaml")
    d = AppDriver(app)
    try:
        np.testing.assert_allclose(d.rough_pose, truth)
        assert d.wait_render() and d.render_shown.source == "rough"
        assert d.render_shown.mode == "range"  # the sample's scan has no intensity field
        # The pose line names the nearest preset and the camera centre (-R^T t) in the lidar frame.
        turned = {k: rotation_angle_deg(truth[:3, :3], preset_T(k)[:3, :3]) for k in ("+x", "-y", "+y", "-x")}
        nearest = min(turned, key=turned.get)
        centre = -truth[:3, :3].T @ truth[:3, 3]
        assert app.align.folder.expand_by_default and d.align_text == (
            f"Rough pose: {turned[nearest]:.1f}° from '{nearest}'; camera centre at ({centre[0]:.2f}, "
            f"{centre[1]:.2f}, {centre[2]:.2f}) m in the lidar frame.")
        assert d.press_preset("-y") == [] and np.array_equal(d.rough_pose, preset_T("-y"))
        assert d.press_back_to_imported() == [] and np.allclose(d.rough_pose, truth)
        assert d.upload_pairs("pairs.yaml", (SAMPLE / "pairs.yaml").read_bytes())[0][0] == "Pairs imported"
        assert d.wait_idle() and app.result is not None and d.wait_render()
        assert d.render_shown.source == "solve"
        np.testing.assert_allclose(d.render_shown.T_camera_lidar, app.result.T_camera_lidar)
        # Solved: the rough pose is not used; the Align folder says so and tabs opened now find it folded.
        assert "A calibration from 4+ pairs is shown" in d.align_text and not app.align.folder.expand_by_default
        notes = d.press_preset("+x")
        assert [t for t, _ in notes] == ["Not accepted"] and "pairs are solved" in notes[0][1]
        assert np.allclose(d.rough_pose, truth)
    finally:
        app.stop()


def test_on_a_panorama_the_render_is_unwrapped_like_the_photo_and_clicks_map_back(tmp_path):
    """The sample's OCam image is shown unwrapped: the render is shown the same way, same size, and a click on it
    picks the cell the render draws at the original pixel under the click; as recorded, likewise."""
    from app.render_pane import RENDER_KEY
    from app.server import CalibrationApp
    from app_driver import AppDriver

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=0)
    d = AppDriver(app)
    try:
        assert d.camera_key == "panorama" and d.wait_render()
        expected = render_from_camera(app.depth, app.camera, preset_T("+x"))  # no pose yet: the '+x' preset
        vs, us = np.nonzero(expected.cell_rc[..., 0] >= 0)
        for view in ("panorama", "raw"):
            if view == "raw":
                assert d.set_panorama(False) == [] and d.camera_key == "raw"
            slot, cam = app.slots[RENDER_KEY], app.slots[view]
            assert (slot.width_px, slot.height_px, slot.render_width, slot.render_height) == (
                cam.width_px, cam.height_px, cam.render_width, cam.render_height)
            assert d.render_texture().shape == app.camera_views[view].image.shape
            for goal in ((200.0, 240.0), (450.0, 300.0)):
                k = int(np.argmin(np.hypot(us - goal[0], vs - goal[1])))
                assert d.click_render(float(us[k]), float(vs[k])) == []
                assert app.state.picks[-1].laser_rc == tuple(int(x) for x in expected.cell_rc[vs[k], us[k]])
    finally:
        app.stop()
