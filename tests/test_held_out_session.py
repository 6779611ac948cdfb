"""Issue 23, the session journal: a journal never outlives the session file it belongs to.

Each test replays what a user does (start, click, kill or quit, delete the
session file, start again) on real files and checks what the next start
restores against what the user did.
"""

from __future__ import annotations

import os

import numpy as np
import yaml

from app import session_store
from app.state import AnnotationState

H, W = 20, 40  # depth matrix
IMG = (320, 240)  # camera image width, height


def make_state(tmp_path, name: str = "session.yaml") -> AnnotationState:
    return AnnotationState(np.ones((H, W), bool), IMG, session_path=tmp_path / name)


def ends(state: AnnotationState) -> list:
    return [(p.id, p.laser_rc, p.pixel) for p in state.picks]


def click_pairs(state: AnnotationState, n: int) -> list:
    for k in range(n):
        state.add_laser(1 + k, 2 + k)
        state.add_pixel(10.0 + k, 20.0 + k)
    return ends(state)


def test_a_restored_journal_is_removed_on_a_clean_exit_and_a_deleted_session_starts_empty(tmp_path):
    path, journal = tmp_path / "session.yaml", tmp_path / "session.yaml.journal"
    first = make_state(tmp_path)
    clicked = click_pairs(first, 3)
    # Killed (kill -9) before the journal was folded: the journal holds changes the YAML does not.
    assert journal.exists() and (not path.exists() or len(yaml.safe_load(path.read_text())["pairs"]) < 3)
    restarted = make_state(tmp_path)
    assert ends(restarted) == clicked  # nothing lost
    restarted.close()  # a clean exit with no new change
    assert not journal.exists()
    assert [(p["id"], tuple(p["laser_rc"]), tuple(p["pixel"])) for p in yaml.safe_load(path.read_text())["pairs"]] \
        == clicked
    path.unlink()  # the user starts over
    assert ends(make_state(tmp_path)) == []


def test_a_journal_whose_session_file_was_deleted_is_ignored_with_one_warning(tmp_path, capfd):
    path, journal = tmp_path / "session.yaml", tmp_path / "session.yaml.journal"
    first = make_state(tmp_path)
    click_pairs(first, 2)
    first.flush_session()  # the session file is written...
    first.add_laser(7, 7)  # ...then one more change, and the server is killed: the journal stays
    assert journal.exists() and path.exists()
    path.unlink()  # the user starts over
    capfd.readouterr()
    fresh = make_state(tmp_path)
    assert ends(fresh) == []
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and str(journal) in err[0] and "no longer exists" in err[0]
    fresh.add_laser(5, 6)  # the new session's first change writes its file and drops the old journal
    assert not journal.exists() and len(yaml.safe_load(path.read_text())["pairs"]) == 1
    fresh.close()
    assert ends(make_state(tmp_path)) == [(1, (5, 6), None)]


def test_a_foreign_journal_is_ignored_and_removed_on_exit(tmp_path, capfd):
    """Another session's journal beside this session file (copied folders, a reused name)."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    other = make_state(a)
    click_pairs(other, 4)  # killed: a.journal holds changes of session A
    mine = make_state(b)
    mine_pairs = click_pairs(mine, 1)
    mine.close()
    os.replace(a / "session.yaml.journal", b / "session.yaml.journal")  # A's journal lands beside B's file
    capfd.readouterr()
    again = make_state(b)
    assert ends(again) == mine_pairs
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ignored the session journal" in err[0]
    ids = {r.session_id for r in session_store.decode_records((b / "session.yaml.journal").read_bytes())}
    assert ids and yaml.safe_load((b / "session.yaml").read_text())[session_store.ID_KEY] not in ids
    again.close()
    assert not (b / "session.yaml.journal").exists()


def test_changes_of_a_session_whose_file_was_never_written_are_restored(tmp_path):
    """The session YAML could not be written (here: a folder in its place), then the server was killed:
    the journal holds the only copy, marked as never filed, and is restored."""
    path = tmp_path / "session.yaml"
    s = make_state(tmp_path)
    path.mkdir()
    s.add_laser(3, 4)  # the YAML cannot be written: the change goes to the journal
    s.add_pixel(7.0, 8.0)
    store = s._store  # noqa: SLF001 - "kill" it: stop its compactor (which keeps retrying) without closing
    with store._lock:
        store._closed = True
        store._cond.notify_all()
    store._thread.join(10)
    path.rmdir()
    records = session_store.decode_records((tmp_path / "session.yaml.journal").read_bytes())
    assert records and not any(r.filed for r in records)
    assert ends(make_state(tmp_path)) == [(1, (3, 4), (7.0, 8.0))]


def test_every_record_and_the_yaml_carry_the_same_session_id(tmp_path):
    s = make_state(tmp_path)
    click_pairs(s, 2)
    data = yaml.safe_load((tmp_path / "session.yaml").read_text())
    records = session_store.decode_records((tmp_path / "session.yaml.journal").read_bytes())
    assert records and {r.session_id for r in records} == {data[session_store.ID_KEY]}
    assert all(r.seq > data["journal_seq"] for r in records)
    s.close()
    store = session_store.SessionStore(tmp_path / "session.yaml")
    restored, from_yaml = store.load()
    assert from_yaml and store.session_id == data[session_store.ID_KEY] and len(restored["pairs"]) == 2
