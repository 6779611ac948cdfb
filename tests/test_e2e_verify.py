"""End to end in headless Chromium: export two formats from the page, and see the Verify plots drawn.

Uses Debian's /usr/bin/chromium through playwright (no browser download).  The
pairs come in through the app's own import (clicking them is
tests/test_e2e_browser.py's job); the formats are chosen, the frames typed
and the downloads received by the browser, and the downloaded bytes compared
with :func:`calib_core.io.extrinsic_formats.export_extrinsics` of the app's
pose.  The plots must be uPlot canvases with something drawn on them.
"""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pytest
from browser_helpers import CHROMIUM, CHROMIUM_ARGS, TIMEOUT_S, free_port, wait_for
from PIL import Image

from app_driver import AppDriver
from calib_core.io.extrinsic_formats import export_extrinsics
from repo_paths import SAMPLE


def page_text(page) -> str:
    return " ".join(page.inner_text("body").split())


@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_export_two_formats_and_see_the_verify_plots(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.server import CalibrationApp

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=free_port())
    try:
        driver = AppDriver(app)
        driver.upload_pairs("pairs.yaml", (SAMPLE / "pairs.yaml").read_bytes())
        driver.mark_check_pair(app.state.picks[4].id)
        assert driver.wait_verified()
        T = app.result.T_camera_lidar
        t_browser = time.monotonic()
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1000, "height": 800}, accept_downloads=True)
            page.goto(app.url)
            wait_for(lambda: "Leave-one-out: mean" in page_text(page), "the Verify summary")
            print(f"\nsummary shown after {time.monotonic() - t_browser:.1f} s")

            def download(fmt: str, parent: str, child: str) -> tuple[str, bytes]:
                select = page.get_by_label("Format", exact=True)
                select.click()
                page.get_by_role("option", name=fmt, exact=True).click()
                wait_for(lambda: app.format_export.chosen_format == fmt, f"the format {fmt} to reach the app")
                for label, value in (("Parent frame", parent), ("Child frame", child)):
                    # viser's text inputs carry no id for their label: the row holding both.
                    row = page.locator(f'div:has(label:text-is("{label}")):has(input)').last
                    box = row.locator("input")
                    box.fill(value)
                    box.press("Tab")
                wait_for(lambda: app.format_export.frame_names == (parent, child), "the frames to reach the app")
                with page.expect_download(timeout=TIMEOUT_S * 1000) as info:
                    page.get_by_role("button", name="Download in this format").click()
                d = info.value
                return d.suggested_filename, Path(d.path()).read_bytes()

            name, data = download("urdf", "velodyne", "camera_optical")
            assert name == "extrinsics_urdf.urdf"
            assert data == export_extrinsics(T, "urdf", "velodyne", "camera_optical").encode()
            # The other order of the frames, another format: TF's parent is now the camera.
            name, data = download("ros2-tf", "camera_optical", "velodyne")
            assert name == "extrinsics_ros2_tf.sh"
            assert data == export_extrinsics(T, "ros2-tf", "camera_optical", "velodyne").encode()
            assert "--frame-id camera_optical --child-frame-id velodyne" in data.decode()

            print(f"two downloads done after {time.monotonic() - t_browser:.1f} s")
            # The Verify plots: uPlot canvases with lines and points drawn on them.
            plots = page.locator(".uplot canvas")
            wait_for(lambda: plots.count() >= 3, "three uPlot canvases")
            for title in ("Error per pair", "Error against the number of pairs so far", "Sigma per parameter"):
                assert title in page_text(page)
            for k in range(3):
                canvas = plots.nth(k)
                canvas.scroll_into_view_if_needed()
                box = canvas.bounding_box()
                assert box is not None and box["width"] > 100 and box["height"] > 50

                def drawn(canvas=canvas) -> bool:
                    rgb = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB"), dtype=int)
                    # Series colours are saturated; the empty plot is white and grey.
                    saturation = rgb.max(axis=2) - rgb.min(axis=2)
                    return int((saturation > 80).sum()) > 50

                wait_for(drawn, f"plot {k} to draw its series", interval=0.3)
            # The heat map and the check pair's line.
            assert "Expected reprojection error" in page_text(page)
            assert "Check pairs: mean" in page_text(page)
            browser.close()
        print(f"\nbrowser time {time.monotonic() - t_browser:.1f} s")
    finally:
        app.stop()


@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_serve_bag_switches_frames_from_the_page(tmp_path):
    """``serve --bag``: the page's "Load this frame" restarts the app on another cloud; the page reconnects to it."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from bag_helpers import CloudSpec, SceneBag, write_bag

    from app.serving import BagServer, BagSource
    from calib_core.io.images import load_image_rgb
    from calib_core.io.scan_readers import read_point_cloud

    cloud = read_point_cloud(SAMPLE / "scan.npz")
    spec = CloudSpec({a: cloud.xyz[:, i].copy() for i, a in enumerate("xyz")}, organized_shape=cloud.organized_shape)
    image = load_image_rgb(SAMPLE / "image.png")
    flipped = image[::-1].copy()
    bag = write_bag(tmp_path / "bag", "mcap", SceneBag(clouds=[spec, spec], cloud_times=[50.0, 50.5],
                                                       images=[image, flipped], image_times=[50.0, 50.5]))
    server = BagServer(BagSource(bag, camera=SAMPLE / "camera.yaml", frames_dir=tmp_path / "frames",
                                 session=tmp_path / "session.yaml"), port=free_port())
    try:
        app = server.load()
        t_browser = time.monotonic()
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1000, "height": 800})
            page.goto(app.url)
            wait_for(lambda: "cloud 0 of 2" in page_text(page), "the Bag frame folder on frame 0")
            box = page.locator('div:has(label:text-is("Cloud index")):has(input)').last.locator("input")
            box.fill("1")
            box.press("Tab")
            wait_for(lambda: int(server.panel.number.value) == 1, "the index to reach the app")
            page.get_by_role("button", name="Load this frame").click()
            index = server.requests.get(timeout=TIMEOUT_S)  # what serve()'s loop receives
            assert index == 1
            app = server.load(index)
            wait_for(lambda: "cloud 1 of 2" in page_text(page), "the page to reconnect to frame 1", timeout=60)
            assert np.array_equal(app.image, flipped)
            browser.close()
        print(f"\nbrowser time {time.monotonic() - t_browser:.1f} s")
    finally:
        server.stop()
