"""By-eye run 4 frictions in the page (docs/by_eye.md), in headless Chromium on the sample.

* The pair bar (pair actions, the live line, the pair status, the guided line) stays in view while the control
  panel scrolls: in run 4, 15 of 67 actions were panel scrolls back to it.
* Delete (or Backspace) deletes the selected pair, undoably, as Edit -> Delete does; nothing without a selection.
* Ctrl+Z undoes the last pair change and leaves the sliders alone (in run 4 it reset "Render over photo": the
  browser's own undo in the slider's number box); Ctrl+Shift+Z redoes it.
* The wheel over a loupe zooms that loupe and leaves the page's view alone (it zoomed the whole page).

Truth comes from the browser (what is drawn at a point of the page: ``document.elementFromPoint``) and from the
app's pairs and settings after the key presses.
"""

from __future__ import annotations

import pytest

from browser_helpers import CHROMIUM, open_sample_tab, page_text, wait_for

pytestmark = [pytest.mark.browser, pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)")]

#: The page rectangle of the innermost element whose text is ``text`` (``exact``) or contains it, and whether that
#: element is what the page shows at the rectangle's centre (not covered, not clipped away); null if none.
SHOWN_JS = """([text, exact]) => {
  const has = e => exact ? e.textContent.trim() === text : e.textContent.includes(text);
  const all = Array.from(document.querySelectorAll('body *')).filter(e => has(e)
    && !Array.from(e.children).some(c => has(c)));
  if (!all.length) return null;
  const r = all[0].getBoundingClientRect();
  const top = document.elementFromPoint((r.left + r.right) / 2, (r.top + r.bottom) / 2);
  return [r.left, r.top, r.right, r.bottom, top !== null && (all[0].contains(top) || top.contains(all[0]))]; }"""
#: Marks the number box beside the slider labelled ``label`` (``data-test-box``); false if it is not shown.
SLIDER_BOX_JS = """(label) => {
  const l = Array.from(document.querySelectorAll('label')).find(e => e.textContent.trim() === label);
  let row = l; while (row && !row.querySelector('input:not([type=hidden])')) row = row.parentElement;
  const box = row && row.querySelector('input:not([type=hidden])');
  if (!box || box.getBoundingClientRect().width === 0) return false;
  box.dataset.testBox = "1"; return true; }"""


def test_the_pair_bar_stays_in_view_and_delete_and_ctrl_z_keys(tmp_path):
    with open_sample_tab(tmp_path, {"width": 1400, "height": 900}) as (app, driver, tab):
        page = tab.page
        live = wait_for(lambda: page.evaluate(SHOWN_JS, ["6 pairs · mean", False]), "the live line")
        intro = page.evaluate(SHOWN_JS, ["Click a point in any", False])
        assert live[4] and intro[4], (live, intro)
        # --- scroll the panel down with the wheel over it, as a person does: the intro goes out of view ...
        page.mouse.move((intro[0] + intro[2]) / 2, (intro[1] + intro[3]) / 2)
        for _ in range(6):
            page.mouse.wheel(0, 400)
            page.wait_for_timeout(100)
        wait_for(lambda: page.evaluate(SHOWN_JS, ["Click a point in any", False])[3] < live[1],
                 "the panel to scroll the intro away")
        # ... and the pair actions and the live line are still where they were, drawn on top.
        for text, exact, before in (("Cancel pair", True, None), ("6 pairs · mean", False, live)):
            shown = wait_for(lambda: (lambda r: r if r and r[4] else None)(page.evaluate(SHOWN_JS, [text, exact])),
                             f"{text!r} to be shown after the scroll", timeout=5.0)
            assert 0 <= shown[1] and shown[3] <= 900, (text, shown)
            if before is not None:
                assert abs(shown[1] - before[1]) < 2.0, (text, shown, before)
        # A real click on the pinned "Cancel pair" reaches the app: it ends a selection.
        first = app.state.picks[0].id
        app.state.select(first)  # as the dropdown does
        wait_for(lambda: f"Pair {first} selected:" in page_text(page), "the selection in the pair status")
        cancel = page.evaluate(SHOWN_JS, ["Cancel pair", True])
        page.mouse.click((cancel[0] + cancel[2]) / 2, (cancel[1] + cancel[3]) / 2)
        wait_for(lambda: app.state.selected is None and f"Pair {first} selected:" not in page_text(page),
                 "Cancel pair to end the selection")

        # --- Delete with no pair selected: nothing happens.
        ids = [q.id for q in app.state.picks]
        page.keyboard.press("Delete")
        page.wait_for_timeout(500)
        assert [q.id for q in app.state.picks] == ids and not app.actions.busy
        # --- Delete with pair 3 selected: it goes; Ctrl+Z brings it back.
        app.state.select(ids[2])  # as the dropdown does
        wait_for(lambda: f"Pair {ids[2]} selected:" in page_text(page), "the selection in the pair status")
        page.keyboard.press("Delete")
        wait_for(lambda: [q.id for q in app.state.picks] == ids[:2] + ids[3:] and not app.actions.busy,
                 "Delete to delete the selected pair")
        page.keyboard.press("Control+z")
        wait_for(lambda: [q.id for q in app.state.picks] == ids and not app.actions.busy, "Ctrl+Z to undo it")

        # --- Ctrl+Z after typing in the "Render over photo" box: the pair change is undone, the slider stays.
        if not page.evaluate(SLIDER_BOX_JS, "Render over photo"):  # its folder is closed: open it
            page.get_by_text("Align (rough pose)", exact=True).click()
        wait_for(lambda: page.evaluate(SLIDER_BOX_JS, "Render over photo"), "the slider's number box")
        page.locator("[data-test-box]").click()  # scrolled into view, once it stands still
        wait_for(lambda: page.evaluate("() => document.activeElement?.dataset?.testBox === '1'"),
                 "the number box to take the focus")
        page.keyboard.press("Control+a")
        page.keyboard.type("0.35")
        page.keyboard.press("Enter")
        wait_for(lambda: abs(app.state.view.render_blend - 0.35) < 1e-9, "the typed blend to apply")
        picks = app.state.picks
        page.mouse.click(*tab.screen("camera", (300.0, 250.0)))  # a half pair (the canvas keeps no focus)
        wait_for(lambda: app.state.pending() is not None and not app.actions.busy, "a click to start a pair")
        page.keyboard.press("Control+z")
        wait_for(lambda: app.state.picks == picks and not app.actions.busy, "Ctrl+Z to undo the half pair")
        page.wait_for_timeout(500)
        assert abs(app.state.view.render_blend - 0.35) < 1e-9
        page.keyboard.press("Control+Shift+z")
        wait_for(lambda: app.state.pending() is not None and not app.actions.busy, "Ctrl+Shift+Z to redo it")
        assert abs(app.state.view.render_blend - 0.35) < 1e-9

        # --- the wheel over a loupe zooms that loupe, and the page's view stays (run 4: it zoomed the page).
        client = app.server.get_clients()[tab.cid]
        wait_for(lambda: page.evaluate("() => Object.keys(window.__baLoupeRects || {}).length === 2"),
                 "the loupes' places on the canvas")
        view = (tuple(client.camera.position), tuple(client.camera.look_at))
        def side(kind: str) -> int:  # after a photo click the lower loupe shows the render (stop 28): its crop
            return app.loupes.render_crop.n if kind == "ba" and app.loupes.shows_render else \
                driver.loupe_view(kind)["size"]

        for kind, label in (("camera", "loupe_camera"), ("ba", "loupe_ba")):
            centre = driver.loupe_view(kind)["center"]
            if kind == "ba" and app.loupes.shows_render:
                centre = app.render_pane.cell_at_pixel(*app.loupes.render_crop.center)
            target = centre if kind == "camera" else (centre[1], centre[0])  # (col, row) of a cell
            page.mouse.move(*tab.screen(label, target))
            size = side(kind)
            page.mouse.wheel(0, -120)  # wheel up: magnify
            wait_for(lambda: side(kind) < size and not app.actions.busy,
                     f"the wheel to magnify the {kind} loupe")
            page.wait_for_timeout(300)
            page.mouse.wheel(0, 120)  # wheel down: widen again
            wait_for(lambda: side(kind) == size and not app.actions.busy,
                     f"the wheel to widen the {kind} loupe")
        page.wait_for_timeout(500)
        assert (tuple(client.camera.position), tuple(client.camera.look_at)) == view
        # Beside the loupes the wheel still zooms the page.
        page.mouse.move(*tab.screen("camera", (300.0, 250.0)))
        page.mouse.wheel(0, -120)
        wait_for(lambda: tuple(client.camera.position) != view[0], "the wheel beside the loupes to zoom the page")
