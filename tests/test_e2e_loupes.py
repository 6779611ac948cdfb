"""Picking through the loupes in a real headless Chromium: 10 pairs on the sample at <= 3 UI actions per pair.

Every click or button press on the page is one action, counted here.  A pair is:

1. a click on the full BA image, aimed a few cells off the wanted cell (the
   full view shows about half a screen pixel per cell: a person cannot do better);
   the BA loupe centres there;
2. the wanted cell, clicked in the BA loupe (it replaces the rough cell);
3. the camera end: while there is no pose yet (pairs 1-4) a click on the full
   camera image, after that a click in the camera loupe, which the BA click
   centred on the predicted pixel.

The ground truth (cells and pixels) comes from :func:`calib_core.synthetic.simulate_pairs`;
screen positions from the app's page-position hook; the scale at each pick
(screen px per BA cell, per image pixel) is measured there too and printed.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import rotation_angle_deg

from browser_helpers import CHROMIUM, TIMEOUT_S, AnnotationTab, free_port, save_small_png, wait_for
from repo_paths import SAMPLE

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[1]
SCREENSHOT = ROOT / "docs" / "img" / "loupes_sample.png"
N_PAIRS = 10
VIEWPORT = {"width": 1400, "height": 900}
ROUGH_OFFSET = (2, -3)  # (rows, cols) of the full-image BA click from the wanted cell


@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_ten_pairs_through_the_loupes(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.server import CalibrationApp
    from app_driver import AppDriver

    t_start = time.monotonic()
    scene = load_sample(SAMPLE)
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    pairs = simulate_pairs(scene, N_PAIRS, np.random.default_rng(3), pixel_noise_px=0.0)
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=free_port())
    driver = AppDriver(app)
    actions = 0
    picks_log: list[str] = []
    ba_scales: list[float] = []
    loupe_px_scales: list[float] = []
    try:
        with sync_api.sync_playwright() as p:
            tab = AnnotationTab(p, app, VIEWPORT)
            page, screen, scale = tab.page, tab.screen, tab.scale


            def click(target: str, uv) -> None:
                nonlocal actions
                before = app.state.version
                page.mouse.click(*screen(target, uv))
                actions += 1
                wait_for(lambda: app.state.version > before, f"the click on {target} to register")
                assert driver.wait_idle(TIMEOUT_S)  # the loupes re-framed (as a person waits to see them move)

            def drawn() -> bool:  # the images and loupes are on the page (not the light backdrop)
                return tab.shows_image_at((("camera", (320.0, 300.0)), ("loupe_ba", driver.loupe_view("ba")["center"][::-1])))

            wait_for(drawn, "the page to draw the images and loupes", interval=0.2)
            for k, pair in enumerate(pairs):
                row, col = pair.laser_rc
                key = app.ba_keys[k % len(app.ba_keys)]
                rough = (int(np.clip(row + ROUGH_OFFSET[0], 0, app.depth.shape[0] - 1)), col + ROUGH_OFFSET[1])
                had_pose = app.pose() is not None
                click(key, (rough[1], rough[0]))
                assert driver.loupe_view("ba")["center"] == rough  # the BA loupe centred on the click
                s_ba = scale("loupe_ba", (col, row))
                click("loupe_ba", (col, row))
                if had_pose:
                    assert driver.loupe_display_pixel("camera", pair.pixel) is not None, "the prediction missed the truth"
                    s_px = scale("loupe_camera", pair.pixel)
                    click("loupe_camera", pair.pixel)
                    loupe_px_scales.append(s_px)
                    where = "camera loupe"
                else:
                    s_px = scale("camera", pair.pixel)
                    click("camera", pair.pixel)
                    where = "full camera view"
                ba_scales.append(s_ba)
                picks_log.append(f"pair {k + 1}: BA loupe {s_ba:.1f} px/cell, {where} {s_px:.2f} px/image px")
                pick = app.state.picks[-1]
                assert len(app.state.picks) == k + 1 and pick.complete
                assert pick.laser_rc == (row, col)
                assert np.hypot(*np.subtract(pick.pixel, pair.pixel)) < 0.05, (pick.pixel, pair.pixel)

            wait_for(lambda: app.result is not None and app.result.n_pairs == N_PAIRS and driver.wait_idle(),
                     "the solve of 10 pairs")
            result = app.result
            rot_err = rotation_angle_deg(result.T_camera_lidar[:3, :3], truth[:3, :3])
            trans_err = float(np.linalg.norm(result.T_camera_lidar[:3, 3] - truth[:3, 3]))

            # A zoom step keeps the loupe's centre and shows more columns (context).
            before = driver.loupe_view("ba")
            page.get_by_role("button", name="BA -").click()
            wait_for(lambda: driver.loupe_view("ba")["size"] > before["size"], "the BA loupe to zoom out")
            assert driver.loupe_view("ba")["center"] == before["center"]

            notes = page.locator(".mantine-Notification-root")

            def close_notifications() -> bool:
                if notes.count() == 0:
                    return True
                try:  # they also close by themselves, so one may vanish under the click
                    notes.first.locator("button").first.click(timeout=1000)
                except sync_api.TimeoutError:
                    pass
                return notes.count() == 0

            wait_for(close_notifications, "notifications to close")
            size = save_small_png(page.screenshot(), SCREENSHOT)
            tab.browser.close()
    finally:
        app.stop()

    elapsed = time.monotonic() - t_start
    print("\n" + "\n".join(picks_log))
    print(f"loupes e2e: {N_PAIRS} pairs in {actions} actions ({actions / N_PAIRS:.2f} per pair); "
          f"BA loupe {min(ba_scales):.1f}-{max(ba_scales):.1f} px/cell; camera loupe "
          f"{min(loupe_px_scales):.1f}-{max(loupe_px_scales):.1f} px/image px; rotation error {rot_err:.3f} deg, "
          f"translation {100 * trans_err:.2f} cm; screenshot {size / 1e3:.0f} kB; run time {elapsed:.1f} s")
    assert actions / N_PAIRS <= 3.0
    assert min(ba_scales) >= 8.0
    assert min(loupe_px_scales) >= 8.0
    assert rot_err <= 0.5 and trans_err <= 0.05


PJLAB = ROOT.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"
PJLAB_PAIRS = ROOT / "real_data" / "pairs" / "auto_calib_pairs.yaml"
PJLAB_SCREENSHOT = ROOT / "docs" / "img" / "loupes_auto_calib.png"
N_REAL = 6


def rough_extrinsic(T: np.ndarray, degrees: float = 2.0, metres: float = 0.20) -> np.ndarray:
    """``T`` turned by ``degrees`` about a fixed oblique axis and shifted by ``metres`` (camera frame)."""
    from scipy.spatial.transform import Rotation

    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    shift = np.array([1.0, -1.0, 0.5]) / np.linalg.norm([1.0, -1.0, 0.5])
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(np.radians(degrees) * axis).as_matrix() @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + metres * shift
    return out


@pytest.mark.realdata
@pytest.mark.skipif(not (PJLAB / "calib.pcd").is_file(), reason=f"real data not found at {PJLAB} (../shared/data)")
@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_six_pairs_on_the_real_scan_from_a_rough_extrinsic(tmp_path):
    """PJLab auto_calib (64 x 1800 scan, 1920 x 1200 photo): 6 pairs at <= 4 actions each, every pick in a loupe.

    The aimed cells and pixels are the committed pairs (real_data/pairs/auto_calib_pairs.yaml: foreground corners,
    pixels projected with the published extrinsic).  The app starts from that extrinsic turned by 2 deg and
    shifted by 20 cm.  A pair: a rough click on the full BA image (a few columns off), the cell in the BA loupe;
    then, if the camera loupe (framed on the predicted pixel) does not show the corner, a rough click on the full
    camera image; the pixel in the camera loupe.
    """
    import json

    import yaml

    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.server import CalibrationApp
    from app_driver import AppDriver
    from calib_core.pairs import load_pairs_yaml

    t_start = time.monotonic()
    doc = json.loads((PJLAB / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    published = np.array(doc["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], float)
    rough = rough_extrinsic(published)
    rough_path = tmp_path / "rough.yaml"
    rough_path.write_text(yaml.safe_dump({"T_camera_lidar": {"matrix": rough.tolist()}}))
    pairs = load_pairs_yaml(PJLAB_PAIRS)[:N_REAL]
    app = CalibrationApp(PJLAB / "calib.pcd", PJLAB / "calib.png", PJLAB / "center_camera-intrinsic.json",
                         session_path=tmp_path / "session.yaml", port=free_port(), initial_extrinsics_path=rough_path)
    driver = AppDriver(app)
    actions = 0
    log: list[str] = []
    cell_scales: list[float] = []
    px_scales: list[float] = []
    try:
        np.testing.assert_allclose(app.initial_T_camera_lidar, rough, atol=1e-9)
        with sync_api.sync_playwright() as p:
            tab = AnnotationTab(p, app, VIEWPORT)
            page, screen, scale = tab.page, tab.screen, tab.scale


            def click(target: str, uv) -> None:
                nonlocal actions
                before = app.state.version
                page.mouse.click(*screen(target, uv))
                actions += 1
                wait_for(lambda: app.state.version > before, f"the click on {target} to register")
                assert driver.wait_idle(TIMEOUT_S)

            def drawn() -> bool:
                return tab.shows_image_at((("camera", (960.0, 600.0)),))

            wait_for(drawn, "the page to draw the images", interval=0.2)
            for k, pair in enumerate(pairs):
                row, col = pair.laser_rc
                key = "diag_pos45"
                click(key, (col - 4, row + 1))  # rough: the full BA image shows about 0.3 px per column
                s_cell = scale("loupe_ba", (col, row))
                click("loupe_ba", (col, row))
                n_actions = 2
                if driver.loupe_display_pixel("camera", pair.pixel) is None:
                    click("camera", (pair.pixel[0] + 6.0, pair.pixel[1] - 4.0))  # rough, to move the camera loupe
                    n_actions += 1
                s_px = scale("loupe_camera", pair.pixel)
                click("loupe_camera", pair.pixel)
                n_actions += 1
                pick = app.state.picks[-1]
                assert len(app.state.picks) == k + 1 and pick.complete
                assert pick.laser_rc == (row, col)  # the aimed cell exactly (0 cells off)
                assert np.hypot(*np.subtract(pick.pixel, pair.pixel)) < 0.05
                cell_scales.append(s_cell)
                px_scales.append(s_px)
                log.append(f"pair {k + 1}: {n_actions} actions, BA loupe {s_cell:.1f} px/cell, "
                           f"camera loupe {s_px:.2f} px/image px")
            wait_for(lambda: app.result is not None and app.result.n_pairs == N_REAL and driver.wait_idle(),
                     "the solve of the 6 pairs")
            notes = page.locator(".mantine-Notification-root")
            for _ in range(notes.count()):
                try:
                    notes.first.locator("button").first.click(timeout=1000)
                except sync_api.TimeoutError:
                    pass
            size = save_small_png(page.screenshot(), PJLAB_SCREENSHOT)
            tab.browser.close()
    finally:
        app.stop()
    print("\n" + "\n".join(log))
    print(f"PJLab loupes e2e: {N_REAL} pairs in {actions} actions ({actions / N_REAL:.2f} per pair); BA loupe "
          f"{min(cell_scales):.1f}-{max(cell_scales):.1f} px/cell; camera loupe {min(px_scales):.2f}-"
          f"{max(px_scales):.2f} px/image px; screenshot {size / 1e3:.0f} kB; run time {time.monotonic() - t_start:.1f} s")
    assert actions / N_REAL <= 4.0
    assert min(cell_scales) >= 6.0 and min(px_scales) >= 2.0
