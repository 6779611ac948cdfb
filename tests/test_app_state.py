"""The browser app's annotation state: picking, editing, history, session file."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import yaml

from app.picks import pair_color
from app.state import AnnotationState
from app.view_settings import ViewSettings
from calib_core.errors import CalibError
from calib_core.pairs import Pair, load_pairs_yaml, save_pairs_yaml
from repo_paths import SAMPLE

H, W = 20, 40  # depth matrix
IMG = (320, 240)  # camera image width, height


def make_valid() -> np.ndarray:
    valid = np.ones((H, W), bool)
    valid[0, :] = False  # a row without returns
    return valid


def make_state(tmp_path=None, name="session.yaml", **kwargs) -> AnnotationState:
    path = None if tmp_path is None else tmp_path / name
    return AnnotationState(make_valid(), IMG, session_path=path, **kwargs)


def ends(state):
    return [(p.id, p.laser_rc, p.pixel) for p in state.picks]


def test_either_click_order_makes_a_pair():
    s = make_state()
    a = s.add_laser(3, 4)
    assert s.add_pixel(10.5, 20.25) == a  # laser first
    b = s.add_pixel(100.0, 50.0)
    assert b != a
    assert s.pending().id == b
    assert s.add_laser(5, 6) == b  # camera first
    assert ends(s) == [(1, (3, 4), (10.5, 20.25)), (2, (5, 6), (100.0, 50.0))]
    assert s.pending() is None
    # The pairs carry the ids the page shows (one id in the UI, warnings and files).
    assert s.pairs() == [Pair((3, 4), None, (10.5, 20.25), id=a), Pair((5, 6), None, (100.0, 50.0), id=b)]


def test_second_click_on_same_side_replaces_the_pending_end():
    s = make_state()
    s.add_laser(3, 4)
    s.add_laser(7, 8)  # changed my mind on the BA image
    assert ends(s) == [(1, (7, 8), None)]
    assert s.pairs() == []  # incomplete picks are not solver input


def test_invalid_clicks_raise_one_line_errors_and_change_nothing():
    s = make_state()
    v0 = s.version
    with pytest.raises(CalibError, match="no laser return"):
        s.add_laser(0, 5)
    with pytest.raises(CalibError, match="outside the 20x40 scan"):
        s.add_laser(20, 0)
    with pytest.raises(CalibError, match="outside the 320x240 camera image"):
        s.add_pixel(320.0, 10.0)
    with pytest.raises(CalibError, match="outside"):
        s.add_pixel(-0.6, 10.0)
    with pytest.raises(CalibError, match="not finite"):
        s.add_pixel(float("nan"), 1.0)
    # The image border itself (pixel-centre convention) is inside.
    s.add_pixel(-0.5, 239.5)
    assert s.version == v0 + 1 and len(s.picks) == 1
    for msg in ("no laser return",):
        with pytest.raises(CalibError) as info:
            s.add_laser(0, 0)
        assert "\n" not in str(info.value) and msg in str(info.value)


def test_ids_and_colours_are_stable_after_delete():
    s = make_state()
    for k in range(3):
        s.add_laser(2 + k, 2)
        s.add_pixel(10.0 * k, 5.0)
    colors = {p.id: p.color for p in s.picks}
    s.delete(2)
    assert [p.id for p in s.picks] == [1, 3]
    assert {p.id: p.color for p in s.picks} == {1: colors[1], 3: colors[3]}
    s.add_laser(9, 9)
    assert s.picks[-1].id == 4  # numbers are never reused
    # Neighbouring ids get clearly different colours.
    c = np.array([pair_color(i) for i in range(1, 13)], float)
    d = np.linalg.norm(c[1:] - c[:-1], axis=1)
    assert d.min() > 60


def test_select_then_click_moves_that_end():
    s = make_state()
    s.add_laser(3, 4)
    s.add_pixel(10.0, 20.0)
    s.add_laser(5, 5)
    s.add_pixel(30.0, 40.0)
    s.select(1)
    assert s.click_pixel(11.0, 21.0) == 1
    assert s.click_laser(6, 7) == 1
    assert ends(s) == [(1, (6, 7), (11.0, 21.0)), (2, (5, 5), (30.0, 40.0))]
    s.select(None)
    assert s.click_laser(8, 8) == 3  # back to adding
    with pytest.raises(CalibError, match="no pair number 42"):
        s.select(42)
    s.delete(1)
    assert s.selected is None


def test_undo_redo_every_change_including_clear_and_import(tmp_path):
    s = make_state()
    history = [ends(s)]
    s.add_laser(3, 4)
    history.append(ends(s))
    s.add_pixel(10.0, 20.0)
    history.append(ends(s))
    s.move_pixel(1, 12.0, 22.0)
    history.append(ends(s))
    s.move_laser(1, 9, 9)
    history.append(ends(s))
    s.add_pixel(50.0, 60.0)
    history.append(ends(s))
    s.delete(1)
    history.append(ends(s))
    pairs_file = tmp_path / "pairs.yaml"
    save_pairs_yaml(pairs_file, [Pair((4, 4), None, (1.0, 2.0)), Pair(None, (1.0, 2.0, 3.0), (3.0, 4.0))])
    assert s.import_pairs_file(pairs_file) == [3, 4]
    history.append(ends(s))
    s.clear()
    history.append(ends(s))
    assert ends(s) == []

    for expected in reversed(history[:-1]):
        assert s.undo()
        assert ends(s) == expected
    assert not s.undo()
    for expected in history[1:]:
        assert s.redo()
        assert ends(s) == expected
    assert not s.redo()
    # A new change after undo drops the redo branch.
    s.undo()
    s.add_laser(2, 2)
    assert not s.can_redo


def test_import_rejects_pairs_outside_this_scene(tmp_path):
    s = make_state()
    f = tmp_path / "bad.yaml"
    save_pairs_yaml(f, [Pair((4, 4), None, (1.0, 2.0)), Pair((0, 3), None, (1.0, 2.0))])
    with pytest.raises(CalibError, match="imported pair 1: laser cell \\(0, 3\\) has no laser return"):
        s.import_pairs_file(f)
    assert s.picks == ()
    f.write_text("pairs: [oops]\n")
    with pytest.raises(CalibError):
        s.import_pairs_file(f)


def test_export_writes_complete_pairs_readable_by_core(tmp_path):
    s = make_state()
    s.add_laser(3, 4)
    s.add_pixel(10.5, 20.0)
    s.add_laser(6, 6)  # incomplete: not exported
    out = tmp_path / "out.yaml"
    assert s.export_pairs_file(out) == 1
    assert load_pairs_yaml(out) == [Pair((3, 4), None, (10.5, 20.0), id=s.picks[0].id)]


def test_every_change_is_on_disk_before_it_returns_and_restored(tmp_path):
    s = make_state(tmp_path)
    path = tmp_path / "session.yaml"
    journal = tmp_path / "session.yaml.journal"
    s.add_laser(3, 4)
    # No flush, no close: a new state on the same files (what a restart after kill -9 does) has it.
    assert ends(make_state(tmp_path)) == [(1, (3, 4), None)]
    s.add_pixel(10.25, 20.5)
    s.add_pixel(33.0, 44.0)
    s.delete(1)
    s.add_laser(7, 8)
    s.set_view(panorama=False, show_edges=True)
    crashed = make_state(tmp_path)
    assert ends(crashed) == [(2, (7, 8), (33.0, 44.0))]
    assert crashed.view == ViewSettings(panorama=False, show_edges=True)
    s.close()  # what the app's stop() does: the YAML itself holds everything, the journal is gone
    assert not journal.exists() and not list(tmp_path.glob("*.tmp"))
    data = yaml.safe_load(path.read_text())
    assert data["pairs"] == [{"id": 2, "laser_rc": [7, 8], "laser_xyz": None, "pixel": [33.0, 44.0], "shot": 0}]

    # "Restart": a new state on the session file.
    t = make_state(tmp_path)
    assert ends(t) == [(2, (7, 8), (33.0, 44.0))]
    assert t.view == ViewSettings(panorama=False, show_edges=True)
    assert t.add_laser(9, 9) == 3  # ids continue after the restored ones
    assert t.pending().id == 3
    t.close()


def test_a_torn_journal_line_is_ignored(tmp_path):
    s = make_state(tmp_path)
    s.add_laser(3, 4)
    s.add_pixel(1.0, 2.0)
    journal = tmp_path / "session.yaml.journal"
    whole = journal.read_bytes()
    # Killed in the middle of writing the third change's line: that change was never acknowledged.
    s.add_laser(5, 5)
    third = journal.read_bytes()[len(whole):]
    journal.write_bytes(whole + third[: len(third) // 2])
    assert ends(make_state(tmp_path)) == [(1, (3, 4), (1.0, 2.0))]
    # A damaged line (bit flip) fails its checksum and is skipped the same way.
    journal.write_bytes(whole + third.replace(b"[5,5]", b"[5,6]"))
    assert ends(make_state(tmp_path)) == [(1, (3, 4), (1.0, 2.0))]


def test_a_change_that_cannot_be_saved_is_refused_and_not_made(tmp_path):
    s = make_state(tmp_path)
    s.add_laser(3, 4)
    s.close()
    s = make_state(tmp_path)
    (tmp_path / "session.yaml.journal").mkdir()  # the journal cannot be written
    v0, picks0 = s.version, s.picks
    with pytest.raises(CalibError, match="cannot save the change.*not made"):
        s.add_pixel(1.0, 2.0)
    with pytest.raises(CalibError, match="not made"):
        s.set_view(panorama=False)
    assert s.version == v0 and s.picks == picks0 and s.view == ViewSettings() and not s.can_redo
    assert s.undo() is False  # the restored state has no history, and the refused change left none
def test_session_accepts_a_plain_pairs_file_and_rejects_other_scenes(tmp_path):
    path = tmp_path / "session.yaml"
    save_pairs_yaml(path, [Pair((4, 5), None, (1.0, 2.0))])
    s = make_state(tmp_path)
    assert ends(s) == [(1, (4, 5), (1.0, 2.0))]
    s.close()
    # A pairs file with ids (as the app exports it) keeps them: one id in the UI and the files.
    save_pairs_yaml(path, [Pair((4, 5), None, (1.0, 2.0), id=9), Pair((6, 7), None, (3.0, 4.0), id=3)])
    s = make_state(tmp_path)
    assert ends(s) == [(9, (4, 5), (1.0, 2.0)), (3, (6, 7), (3.0, 4.0))]
    assert s.add_laser(8, 8) == 10  # new ids never collide with them
    s.close()
    path.write_text(
        yaml.safe_dump(
            {"format": "ba-calib-session", "version": 1, "pairs": [{"id": 1, "laser_rc": [99, 0], "pixel": None}]}
        )
    )
    with pytest.raises(CalibError, match="outside the 20x40 scan"):
        make_state(tmp_path)
    save_pairs_yaml(path, [Pair((4, 5), None, (1.0, 900.0))])
    with pytest.raises(CalibError, match="outside the 320x240 camera image"):
        make_state(tmp_path)


def test_session_yaml_is_always_whole_and_ends_at_the_newest_state(tmp_path):
    from app import session_store

    path = tmp_path / "session.yaml"
    s = make_state(tmp_path)
    seen, stop = [], threading.Event()

    def reader() -> None:  # a crash can happen at any moment: the YAML must always be a whole session
        while not stop.is_set():
            if path.exists():
                seen.append(yaml.safe_load(path.read_text()))

    t = threading.Thread(target=reader)
    t.start()
    try:
        for k in range(2 * session_store.COMPACT_RECORDS // 2 + 10):  # past the compaction threshold
            s.add_laser(1 + k % 19, k % 40)
            s.add_pixel(float(k), 2.0)
            if k % 30 == 29:
                s.flush_session()  # let some compactions overlap the reader
    finally:
        stop.set()
        t.join()
    s.flush_session()
    final = yaml.safe_load(path.read_text())
    n = session_store.COMPACT_RECORDS + 10
    assert {k: final[k] for k in s.session_dict()} == s.session_dict() and len(final["pairs"]) == n
    assert len(seen) > 1 and all(d["format"] == "ba-calib-session" for d in seen)
    # Never an older state after a newer one.
    assert [d["journal_seq"] for d in seen] == sorted(d["journal_seq"] for d in seen)
    s.close()
    assert ends(make_state(tmp_path)) == ends(s)


def test_a_failed_yaml_update_is_reported_retried_and_loses_nothing(tmp_path):
    errors, failed = [], threading.Event()
    s = make_state(tmp_path, on_save_error=lambda msg: (errors.append(msg), failed.set()))
    path = tmp_path / "session.yaml"
    path.mkdir()  # the session YAML cannot be replaced: compactions fail, the journal still works
    s.add_laser(3, 4)  # accepted: it is in the journal
    assert failed.wait(10.0)
    assert str(path) in errors[0] and "cannot save the session" in errors[0] and "\n" not in errors[0]
    with pytest.raises(CalibError, match="cannot save the session"):
        s.flush_session()
    path.rmdir()  # the disk is fixed: the kept change is written, nothing was lost
    s.flush_session()
    assert yaml.safe_load(path.read_text())["pairs"] == [{"id": 1, "laser_rc": [3, 4], "laser_xyz": None,
                                                          "pixel": None, "shot": 0}]
    s.close()


def test_bad_session_fields_are_one_line_errors(tmp_path):
    path = tmp_path / "session.yaml"
    base = {"format": "ba-calib-session", "version": 1, "pairs": [{"id": 1, "laser_rc": [3, 4], "pixel": None}]}
    for change, message in (({"version": 999}, "version 999 is not supported"),
                            ({"next_id": "abc"}, "next_id must be an integer"),
                            ({"pairs": [{"id": 1, "laser_rc": [3.5, 4], "pixel": None}]}, "two integers"),
                            ({"pairs": [{"id": float("inf"), "laser_rc": [3, 4]}]}, "id must be an integer")):
        path.write_text(yaml.safe_dump({**base, **change}))
        with pytest.raises(CalibError, match=message):
            make_state(tmp_path)


def test_listeners_hear_every_change():
    s = make_state()
    seen = []
    s.subscribe(lambda st: seen.append(st.version))
    s.add_laser(3, 4)
    s.add_pixel(1.0, 1.0)
    s.select(1)
    s.undo()
    s.redo()
    s.clear()
    assert len(seen) == 6 and seen == sorted(seen)


def test_concurrent_changes_from_threads_lose_nothing(tmp_path):
    # Two tabs = several viser callback threads changing one state.
    s = make_state(tmp_path)
    n_threads, per_thread = 6, 8
    barrier = threading.Barrier(n_threads)

    def worker(k: int) -> None:
        barrier.wait()
        for i in range(per_thread):
            s.import_pairs([Pair((1 + k, i), None, (float(k), float(i)))])

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(n_threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    picks = s.picks
    assert len(picks) == n_threads * per_thread
    assert sorted(p.id for p in picks) == list(range(1, n_threads * per_thread + 1))
    assert {(p.laser_rc, p.pixel) for p in picks} == {
        ((1 + k, i), (float(k), float(i))) for k in range(n_threads) for i in range(per_thread)
    }
    s.flush_session()
    assert ends(make_state(tmp_path)) == ends(s)  # the last saved session has them all
    n_undo = 0
    while s.undo():
        n_undo += 1
    assert n_undo == n_threads * per_thread and s.picks == ()


# --------------------------------------------------------------------------- layout
def test_click_ray_maps_to_the_pixel_under_it():
    from app.layout import ImageSlot

    # 200 x 100 px image drawn 2 x 1 units wide, centred at (3, 4, 0).
    slot = ImageSlot("img", 200, 100, (3.0, 4.0, 0.0), 2.0, 1.0)
    # Pixel centres: u = 0 is 0.005 units right of the left edge x = 2.
    np.testing.assert_allclose(slot.world_from_pixel([[0.0, 0.0], [199.0, 99.0]]), [[2.005, 3.505, 0.0], [3.995, 4.495, 0.0]])
    # A ray from a viewer at z = -10 through the world point of pixel (10, 20).
    target = np.array([2.0 + 10.5 / 100.0, 3.5 + 20.5 / 100.0, 0.0])
    origin = np.array([0.3, -0.2, -10.0])
    uv = slot.pixel_from_ray(origin, (target - origin) / np.linalg.norm(target - origin))
    np.testing.assert_allclose(uv, (10.0, 20.0), atol=1e-9)
    assert slot.pixel_from_ray(origin, (origin - target)) is None  # pointing away
    assert slot.contains((-0.5, 99.5)) and not slot.contains((199.6, 0.0))


def test_layout_puts_four_ba_images_under_the_camera_image():
    from app.layout import CAMERA_WIDTH, annotation_layout

    keys = ("horizontal", "vertical", "diag_pos45", "diag_neg45")
    slots = annotation_layout({"raw": (640, 480), "panorama": (1000, 500)}, (720, 180), keys)
    for key in keys:
        s = slots[key]
        assert s.render_width / s.render_height == pytest.approx(720 / 180)  # square cells
        for cam in ("raw", "panorama"):
            assert slots[cam].bounds()[3] < s.bounds()[1]  # camera image above every BA image
    assert slots["raw"].render_width == CAMERA_WIDTH
    assert slots["raw"].bounds()[3] == pytest.approx(slots["panorama"].bounds()[3])  # bottoms aligned
    # No two BA images overlap.
    b = [slots[k].bounds() for k in keys]
    for i in range(4):
        for j in range(i + 1, 4):
            assert b[i][2] <= b[j][0] or b[j][2] <= b[i][0] or b[i][3] <= b[j][1] or b[j][3] <= b[i][1]


# ---------------------------------------------------------------------- live solver
def test_live_solver_coalesces_bursts_and_survives_failures():
    from app.live_solver import LiveSolver

    started, release = threading.Event(), threading.Event()
    solved, done = [], []

    def solve(payload):
        if payload == "first":
            started.set()
            release.wait(5)
        if payload == "bad":
            raise CalibError("degenerate pairs")
        solved.append(payload)
        return payload.upper()

    solver = LiveSolver(solve, lambda version, result, error: done.append((version, result, error)))
    try:
        solver.submit(1, "first")
        assert started.wait(5)
        for v in range(2, 10):  # a burst while the first solve runs
            solver.submit(v, f"job{v}")
        release.set()
        assert solver.wait_idle(5)
        assert solved == ["first", "job9"]  # only the newest of the burst was solved
        assert [d[0] for d in done] == [1, 9]
        solver.submit(10, "bad")
        assert solver.wait_idle(5)
        version, result, error = done[-1]
        assert version == 10 and result is None and isinstance(error, CalibError)
        solver.submit(11, "ok")  # the worker is still alive after a failure
        assert solver.wait_idle(5) and done[-1] == (11, "OK", None)
    finally:
        solver.stop()


# ------------------------------------------------------------------ BA display
def sphere_directions(elevation_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """Unit directions (H, W, 3) of a spinning lidar: rows = elevation, columns = azimuth."""
    e, a = np.meshgrid(np.radians(elevation_deg), np.radians(azimuth_deg), indexing="ij")
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)


def test_cell_aspect_makes_cells_square_in_angle():
    from app.ba_view import cell_aspect_from_directions

    # 64 beams 0.625 deg apart (+15 ... -24.4 deg), 1800 columns 0.2 deg apart: cells 3.125x taller.
    d = sphere_directions(15.0 - 0.625 * np.arange(64), 0.2 * np.arange(1800))
    assert cell_aspect_from_directions(d) == pytest.approx(0.625 / 0.2, rel=1e-6)
    # Uneven beams 1, 3, 1 deg apart: one average stretch (5 deg / 3 rows) over the 0.5 deg columns
    # (measured at the horizon row; at 4 deg elevation 0.5 deg of azimuth is only 0.4988 deg).
    d = sphere_directions(np.array([4.0, 3.0, 0.0, -1.0]), 0.5 * np.arange(720))
    assert cell_aspect_from_directions(d) == pytest.approx((5.0 / 3.0) / 0.5, rel=1e-6)
    # Unknown directions (NaN rows, or all NaN) do not break it.
    d[1] = np.nan
    assert np.isfinite(cell_aspect_from_directions(d))
    assert cell_aspect_from_directions(np.full((4, 5, 3), np.nan)) == 1.0


def test_column_window_wraps_and_clips():
    from app.ba_view import ColumnWindow

    w = ColumnWindow.make(1790, 20, 1800, wrap=True)
    assert list(w.columns[:11]) == list(range(1790, 1800)) + [0] and w.columns[-1] == 9
    u, shown = w.display_cols(np.array([1790, 5, 9, 10, 1000]))
    np.testing.assert_array_equal(u[shown], [0, 15, 19])
    np.testing.assert_array_equal(shown, [True, True, True, False, False])
    assert ColumnWindow.make(-5, 20, 1800, wrap=True).start == 1795
    assert ColumnWindow.make(1790, 20, 1800, wrap=False).start == 1780  # stays inside the scan
    assert ColumnWindow.make(7, 5000, 1800, wrap=False) == ColumnWindow(0, 1800, 1800, False)
    assert ColumnWindow.make(7, 0, 1800, wrap=True).width == 1


def test_covering_window_is_the_narrowest_arc_through_the_seen_columns():
    from app.ba_view import covering_window

    seen = np.zeros(1800, bool)
    seen[780:1027] = True  # what the published calibration of auto_calib projects
    w = covering_window(seen, wrap=True)
    assert (w.start, w.width) == (780, 247)
    # Margin 8, ends moved out to multiples of 8: 772 -> 768, 1034 + 1 -> 1040.
    w = covering_window(seen, wrap=True, margin=8, quantum=8)
    assert (w.start, w.width) == (768, 272)
    # A view across column 0 (the lidar's back) is one arc through 0, not the whole scan.
    seen[:] = False
    seen[1795:] = True
    seen[:11] = True
    w = covering_window(seen, wrap=True, margin=2)
    assert (w.start, w.width) == (1793, 20)
    assert covering_window(seen, wrap=False).width == 1800  # without wrap it must span 0 ... 1799
    seen[:] = False
    assert covering_window(seen, wrap=True) is None
    seen[42] = True
    assert (covering_window(seen, wrap=True).start, covering_window(seen, wrap=True).width) == (42, 1)


def test_ba_texture_is_a_nearest_neighbour_enlargement_of_the_window():
    from app.ba_view import ColumnWindow, ba_texture, texture_factor

    gray = np.arange(2 * 6, dtype=np.uint8).reshape(2, 6) * 10
    w = ColumnWindow.make(4, 3, 6, wrap=True)  # scan columns 4, 5, 0
    tex = ba_texture(gray, w, 3)
    assert tex.shape == (6, 9) and tex.dtype == np.uint8
    np.testing.assert_array_equal(tex[0:3, 0:3], 40)  # cell (row 0, col 4)
    np.testing.assert_array_equal(tex[3:6, 6:9], 60)  # cell (row 1, col 0)
    np.testing.assert_array_equal(tex[::3, ::3], [[40, 50, 0], [100, 110, 60]])
    # Factors: 64 x 1800 is limited by the 8192 px side, a 64 x 272 window by the texel budget.
    assert texture_factor(1800, 64) == 4  # 7200 px wide
    assert texture_factor(272, 64) == 10  # 2720 x 640 = 1.7 Mpx
    assert texture_factor(10000, 64) == 1


def test_clicks_on_a_stretched_windowed_ba_image_map_to_the_exact_cell():
    from app.ba_view import ColumnWindow
    from app.layout import annotation_layout

    keys = ("horizontal", "vertical", "diag_pos45", "diag_neg45")
    window = ColumnWindow.make(1790, 40, 1800, wrap=True)
    slots = annotation_layout({"raw": (1920, 1200)}, (window.width, 64), keys, cell_aspect=3.24)
    slot = slots["diag_neg45"]
    # Drawn cells are 3.24 times taller than wide.
    assert slot.units_per_px_y / slot.units_per_px == pytest.approx(3.24)
    rng = np.random.default_rng(0)
    viewer = np.array([0.4, -1.0, -9.0])
    for _ in range(200):
        row, u = int(rng.integers(0, 64)), int(rng.integers(0, window.width))
        # Aim anywhere inside the cell, up to 0.49 cell from its centre.
        du, dv = rng.uniform(-0.49, 0.49, size=2)
        x0, y0, _, _ = slot.bounds()
        target = np.array([x0 + (u + 0.5 + du) * slot.units_per_px, y0 + (row + 0.5 + dv) * slot.units_per_px_y, 0.0])
        uv = slot.pixel_from_ray(viewer, target - viewer)
        assert window.cell_at(uv, 64) == (row, (1790 + u) % 1800)
    # The image border belongs to the edge cells.
    assert window.cell_at((-0.5, -0.5), 64) == (0, 1790)
    assert window.cell_at((39.5, 63.5), 64) == (63, 29)


def test_ba_grid_follows_the_shape_of_the_shown_images():
    from app.layout import annotation_layout

    keys = ("horizontal", "vertical", "diag_pos45", "diag_neg45")

    def columns(ba_size, aspect):
        slots = annotation_layout({"raw": (1920, 1200)}, ba_size, keys, cell_aspect=aspect)
        return len({round(slots[k].center[0], 6) for k in keys})

    assert columns((1800, 64), 3.24) == 1  # a whole 360 deg scan: stacked, full width
    assert columns((272, 64), 3.24) == 2  # the part facing the camera: 2 x 2
    assert columns((60, 64), 3.24) == 4  # a narrow window: side by side
    assert columns((720, 180), 2.0) == 2  # the sample


def test_pick_markers_are_rings_that_leave_the_picked_cell_visible():
    from app.ui_common import RING_SEGMENTS, marker_segments

    centre = np.array([[1.0, 2.0, -0.01]])
    segs = marker_segments(centre, 0.1, cell_half_size=(0.01, 0.03))
    assert segs.shape == (RING_SEGMENTS + 4 + 4, 2, 3)
    dist = np.linalg.norm(segs[..., :2] - centre[0, :2], axis=-1)
    np.testing.assert_allclose(dist[:RING_SEGMENTS], 0.1)  # ring
    assert dist[RING_SEGMENTS:RING_SEGMENTS + 4].min() == pytest.approx(0.04)  # ticks stop short of the centre
    outline = segs[RING_SEGMENTS + 4:, :, :2] - centre[0, :2]
    np.testing.assert_allclose(np.abs(outline), np.broadcast_to([0.01, 0.03], outline.shape))  # the cell's border
    assert np.all(segs[..., 2] == -0.01)
    assert marker_segments(np.empty((0, 3)), 0.1).shape == (0, 2, 3)


# ------------------------------------------------ the app on the sample (no browser)
def test_app_column_window_clicks_markers_and_zoom_on_the_sample(tmp_path):
    from app.ba_view import ColumnWindow
    from app.server import CalibrationApp
    from app_driver import AppDriver
    from app.ui_common import PANEL_PX, ZOOM_PX_PER_CELL

    session = tmp_path / "session.yaml"
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml", session_path=session,
                         port=0)
    d = AppDriver(app)
    try:
        assert app.depth.shape == (180, 720) and app.ba_window.is_full
        # 180 rows over 180 deg, 720 columns over 360 deg: cells drawn twice as tall as wide.
        assert app.ba_cell_aspect == pytest.approx(2.0, rel=1e-3)
        s = app.slots["horizontal"]
        assert s.units_per_px_y / s.units_per_px == pytest.approx(2.0, rel=1e-3)

        # Before any pose the BA panes face the camera as the '+x' preset puts it (the default); this
        # catadioptric camera sees all round, so every column is shown.
        assert d.ba_columns_choice == "Facing the camera" and app.ba_window.is_full
        # The user sets a custom window across column 0 with the sliders.
        d.set_ba_columns(700, 60)
        assert app.ba_window == ColumnWindow(700, 60, 720, True)
        tex = d.ba_texture("horizontal")
        assert tex.shape[1] == 60 * (tex.shape[0] // 180)

        # A click at display (25.3, 10.4) is scan cell (row 10, column 700 + 25 - 720 = 5).
        assert d.click("horizontal", (25.3, 10.4)) == []
        pid = app.state.picks[-1].id
        assert app.state.get(pid).laser_rc == (10, 5)
        app.state.add_pixel(100.0, 100.0)
        other = app.state.add_laser(20, 300)  # outside the window
        assert d.marker_ids("vertical") == [pid] and other not in d.marker_ids("vertical")
        assert d.marker_display_pixel("vertical", pid) == (25.0, 10.0)

        # Zoom on that click: the cell comes to the middle of the canvas left of the panel, one step (x2)
        # larger per press, so the surroundings stay in view, until a cell is 14 px wide.
        d.click("diag_neg45", (25.0, 10.0))  # the same cell, re-clicked on another trace
        cam = d.tab.camera
        centre = app.slots["diag_neg45"].world_from_pixel([[25.0, 10.0]])[0]
        right = app.slots["diag_neg45"].world_from_pixel([[26.0, 10.0]])[0]
        for _ in range(2):  # start from an overview, several steps below the cap
            assert d.press_zoom("Out") == []
        cell_px = cam.screen_of(right)[0] - cam.screen_of(centre)[0]
        assert cell_px < ZOOM_PX_PER_CELL / 4
        widths = []
        for _ in range(8):
            assert d.press_zoom("On last click") == []
            x, y = cam.screen_of(centre)
            assert (x, y) == pytest.approx(((cam.image_width - PANEL_PX) / 2, cam.image_height / 2))
            widths.append(cam.screen_of(right)[0] - x)
        assert widths[0] == pytest.approx(2 * cell_px)  # one step, not a jump to the cap
        assert widths[1] == pytest.approx(4 * cell_px)
        assert widths[-1] == pytest.approx(ZOOM_PX_PER_CELL) and widths[-2] == pytest.approx(ZOOM_PX_PER_CELL)
        assert all(b >= a - 1e-9 for a, b in zip(widths, widths[1:]))
        assert d.press_zoom("Out") == []  # half the magnification, same point in the middle
        assert cam.screen_of(right)[0] - cam.screen_of(centre)[0] == pytest.approx(ZOOM_PX_PER_CELL / 2)
        assert cam.screen_of(centre)[0] == pytest.approx(x)
    finally:
        app.stop()

    # The window is part of the session.
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml", session_path=session,
                         port=0)
    try:
        assert app.ba_window == ColumnWindow(700, 60, 720, True)
        assert AppDriver(app).ba_columns_choice == "Custom"
    finally:
        app.stop()


def test_a_click_updates_only_what_it_changed_in_place(tmp_path):
    import socket

    from app.server import CalibrationApp

    import time

    session = tmp_path / "session.yaml"
    session.write_text(yaml.safe_dump({"format": "ba-calib-session", "version": 1, "pairs": [],
                                       "view": {"panorama": False}}))
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml", session_path=session,
                         port=port)
    try:
        assert app.live.last_click_to_update() is None and app.last_update_time is None  # nothing solved yet
        ids = app.state.import_pairs(load_pairs_yaml(SAMPLE / "pairs.yaml")[:5])
        assert app.wait_idle(60) and app.result is not None
        node = lambda name: app.nodes.drawn[name][0]  # noqa: E731
        ba_ring, cam_ring = node("/annot/markers/horizontal/ring"), node("/annot/markers/raw/ring")
        segments = app.nodes.segments
        ba_points, cam_points = segments("/annot/markers/horizontal/ring"), segments("/annot/markers/raw/ring")
        label = node(f"/annot/labels/raw/{ids[1]}")
        label_pos = np.array(label.position)
        residuals = node("/annot/overlay/residuals")
        old_residuals = residuals.points.copy()

        u, v = app.state.get(ids[1]).pixel
        t0 = time.perf_counter()
        app.state.move_pixel(ids[1], u + 3.0, v)
        assert app.wait_idle(60)
        # The timing hook: this click's solve was shown after the click, and the duration counts from the change.
        assert t0 < app.last_update_time <= time.perf_counter()
        assert 0.0 < app.live.last_click_to_update() <= app.last_update_time - t0
        # The same scene nodes, updated in place, not re-created.
        assert node("/annot/markers/horizontal/ring") is ba_ring and node("/annot/markers/raw/ring") is cam_ring
        assert node(f"/annot/labels/raw/{ids[1]}") is label and node("/annot/overlay/residuals") is residuals
        np.testing.assert_array_equal(segments("/annot/markers/horizontal/ring"), ba_points)  # BA ends did not move
        # The camera image is 8 units over 640 px: 3 px = 0.0375 units along x, for pair 2's ring only.
        per_pick = len(cam_points) // 5
        moved = segments("/annot/markers/raw/ring") - cam_points
        np.testing.assert_allclose(moved[per_pick:2 * per_pick, :, 0], 0.0375, atol=1e-5)
        np.testing.assert_allclose(moved[per_pick:2 * per_pick, :, 1:], 0.0, atol=1e-6)
        assert np.all(moved[:per_pick] == 0) and np.all(moved[2 * per_pick:] == 0)
        np.testing.assert_allclose(np.array(label.position) - label_pos, [0.0375, 0.0, 0.0], atol=1e-6)
        assert not np.array_equal(residuals.points, old_residuals)  # a new solve, new residual lines

        # A new pick adds one ring.
        app.state.add_pixel(100.0, 100.0)
        assert app.wait_idle(60)
        assert len(segments("/annot/markers/raw/ring")) == 6 * per_pick
        assert f"/annot/labels/raw/{ids[-1] + 1}" in app.nodes.drawn
        app.state.undo()
        assert app.wait_idle(60)
        assert len(segments("/annot/markers/raw/ring")) == 5 * per_pick
        assert f"/annot/labels/raw/{ids[-1] + 1}" not in app.nodes.drawn
    finally:
        app.stop()


def test_cloud_is_recoloured_only_while_a_tab_shows_3d(tmp_path):
    from app.server import CalibrationApp
    from app_driver import AppDriver
    from calib_core.io.extrinsics import load_extrinsics_yaml
    from calib_core.transforms import transform_points

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=0)
    d = AppDriver(app)
    try:
        ids = app.state.import_pairs(load_pairs_yaml(SAMPLE / "pairs.yaml"))
        assert app.wait_idle(60) and app.result is not None
        # No tab shows the 3-D view: the error display is up, the cloud is not recoloured.
        assert np.all(d.cloud_colors == 150)

        d.show("3D cloud")  # a tab switches to 3-D: the current solve's colours follow
        assert app.wait_idle(60)
        colors = d.cloud_colors
        # Truth: the image colour where the ground-truth pose projects each point (points the camera sees).
        truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
        uv, ok = app.camera.project(transform_points(truth, app.cloud_points_lidar))
        coloured = np.any(colors != 110, axis=1)
        assert coloured.sum() > 1000 and not np.any(coloured & ~ok)
        px = np.round(uv[coloured]).astype(int)
        expected = app.image[px[:, 1], px[:, 0]].astype(float)
        # Most points get the colour under them (the solved pose is close to the truth; edges and occlusion aside).
        assert np.median(np.abs(colors[coloured] - expected).max(axis=1)) < 10

        u, v = app.state.get(ids[0]).pixel
        app.state.move_pixel(ids[0], u + 2.0, v)  # still in 3-D: each new solve recolours
        assert app.wait_idle(60)
        assert d.cloud_shows_current_solve
        d.show("2D annotation")
        app.state.move_pixel(ids[0], u, v)  # back in 2-D: the cloud keeps the old colours
        assert app.wait_idle(60)
        assert not d.cloud_shows_current_solve
        app.state.clear()  # fewer than 4 pairs: grey again
        assert app.wait_idle(60)
        assert np.all(d.cloud_colors == 150)
    finally:
        app.stop()
