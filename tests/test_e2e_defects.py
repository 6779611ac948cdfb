"""By-eye trial defects (issue 20, item 5) in headless Chromium, on a real 64 x 1800 scan, in one app start.

* The loupe controls are in a "Loupes" folder right after "Pairs", visible without scrolling the panel.
* The Verify plots: numeric x axes (not uPlot's time axis), finite data points, no page error.
* Number boxes: "800" typed key by key into "BA columns shown" and "BA first column" is applied as 800 and
  the box still reads 800, also when the app is slow to apply (as on a loaded machine: each BA texture update
  is delayed here, so the earlier keystrokes' updates are still being applied while the person types on).
* The layout after a new BA column window and a window resized to 1100 x 800 and back: the images and the
  loupes stay inside the viewport and left of the control panel (read from the DOM).

Truth comes from the browser: the DOM (panel rectangle, folder order, the number box's text), uPlot's own chart
objects (viser registers them as ``window.__viserTestpoints.uplots``) and the camera the tab reports.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from browser_helpers import CHROMIUM, CHROMIUM_ARGS, TIMEOUT_S, free_port, page_text, screen_rect, wait_for

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"
PAIRS = ROOT / "real_data" / "pairs" / "auto_calib_pairs.yaml"
SLOW_TEXTURE_S = 0.25  # added to each BA texture update while typing: the app is slower than the typist

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(not (DATA / "calib.pcd").is_file(), reason=f"real data not found at {DATA} (../shared/data)"),
    pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)"),
]

#: The folder titles in page order, with their top edge (CSS px), and the control panel's rectangle.
FOLDERS_JS = """() => Array.from(document.querySelectorAll('.mantine-Paper-root > .mantine-Paper-root:first-child'))
    .filter(e => e.querySelector('svg') !== null)
    .map(e => [e.textContent.trim(), e.getBoundingClientRect().top, e.getBoundingClientRect().bottom])"""
PANEL_JS = """() => { const all = Array.from(document.querySelectorAll('.mantine-Paper-root'))
    .filter(e => e.textContent.includes('Loupe zoom') && e.textContent.includes('Pairs'));
  const r = all.map(e => e.getBoundingClientRect()).sort((a, b) => b.width * b.height - a.width * a.height)[0];
  return [r.left, r.top, r.right, r.bottom]; }"""
FOLDER_TEXT_JS = """(label) => {
  const t = Array.from(document.querySelectorAll('.mantine-Paper-root > .mantine-Paper-root:first-child'))
    .find(e => e.textContent.trim() === label);
  return t ? t.parentElement.textContent : null; }"""
#: Per uPlot chart: x-scale time flag, the data lengths, the y-scale range and the x axis's tick labels.
UPLOTS_JS = """() => Object.values(window.__viserTestpoints?.uplots || {}).map(t => ({
    time: t.chart.scales.x.time, lengths: t.chart.data.map(a => a === null ? -1 : a.length),
    y: [t.chart.scales.y?.min ?? null, t.chart.scales.y?.max ?? null], ticks: t.chart.axes[0]._values,
    title: t.chart.title ?? ''}))"""


def is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def test_number_boxes_verify_plots_layout_and_loupes_folder_in_the_browser(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.server import CalibrationApp
    from app_driver import AppDriver

    app = CalibrationApp(DATA / "calib.pcd", DATA / "calib.png", DATA / "center_camera-intrinsic.json",
                         session_path=tmp_path / "session.yaml", port=free_port())
    errors: list[tuple[str, str]] = []
    try:
        driver = AppDriver(app)
        notes = driver.upload_pairs("pairs.yaml", PAIRS.read_bytes())
        assert [t for t, _ in notes] == ["Pairs imported"], notes
        assert driver.wait_verified(120.0) and app.verify_panel.current is not None
        n_cols = app.depth.shape[1]
        assert n_cols >= 1000 and app.wrap_cols  # room for 800 columns from column 800
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.on("pageerror", lambda exc: errors.append(("pageerror", str(exc))))
            page.on("console", lambda msg: errors.append(("console", msg.text)) if msg.type == "error" else None)
            page.goto(app.url)
            cid = wait_for(lambda: driver.client_ids(), "the tab to connect")[0]
            client = app.server.get_clients()[cid]
            wait_for(lambda: app.view.view_settled(cid), "the annotation view to be set")
            notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
            notice.first.wait_for(state="detached", timeout=TIMEOUT_S * 1000)  # the page closes it (stop 28)
            wait_for(lambda: "Leave-one-out: mean" in page_text(page), "the Verify summary")

            # --- item 7: the loupe controls, right after Pairs, seen without scrolling the panel.
            folders = page.evaluate(FOLDERS_JS)
            names = [f[0] for f in folders]
            assert "Pairs" in names and "Loupes" in names, names
            assert names[names.index("Pairs") + 1] == "Loupes", names
            loupes_text = page.evaluate(FOLDER_TEXT_JS, "Loupes")
            for label in ("Loupe zoom", "BA loupe shows", "Laser contrast", "Hide marks"):
                assert label in loupes_text, (label, loupes_text)
            panel = page.evaluate(PANEL_JS)
            top, bottom = folders[names.index("Loupes")][1:]
            assert panel[1] < top and bottom < panel[3], (folders, panel)

            # --- item 4: Verify plots with numeric x axes and data points, no page error.
            page.locator(".uplot").first.scroll_into_view_if_needed()

            def charts_with_data() -> list | None:
                charts = page.evaluate(UPLOTS_JS)
                return charts if len(charts) == 3 and all(min(c["lengths"]) > 0 for c in charts) else None

            for chart in wait_for(charts_with_data, "three Verify plots with data"):
                assert chart["time"] is False, chart
                assert min(chart["lengths"]) >= 3 and -1 not in chart["lengths"], chart
                assert all(v is not None and math.isfinite(v) for v in chart["y"]), chart
                ticks = [t for t in chart["ticks"] or [] if t]
                assert ticks and all(is_number(t) for t in ticks), chart  # numbers, not times like ':01.000'
            assert not [e for e in errors if "not iterable" in e[1] or e[0] == "pageerror"], errors

            # --- item 1: "800" typed key by key while the app is slow to apply each change.
            real_set_ba = app.page.set_ba

            def slow_set_ba(*args, **kwargs):
                time.sleep(SLOW_TEXTURE_S)
                return real_set_ba(*args, **kwargs)

            def number_box(label: str):
                row = page.locator(f'div:has(label:text-is("{label}")):has(input)').last
                return row.locator("input:not([type=hidden])").last

            app.page.set_ba = slow_set_ba
            try:
                for label, slider, field in (("BA columns shown", app.view.ba_width_slider, "width"),
                                             ("BA first column", app.view.ba_start_slider, "start")):
                    box = number_box(label)
                    box.scroll_into_view_if_needed()
                    box.click()
                    box.press("Control+a")
                    assert driver.wait_idle()  # nothing else queued: the first keystroke's update is applied at once
                    page.keyboard.type("800", delay=120)
                    wait_for(lambda: not app.actions.busy and slider.value == 800
                             and getattr(app.ba_window, field) == 800, f"800 typed into {label!r} to be applied",
                             timeout=20)
                    assert driver.wait_idle()
                    assert box.input_value() == "800", (label, box.input_value(), slider.value, app.ba_window)
            finally:
                app.page.set_ba = real_set_ba
            assert (app.ba_window.start, app.ba_window.width) == (800, 800)
            assert (app.state.view.ba_window_start, app.state.view.ba_window_width) == (800, 800)
            box = number_box("Laser contrast")
            box.click()
            box.press("Control+a")
            page.keyboard.type("2.5", delay=120)
            wait_for(lambda: app.state.view.contrast == 2.5 and not app.actions.busy, "contrast 2.5 to be applied")
            assert box.input_value() == "2.5"

            # --- item 6: images and loupes inside the viewport and left of the panel, also after resizing.
            def layout_ok(size: dict) -> str | None:
                """None when the layout is right at this viewport size, else what is wrong."""
                cam = client.camera
                # In device pixels: viser scales them by its own adaptive pixel ratio, the shape stays.
                if abs(cam.image_width * size["height"] / (cam.image_height * size["width"]) - 1.0) > 0.005:
                    return f"the tab reports a {cam.image_width} x {cam.image_height} canvas, not the new shape"
                canvas = page.locator("canvas").first.bounding_box()
                left_of = page.evaluate(PANEL_JS)[0]
                slots = {"loupe " + k: app.loupes.slot(k) for k in ("ba", "camera")}
                slots |= {k: app.slots[k] for k in (*app.ba_keys, app.camera_slot().key)}
                for name, slot in slots.items():
                    x0, y0, x1, y1 = screen_rect(cam, canvas, slot.bounds())
                    if not (0 <= x0 and 0 <= y0 and x1 <= size["width"] and y1 <= size["height"]):
                        return f"{name} at {x0:.0f}, {y0:.0f} - {x1:.0f}, {y1:.0f} leaves the {size} viewport"
                    if x1 > left_of:
                        return f"{name} ends at x = {x1:.0f}, under the control panel (from x = {left_of:.0f})"
                return None

            for width, height in ((1400, 900), (1100, 800), (1400, 900)):
                size = {"width": width, "height": height}
                page.set_viewport_size(size)
                deadline = time.monotonic() + TIMEOUT_S
                while True:  # polled: the tab reports its size, the app frames it again, the tab reports the view
                    why = layout_ok(size)
                    if why is None and app.view.view_settled(cid) and not app.actions.busy:
                        break
                    if time.monotonic() > deadline:
                        pytest.fail(f"at {width} x {height}: {why or 'the view never settled'}")
                    time.sleep(0.1)
            browser.close()
    finally:
        app.stop()
    assert not [e for e in errors if e[0] == "pageerror" or "not iterable" in e[1]], errors
