"""Edge pairs in the app: with "Photo end on an edge" ticked, a photo click on a straight edge makes a pair whose
photo end may slide along that edge (``Pick.edge_deg``, the photo's edge direction there); the pair keeps it in the
session, hands it to the solve and draws its photo end as a line along the edge.

The photo is the sample's with a painted band at a known angle, so the expected direction is known by
construction, not from the code under test."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from app_driver import AppDriver
from repo_paths import SAMPLE

BAND_DEG = 30.0  # from +u towards +v
BAND_CENTRE = (320.0, 240.0)
FLAT_PIXEL = (80.0, 420.0)  # inside a uniform patch


@pytest.fixture
def band_app(tmp_path):
    from app.server import CalibrationApp

    image = cv2.imread(str(SAMPLE / "image.png"))
    image[380:460, 40:120] = 90  # the uniform patch around FLAT_PIXEL
    a = np.radians(BAND_DEG)
    d = np.array([np.cos(a), np.sin(a)])
    p0, p1 = (np.array(BAND_CENTRE) - 150 * d), (np.array(BAND_CENTRE) + 150 * d)
    image[200:280, 240:400] = 40
    cv2.line(image, tuple(int(round(x)) for x in p0), tuple(int(round(x)) for x in p1), (230, 230, 230), 11,
             lineType=cv2.LINE_AA)
    photo = tmp_path / "image.png"
    cv2.imwrite(str(photo), image)
    app = CalibrationApp(SAMPLE / "scan.npz", photo, SAMPLE / "camera.yaml", session_path=tmp_path / "session.yaml",
                         port=0)
    yield app, photo, tmp_path / "session.yaml"
    app.stop()


def _fold(deg: float) -> float:
    return float(deg) % 180.0


def _angle_diff(a: float, b: float) -> float:
    d = abs(_fold(a) - _fold(b))
    return min(d, 180.0 - d)


def _edge_pair_at(app, uv) -> tuple[AppDriver, list]:
    """With "Photo end on an edge" ticked: a laser click, then a photo click at original pixel ``uv``; the
    driver and the photo click's notifications."""
    d = AppDriver(app)
    assert d.set_edge_pairs(True) == []
    assert d.click_cell(app.ba_keys[0], 20, 100) == []
    return d, d.click_camera(*uv)


def test_a_click_on_a_band_takes_its_direction_and_keeps_it(band_app):
    app, photo, session = band_app
    d, notes = _edge_pair_at(app, BAND_CENTRE)
    assert notes == []
    (pick,) = app.state.complete_picks()
    assert pick.edge_deg is not None and _angle_diff(pick.edge_deg, BAND_DEG) <= 3.0, pick.edge_deg
    assert app.state.pairs()[0].edge_deg == pick.edge_deg  # what the solve gets
    assert "on an edge" in d.pairs_panel  # the Pairs summary counts it
    # The session keeps it: a new app on the same files reads the pair back with its edge.
    app.stop()
    from app.server import CalibrationApp

    again = CalibrationApp(SAMPLE / "scan.npz", photo, SAMPLE / "camera.yaml", session_path=session, port=0)
    try:
        (back,) = again.state.complete_picks()
        assert back.edge_deg == pytest.approx(pick.edge_deg)
        assert again.state.view.edge_pairs  # the tick is a view setting, saved too
    finally:
        again.stop()


def test_the_photo_loupe_draws_an_edge_end_along_the_edge(band_app):
    d, _ = _edge_pair_at(band_app[0], BAND_CENTRE)
    segs = d.drawn_segment_pixels("/annot/loupe/camera_marks", "loupe_camera")
    assert len(segs) == 2  # one line along the edge and a short bar across, no "+"
    vec = segs[:, 1] - segs[:, 0]
    lengths = np.hypot(vec[:, 0], vec[:, 1])
    along = vec[np.argmax(lengths)]
    assert _angle_diff(np.degrees(np.arctan2(along[1], along[0])), BAND_DEG) <= 3.0
    assert lengths.max() >= 4 * lengths.min()


def test_no_straight_edge_means_a_corner_pair_and_says_so(band_app):
    app = band_app[0]
    d, notes = _edge_pair_at(app, FLAT_PIXEL)
    assert any("no single straight edge" in " ".join(n).lower() for n in notes), notes
    (pick,) = app.state.complete_picks()
    assert pick.edge_deg is None


def test_unticked_a_moved_photo_end_is_a_corner_again(band_app):
    app = band_app[0]
    d, _ = _edge_pair_at(app, BAND_CENTRE)
    (pick,) = app.state.complete_picks()
    assert pick.edge_deg is not None
    d.set_edge_pairs(False)
    # A refining click in the photo loupe moves the photo end: made without the tick, it is a corner.
    assert d.click_loupe_camera(BAND_CENTRE[0] + 1.0, BAND_CENTRE[1]) == []
    (moved,) = app.state.complete_picks()
    assert moved.pixel[0] == pytest.approx(BAND_CENTRE[0] + 1.0, abs=0.6) and moved.edge_deg is None


def test_an_edge_pairs_residual_line_runs_across_its_edge(tmp_path, scene):
    """The photo's residual lines join each click to its reprojected laser point; for an edge pair the click may
    lie anywhere along the edge, so its line goes to the foot on the edge: the across-edge error only."""
    from app.server import CalibrationApp
    from calib_core.synthetic import simulate_pairs
    from calib_core.transforms import transform_points

    corners = simulate_pairs(scene, 6, np.random.default_rng(11), pixel_noise_px=0.3)
    # An edge pair's laser end: a valid cell near the image centre, away from the corner pairs' cells.
    valid = np.argwhere(np.asarray(scene.depth.valid))
    uv, ok = scene.camera.project(transform_points(scene.T_camera_lidar, scene.depth.points[valid[:, 0], valid[:, 1]]))
    uv = np.asarray(uv)
    centre = np.array([scene.camera.width / 2, scene.camera.height / 2])
    far = np.min([np.hypot(*(uv - np.array(p.pixel)).T) for p in corners], axis=0)
    score = np.where(np.asarray(ok) & (far > 40), np.hypot(*(uv - centre).T), np.inf)
    k = int(np.argmin(score))
    cell, true_px = tuple(int(x) for x in valid[k]), uv[k]
    # The photo: a band at BAND_DEG through the cell's true projection; the click 25 px along the band.
    image = cv2.imread(str(SAMPLE / "image.png"))
    a = np.radians(BAND_DEG)
    d_band = np.array([np.cos(a), np.sin(a)])
    cv2.circle(image, tuple(int(x) for x in true_px), 60, (40, 40, 40), -1)
    cv2.line(image, tuple(int(x) for x in true_px - 55 * d_band), tuple(int(x) for x in true_px + 55 * d_band),
             (230, 230, 230), 11, lineType=cv2.LINE_AA)
    photo = tmp_path / "image.png"
    cv2.imwrite(str(photo), image)
    app = CalibrationApp(SAMPLE / "scan.npz", photo, SAMPLE / "camera.yaml", session_path=tmp_path / "s.yaml", port=0)
    try:
        d = AppDriver(app)
        for p in corners:
            assert d.click_cell(app.ba_keys[0], *p.laser_rc) == [] and d.click_camera(*p.pixel) == []
        d.set_edge_pairs(True)
        click = true_px + 25.0 * d_band
        assert d.click_cell(app.ba_keys[0], *cell) == [] and d.click_camera(*click) == []
        edge_pick = app.state.complete_picks()[-1]
        assert edge_pick.edge_deg is not None and _angle_diff(edge_pick.edge_deg, BAND_DEG) <= 3.0
        assert d.wait_idle()
        segs = d.drawn_segment_pixels("/annot/overlay/residuals", d.camera_key)
        assert len(segs) == 7
        # The edge pair's line starts at the foot on the edge (not at the click, 25 px along it) ...
        clicked_disp = np.asarray(d.camera_display_pixel(*click))
        starts = segs[:, 0]
        assert np.min(np.hypot(*(starts - clicked_disp).T)) > 5.0
        # ... and is short: the click is on the band through the true projection.
        lengths = np.hypot(*(segs[:, 1] - segs[:, 0]).T)
        assert lengths.max() < 6.0, lengths
    finally:
        app.stop()


def test_ticked_after_the_photo_click_the_tick_reaches_the_pair_being_made(band_app):
    """Run 16 (KITTI): a photo click, then the tick, then the laser click: the pair stayed a corner pair (43 px
    off) until its photo end was clicked again."""
    app = band_app[0]
    d = AppDriver(app)
    assert d.click_camera(*BAND_CENTRE) == []
    assert app.state.pending().edge_deg is None
    assert d.set_edge_pairs(True) == []
    assert _angle_diff(app.state.pending().edge_deg, BAND_DEG) <= 3.0
    assert d.click_cell(app.ba_keys[0], 20, 100) == []
    (pick,) = app.state.complete_picks()
    assert pick.edge_deg is not None


def test_an_older_pair_moved_with_the_tick_on_keeps_its_kind(band_app):
    """Run 16 (PJLab): with the tick on, moving a corner pair's photo end (selected by Shift+click) made it an
    edge pair, unasked."""
    app = band_app[0]
    d = AppDriver(app)
    assert d.click_cell(app.ba_keys[0], 20, 100) == [] and d.click_camera(*BAND_CENTRE) == []  # a corner pair
    corner = app.state.complete_picks()[0]
    d, _ = _edge_pair_at(app, (BAND_CENTRE[0] + 20 * np.cos(np.radians(BAND_DEG)),
                               BAND_CENTRE[1] + 20 * np.sin(np.radians(BAND_DEG))))
    assert app.state.complete_picks()[1].edge_deg is not None  # the newest: an edge pair
    assert d.select_in_dropdown(corner.id) == []
    assert d.click_camera(BAND_CENTRE[0] - 3.0, BAND_CENTRE[1] - 1.5) == []  # moves the selected corner pair
    moved = app.state.get(corner.id)
    assert moved.pixel[0] == pytest.approx(BAND_CENTRE[0] - 3.0, abs=0.6) and moved.edge_deg is None


def test_a_failed_solve_says_so_in_the_live_line(band_app, scene):
    """Run 16 (PJLab): with fewer than 4 corner pairs left beside the edge pairs the solve failed, but the live
    line kept the last good solve's figures; only the Calibration panel said so."""
    from calib_core.synthetic import simulate_pairs

    app = band_app[0]
    d = AppDriver(app)
    for pair in simulate_pairs(scene, 4, np.random.default_rng(8), pixel_noise_px=0.3):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    _edge_pair_at(app, BAND_CENTRE)
    assert d.wait_idle() and "Quality" in app.pairs_panel.bar.live_line
    first = app.state.complete_picks()[0].id
    assert d.select_in_dropdown(first) == [] and d.press_edit("Delete") == []
    assert d.wait_idle()
    line = app.pairs_panel.bar.live_line
    assert line.startswith("**Solve failed:**") and "4 corner pairs" in line, line
