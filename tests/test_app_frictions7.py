"""By-eye frictions left open after run 6 (docs/by_eye.md, issue 20), driven through :class:`app_driver.AppDriver`
on the committed sample: guided actions in the sticky pair bar, ... (one test per friction)."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

import numpy as np

from calib_core.synthetic import simulate_pairs

from app_driver import AppDriver


def _pairs(d: AppDriver, app, scene, n: int, seed: int = 3) -> None:
    for pair in simulate_pairs(scene, n, np.random.default_rng(seed), pixel_noise_px=0.0):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()


def _press_bar_guided(d: AppDriver, label: str) -> list:
    """Press one of the pair bar's guided buttons as viser delivers the click."""
    bar = d.app.pairs_panel.bar
    before = len(d.tab.notifications)
    asyncio.run(bar.guided_action_callback(SimpleNamespace(client=d.tab, target=SimpleNamespace(value=label))))
    d.app.actions.join()
    return d.tab.notifications[before:]


def test_guided_skip_not_a_corner_stop_are_in_the_pair_bar_while_a_proposal_is_shown(app, scene):
    d = AppDriver(app)
    bar = app.pairs_panel.bar
    _pairs(d, app, scene, 4)
    assert not bar.guided_actions_shown  # no guided session: nothing to skip
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    first = d.guide_proposal
    assert first is not None and bar.guided_actions_shown
    # Skip in the bar moves on as the Guided folder's Skip does.
    assert _press_bar_guided(d, "Skip") == [] and d.wait_guide()
    second = d.guide_proposal
    assert second is not None and tuple(second.laser_rc) != tuple(first.laser_rc)
    # Not a corner in the bar drops the cell for good.
    assert _press_bar_guided(d, "Not a corner") == [] and d.wait_guide()
    dropped = tuple(int(v) for v in second.laser_rc)
    assert d.guide_proposal is None or tuple(int(v) for v in d.guide_proposal.laser_rc) != dropped
    assert all(tuple(int(v) for v in p.laser_rc) != dropped for p in app.guide.proposals)
    # The folder's copies still work: its Skip moves on too.
    if d.guide_proposal is not None:
        here = tuple(d.guide_proposal.laser_rc)
        assert d.press_guide("Skip") == [] and d.wait_guide()
        assert d.guide_proposal is None or tuple(d.guide_proposal.laser_rc) != here
    # Stop in the bar ends guided picking, removes the guided half pick, and hides the bar's buttons.
    assert d.press_guide("Next pair") == [] and d.wait_guide() and bar.guided_actions_shown
    assert _press_bar_guided(d, "Stop") == [] and d.wait_guide()
    assert app.state.pending() is None and not bar.guided_actions_shown
    assert bar.guide_status == ""
    # Hidden buttons do nothing (a stale click after Stop must not restart guided picking).
    assert _press_bar_guided(d, "Skip") == [] and d.wait_guide()
    assert bar.guide_status == "" and not bar.guided_actions_shown
