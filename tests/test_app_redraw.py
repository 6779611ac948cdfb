"""After a click that moves a pair, the page shows the new state: the moved marker, and the new solve's error
display, residual table and 2-D overlays.  A click is drawn once (by its solve's redraw), so this checks that the
one redraw draws everything, against a solve computed here with calib_core on the same pairs."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial import cKDTree

from calib_core.pairs import load_pairs_yaml, resolve_pairs
from calib_core.solve import calibrate
from browser_helpers import start_sample_app
from repo_paths import SAMPLE


@pytest.fixture(params=["panorama", "raw"])
def driver(request, tmp_path):
    """The app on the sample with its 10 pairs, showing the camera as a panorama or as recorded."""
    session = tmp_path / "session.yaml"
    session.write_text("format: ba-calib-session\nversion: 1\nnext_id: 1\npairs: []\n"
                       f"view: {{panorama: {'true' if request.param == 'panorama' else 'false'}}}\n")
    app, d = start_sample_app(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml"), session_path=session)
    try:
        yield d
    finally:
        app.stop()


def _display(driver, uv: np.ndarray, shown_only: bool = False) -> np.ndarray:
    """Display pixels of original pixels ``uv`` in the visible camera view (``shown_only``: drop those not shown)."""
    disp = [driver.camera_display_pixel(float(u), float(v)) for u, v in uv]
    if shown_only:
        disp = [d for d in disp if d is not None]
    return np.array(disp, dtype=np.float64).reshape(-1, 2)


def _moved_marker_check(driver, key: str, old: tuple, new: tuple) -> None:
    drawn = driver.drawn_marker_pixels(key)
    d_new = np.linalg.norm(drawn - driver.camera_display_pixel(*new), axis=1)
    d_old = np.linalg.norm(drawn - driver.camera_display_pixel(*old), axis=1)
    assert d_new.min() < 1e-2, f"no marker drawn at the new pixel (nearest {d_new.min():.3f} px)"
    assert d_old.min() > 1.0, "a marker is still drawn at the old pixel"


def test_click_shows_moved_marker_and_the_new_solve(driver):
    app = driver.app
    key = driver.camera_key
    assert key == ("panorama" if app.state.view.panorama else "raw")  # the sample's OCam camera has both
    pick = app.state.picks[3]
    old = pick.pixel
    new = (old[0] + 4.0, old[1] - 3.0)
    driver.select_in_dropdown(pick.id)
    notes = driver.click_camera(*new)
    assert [n for n in notes if n[0] in ("Internal error", "Not accepted")] == [], notes
    # The click returns once the page shows it: the marker has moved even before the solve is waited for.
    _moved_marker_check(driver, key, old, new)
    assert driver.wait_idle()
    _moved_marker_check(driver, key, old, new)

    # Independent truth: the same pairs solved here.
    pairs = app.state.pairs()
    assert np.allclose(app.state.get(pick.id).pixel, new, atol=1e-3)  # through the view's display pixels and back
    ref = calibrate(pairs, app.depth, app.camera)
    T = ref.T_camera_lidar
    assert np.allclose(app.result.T_camera_lidar, T, atol=1e-9)

    # Error display and residual table.
    mean = float(re.search(r"\*\*Mean error: ([0-9.]+) px\*\*", driver.result_panel).group(1))
    assert mean == pytest.approx(ref.mean_px, abs=6e-4)
    rows = {int(m.group(1)): float(m.group(2))
            for m in re.finditer(r"^\| \**(\d+)\** \| \**([0-9.]+)\**", driver.residual_table, re.M)}
    assert sorted(rows) == sorted(p.id for p in pairs)
    for k, pos in enumerate(getattr(ref, "pair_positions", None) or range(len(pairs))):
        assert rows[pairs[pos].id] == pytest.approx(float(ref.residual_px[k]), abs=6e-3)

    # 2-D overlays: the laser points reprojected by the new pose, and a residual line from each clicked pixel.
    points, _, clicked = resolve_pairs(pairs, app.depth, app.camera)
    uv, ok = app.camera.project(points @ T[:3, :3].T + T[:3, 3])
    assert ok.all()
    want = _display(driver, uv)
    drawn = driver.drawn_display_pixels("/annot/overlay/reprojected", key)
    assert len(drawn) == len(want)
    assert cKDTree(drawn).query(want)[0].max() < 1e-2
    segs = driver.drawn_segment_pixels("/annot/overlay/residuals", key)
    ends = np.concatenate([_display(driver, clicked), want], axis=1)  # (N, 4): clicked, reprojected
    assert len(segs) == len(ends)
    assert cKDTree(segs.reshape(-1, 4)).query(ends)[0].max() < 1e-2

    # The BA-edge points (off by default since stop 28): where the new pose puts them (every one drawn is one of
    # them, and most are drawn).
    app.state.set_view(show_edges=True)
    assert driver.wait_idle()
    edges = app.scene_data.edge_points_lidar
    e_uv, e_ok = app.camera.project(edges @ T[:3, :3].T + T[:3, 3])
    e_want = _display(driver, e_uv[e_ok], shown_only=True)
    e_drawn = driver.drawn_display_pixels("/annot/overlay/edges", key)
    assert len(e_drawn) > 0.5 * len(e_want)
    assert cKDTree(e_want).query(e_drawn)[0].max() < 1e-2


def test_click_during_a_slow_solve_shows_the_marker_before_the_solve(driver, monkeypatch):
    """A solve that takes longer than the click waits for: the click draws the moved marker itself and says it is
    solving; the overlays follow when the solve is done."""
    import threading

    import app.live_coordinator as live_module

    app = driver.app
    key = driver.camera_key
    release = threading.Event()

    def held_calibrate(*args, **kwargs):
        release.wait(30.0)  # the solve cannot finish before the test has looked at the page
        return calibrate(*args, **kwargs)

    monkeypatch.setattr(live_module, "calibrate", held_calibrate)
    pick = app.state.picks[5]
    old = pick.pixel
    new = (old[0] - 5.0, old[1] + 2.0)
    before = driver.drawn_display_pixels("/annot/overlay/reprojected", key)
    driver.select_in_dropdown(pick.id)
    try:
        notes = driver.click_camera(*new)
        assert [n for n in notes if n[0] in ("Internal error", "Not accepted")] == [], notes
        _moved_marker_check(driver, key, old, new)  # drawn while the solve is still held
        assert "Solving 10 pairs" in driver.result_panel
        assert np.array_equal(driver.drawn_display_pixels("/annot/overlay/reprojected", key), before)
    finally:
        release.set()
    assert driver.wait_idle()
    _moved_marker_check(driver, key, old, new)
    assert "Solving" not in driver.result_panel
    ref = calibrate(app.state.pairs(), app.depth, app.camera)
    points, _, _ = resolve_pairs(app.state.pairs(), app.depth, app.camera)
    T = ref.T_camera_lidar
    want = _display(driver, app.camera.project(points @ T[:3, :3].T + T[:3, 3])[0])
    drawn = driver.drawn_display_pixels("/annot/overlay/reprojected", key)
    assert len(drawn) == len(want) and cKDTree(drawn).query(want)[0].max() < 1e-2
