"""By-eye run 7 friction in the page (docs/by_eye.md): the panel's controls jumped by about 18 px when the pair
bar's status line came or went (a pair started, then Esc; "Leave selected pair out"; a Shift+click), so clicks
aimed at a control landed on nothing.

Truth comes from the browser: the page rectangle of the Pairs folder's controls before and after each change.
"""

from __future__ import annotations

import pytest

from browser_helpers import CHROMIUM, open_sample_tab, page_text, wait_for

pytestmark = [pytest.mark.browser, pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)")]

#: The page rectangle ``[left, top, right, bottom]`` of the innermost shown element whose text contains ``text``.
RECT_JS = """(text) => {
  const all = Array.from(document.querySelectorAll('body *')).filter(e => e.textContent.includes(text)
    && !Array.from(e.children).some(c => c.textContent.includes(text)) && e.getBoundingClientRect().width > 0);
  if (!all.length) return null;
  const r = all[0].getBoundingClientRect();
  return [r.left, r.top, r.right, r.bottom]; }"""

#: Controls under the pair bar whose place a person aims at.
BELOW = ("Click a point in any", "Leave selected pair out", "Clear all pairs")


@pytest.fixture(scope="module")
def sample_tab(tmp_path_factory):
    """``(app, driver, tab)``: the sample with 6 pairs and one tab on it (1400 x 1000), shared by this file's tests,
    which each leave no pair pending or selected."""
    with open_sample_tab(tmp_path_factory.mktemp("bar8"), {"width": 1400, "height": 1000}) as opened:
        yield opened


def test_controls_under_the_pair_bar_do_not_move_when_its_status_line_comes_and_goes(sample_tab):
    app, driver, tab = sample_tab
    page = tab.page
    wait_for(lambda: page.evaluate(RECT_JS, "6 pairs · mean"), "the live line")
    wait_for(lambda: all(page.evaluate(RECT_JS, t) for t in BELOW), "the Pairs folder's controls")
    page.wait_for_timeout(800)

    def places() -> list:
        return [page.evaluate(RECT_JS, t) for t in BELOW]

    def settled(what: str) -> list:
        page.wait_for_timeout(600)  # the page re-lays out after the text changed
        return places()

    start = places()
    # A half pair: "Pair 7 waits for a BA click" shows in the bar; the controls stay put.
    page.mouse.click(*tab.screen("camera", (300.0, 250.0)))
    wait_for(lambda: "waits for a" in page_text(page), "the pending pair's status line")
    assert settled("pending") == start
    # Esc drops it: the line goes; the controls still stay put.
    page.keyboard.press("Escape")
    wait_for(lambda: app.state.pending() is None and "waits for a" not in page_text(page), "Esc to drop it")
    assert settled("cancelled") == start
    # A selection (as a Shift+click makes it) and "Leave selected pair out": the controls stay put.
    first = app.state.picks[0].id
    app.state.select(first)
    wait_for(lambda: f"Pair {first} selected" in page_text(page), "the selection in the status line")
    assert settled("selected") == start
    leave = page.evaluate(RECT_JS, "Leave selected pair out")
    page.mouse.click((leave[0] + leave[2]) / 2, (leave[1] + leave[3]) / 2)
    wait_for(lambda: app.state.get(first).check and not app.actions.busy, "the pair to be left out")
    assert settled("left out") == start
    page.keyboard.press("Control+z")
    wait_for(lambda: not app.state.get(first).check and not app.actions.busy, "Ctrl+Z to put it back")
    assert settled("undone") == start
    app.state.select(None)


def test_a_real_shift_click_on_a_markers_number_label_selects_its_pair(sample_tab):
    """Run 7: a Shift+click on the "2" label beside marker 2 said "No pair within 18 px".  The label's place is
    found in the page's pixels (they change where it is drawn when "Hide marks" hides it), not from the app."""
    import io

    import numpy as np
    from PIL import Image

    from app.ui_common import pick_tolerance_px
    from browser_helpers import screen_rect

    app, driver, tab = sample_tab
    page = tab.page
    client = app.server.get_clients()[tab.cid]
    key = driver.camera_key
    pick = app.state.picks[1]
    name = f"/annot/labels/{key}/{pick.id}"
    wait_for(lambda: name in driver.drawn_labels(), "the pair's number label")
    pos = app.nodes.drawn[name][1][2]
    ax, ay = screen_rect(client.camera, tab.box, (pos[0], pos[1], pos[0], pos[1]))[:2]  # the label's anchor
    clip = {"x": ax - 4, "y": ay - 24, "width": 30, "height": 28}  # around it, up and right

    def grab() -> np.ndarray:
        return np.asarray(Image.open(io.BytesIO(page.screenshot(clip=clip))).convert("L"), dtype=float)

    page.wait_for_timeout(800)
    shown = grab()
    app.state.set_view(hide_marks=True)  # as the "Hide marks" box does
    wait_for(lambda: name not in driver.drawn_labels(), "the marks to be hidden")
    page.wait_for_timeout(800)
    hidden = grab()
    app.state.set_view(hide_marks=False)
    wait_for(lambda: name in driver.drawn_labels(), "the marks to be back")
    # Where the label is drawn: the pixels that differ with the marks hidden, right of the anchor (the
    # marker's ring passes the anchor's lower left; the label lies up and right of it).
    differs = np.abs(shown - hidden) > 40
    ys, xs = np.nonzero(differs[:, 6:])
    assert len(xs) > 10, "no label drawn up and right of its anchor"
    gx, gy = clip["x"] + 6 + float(np.median(xs)), clip["y"] + float(np.median(ys))
    # That spot is beyond the marker's own reach (the ring test alone finds no pair there).
    marker = np.array(tab.screen("camera", pick.pixel))
    x0, y0, x1, _ = screen_rect(client.camera, tab.box, (0.0, 0.0, 1.0, 0.0))
    slot = app.slot_of(key)
    display_px = np.hypot(gx - marker[0], gy - marker[1]) / (x1 - x0) / slot.units_per_px
    assert display_px > pick_tolerance_px(slot.units_per_px, slot.units_per_px_y), display_px
    page.wait_for_timeout(800)
    page.keyboard.down("Shift")
    page.mouse.click(gx, gy)
    page.keyboard.up("Shift")
    wait_for(lambda: app.state.selected == pick.id, f"the Shift+click on label {pick.id} to select its pair")
    assert "No pair within" not in page_text(page)
    app.state.select(None)
