"""Guided picking end to end in a real headless Chromium (issue 9's browser test).

4 pairs are clicked on the full images at ground-truth corner pairs (the
cell nearest each corner and its true pixel); then "Next pair" is pressed
once and 10 guided pairs are made, each by one click in the camera loupe at
the proposal's true projection (the proposed cell's laser point projected
with sample_data/ground_truth.yaml) + 0.3 px noise.  Every click and button
press counts as a UI action.  Screen positions come from the app's
``page_position`` (the viser camera the tab reported and the image layout).
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.solve.quality import NO_ERROR_ESTIMATE, error_estimate_reason, pairs_in_fit
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import rotation_angle_deg, transform_points

from browser_helpers import CHROMIUM, TIMEOUT_S, AnnotationTab, page_text, free_port, wait_for
from repo_paths import SAMPLE

pytestmark = pytest.mark.browser

N_GUIDED = 10
CLICK_SIGMA_PX = 0.3
MAX_ACTIONS_PER_PAIR = 1.5  # issue 9
MIN_SCREEN_PX_PER_IMAGE_PX = 8.0  # issue 9, camera loupe


@pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
def test_guided_pairs_in_headless_chromium(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.server import CalibrationApp

    scene = load_sample(SAMPLE)
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    start_pairs = simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=0.0)
    rng = np.random.default_rng(5)

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=free_port())
    try:
        with sync_api.sync_playwright() as p:
            tab = AnnotationTab(p, app, {"width": 1400, "height": 900})
            page, screen = tab.page, tab.screen


            def drawn() -> bool:  # the images are on the page (not the light-grey backdrop)
                return tab.shows_image_at((("camera", (320.0, 300.0)), (app.ba_keys[0], (360.0, 90.0))))

            wait_for(drawn, "the page to draw the images", interval=0.2)
            t_browser = time.monotonic()

            def solved(n: int):
                text = page_text(page)
                ok = f"Solved with {n} pairs" in text and "Solving" not in text
                m = re.search(r"Mean error: ([0-9.]+ px|no error estimate yet)", text)  # none at 4 pairs (issue 20)
                return m.group(1).removesuffix(" px") if ok and m else None

            for k, pair in enumerate(start_pairs):
                before = app.state.version
                page.mouse.click(*screen(app.ba_keys[0], (pair.laser_rc[1], pair.laser_rc[0])))
                wait_for(lambda: app.state.version > before, f"start pair {k + 1}: the BA click to register")
                before = app.state.version
                page.mouse.click(*screen("camera", pair.pixel))
                wait_for(lambda: app.state.version > before, f"start pair {k + 1}: the camera click to register")
            shown_errors = [wait_for(lambda: solved(4), "the error display for 4 pairs")]
            T4 = app.result.T_camera_lidar
            start_s = time.monotonic() - t_browser

            actions = 0
            # The guided buttons must not move while the panel's status text changes (a click planned from
            # one look would hit another button: by-eye trial, issue 20).
            not_a_corner = page.get_by_role("button", name="Not a corner").last  # the folder's (the pair bar repeats it)
            heading = page.get_by_text("Guided picking", exact=True).first  # the folder title

            def offset() -> float:  # the button's place in its folder (the panel itself may scroll)
                # Both boxes in one JavaScript call: a scroll between two separate look-ups is not a move.
                return not_a_corner.evaluate("(button, heading) => button.getBoundingClientRect().y"
                                             " - heading.getBoundingClientRect().y", heading.element_handle())

            offset0 = offset()
            page.get_by_role("button", name="Next pair").first.click()  # the panel's top row (Guided has its own)
            actions += 1
            px_per_image_px = []
            n_new = 0
            for k in range(N_GUIDED):

                def framed():
                    """(proposal, pick the click goes to) once the proposal is framed: a guided half pick at its
                    cell, or for a re-click the rough pair selected; the camera loupe on the predicted pixel."""
                    if not app.guide.idle:  # proposals in flight may re-frame the loupes after the look
                        return None
                    prop, half, sel = app.guide.current, app.state.pending(), app.state.selected
                    if prop is not None and prop.replaces is not None and sel is None and half is None \
                            and "Press **Next pair** to re-click" in app.guide.text:
                        return "press"  # after a re-click the next re-click waits for Next pair (run 5)
                    if prop is None or not np.allclose(app.loupes.camera_crop.center, prop.pixel, atol=0.5):
                        return None
                    if prop.replaces is not None:
                        ok = sel is not None and half is None and app.state.get(sel).laser_rc == tuple(prop.laser_rc)
                        return (prop, sel) if ok else None
                    ok = half is not None and half.source == "guided" and half.pixel is None
                    return (prop, half.id) if ok and half.laser_rc == tuple(prop.laser_rc) else None

                got = wait_for(framed, f"guided pair {k + 1}: the proposal to be framed in the loupes")
                if got == "press":
                    page.get_by_role("button", name="Next pair").first.click()
                    actions += 1
                    got = wait_for(lambda: (lambda f: None if f == "press" else f)(framed()),
                                   f"guided pair {k + 1}: the re-click to be framed after Next pair")
                prop, target = got
                assert abs(offset() - offset0) <= 1, (offset0, offset())
                n_new += prop.replaces is None
                pix, ok = scene.camera.project(transform_points(truth, np.asarray(prop.laser_xyz, float)[None]))
                assert ok[0]
                click_px = pix[0] + rng.normal(0.0, CLICK_SIGMA_PX, 2)
                x, y = screen("loupe_camera", click_px)
                x1, y1 = screen("loupe_camera", click_px + [1.0, 0.0])
                px_per_image_px.append(float(np.hypot(x1 - x, y1 - y)))
                page.mouse.click(x, y)
                actions += 1

                def placed():  # a re-click keeps its pair's source ("clicked")
                    got = app.state.get(target)
                    return (got.pixel is not None and np.hypot(*np.subtract(got.pixel, click_px)) < 0.1
                            and got.source == ("clicked" if prop.replaces is not None else "guided")
                            and got.precision_px == CLICK_SIGMA_PX)

                try:
                    wait_for(placed, f"guided pair {k + 1}: the loupe click to place the pixel")
                except BaseException:  # say what the app did with the click (CI saw this once; not reproduced here)
                    print(f"click at {click_px} for proposal {prop.laser_rc} (replaces {prop.replaces}): now pick "
                          f"{app.state.get(target)}, proposal {getattr(app.guide.current, 'laser_rc', None)}, camera loupe "
                          f"centre {app.loupes.camera_crop.center}, picks {app.state.picks}")
                    raise
                assert len(app.state.complete_picks()) == 4 + n_new
                # The page shows the solve of these pairs.
                assert app.wait_idle(TIMEOUT_S) and app.guide.wait_idle(TIMEOUT_S) and app.wait_idle(TIMEOUT_S)
                r = app.result
                # A re-click keeps 4 pairs: no error estimate is shown then (issue 20).
                mean = f"{r.mean_px:.3f}" if error_estimate_reason(pairs_in_fit(r)) is None else NO_ERROR_ESTIMATE
                shown_errors.append(wait_for(lambda: solved(r.n_pairs) == mean and mean,
                                             f"the error display after guided pair {k + 1}"))
            browser_s = time.monotonic() - t_browser
            tab.browser.close()
        T = app.result.T_camera_lidar
    finally:
        app.stop()

    def err(T_):
        return rotation_angle_deg(T_[:3, :3], truth[:3, :3]), 100 * float(np.linalg.norm(T_[:3, 3] - truth[:3, 3]))

    per_pair = actions / N_GUIDED
    print(f"\ne2e guided: {actions} UI actions for {N_GUIDED} guided pairs ({n_new} new, {N_GUIDED - n_new} re-clicks "
          f"of the clicked ones) = {per_pair:.2f} per pair; "
          f"camera loupe screen px per image pixel at each click: {[round(v, 1) for v in px_per_image_px]}; "
          f"error after 4 clicks {err(T4)[0]:.3f} deg {err(T4)[1]:.2f} cm, after {N_GUIDED} guided pairs "
          f"{err(T)[0]:.3f} deg {err(T)[1]:.2f} cm; mean px error shown: {shown_errors}; "
          f"browser time {browser_s:.1f} s ({start_s:.1f} s for the 4 clicked pairs)")
    assert per_pair <= MAX_ACTIONS_PER_PAIR
    assert len(set(shown_errors)) > 1  # the error panel followed the pairs
    assert err(T)[0] < err(T4)[0] and err(T)[1] < err(T4)[1]
    assert min(px_per_image_px) >= MIN_SCREEN_PX_PER_IMAGE_PX
