"""The loupes, driven as a tab would through :class:`app_driver.AppDriver` (no browser).

Truth: the sample's ground-truth extrinsics and :func:`calib_core.synthetic.simulate_pairs` (cells and pixels of
real scene corners), and hand-computed geometry (a 3-sigma circle of a 4 px^2 covariance has radius 6 px).
"""

from __future__ import annotations


import numpy as np
import pytest

from app_driver import sample_app
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


def test_loupe_clicks_map_back_exactly_and_refine_the_full_image_click(tmp_path, scene):
    from app_driver import AppDriver

    pair = simulate_pairs(scene, 1, np.random.default_rng(4), pixel_noise_px=0.0)[0]
    row, col = pair.laser_rc
    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        assert d.click_cell("vertical", row + 2, col - 3) == []  # a rough click on the full BA image
        assert d.loupe_view("ba") == {"key": "vertical", "center": (row + 2, col - 3), "size": 32}
        assert d.click_loupe_cell(row, col) == []  # the wanted cell, in the loupe: replaces the rough one
        assert [p.laser_rc for p in app.state.picks] == [(row, col)]
        u, v = pair.pixel
        assert d.click_camera(u + 4.0, v - 3.0) == []  # completes the pair roughly ...
        assert d.loupe_view("camera")["center"] == pytest.approx((u + 4.0, v - 3.0))
        assert d.click_loupe_camera(u, v) == []  # ... and the loupe click refines that end, sub-pixel
        (pick,) = app.state.picks
        assert pick.laser_rc == (row, col)
        assert np.hypot(pick.pixel[0] - u, pick.pixel[1] - v) < 1e-6
        # While the loupes show this finished pair, a second loupe click refines it again (by-eye runs 1 and 4:
        # a new pair there surprised the person); a new pair starts on the full images.
        assert d.click_loupe_camera(u + 1.25, v) == []
        (pick,) = app.state.picks
        assert pick.pixel == pytest.approx((u + 1.25, v)) and pick.laser_rc == (row, col)
        assert d.click_loupe_cell(row, col + 1) == []  # the laser loupe refines the laser end the same way
        (pick,) = app.state.picks
        assert pick.laser_rc == (row, col + 1)
        assert d.click_cell("vertical", row + 5, col + 5) == []  # the full image: a new pair
        assert len(app.state.picks) == 2
        # Outside the image: refused with one line, nothing changes.
        app.loupes.frame_camera(2.0, 2.0)
        notes = d.click("loupe_camera", (0.0, 0.0))
        assert notes and "outside the camera image" in notes[0][1] and len(app.state.picks) == 2
    finally:
        app.stop()


def test_predictions_both_ways_from_an_imported_initial_extrinsic(tmp_path, scene):
    from app_driver import AppDriver

    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    pairs = simulate_pairs(scene, 6, np.random.default_rng(7), pixel_noise_px=0.0)
    app = sample_app(tmp_path / "session.yaml", initial_extrinsics_path=SAMPLE / "ground_truth.yaml")
    try:
        np.testing.assert_allclose(app.initial_T_camera_lidar, truth, atol=1e-12)
        d = AppDriver(app)
        for pair in pairs[:3]:  # BA click -> the camera loupe on the predicted pixel, near the true corner
            d.click_cell("horizontal", *pair.laser_rc)
            centre = np.array(d.loupe_view("camera")["center"])
            # The cell's point is within half a cell of the corner: a few pixels at most on this 640 px image.
            assert np.hypot(*(centre - pair.pixel)) < 3.0
            assert d.loupe_display_pixel("camera", pair.pixel) is not None
            d.click_loupe_camera(*pair.pixel)
        for pair in pairs[3:]:  # camera click -> the BA loupe on the cell seen there
            d.click_camera(*pair.pixel)
            r, c = d.loupe_view("ba")["center"]
            assert abs(r - pair.laser_rc[0]) <= 1 and abs(c - pair.laser_rc[1]) <= 1
            d.click_loupe_cell(*pair.laser_rc)
        assert [p.laser_rc for p in app.state.picks] == [p.laser_rc for p in pairs]
    finally:
        app.stop()


def test_frame_camera_draws_the_3_sigma_ellipse_and_zoom_keeps_the_centre(tmp_path):
    from app_driver import AppDriver

    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        app.loupes.frame_camera(300.25, 200.5, cov_px2=np.diag([4.0, 4.0]))
        slot = app.loupes.slot("camera")
        ring = app.nodes.segments("/annot/loupe/ellipse").reshape(-1, 3)
        centre = slot.world_from_pixel(np.array([[300.25, 200.5]]) - [app.loupes.camera_crop.u0,
                                                                       app.loupes.camera_crop.v0])[0]
        radius_px = np.hypot(ring[:, 0] - centre[0], ring[:, 1] - centre[1]) / slot.units_per_px
        np.testing.assert_allclose(radius_px, 6.0, rtol=1e-4)  # 3 * sqrt(4)
        app.loupes.frame_camera(300.25, 200.5)
        assert len(app.nodes.segments("/annot/loupe/ellipse")) == 0

        app.loupes.frame_ba("diag_pos45", 90, 700)
        before = d.loupe_view("ba")
        assert d.press_loupe_zoom("BA -") == []
        after = d.loupe_view("ba")
        assert after["center"] == before["center"] and after["size"] > before["size"]
        assert d.press_loupe_zoom("Camera +") == []
        assert d.loupe_view("camera")["size"] < 36 and d.loupe_view("camera")["center"] == (300.25, 200.5)
        # The BA loupe wraps around a 360 deg scan: column 719 and column 0 sit side by side.
        app.loupes.frame_ba("horizontal", 90, 719)
        a, b = d.loupe_display_pixel("ba", (719, 90)), d.loupe_display_pixel("ba", (0, 90))
        assert b[0] - a[0] == pytest.approx(1.0)
        assert d.click_loupe_cell(90, 0) == [] and app.state.picks[-1].laser_rc == (90, 0)
    finally:
        app.stop()


def test_initial_extrinsics_upload(tmp_path):
    from app_driver import AppDriver

    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        assert app.initial_T_camera_lidar is None and app.pose() is None
        notes = d.upload_initial_extrinsics("rough.yaml", b"not: an extrinsics file\n")
        assert len(notes) == 1 and notes[0][0] == "Not accepted" and "\n" not in notes[0][1]
        assert app.initial_T_camera_lidar is None
        content = (SAMPLE / "ground_truth.yaml").read_bytes()
        notes = d.upload_initial_extrinsics("ground_truth.yaml", content)
        assert notes and notes[0][0] == "Initial extrinsics imported"
        truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
        np.testing.assert_allclose(app.pose(), truth, atol=1e-12)
    finally:
        app.stop()


def test_loupe_shows_range_and_contrast_and_the_edge_overlay_stays_in_the_fisheye_circle(tmp_path):
    import yaml

    from app_driver import AppDriver
    from calib_core.pairs import load_pairs_yaml

    session = tmp_path / "session.yaml"
    session.write_text(yaml.safe_dump({"format": "ba-calib-session", "version": 1, "pairs": [],
                                       "view": {"panorama": False}}))
    from app.server import CalibrationApp

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml", session_path=session,
                         port=0)
    try:
        d = AppDriver(app)
        assert "Range" in app.laser_images.loupe_sources()
        app.loupes.frame_ba("horizontal", 90, 300)
        k = app.loupes.texture("ba").shape[1] // app.loupes.ba_crop.n_cols  # texels per cell
        ba_centre = d.loupe_texture("ba")[::k, ::k]
        assert d.choose_loupe_source("Range") == []
        rng = d.loupe_texture("ba")[::k, ::k]
        c = app.loupes.ba_crop
        depth = app.depth.range_m[c.row0:c.row0 + c.n_rows, c.col0:c.col0 + c.n_cols]
        valid = app.depth.valid[c.row0:c.row0 + c.n_rows, c.col0:c.col0 + c.n_cols]
        # Nearer is darker: the grey order follows the range order (log stretch is monotone).
        order = np.argsort(depth[valid])
        assert np.all(np.diff(rng[valid][order].astype(int)) >= 0) and not np.array_equal(rng, ba_centre)
        assert "Range loupe" in app.loupes.title("ba")
        # Contrast 2 spreads the grey levels of the BA panes about their median.
        before = app.laser_images.ba_display("horizontal").astype(float)
        assert d.set_slider("Laser contrast", 2.0) == []
        after = app.laser_images.ba_display("horizontal").astype(float)
        ok = before > 0
        assert after[ok].std() > 1.3 * before[ok].std() and np.all(after[~ok] == 0)

        app.state.set_view(show_edges=True)  # off by default since stop 28
        app.state.import_pairs(load_pairs_yaml(SAMPLE / "pairs.yaml"))
        assert d.wait_idle()
        pts, cols = d.drawn_points("/annot/overlay/edges")
        assert len(pts) > 100
        uv = np.round(app.slots["raw"].pixel_from_world(pts)).astype(int)
        lit = app.image.max(axis=2) > 0  # the fisheye circle, from the image itself
        assert lit[uv[:, 1], uv[:, 0]].all()
        # Opacity 0.5: each point's colour is halfway between the edge colour and the image under it.
        assert d.set_slider("BA-edge opacity", 0.5) == []
        pts, cols = d.drawn_points("/annot/overlay/edges")
        uv = np.round(app.slots["raw"].pixel_from_world(pts)).astype(int)
        expected = 0.5 * np.array([0, 190, 255]) + 0.5 * app.image[uv[:, 1], uv[:, 0]]
        assert np.abs(cols.astype(float) - expected).max() <= 1.0
        assert d.set_slider("BA-edge opacity", 0.0) == [] and len(d.drawn_points("/annot/overlay/edges")[0]) == 0
    finally:
        app.stop()


def test_bad_initial_extrinsics_and_bad_frames_are_one_line_errors(tmp_path):
    from calib_core.errors import CalibError

    with pytest.raises(CalibError, match="extrinsics file not found") as info:
        sample_app(tmp_path / "session.yaml", initial_extrinsics_path=tmp_path / "missing.yaml")
    assert "\n" not in str(info.value)
    app = sample_app(tmp_path / "session.yaml")
    try:
        with pytest.raises(CalibError, match="no BA image 'nope'"):
            app.loupes.frame_ba("nope", 1, 1)
        with pytest.raises(CalibError, match="outside the 180 x 720 scan"):
            app.loupes.frame_ba("horizontal", 180, 0)
        with pytest.raises(CalibError, match="2x2 covariance"):
            app.loupes.frame_camera(10.0, 10.0, cov_px2=np.eye(3))
    finally:
        app.stop()


def test_last_laser_pane_shows_range_picks_the_same_cells_and_is_saved(tmp_path):
    from app.server import CalibrationApp
    from app_driver import AppDriver

    session = tmp_path / "session.yaml"
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml", session_path=session,
                         port=0)
    try:
        d = AppDriver(app)
        last, first = app.ba_keys[-1], app.ba_keys[0]
        assert app.laser_images.last_pane_sources()[0] == app.laser_images.ba_title(last) and "Range" in app.laser_images.last_pane_sources()
        ba_tex, other_tex = d.ba_texture(last).copy(), d.ba_texture(first).copy()
        assert d.choose_last_pane_source("Range") == []
        tex = d.ba_texture(last)
        f = tex.shape[0] // app.depth.shape[0]  # texels per cell
        grey = tex[::f, ::f][..., 0] if tex.ndim == 3 else tex[::f, ::f]
        valid = app.depth.valid
        # Nearer is darker: the grey order follows the scan's range order.
        order = np.argsort(app.depth.range_m[valid])
        assert np.all(np.diff(grey[valid][order].astype(int)) >= 0)
        assert not np.array_equal(tex, ba_tex) and np.array_equal(d.ba_texture(first), other_tex)
        assert app.laser_images.ba_title(last) == "Range"
        # A click on the range pane picks the cell under it, as on a BA pane.
        assert d.click(last, (301.3, 80.4)) == []  # cell centres at whole display pixels
        assert app.state.picks[-1].laser_rc == (80, 301)
    finally:
        app.stop()

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml", session_path=session,
                         port=0)
    try:
        d = AppDriver(app)
        assert app.laser_images.last_pane_source == "Range" and np.array_equal(d.ba_texture(last), tex)
        assert d.choose_last_pane_source(app.laser_images.last_pane_sources()[0]) == []
        assert np.array_equal(d.ba_texture(last), ba_tex) and app.state.view.last_pane_shows == ""
    finally:
        app.stop()
