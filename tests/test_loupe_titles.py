"""The loupes' titles fit the loupe, and the camera loupe's two marks are told apart (by-eye frictions, issue 20).

The walkthrough at 1400 x 900 saw the laser loupe's title cut by the control panel ("row 4, column 893, range 10"
-- before the unit), and after a refining click could not tell the photo point from the projected laser point.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.layout import LABEL_HEIGHT, bounds_of, layout_with_render, loupe_areas
from app.loupe_marks import LEGEND, TITLE_MAX_CHARS, ba_title, camera_title, render_title
from app_driver import AppDriver, sample_app
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import transform_points
from repo_paths import SAMPLE

#: viser's screen labels: a 12 CSS px em (its LabelRenderer) x the loupe titles' font_screen_scale 0.9; a
#: proportional sans-serif character is at most about 0.65 em on average over digits and letters.
CHAR_PX = 0.65 * 12 * 0.9
KEYS = ("horizontal", "vertical", "diag_pos45", "diag_neg45")


def loupe_width_px(camera_size, ba_size, cell_aspect, canvas=(1000, 900)) -> float:
    """Screen width (px) of a loupe when the whole page is fitted into ``canvas`` (1400 x 900 less the panel)."""
    slots = layout_with_render({"raw": camera_size}, "raw", ba_size, KEYS, cell_aspect)
    x0, y0, x1, y1 = bounds_of(list(slots.values()))
    areas = loupe_areas((x0, y0, x1, y1))
    for a in areas.values():
        x1, y1 = max(x1, a.x0 + a.width), max(y1, a.y0 + a.height)
    return areas["camera"].width * min(canvas[0] / (x1 - x0), canvas[1] / (y1 - y0))


@pytest.mark.parametrize("camera_size, ba_size, cell_aspect", [
    ((1920, 1200), (272, 64), 3.3),  # PJLab manual_calib, the columns facing the camera
    ((1242, 375), (520, 64), 2.53),  # KITTI 000002
])
def test_the_longest_titles_fit_the_loupe(camera_size, ba_size, cell_aspect):
    width = loupe_width_px(camera_size, ba_size, cell_aspect)
    longest = [ba_title("BA horizontal", 127, 4095, 120.0), ba_title("Intensity", 127, 4095, None),
               render_title((127, 4095), 120.0), render_title(None, None),
               render_title((127, 4095), 120.0, 1200), render_title(None, None, 1200),
               camera_title(camera_size[0] - 0.5, camera_size[1] - 0.5, 1200)]
    for title in longest:
        assert len(title) <= TITLE_MAX_CHARS, title
    assert TITLE_MAX_CHARS * CHAR_PX <= width, (TITLE_MAX_CHARS, width)
    assert len(LEGEND) * CHAR_PX * 0.8 / 0.9 <= width


def test_the_legend_has_its_own_line_under_the_camera_loupe():
    slots = layout_with_render({"raw": (1920, 1200)}, "raw", (272, 64), KEYS, 3.3)
    main = bounds_of(list(slots.values()))
    cam, ba = loupe_areas(main)["camera"], loupe_areas(main)["ba"]
    # Camera loupe, legend line, the laser loupe's title line, the laser loupe: no overlap, inside the page.
    assert ba.y0 - LABEL_HEIGHT >= cam.y0 + cam.height + LABEL_HEIGHT - 1e-9
    assert ba.y0 + ba.height <= main[3] + LABEL_HEIGHT + 1e-9  # as low as before the legend line


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


def test_app_titles_and_the_two_marks_after_a_refining_click(tmp_path, scene):
    """After 5 pairs (a solve) and a refining click in the camera loupe: a cross at the clicked pixel, a ring at the
    pair's laser point projected under the pose shown (projected here), and the legend naming both."""
    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        pairs = simulate_pairs(scene, 5, np.random.default_rng(4), pixel_noise_px=2.0)
        for p in pairs:
            assert d.click_cell("vertical", *p.laser_rc) == [] and d.click_camera(*p.pixel) == []
        assert d.wait_idle() and app.pose() is not None
        last = pairs[-1]
        u, v = last.pixel[0] + 1.5, last.pixel[1] - 1.0
        assert d.click_loupe_camera(u, v) == [] and d.wait_idle()  # the refining click
        assert app.state.picks[-1].pixel == pytest.approx((u, v))
        for kind in ("ba", "camera"):
            assert len(d.loupe_title(kind)) <= TITLE_MAX_CHARS, d.loupe_title(kind)
        assert f"({u:.1f}, {v:.1f})" in d.loupe_title("camera")
        assert app.loupes.legend == LEGEND and "your click" in LEGEND and "laser point projected" in LEGEND

        c = app.loupes.camera_crop
        # Crosses: two straight segments per click, crossing at the clicked pixel.
        cross = d.drawn_segment_pixels("/annot/loupe/camera_marks", "loupe_camera").reshape(-1, 2, 2, 2)
        centres = cross.mean(axis=(1, 2)) + [c.u0, c.v0]
        k = np.argmin(np.linalg.norm(centres - [u, v], axis=1))
        assert np.linalg.norm(centres[k] - [u, v]) < 0.05
        arms = cross[k, :, 1] - cross[k, :, 0]
        assert abs(float(np.dot(arms[0], arms[1]))) < 1e-6  # perpendicular: a "+"
        # Rings: the pairs' laser points projected under the pose the app predicts with.
        pts = app.depth.points[last.laser_rc[0], last.laser_rc[1]][None]
        uv, ok = app.camera.project(transform_points(app.pose(), pts))
        assert ok[0]
        ring = d.drawn_segment_pixels("/annot/loupe/camera_laser", "loupe_camera")
        from app.ui_common import RING_SEGMENTS

        per_ring = ring.reshape(-1, RING_SEGMENTS, 2, 2)  # rings only: no ticks, no cell outline
        rings = per_ring[:, :, 0, :].mean(axis=1) + [c.u0, c.v0]
        j = int(np.argmin(np.linalg.norm(rings - uv[0], axis=1)))
        assert np.linalg.norm(rings[j] - uv[0]) < 0.05
        # Neither looks like the other: every point of the ring is off its centre by the same radius (nothing
        # drawn through it), and both arms of the cross pass through its centre.
        radii = np.linalg.norm(per_ring[j] + [c.u0, c.v0] - rings[j], axis=-1)
        assert radii.min() > 1.0 and np.ptp(radii) < 0.05 * radii.mean()
        assert np.allclose(cross[k].mean(axis=1) + [c.u0, c.v0], [u, v], atol=0.05)
        # The click and its laser point differ by the pair's residual: both marks are there to compare.
        assert np.linalg.norm(uv[0] - [u, v]) > 0.1
    finally:
        app.stop()


def test_the_render_loupe_names_its_side_as_the_photo_loupe_does():
    """Run 13: the photo loupe's title gave its side in px and the render loupe's did not, so their scales could not
    be compared."""
    assert render_title((4, 893), 10.2, 72) == "Render · r4 c893 · 10.20 m · 72 px"
    assert render_title(None, None, 108) == "Render · no return here · 108 px"
    assert camera_title(620.5, 187.0, 72).endswith("· 72 px")
