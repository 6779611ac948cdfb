"""By-eye run 8 friction in the page (docs/by_eye.md): after a choice in the "Render shading" dropdown, Escape did
not cancel a half-made pair (the dropdown kept the keys); only the Cancel pair button did.

Truth comes from the browser: the key pressed in a real tab, the app's pending pair read from its state.
"""

from __future__ import annotations

import pytest

from browser_helpers import CHROMIUM, AnnotationTab, page_text, start_sample_app, wait_for
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
      if (input && input.getBoundingClientRect().width > 0) { input.scrollIntoView({block: 'center'}); const r = input.getBoundingClientRect();
                   return [r.left, r.top, r.right, r.bottom]; }
    }
  }
  return null; }"""


def test_escape_cancels_a_half_pair_after_a_choice_in_the_render_shading_dropdown(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    app, driver = start_sample_app(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml")[:6])
    try:
        with sync_api.sync_playwright() as p:
            tab = AnnotationTab(p, app, {"width": 1400, "height": 1000})
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
    finally:
        app.stop()
