"""By-eye run 5's guided re-clicks in the page (docs/by_eye.md), in headless Chromium on the sample.

The real "Next pair" button of the pair bar moves on from a started re-click (run 5: the same "Proposal 1 of 5"
stayed), a click in the camera loupe makes the next re-click, after which no pair is selected, and one Ctrl+Z takes
the whole re-click back (run 5: the first only "a change of pair 9").  Truth: the app's pairs before and after, and
the pair bar's text as the browser shows it.  Only re-clicks are proposed (a screen no new cell passes, as in
tests/test_app_pair_bar.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from browser_helpers import CHROMIUM, AnnotationTab, page_text, start_sample_app, wait_for
from calib_core.guide.evidence import ProposalScreen
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import transform_points
from repo_paths import SAMPLE

pytestmark = [pytest.mark.browser, pytest.mark.skipif(
    not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium)")]


def test_next_pair_moves_on_and_ctrl_z_takes_a_reclick_back_whole(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    scene = load_sample(SAMPLE)
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    app, d = start_sample_app(tmp_path, simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=1.0))
    app.guide.screen = ProposalScreen(max_range_m=0.5, max_ellipse_px=app.guide.screen.max_ellipse_px)
    try:
        with sync_api.sync_playwright() as p:
            tab = AnnotationTab(p, app, {"width": 1400, "height": 900})
            page = tab.page
            next_pair = page.get_by_role("button", name="Next pair").first  # the pair bar's (Guided has its own)
            next_pair.click()
            first = wait_for(lambda: app.state.selected, "Next pair to select a re-click's pair")
            wait_for(lambda: f"Pair {first} (selected): re-click" in page_text(page), "the bar to say which pair")

            # Next pair again: that re-click is skipped, the next one's pair selected, and the bar says so.
            next_pair.click()
            second = wait_for(lambda: (lambda s: s if s not in (None, first) else None)(app.state.selected),
                              "Next pair to move on to another re-click")
            wait_for(lambda: f"Skipped the re-click of pair {first}." in page_text(page), "the bar to say it skipped")
            assert app.guide.current.replaces is not None
            assert app.state.get(second).laser_rc == tuple(app.guide.current.laser_rc)

            # The re-click: a click in the camera loupe at the corner's true projection.
            before = app.state.picks
            xyz = np.asarray(app.guide.current.laser_xyz, dtype=float)[None]
            pix, ok = scene.camera.project(transform_points(truth, xyz))
            assert ok[0]
            page.mouse.click(*tab.screen("loupe_camera", pix[0]))
            wait_for(lambda: app.state.get(second).precision_px == 0.3 and d.wait_guide(), "the re-click to land")
            after = app.state.picks
            assert np.hypot(*np.subtract(app.state.get(second).pixel, pix[0])) < 0.1
            # Nothing selected by itself afterwards: the bar asks for Next pair.
            wait_for(lambda: "Press Next pair to re-click pair" in page_text(page), "the bar to ask for Next pair")
            assert app.state.selected is None and "(selected)" not in page_text(page)

            # One Ctrl+Z: the whole re-click goes (pixel and precision), and nothing follows it.
            page.keyboard.press("Control+z")
            wait_for(lambda: app.state.picks == before, "one Ctrl+Z to take the re-click back")
            wait_for(lambda: f"Undone: the move of pair {second}'s camera point." in page_text(page),
                     "the bar to say what was undone")
            assert d.wait_guide() and d.wait_idle() and app.state.picks == before and app.state.can_redo
            assert after != before
    finally:
        app.stop()
