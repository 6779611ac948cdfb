"""The browser app's annotation state: picking, editing, history, session file."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import yaml

from app.state import AnnotationState, pair_color
from calib_core.errors import CalibError
from calib_core.pairs import Pair, load_pairs_yaml, save_pairs_yaml

H, W = 20, 40  # depth matrix
IMG = (320, 240)  # camera image width, height


def make_valid() -> np.ndarray:
    valid = np.ones((H, W), bool)
    valid[0, :] = False  # a row without returns
    return valid


def make_state(tmp_path=None, name="session.yaml") -> AnnotationState:
    path = None if tmp_path is None else tmp_path / name
    return AnnotationState(make_valid(), IMG, session_path=path)


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
    assert s.pairs() == [Pair((3, 4), None, (10.5, 20.25)), Pair((5, 6), None, (100.0, 50.0))]


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
    assert load_pairs_yaml(out) == [Pair((3, 4), None, (10.5, 20.0))]


def test_session_is_saved_after_every_change_and_restored(tmp_path):
    s = make_state(tmp_path)
    path = tmp_path / "session.yaml"
    s.add_laser(3, 4)
    # Written already, with the incomplete pick: no click is lost.
    data = yaml.safe_load(path.read_text())
    assert data["pairs"] == [{"id": 1, "laser_rc": [3, 4], "laser_xyz": None, "pixel": None}]
    s.add_pixel(10.25, 20.5)
    s.add_pixel(33.0, 44.0)
    s.delete(1)
    s.add_laser(7, 8)
    s.set_view(panorama=False, show_edges=True)
    assert not list(tmp_path.glob("*.tmp"))  # atomic write left no temporary file

    # "Restart": a new state on the same session file.
    t = make_state(tmp_path)
    assert ends(t) == [(2, (7, 8), (33.0, 44.0))]
    assert t.view_settings() == {"panorama": False, "show_edges": True}
    assert t.add_laser(9, 9) == 3  # ids continue after the restored ones
    assert t.pending().id == 3


def test_session_accepts_a_plain_pairs_file_and_rejects_other_scenes(tmp_path):
    path = tmp_path / "session.yaml"
    save_pairs_yaml(path, [Pair((4, 5), None, (1.0, 2.0))])
    s = make_state(tmp_path)
    assert ends(s) == [(1, (4, 5), (1.0, 2.0))]
    path.write_text(
        yaml.safe_dump(
            {"format": "ba-calib-session", "version": 1, "pairs": [{"id": 1, "laser_rc": [99, 0], "pixel": None}]}
        )
    )
    with pytest.raises(CalibError, match="outside the 20x40 scan"):
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
    assert ends(make_state(tmp_path)) == ends(s)  # the last saved session has them all
    n_undo = 0
    while s.undo():
        n_undo += 1
    assert n_undo == n_threads * per_thread and s.picks == ()
