"""By-eye run 6 friction in the page (docs/by_eye.md): guided picking's Skip / Not a corner / Stop sit in the sticky
pair bar while a proposal is shown, so a person need not scroll to the Guided folder for them.

Truth comes from the browser (what the page draws at the button's place after the panel scrolled:
``document.elementFromPoint``) and from the app's guided proposal after a real mouse click there.
"""

from __future__ import annotations

import pytest

from browser_helpers import CHROMIUM, open_sample_tab, wait_for

pytestmark = [pytest.mark.browser, pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)")]

#: The page rectangle of the button labelled ``label`` inside the pinned pair bar (an ancestor marked
#: ``data-ba-pinned``), and whether the page shows it at its centre; null if there is none or it is hidden.
PINNED_BUTTON_JS = """(label) => {
  const b = Array.from(document.querySelectorAll('button')).find(e => e.textContent.trim() === label
    && e.closest('[data-ba-pinned]') && e.getBoundingClientRect().width > 0);
  if (!b) return null;
  const r = b.getBoundingClientRect();
  const top = document.elementFromPoint((r.left + r.right) / 2, (r.top + r.bottom) / 2);
  return [r.left, r.top, r.right, r.bottom, top !== null && (b.contains(top) || top.contains(b))]; }"""


def test_a_real_click_on_the_pinned_skip_reaches_the_guide(tmp_path):
    with open_sample_tab(tmp_path, {"width": 1400, "height": 900}) as (app, driver, tab):
        page = tab.page
        wait_for(lambda: page.evaluate(PINNED_BUTTON_JS, "Cancel pair"), "the pinned pair bar")
        assert page.evaluate(PINNED_BUTTON_JS, "Skip") is None  # no proposal: no Skip in the bar
        nxt = page.evaluate(PINNED_BUTTON_JS, "Next pair")  # the pair action starts guided picking
        page.mouse.click((nxt[0] + nxt[2]) / 2, (nxt[1] + nxt[3]) / 2)
        wait_for(lambda: driver.guide_proposal is not None and driver.wait_guide(), "a guided proposal")
        first = driver.guide_proposal
        assert first is not None
        wait_for(lambda: page.evaluate(PINNED_BUTTON_JS, "Skip"), "Skip in the pair bar")
        # Scroll the panel down with the wheel, as a person does: the bar (and its Skip) stays in view.
        cancel = page.evaluate(PINNED_BUTTON_JS, "Cancel pair")
        page.mouse.move((cancel[0] + cancel[2]) / 2, cancel[3] + 120)
        for _ in range(6):
            page.mouse.wheel(0, 400)
            page.wait_for_timeout(100)
        skip = wait_for(lambda: (lambda r: r if r and r[4] else None)(page.evaluate(PINNED_BUTTON_JS, "Skip")),
                        "the pinned Skip to be shown after the scroll", timeout=5.0)
        assert 0 <= skip[1] and skip[3] <= 900, skip
        page.mouse.click((skip[0] + skip[2]) / 2, (skip[1] + skip[3]) / 2)
        wait_for(lambda: driver.wait_guide() and driver.guide_proposal is not None
                 and tuple(driver.guide_proposal.laser_rc) != tuple(first.laser_rc),
                 "the click on the pinned Skip to move to the next proposal")
        # Stop in the bar ends guided picking and the bar's guided buttons go.
        stop = page.evaluate(PINNED_BUTTON_JS, "Stop")
        page.mouse.click((stop[0] + stop[2]) / 2, (stop[1] + stop[3]) / 2)
        wait_for(lambda: page.evaluate(PINNED_BUTTON_JS, "Skip") is None and app.state.pending() is None,
                 "Stop to end guided picking and hide the bar's Skip")
