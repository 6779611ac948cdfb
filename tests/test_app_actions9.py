"""Stop 28 (docs/by_eye.md, run 8): a precise pair in three clicks, and run 8's frictions in the render, its loupe
and the pair bar; driven through :class:`app_driver.AppDriver` on the committed sample (one test per friction)."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from calib_core.transforms import transform_points

from app_driver import AppDriver


def _near_truth_render(d: AppDriver, scene, turn: tuple[float, float, float] = (0.003, -0.002, 0.002)) -> None:
    """A rough pose about 0.2 deg off the truth, and its render shown."""
    from calib_core.alignment import rotate_about_camera

    d.app.pose_source.adopt_rough_pose(rotate_about_camera(scene.T_camera_lidar, *turn))
    assert d.wait_idle() and d.wait_render()


def _a_corner(scene, k: int = 3):
    from calib_core.synthetic import simulate_pairs

    return simulate_pairs(scene, 8, np.random.default_rng(11), pixel_noise_px=0.0)[k]


def test_a_precise_pair_takes_three_clicks_photo_then_the_lower_loupe_then_the_photo_loupe(app, scene):
    """Run 8 (KITTI): each pair took 4 clicks (photo, render, then one in each loupe).  A rough click on the photo
    now shows the render at that place in the lower loupe, a click there makes the laser end, and a click in the
    photo loupe puts the photo end exactly; the bar says which click comes next and where."""
    d = AppDriver(app)
    _near_truth_render(d, scene)
    pair = _a_corner(scene)
    (u, v) = pair.pixel
    cell = app.render_pane.cell_at_pixel(u, v)  # what the render draws at the corner (the person's target)
    assert cell is not None
    # 1: a rough click on the full photo, 5 px off the corner.
    assert d.click_camera(u + 4.0, v - 3.0) == []
    half = app.state.pending()
    assert half is not None and half.laser_rc is None
    assert app.loupes.shows_render  # the lower loupe shows the render at the photo click
    assert "waits for a BA click → **lower loupe**" in d.pair_status, d.pair_status
    # 2: a click in the lower loupe where it draws the corner's cell makes the laser end.
    where = d.loupe_display_pixel("ba", (cell[1], cell[0]))
    assert where is not None, "the corner's cell is not in the lower loupe"
    assert d.click("loupe_ba", where) == []
    made = app.state.get(half.id)
    assert made.complete and made.laser_rc == cell and app.state.pending() is None
    assert f"Pair {half.id} made" in d.pair_status and "**photo loupe**" in d.pair_status, d.pair_status
    # 3: a click in the photo loupe on the corner moves the photo end there (the same pair, no new one).
    assert d.click_loupe_camera(u, v) == []
    assert len(app.state.picks) == 1 and app.state.get(half.id).pixel == pytest.approx((u, v), abs=1e-6)
    assert app.state.get(half.id).laser_rc == cell
    assert "made" not in d.pair_status, d.pair_status  # done: the next click on the photo starts the next pair
    # The next full-photo click starts pair 2.
    nxt = _a_corner(scene, 5)
    assert d.click_camera(*nxt.pixel) == [] and app.state.pending().id != half.id


def test_undo_takes_the_undone_cell_out_of_the_render_loupes_title(app, scene):
    """Run 8: after Ctrl+Z the render loupe's title kept naming the cell the undone click had chosen."""
    d = AppDriver(app)
    _near_truth_render(d, scene)
    pair = _a_corner(scene)
    assert d.click_render(*pair.pixel) == [] and d.click_camera(*pair.pixel) == [] and d.wait_idle()
    first = app.state.picks[-1].laser_rc
    # A refining click in the render loupe on another cell, a quarter of the crop from its centre.
    crop = app.loupes.render_crop
    centre_cell = app.render_pane.cell_at_pixel(*crop.center)
    spot = None
    for dx, dy in ((-0.3, -0.3), (0.3, -0.3), (-0.3, 0.3), (0.3, 0.3)):
        x, y = (0.5 + dx) * crop.n, (0.5 + dy) * crop.n
        c = app.render_pane.cell_at_pixel(crop.u0 + x, crop.v0 + y)
        if c is not None and c not in (first, centre_cell):
            spot, moved = (x, y), c
            break
    assert spot is not None
    assert d.click("loupe_ba", spot) == [] and app.state.picks[-1].laser_rc == moved
    assert f"r{moved[0]} c{moved[1]}" in d.loupe_title("ba")
    assert d.press_pair_action("Undo") == [] and d.wait_idle()
    assert app.state.picks[-1].laser_rc == first
    assert f"r{moved[0]} c{moved[1]}" not in d.loupe_title("ba"), d.loupe_title("ba")


def _edge_render(width: int = 40, height: int = 20):
    """A wall at 37 m (cells (5, c)) with a pole 2 px wide at 30 m (cell (2, 7)) at columns 20-21."""
    cell_rc = np.zeros((height, width, 2), np.int32)
    cell_rc[..., 0] = 5
    cell_rc[..., 1] = np.arange(width)[None, :] // 4
    depth = np.full((height, width), 37.0, np.float32)
    cell_rc[:, 20:22] = (2, 7)
    depth[:, 20:22] = 30.0
    edge = np.zeros((height, width), bool)
    edge[:, 19:23] = True  # the render outlines the pole (both sides of each jump)
    render = SimpleNamespace(cell_rc=cell_rc, camera_depth_m=depth, range_m=depth, edge=edge)
    from app.shown_render import ShownRender

    return ShownRender(np.eye(4), "range", "rough", render, np.zeros((height, width, 4), np.uint8), 0.0)


def test_a_click_beside_a_thin_near_object_takes_it_not_the_wall_behind():
    """Run 8: a laser click at a thin near object's edge took the background cell (36.96 m instead of about 30 m)."""
    from app.shown_render import cell_at_pixel

    shown = _edge_render()
    # On the pixel itself: the cell the z-buffer drew there.
    assert cell_at_pixel(shown, 20.0, 10.0) == (2, 7) and cell_at_pixel(shown, 23.0, 10.0) == (5, 5)
    # One pixel right of the pole, where a click on the page's scaled-down render lands: the pole.
    assert cell_at_pixel(shown, 22.0, 10.0, edge_px=1.5) == (2, 7)
    assert cell_at_pixel(shown, 22.4, 10.0, edge_px=1.5) == (2, 7)
    # Farther than the edge radius: the wall; and no edge radius (a loupe, where a pixel is many screen pixels):
    # exactly what is drawn.
    assert cell_at_pixel(shown, 25.0, 10.0, edge_px=1.5) == (5, 6)
    assert cell_at_pixel(shown, 22.0, 10.0, edge_px=0.0) == (5, 5)
    # The pole itself is never traded for the wall.
    assert cell_at_pixel(shown, 21.0, 10.0, edge_px=3.0) == (2, 7)
    # A nearer surface the render does not outline (a smooth slope, e.g. the ground before a wall's foot) is no
    # edge: the click keeps what is drawn.
    shown.render.edge[:] = False
    assert cell_at_pixel(shown, 22.0, 10.0, edge_px=1.5) == (5, 5)


def test_a_click_on_the_render_at_a_depth_edge_takes_the_foreground(app, scene):
    """The same on the sample's render, clicked as a tab would: a pixel just behind a nearer surface."""
    d = AppDriver(app)
    _near_truth_render(d, scene)
    r = d.render_shown.render
    depth = np.where(r.cell_rc[..., 0] >= 0, r.camera_depth_m, np.inf)
    h, w = depth.shape
    left = np.full_like(depth, np.inf)
    left[:, 1:] = depth[:, :-1]  # the depth one pixel to the left
    behind = np.isfinite(depth) & (left * 1.1 < depth) & r.edge & np.roll(r.edge, 1, axis=1)
    behind[:, :5] = behind[:, -5:] = False
    behind[:5] = behind[-5:] = False
    vs, us = np.nonzero(behind)
    assert len(vs) > 10
    for k in np.linspace(0, len(vs) - 1, 6).astype(int):
        u, v = int(us[k]), int(vs[k])
        assert d.click_render(float(u), float(v)) == []
        got = app.state.pending().laser_rc
        front = tuple(int(x) for x in r.cell_rc[v, u - 1])
        near = {tuple(int(x) for x in r.cell_rc[v + dv, u + du]) for du in (-1, 0, 1) for dv in (-1, 0, 1)
                if np.isfinite(depth[v + dv, u + du]) and depth[v + dv, u + du] <= depth[v, u - 1] * 1.1 * 1.1}
        assert got != tuple(int(x) for x in r.cell_rc[v, u]) or got == front, (u, v)
        assert got in near | {front}, (u, v, got, front)
        assert d.press_pair_action("Cancel pair") == []


def test_the_render_loupes_mark_sits_in_the_middle_of_what_its_cell_draws(app, scene):
    """Run 8: the cross sat on a cell's edge, and a click about 10 px beside it said "No change ... same cell"."""
    from scipy import ndimage

    d = AppDriver(app)
    _near_truth_render(d, scene)
    r = d.render_shown.render
    from calib_core.synthetic import simulate_pairs

    cells = np.array([p.laser_rc for p in simulate_pairs(scene, 40, np.random.default_rng(2), pixel_noise_px=0.0)])
    uv = app.render_pane.pixel_of_cells(cells)
    checked = 0
    for (row, col), (u, v) in zip(cells, uv):
        if not np.isfinite(u):
            continue
        iu, iv = int(u), int(v)
        mine = (r.cell_rc[..., 0] == row) & (r.cell_rc[..., 1] == col)
        if u != iu or not mine[iv, iu]:
            continue  # the render does not draw that cell near its point (hidden): the mark is its projection
        labels, _ = ndimage.label(mine)
        blob = labels == labels[iv, iu]
        if blob.sum() < 4:
            continue
        bv, bu = np.nonzero(blob)
        # The mark is the drawn pixel nearest the middle of the cell's patch (within 1 px of its centroid, unless
        # the patch is not convex: then the drawn pixel nearest it).
        d2 = (bu - bu.mean()) ** 2 + (bv - bv.mean()) ** 2
        assert (iu - bu.mean()) ** 2 + (iv - bv.mean()) ** 2 <= d2.min() + 1.0 + 1e-9, (row, col, u, v)
        checked += 1
    assert checked >= 4


def test_the_bar_names_the_worst_pair_and_its_error(app, scene):
    """Run 8: which pair was bad was three panel scrolls away (the Calibration table)."""
    from calib_core.synthetic import simulate_pairs

    d = AppDriver(app)
    pairs = simulate_pairs(scene, 8, np.random.default_rng(3), pixel_noise_px=0.7)
    for k, pair in enumerate(pairs):
        u, v = pair.pixel
        if k == 5:
            u, v = u + 4.0, v - 3.0  # a bad click: 5 px off
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(u, v) == []
    assert d.wait_idle() and app.result is not None
    line = app.pairs_panel.bar.live_line
    m = re.search(r" · worst: pair (\d+) ([0-9.]+) px", line)
    assert m, line
    # Independent: each fitted pair's reprojection error under the solved pose, computed here.
    r = app.result
    fitted = [p for p in app.state.complete_picks() if p.id not in set(getattr(r, "outlier_ids", []))]
    pts = np.array([app.depth.points[p.laser_rc] for p in fitted])
    uv, ok = app.camera.project(transform_points(r.T_camera_lidar, pts))
    err = np.linalg.norm(np.asarray(uv) - np.array([p.pixel for p in fitted]), axis=1)
    worst = int(np.argmax(err))
    assert int(m.group(1)) == fitted[worst].id == app.state.complete_picks()[5].id
    assert float(m.group(2)) == pytest.approx(err[worst], abs=0.06)


def test_ba_edge_points_are_off_by_default_and_the_view_checkbox_shows_them(app, scene):
    """Runs 7 and 8: "Reprojected BA-edge points" (on by default) cluttered the zoomed photo with cyan dots while
    picking; they are for checking a pose, so they wait until the person ticks them."""
    from calib_core.pairs import load_pairs_yaml
    from repo_paths import SAMPLE

    d = AppDriver(app)
    app.state.import_pairs(load_pairs_yaml(SAMPLE / "pairs.yaml"))
    assert d.wait_idle() and app.result is not None and len(app.solve_bundle.edges_camera) > 100
    assert not app.state.view.show_edges and len(d.drawn_points("/annot/overlay/edges")[0]) == 0
    app.state.set_view(show_edges=True)
    assert d.wait_idle() and len(d.drawn_points("/annot/overlay/edges")[0]) > 100
