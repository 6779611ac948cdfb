"""Guided re-clicks declined while new proposals are being computed (run 8, PJLab: "guided picking loops over
re-clicks of pairs 2, 1, 3, 1, each a Skip"), driven through :class:`app_driver.AppDriver` on the committed sample.

PJLab's ranking takes a moment; a Skip pressed meanwhile found the panel busy and was dropped, so the re-click
came back with the next ranking.  Here the ranking is held until the Skip is in (the worker waits on an event).
"""

from __future__ import annotations

import threading

import app.guide_panel as guide_panel
from calib_core.guide.evidence import ProposalScreen

from app_driver import AppDriver
from test_app_pair_bar import click_pairs


def test_a_skip_pressed_while_proposals_are_computed_is_kept(app, scene, monkeypatch):
    d = AppDriver(app)
    click_pairs(d, scene, 4)
    app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=app.guide.screen.max_ellipse_px)
    assert d.press_pair_action("Next pair") == [] and d.wait_guide()
    first = d.guide_proposal
    assert first is not None and first.replaces is not None  # a re-click (no new cell passes this screen)
    gate = threading.Event()
    rank = guide_panel.rank_proposals
    monkeypatch.setattr(guide_panel, "rank_proposals", lambda *a, **k: (gate.wait(60), rank(*a, **k))[1])
    with app.guide._lock:  # a new ranking in flight, as after any change of the pairs
        app.guide._submitted = None
    app.guide._on_state_change(app.state)
    assert not app.guide.idle and d.guide_proposal is first  # busy; the re-click still shown
    assert d.press_guide("Skip") == []
    gate.set()
    assert d.wait_guide()
    shown = []
    for _ in range(8):  # the other re-clicks, each skipped; the first never comes back
        p = d.guide_proposal
        if p is None:
            break
        shown.append(tuple(p.laser_rc))
        assert d.press_guide("Skip") == [] and d.wait_guide()
    assert tuple(first.laser_rc) not in shown, shown
    assert len(shown) == len(set(shown)) and len(shown) <= 3
