"""End to end in headless Chromium: several shots of one rig in one session (issue 21).

``serve --shot`` on the sample with 4 pairs; in the page, the "Shots" folder adds a second shot (room 1 of
the synthetic generator seen by the sample's rig, written by tests/shots_helpers.py) from its files; the
page reconnects showing that shot; a pair is clicked in it (BA cell and camera pixel at the truth); the
page then counts it in the joint solve (5 pairs) and Verify lists both shots.  Truth: the simulated pair
(the cell and pixel aimed at) and :func:`calib_core.shots.solve_shots` of the same pairs, called here.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from browser_helpers import CHROMIUM, CHROMIUM_ARGS, WebGLNotice, free_port, page_text, wait_for

from app_driver import AppDriver
from calib_core.shots import Shot, solve_shots
from calib_core.synthetic import simulate_pairs
from repo_paths import SAMPLE

pytestmark = pytest.mark.browser


@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_add_a_shot_in_the_page_pick_in_it_and_see_it_in_the_joint_solve(tmp_path, second_shot):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.serving import ShotServer

    s0, s1, scan1, image1 = second_shot  # shots_helpers.write_second_shot (tests/conftest.py)
    rng = np.random.default_rng(7)
    pairs0 = simulate_pairs(s0, 4, rng)
    server = ShotServer([(SAMPLE / "scan.npz", SAMPLE / "image.png")], SAMPLE / "camera.yaml",
                        session_path=tmp_path / "session.yaml", port=free_port())
    try:
        app = server.load()
        app.state.import_pairs(pairs0)
        assert app.wait_idle(120) and app.result is not None and app.result.n_pairs == 4
        t_browser = time.monotonic()
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            notice = WebGLNotice(page)
            page.goto(app.url)
            wait_for(lambda: "Showing shot 0 of 1" in page_text(page), "the Shots folder on shot 0")
            notice.wait_closed()
            for label, value in (("New shot: scan", str(scan1)), ("New shot: photo", str(image1))):
                box = page.locator(f'div:has(label:text-is("{label}")):has(input)').last.locator("input")
                box.fill(value)
                box.press("Tab")
            panel = server.panel
            wait_for(lambda: (panel.scan_text.value, panel.image_text.value) == (str(scan1), str(image1)),
                     "the new shot's files to reach the app")
            page.get_by_role("button", name="Add this shot").click()
            shot = server.requests.get(timeout=120)  # what serve()'s loop receives
            assert shot == 1 and server.state.n_shots == 2
            app = server.load(shot)
            wait_for(lambda: "Showing shot 1 of 2" in page_text(page), "the page to reconnect to shot 1", timeout=60)
            print(f"\nshot added and shown after {time.monotonic() - t_browser:.1f} s")

            # A pair in shot 1, clicked where the truth puts it: the BA cell, then the camera pixel.
            driver = AppDriver(app)
            cid = wait_for(lambda: driver.client_ids(), "the tab to reconnect")[0]
            # A reconnected tab reports its camera only when it changes: a resize makes it report.
            page.set_viewport_size({"width": 1400, "height": 901})
            wait_for(lambda: app.view.view_settled(cid), "the annotation view to be set")
            notice.wait_closed()  # the notice shows once per load of the page: a reconnect brings none, a reload one
            canvas = page.locator("canvas").first.bounding_box()
            candidates = simulate_pairs(s1, 12, np.random.default_rng(3), pixel_noise_px=0.0)
            pair = next(q for q in candidates if app.ba_window.display_cols(np.array([q.laser_rc[1]]))[1][0])
            row, col = pair.laser_rc

            def click(target: str, uv) -> None:
                fx, fy = driver.page_position(cid, target, uv)
                assert 0.0 < fx < 1.0 and 0.0 < fy < 1.0, f"{target} {uv} is off screen"
                page.mouse.click(canvas["x"] + fx * canvas["width"], canvas["y"] + fy * canvas["height"])

            wait_for(lambda: app.image is not None and len(app.ba_keys) > 0, "the panes")
            for target, uv in ((app.ba_keys[0], (col, row)), ("camera", pair.pixel)):
                before = app.state.version
                click(target, uv)
                wait_for(lambda: app.state.version > before, f"the {target} click to register")
            pick = app.state.picks[-1]
            assert pick.shot == 1 and pick.complete and pick.laser_rc == (row, col)
            assert np.hypot(*np.subtract(pick.pixel, pair.pixel)) < 0.05

            # Counted in the joint solve, on the page and in Verify.
            wait_for(lambda: "1 complete in shot 1 (shown); 5 in all 2 shots" in page_text(page), "the pairs count")
            wait_for(lambda: "Solved with 5 pairs" in page_text(page) and "Solving" not in page_text(page),
                     "the joint solve of 5 pairs", timeout=60)
            wait_for(lambda: "2 shots, one calibration" in page_text(page) and "Fit on 5 pairs" in page_text(page),
                     "Verify with both shots", timeout=90)
            text = page_text(page)
            assert "| 1 (shown) | 1 |" in app.verify_panel.shots_text and "| 0 | 4 |" in app.verify_panel.shots_text
            ids0 = [q.id for q in app.state.all_picks if q.shot == 0]
            here = solve_shots([
                Shot.from_pairs([dataclasses.replace(q, id=i) for q, i in zip(pairs0, ids0)], s0.depth, s0.camera),
                Shot.from_pairs([pick.to_pair()], s1.depth, s1.camera)], s0.camera)
            np.testing.assert_allclose(app.result.T_camera_lidar, here.result.T_camera_lidar, rtol=0, atol=1e-12)
            assert "Showing shot 1 of 2" in text
            browser.close()
        print(f"browser time {time.monotonic() - t_browser:.1f} s")
    finally:
        server.stop()
    # The session lists both shots and each pair's shot.
    import yaml

    data = yaml.safe_load((tmp_path / "session.yaml").read_text())
    assert len(data["shots"]) == 2 and [q["shot"] for q in data["pairs"]] == [0, 0, 0, 0, 1]
