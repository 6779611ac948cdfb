"""The browser app on a real 64 x 1800 scan (PJLab OpenCalib ``auto_calib``).

A spinning-lidar BA image is a 28:1 strip; these tests check that the app
shows the part facing the camera and that clicks land on the exact cell the
user aims at, also after zooming.  The independent truth is the dataset's
published extrinsic (which scan columns the camera sees) and the cells and
pixels of ``real_data/pairs/auto_calib_pairs.yaml`` (generated from that
calibration, see ``real_data/README.md``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from calib_core.pairs import load_pairs_yaml, save_pairs_yaml
from calib_core.transforms import transform_points

from browser_helpers import CHROMIUM, AnnotationTab, free_port, wait_for

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(not (DATA / "calib.pcd").is_file(), reason=f"real data not found at {DATA} (../shared/data)"),
]
PAIRS = ROOT / "real_data" / "pairs" / "auto_calib_pairs.yaml"
N_PRELOADED = 6  # pairs imported before the browser test clicks more


def scene_files() -> tuple[Path, Path, Path]:
    return DATA / "calib.pcd", DATA / "calib.png", DATA / "center_camera-intrinsic.json"


def published_T() -> np.ndarray:
    data = json.loads((DATA / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    return np.array(data["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], dtype=float)


def make_app(session: Path, **kwargs):
    from app.server import CalibrationApp

    scan, image, camera = scene_files()
    return CalibrationApp(scan, image, camera, session_path=session, port=free_port(), **kwargs)


def test_facing_the_camera_from_an_imported_extrinsic_before_any_pair(tmp_path):
    """With the published extrinsic imported (its own JSON format), "Facing the camera" works with no pairs,
    and a BA click frames the camera loupe on the published projection of that cell."""
    from app_driver import AppDriver

    extrinsic = DATA / "top_center_lidar-to-center_camera-extrinsic.json"
    app = make_app(tmp_path / "session.yaml", initial_extrinsics_path=extrinsic)
    try:
        np.testing.assert_allclose(app.initial_T_camera_lidar, published_T(), atol=1e-9)
        driver = AppDriver(app)
        assert driver.choose_ba_columns("Facing the camera") == []  # no "No calibration yet"
        assert app.wait_idle(10) and not app.ba_window.is_full and app.result is None
        points, rows_cols = app.depth.valid_points()
        _, in_image = app.camera.project(transform_points(published_T(), points))
        seen = np.unique(rows_cols[in_image, 1])
        assert set(range(seen.min(), seen.max() + 1)) <= set(app.ba_window.columns.tolist())
        pair = load_pairs_yaml(PAIRS)[0]
        driver.click_cell("horizontal", *pair.laser_rc)
        truth, ok = app.camera.project(transform_points(published_T(), app.depth.cell_points(
            np.array([pair.laser_rc]))))
        assert ok[0]
        np.testing.assert_allclose(driver.loupe_view("camera")["center"], truth[0], atol=1e-6)
        # The scan has intensity: the BA loupe can show it, brighter where the sensor reported more.
        assert driver.choose_loupe_source("Intensity") == []
        c = app.loupes.ba_crop
        k = driver.loupe_texture("ba").shape[1] // c.n_cols
        shown = driver.loupe_texture("ba")[::k, ::k].astype(int)
        rows = np.clip(np.arange(c.row0, c.row0 + c.n_rows), 0, 63)
        values = app.depth.meta["field_images"]["intensity"][rows][:, np.arange(c.col0, c.col0 + c.n_cols) % 1800]
        ok = np.isfinite(values) & (np.arange(c.row0, c.row0 + c.n_rows) >= 0)[:, None]
        order = np.argsort(values[ok], kind="stable")
        assert ok.sum() > 50 and np.all(np.diff(shown[ok][order]) >= 0)
    finally:
        app.stop()


def test_camera_facing_window_shows_what_the_published_calibration_projects(tmp_path):
    from app_driver import AppDriver

    session = tmp_path / "session.yaml"
    app = make_app(session)
    try:
        assert app.depth.shape == (64, 1800)
        # 40 deg of beams over 360 deg of columns: cells drawn about 3.2x taller than wide.
        assert 2.5 < app.ba_cell_aspect < 4.5
        driver = AppDriver(app)
        # Default: the columns facing the camera, before any pose as the '+x' preset puts it (the camera looks ahead).
        assert driver.ba_columns_choice == "Facing the camera" and not app.ba_window.is_full
        assert driver.choose_ba_columns("All columns") == [] and app.ba_window.is_full
        app.state.import_pairs_file(PAIRS)
        assert app.wait_idle(60) and app.result is not None
        assert driver.choose_ba_columns("Facing the camera") == []
        assert app.wait_idle(10)
        window = app.ba_window

        # Truth: the columns whose points the PUBLISHED extrinsic projects into the image.
        points, rows_cols = app.depth.valid_points()
        _, in_image = app.camera.project(transform_points(published_T(), points))
        seen = np.unique(rows_cols[in_image, 1])
        assert seen.max() - seen.min() < 400  # one arc, not across column 0
        shown = set(window.columns.tolist())
        assert set(range(seen.min(), seen.max() + 1)) <= shown
        assert window.width <= (seen.max() - seen.min() + 1) + 40  # small margins only
        # The BA images show exactly those columns, each cell a square block of texels.
        tex = driver.ba_texture("horizontal")
        k = tex.shape[0] // 64
        assert tex.shape == (64 * k, window.width * k) and k >= 4
        np.testing.assert_array_equal(tex[::k, ::k], app.ba_gray["horizontal"][:, window.columns])
        # Markers of pairs outside the window are hidden; those inside keep their cell.
        ids = driver.marker_ids("horizontal")
        assert len(ids) == len(load_pairs_yaml(PAIRS))  # every generated pair faces the camera
        for pid in ids:
            u, v = driver.marker_display_pixel("horizontal", pid)
            assert (int(v), window.scan_col(int(u))) == app.state.get(pid).laser_rc
    finally:
        app.stop()

    # The choice is part of the session: a restart shows the same window after its first solve.
    app = make_app(session)
    try:
        assert app.wait_idle(60) and app.result is not None
        assert app.wait_idle(10)
        assert app.ba_window == window
    finally:
        app.stop()


@pytest.mark.browser
@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_pick_exact_cells_on_the_real_scan_in_headless_chromium(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")

    scene_files()
    t_start = time.monotonic()
    pairs = load_pairs_yaml(PAIRS)
    preloaded = tmp_path / "first_pairs.yaml"
    save_pairs_yaml(preloaded, pairs[:N_PRELOADED])
    app = make_app(tmp_path / "session.yaml")
    report: list[str] = []
    try:
        app.state.import_pairs_file(preloaded)  # a calibration exists: the camera-facing window is known
        assert app.wait_idle(60) and app.result is not None
        with sync_api.sync_playwright() as p:
            tab = AnnotationTab(p, app, {"width": 1400, "height": 900})
            page, cid, screen = tab.page, tab.cid, tab.screen


            def px_per_cell(key: str, row: int, col: int) -> tuple[float, float]:
                x0, y0 = screen(key, (col, row))
                x1, _ = screen(key, (col + 1, row))
                _, y1 = screen(key, (col, row + 1))
                return x1 - x0, y1 - y0

            def drawn(target: str, uv) -> bool:  # not the grey backdrop
                return tab.shows_image_at(((target, uv),))

            def set_view(button: str) -> None:
                before = app.view.view_set_time(cid)
                page.get_by_role("button", name=button, exact=True).click()
                wait_for(lambda: app.view.view_set_time(cid) > before, f"'{button}' to apply")
                wait_for(lambda: app.view.view_settled(cid), f"the view after '{button}'")

            def click_ba(key: str, row: int, col: int, offset=(0.0, 0.0)) -> tuple[int, int]:
                """Click display position cell + offset (in cells); return the cell the app recorded."""
                before = app.state.version
                page.mouse.click(*screen(key, (col + offset[0], row + offset[1])))
                wait_for(lambda: app.state.version > before, f"the click on cell {(row, col)} to register")
                return app.state.picks[-1].laser_rc

            key = "diag_pos45"  # the trace where poles and the block stand out most
            target = pairs[N_PRELOADED]  # a real foreground corner (a pole or block edge)
            row, col = target.laser_rc
            # The page opens on the columns facing the camera; the user first looks at all 1800.
            page.get_by_label("BA columns").click()
            page.get_by_role("option", name="All columns").click()
            wait_for(lambda: app.ba_window.is_full, "the BA images to show every column")
            wait_for(lambda: app.view.view_settled(cid), "the view to re-frame")
            assert app.ba_window.is_full
            report.append(f"all 1800 columns: {'x'.join(f'{s:.2f}' for s in px_per_cell(key, row, col))} px per cell")

            # The user picks "Facing the camera" in the BA columns dropdown.
            page.get_by_label("BA columns").click()
            page.get_by_role("option", name="Facing the camera").click()
            wait_for(lambda: not app.ba_window.is_full, "the BA images to show the camera-facing columns")
            wait_for(lambda: app.view.view_settled(cid), "the view to re-frame")
            set_view("BA images")
            wait_for(lambda: drawn(key, (col, row)), "the windowed BA image to be drawn", interval=0.2)
            w = app.ba_window
            report.append(f"window {w.start}-{(w.start + w.width - 1) % w.n_cols} ({w.width} columns), framed: "
                          f"{'x'.join(f'{s:.2f}' for s in px_per_cell(key, row, col))} px per cell")
            hits = []
            hits.append((click_ba(key, row, col), (row, col)))

            # Zoom on the clicked cell (x2 per press, up to 14 px per cell), then pick its neighbours near
            # their edges (0.3 cell off centre).
            presses = 0
            while presses < 6:
                set_view("On last click")
                presses += 1
                wait_for(lambda: drawn(key, (col, row)), "the zoomed view to be drawn", interval=0.2)
                zoomed = px_per_cell(key, row, col)
                if min(zoomed) >= 10.0:
                    break
            report.append(f"zoomed on last click ({presses} presses): {'x'.join(f'{s:.2f}' for s in zoomed)} "
                          "px per cell")
            assert min(zoomed) >= 10.0
            for d_row, d_col, off in ((0, 1, (0.3, -0.3)), (1, 0, (-0.3, 0.3)), (-1, -1, (0.3, 0.3)), (0, 0, (-0.3, -0.3))):
                aim = (row + d_row, col + d_col)
                hits.append((click_ba(key, aim[0], aim[1], off), aim))

            # Frame the camera image and click the true pixel of the same corner: the pair completes.
            set_view("Camera")
            wait_for(lambda: drawn("camera", target.pixel), "the camera image to be drawn", interval=0.2)
            before = app.state.version
            page.mouse.click(*screen("camera", target.pixel))
            wait_for(lambda: app.state.version > before, "the camera click to register")
            pick = app.state.picks[-1]
            assert pick.complete and pick.laser_rc == (row, col)
            pixel_err = float(np.hypot(*np.subtract(pick.pixel, target.pixel)))
            text_ok = wait_for(lambda: f"Solved with {N_PRELOADED + 1} pairs" in page.inner_text("body"),
                               "the solve with the clicked pair")
            assert text_ok
            set_view("BA images")
            page.screenshot(path=str(tmp_path / "real_scene.png"))
            tab.browser.close()
    finally:
        app.stop()

    exact = sum(got == aim for got, aim in hits)
    print(f"\nreal scene ({time.monotonic() - t_start:.1f} s): " + "; ".join(report)
          + f"; BA clicks on the aimed cell: {exact}/{len(hits)}; camera click {pixel_err:.3f} px from the aim; "
          + f"screenshot {tmp_path / 'real_scene.png'}")
    assert exact == len(hits), hits
    assert pixel_err < 0.5
