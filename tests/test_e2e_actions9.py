"""By-eye run 8 friction in the page (docs/by_eye.md): after a choice in the "Render shading" dropdown, Escape did
not cancel a half-made pair (the dropdown kept the keys); only the Cancel pair button did.

Truth comes from the browser: the key pressed in a real tab, the app's pending pair read from its state.
"""

from __future__ import annotations

import pytest

from browser_helpers import CHROMIUM, open_sample_tab, page_text, start_sample_app, wait_for
from calib_core.pairs import load_pairs_yaml
from repo_paths import SAMPLE

pytestmark = [pytest.mark.browser, pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)")]

#: The page rectangle ``[left, top, right, bottom]`` of the input of the control whose label is ``label``.
INPUT_JS = """(label) => {
  const labels = Array.from(document.querySelectorAll('label')).filter(e => e.textContent.trim() === label);
  for (const l of labels) {
    for (let row = l.parentElement; row; row = row.parentElement) {
      const input = row.querySelector('input[role="combobox"]');
      if (input && input.getBoundingClientRect().width > 0) {
        input.scrollIntoView({block: 'center'});
        const r = input.getBoundingClientRect();
        return [r.left, r.top, r.right, r.bottom];
      }
    }
  }
  return null; }"""


def test_escape_cancels_a_half_pair_after_a_choice_in_the_render_shading_dropdown(tmp_path):
    with open_sample_tab(tmp_path, {"width": 1400, "height": 1000}) as (app, driver, tab):
        page = tab.page
        # A half pair: a click on the photo; then (run 8) a change of the render's shading before Escape.
        page.mouse.click(*tab.screen("camera", (300.0, 250.0)))
        wait_for(lambda: app.state.pending() is not None, "the half pair")
        wait_for(lambda: "waits for a" in page_text(page), "the pending pair's status line")
        wait_for(lambda: "Align (rough pose)" in page_text(page), "the Align folder")
        if not page.evaluate(INPUT_JS, "Render shading"):
            page.get_by_text("Align (rough pose)", exact=True).first.click()  # open the folder
        expanded = "() => document.activeElement && document.activeElement.getAttribute('aria-expanded') === 'true'"
        for _ in range(5):  # the folder opens with an animation: aim again until the dropdown is open
            page.wait_for_timeout(600)
            box = wait_for(lambda: page.evaluate(INPUT_JS, "Render shading"), "the Render shading dropdown")
            page.mouse.click((box[0] + box[2]) / 2, (box[1] + box[3]) / 2)
            page.wait_for_timeout(300)
            if page.evaluate(expanded):
                break
        assert page.evaluate(expanded), "the Render shading dropdown did not open"
        option = page.locator("[role=option]:visible").filter(has_text="Intensity").first
        option.wait_for(state="visible", timeout=5000)
        option.click()
        wait_for(lambda: app.state.view.render_mode == "intensity" and not app.actions.busy, "the new shading")
        page.wait_for_timeout(500)
        focused = page.evaluate("() => document.activeElement && document.activeElement.tagName")
        assert focused == "INPUT"  # the dropdown keeps the focus, as in run 8
        page.keyboard.press("Escape")
        wait_for(lambda: app.state.pending() is None, "Escape to drop the half pair", timeout=10.0)


N_FLOW_PAIRS = 6
ROUGH_PX = (5.0, -4.0)  # how far the full-photo click lands from the corner (a person on the scaled-down photo)


def test_pairs_in_three_clicks_photo_then_lower_loupe_then_photo_loupe_with_the_bar_saying_where(tmp_path):
    """Run 8 (KITTI): 4 clicks a pair (photo, render, both loupes).  Here, with a pose (6 pairs imported), each new
    pair is: a rough click on the full photo; a click in the lower loupe (the render at that place) on the cell the
    render draws at the corner; a click in the photo loupe on the corner.  Counted as a person's actions; the pair
    bar's text (as the page shows it) names the loupe of the next click."""
    import numpy as np

    from calib_core.synthetic import load_sample, simulate_pairs

    scene = load_sample(SAMPLE)
    actions, made = 0, 0
    with open_sample_tab(tmp_path, {"width": 1400, "height": 900}) as (app, driver, tab):
        taken = {tuple(p.laser_rc) for p in app.state.picks}
        corners = [p for p in simulate_pairs(scene, 40, np.random.default_rng(21), pixel_noise_px=0.0)
                   if tuple(p.laser_rc) not in taken]
        page = tab.page
        wait_for(lambda: driver.wait_render(), "the render")

        def click(target: str, uv) -> None:
            nonlocal actions
            before = app.state.version
            page.mouse.click(*tab.screen(target, uv))
            actions += 1
            wait_for(lambda: app.state.version > before, f"the click on {target} to register")
            assert driver.wait_idle()

        for pair in corners:
            if made == N_FLOW_PAIRS:
                break
            u, v = pair.pixel
            cell = app.render_pane.cell_at_pixel(u, v)  # what the render draws at the corner
            if cell is None or cell in taken:
                continue
            click("camera", (u + ROUGH_PX[0], v + ROUGH_PX[1]))
            pid = app.state.pending().id
            wait_for(lambda: "waits for a BA click → lower loupe" in page_text(page),
                     "the bar naming the lower loupe")
            assert app.loupes.shows_render
            click("loupe_ba", (cell[1], cell[0]))
            assert app.state.get(pid).laser_rc == cell and app.state.pending() is None
            wait_for(lambda: f"Pair {pid} made" in page_text(page), "the bar naming the photo loupe")
            click("loupe_camera", (u, v))
            got = app.state.get(pid)
            assert np.hypot(got.pixel[0] - u, got.pixel[1] - v) < 0.05 and got.laser_rc == cell
            taken.add(cell)
            made += 1
    print(f"\nthree-click flow e2e: {made} pairs in {actions} actions ({actions / max(made, 1):.2f} per pair)")
    assert made == N_FLOW_PAIRS and actions / made <= 3.0


def test_the_page_closes_the_software_webgl_notice_itself(tmp_path):
    """Runs 1-8: the first action of every walkthrough was a click on the close button of viser's "Software WebGL
    rendering detected" notice (headless Chromium renders in software), which covers the panel's lower end."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from browser_helpers import CHROMIUM_ARGS
    from app_driver import AppDriver

    app, driver = start_sample_app(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml")[:6])
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            warnings: list[str] = []
            page.on("console", lambda m: warnings.append(m.text) if m.type == "warning" else None)
            page.goto(app.url)
            d = AppDriver(app)
            cid = wait_for(lambda: d.client_ids(), "the tab to connect")[0]
            wait_for(lambda: app.view.view_settled(cid), "the annotation view to be set")
            # The notice comes (software WebGL here) and goes without a click; the console keeps its words.
            wait_for(lambda: page.wait_for_timeout(100) or any("Software WebGL" in w for w in warnings),
                     "the notice to be seen and closed")  # (events arrive while playwright runs)
            notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
            wait_for(lambda: notice.count() == 0, "the notice to go", timeout=5.0)
            page.wait_for_timeout(1500)
            assert notice.count() == 0
            browser.close()
    finally:
        app.stop()
