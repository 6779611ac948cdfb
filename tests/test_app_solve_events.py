"""Panels learn of the live solve and of display changes by subscribing (issue 22 item 3), not by being called.

``app.subscribe_solve`` listeners see what the solve shows on every redraw, under the UI lock; ``app.subscribe_solved``
listeners see each finished solve after it is shown, outside the lock; ``app.display.subscribe`` listeners see what
the laser panes show change.  Checked against what the test itself did (the pairs it imported, the settings it
changed), on the committed sample.
"""

from __future__ import annotations

import pytest

from app_driver import AppDriver, sample_app
from calib_core.pairs import load_pairs_yaml
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    app = sample_app(tmp_path_factory.mktemp("events") / "session.yaml")
    try:
        yield app
    finally:
        app.stop()


def test_the_live_solve_publishes_what_it_shows_and_each_finished_solve(app):
    shown, solved = [], []
    app.subscribe_solve(lambda s: shown.append((s, app.ui_lock.held_here())))
    app.subscribe_solved(lambda s: solved.append((s, app.ui_lock.held_here())))
    app.state.clear()
    assert app.wait_idle(60)
    shown.clear()
    solved.clear()
    ids = app.state.import_pairs(load_pairs_yaml(SAMPLE / "pairs.yaml")[:6])
    assert app.wait_idle(120)
    assert shown and all(held for _, held in shown)  # every redraw under the UI lock
    assert solved and not any(held for _, held in solved)  # follow-up work outside it
    last, _ = shown[-1]
    assert last.n_complete == 6 and not last.solving and last.error is None
    assert last.bundle is app.solve_bundle and sorted(last.bundle.pick_ids) == sorted(ids)
    assert solved[-1][0].bundle is app.solve_bundle
    assert "Solved with 6 pairs" in app.calibration_panel.result_text  # the panel subscribed too

    # Below 4 pairs the solve is dropped: shown at once, with no finished solve to follow.
    for pick_id in ids[4:]:
        app.state.delete(pick_id)
    assert app.wait_idle(60)
    assert shown[-1][0].n_complete == 4 and shown[-1][0].bundle is app.solve_bundle is not None
    shown.clear()
    solved.clear()
    app.state.delete(ids[3])
    assert app.wait_idle(60)
    assert shown[-1][0].bundle is None and shown[-1][0].n_complete == 3 and app.solve_bundle is None
    assert solved == []
    assert "needs 4 pairs" in app.calibration_panel.result_text


def test_display_changes_are_published_to_subscribers(app):
    seen = []
    app.display.subscribe(lambda what: seen.append((what, app.ui_lock.held_here())))
    driver = AppDriver(app)
    key = app.ba_keys[0]
    before = driver.ba_texture(key).copy()
    driver.set_slider("Laser contrast", 2.5)
    driver.set_hide_marks(True)
    driver.set_hide_marks(False)
    assert seen == [("contrast", True), ("marks", False), ("marks", False)]
    assert (driver.ba_texture(key) != before).any()  # the wired redraw still happened
