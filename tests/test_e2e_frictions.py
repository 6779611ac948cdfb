"""Frictions of the by-eye runs (docs/by_eye.md) that live in the page, in headless Chromium on the sample.

* Notifications ("Not accepted" ...) do not cover the images or the loupes: viser puts them over the photo's
  top-left, where a click meant for a close button moved a pending point.
* The pair actions (Undo, Cancel pair, Next pair) are the first thing in the control panel, above the intro text
  and the Pairs folder, visible without scrolling.
* Escape cancels a half-made pair (as "Cancel pair" does).

Truth comes from the browser: the DOM's rectangles, the camera the tab reports (where each image lies on the
screen, projected here) and the app's pairs after a key press.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from browser_helpers import CHROMIUM, TIMEOUT_S, open_sample_tab, page_text, screen_rect, wait_for

#: Set BA_CALIB_SHOTS=dir to keep a screenshot of the page with the notification (for looking, not for checking).
SHOT_DIR = Path(os.environ["BA_CALIB_SHOTS"]) if os.environ.get("BA_CALIB_SHOTS") else None

pytestmark = [pytest.mark.browser, pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)")]

#: The page rectangle (left, top, right, bottom) of the innermost element whose text is ``text`` (``exact``) or
#: contains it; null if none.
RECT_JS = """([text, exact]) => {
  const has = e => exact ? e.textContent.trim() === text : e.textContent.includes(text);
  const all = Array.from(document.querySelectorAll('body *')).filter(e => has(e)
    && !Array.from(e.children).some(c => has(c)));
  if (!all.length) return null;
  const r = all[0].getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; }"""


def overlaps(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def test_notifications_the_panels_top_and_escape_in_the_browser(tmp_path):
    with open_sample_tab(tmp_path, {"width": 1400, "height": 900}) as (app, driver, tab):
        page, cid = tab.page, tab.cid
        client = app.server.get_clients()[cid]

        # --- the pair actions: first in the panel, above the intro and the Pairs folder, on screen.
        cancel = wait_for(lambda: page.evaluate(RECT_JS, ["Cancel pair", True]), "the Cancel pair button")
        intro = page.evaluate(RECT_JS, ["Click a point in any", False])
        pairs = page.evaluate(RECT_JS, ["Pairs", True])
        assert intro is not None and pairs is not None
        assert 0 <= cancel[1] and cancel[3] <= 900 and cancel[3] <= intro[1] < pairs[1], (cancel, intro, pairs)
        for label in ("Undo", "Next pair"):
            button = page.evaluate(RECT_JS, [label, True])
            assert button is not None and abs(button[1] - cancel[1]) < 2, (label, button, cancel)

        # --- a notification: on screen, over none of the images and loupes.
        app.notify(client, "Not accepted", "frictions test: no laser return here")
        toast = page.locator(".mantine-Notification-root", has_text="frictions test")
        toast.first.wait_for(timeout=TIMEOUT_S * 1000)
        box = toast.first.bounding_box()
        rect = (box["x"], box["y"], box["x"] + box["width"], box["y"] + box["height"])
        assert 0 <= rect[0] and 0 <= rect[1] and rect[2] <= 1400 and rect[3] <= 900, rect
        assert app.view.view_settled(cid)
        canvas = page.locator("canvas").first.bounding_box()
        slots = {"loupe " + k: app.loupes.slot(k) for k in ("ba", "camera")}
        slots |= {k: app.slots[k] for k in (*app.ba_keys, "render", app.camera_slot().key)}
        for name, slot in slots.items():
            shown = screen_rect(client.camera, canvas, slot.bounds())
            assert not overlaps(rect, shown), (name, shown, rect)
        if SHOT_DIR is not None:
            page.screenshot(path=str(SHOT_DIR / "frictions_toast.png"))
        toast.first.locator("button").click()

        # --- Escape cancels a half-made pair.
        n = len(app.state.picks)
        page.mouse.click(*tab.screen("camera", (300.0, 250.0)))
        half = wait_for(lambda: app.state.pending(), "a click on the photo to start a pair")
        wait_for(lambda: f"Pair {half.id} waits for a BA click" in page_text(page), "the half pair's status")
        page.keyboard.press("Escape")
        wait_for(lambda: app.state.pending() is None and not app.actions.busy, "Escape to cancel the half pair")
        assert len(app.state.picks) == n
        wait_for(lambda: "waits for a BA click" not in page_text(page), "the status line to go")
