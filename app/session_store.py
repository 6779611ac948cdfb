"""Durable session storage: an fsync'd append-only journal, compacted into the session YAML.

A change of the annotation state is acknowledged in the UI only after
:meth:`SessionStore.append` returned, and that only returns once the change
is on disk: one JSON line appended to ``<session>.journal`` and
``fdatasync``'d (about 1 ms, against about 20 ms for dumping and replacing
the whole YAML).  A background thread compacts the journal into the session
YAML (:func:`calib_core.io.atomic.write_bytes_atomic`) when the user pauses
or the journal grows, and then empties the journal.

Every record is the whole session plus a sequence number, so recovery takes
the newest complete record: the session YAML carries the sequence number it
was compacted at (``journal_seq``), and journal records with a higher number
win.  A torn last line (the process was killed while writing it) fails its
CRC and is ignored; that change was never acknowledged.

A journal belongs to one session file and never outlives it.  The YAML
carries a random ``session_id``, and every journal record carries the same
id and whether a YAML with that id had been written (``filed``).  The first
change of a session writes the YAML itself (with the id), before any journal
line, so a journal normally never exists without its file.  On start, records
of another session id, or records of a filed session whose YAML is gone (the
user deleted it to start over), are ignored with one warning line; a clean
exit folds the journal into the YAML and removes it.
"""

from __future__ import annotations

import atexit
import json
import os
import stat
import sys
import threading
import time
import uuid
import weakref
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import yaml

from calib_core.errors import CalibError, one_line
from calib_core.io.atomic import fsync_folder, write_bytes_atomic
from calib_core.io.yaml_files import read_yaml_mapping

JOURNAL_SUFFIX = ".journal"
#: Compact after this many journal records, or this many bytes, or this long after the last change.
COMPACT_RECORDS = 200
COMPACT_BYTES = 4 << 20
COMPACT_IDLE_S = 0.5
#: Past this size the journal is compacted inside the append (a burst that never pauses).
HARD_CAP_BYTES = 64 << 20
#: A failed compaction is retried this often (seconds); the journal keeps the data meanwhile.
RETRY_S = 1.0
SEQ_KEY = "journal_seq"
#: The session file's id, which its journal records repeat.
ID_KEY = "session_id"

_fdatasync = getattr(os, "fdatasync", os.fsync)


@dataclass(frozen=True)
class JournalRecord:
    """One intact journal line."""

    seq: int  # sequence number of the change
    session: dict  # the whole session after the change
    session_id: str | None = None  # the session file's id (None: a journal of an older ba-calib)
    filed: bool = True  # a session YAML with this id had been written when the line was


def encode_record(seq: int, data: dict, session_id: str | None = None, filed: bool = True) -> bytes:
    """One journal line: ``<crc32 hex> <json>\\n`` of ``{"seq", "id", "filed", "session"}``."""
    record = {"seq": int(seq), "id": session_id, "filed": bool(filed), "session": data}
    body = json.dumps(record, separators=(",", ":"), allow_nan=False).encode()
    return b"%08x %s\n" % (zlib.crc32(body), body)


def decode_records(raw: bytes) -> list[JournalRecord]:
    """The intact records of a journal; torn or damaged lines are skipped."""
    out = []
    for line in raw.split(b"\n")[:-1]:  # the part after the last newline is torn
        crc, _, body = line.partition(b" ")
        try:
            if int(crc, 16) != zlib.crc32(body):
                continue
            rec = json.loads(body)
            seq, data = int(rec["seq"]), rec["session"]
            session_id, filed = rec.get("id"), bool(rec.get("filed", True))
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
            continue
        if isinstance(data, dict) and (session_id is None or isinstance(session_id, str)):
            out.append(JournalRecord(seq, data, session_id, filed))
    return out


def _yaml_session_id(data: dict) -> str | None:
    """The ``session_id`` a session YAML carries, or None (a pairs file, an older session, a malformed id)."""
    value = data.get(ID_KEY)
    if isinstance(value, str) and 8 <= len(value) <= 64 and value.isalnum():
        return value
    return None


class SessionStore:
    """A session file that every acknowledged change reaches before it is shown.

    Parameters
    ----------
    path : path-like
        The session YAML; the journal is ``<path>.journal`` beside it.
    on_error : callable, optional
        ``on_error(message)`` (one line) after a failed background compaction;
        it is retried, and the journal keeps every change meanwhile.
    """

    def __init__(self, path: str | os.PathLike, on_error: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        self.journal_path = self.path.with_name(self.path.name + JOURNAL_SUFFIX)
        self._on_error = on_error
        self._lock = threading.Lock()  # appends, and the journal truncation
        self._compact_lock = threading.Lock()  # one compaction at a time, in order
        self._cond = threading.Condition(self._lock)
        self._fd: int | None = None
        self._seq = 0
        self._latest: dict | None = None
        self._compacted = 0  # sequence number the YAML holds
        self._records = 0  # journal records and bytes since the last compaction (its triggers)
        self._new_bytes = 0
        self._bytes = 0  # journal size
        self._last_append = 0.0
        self._closed = False
        self._thread: threading.Thread | None = None
        #: The id the session YAML and every journal record carry (adopted from the YAML on :meth:`load`).
        self.session_id = uuid.uuid4().hex
        self._filed = False  # a YAML with this id has been written (read on load, or written here)
        self._claim_tried = False  # the first change tried to write the YAML (later ones leave it to compaction)
        #: Session YAML writes so far (compactions).
        self.compactions = 0
        #: The one-line warning :meth:`load` printed about an ignored journal, or None.
        self.warning: str | None = None

    # ------------------------------------------------------------------ reading
    def load(self) -> tuple[dict | None, bool]:
        """The newest saved session and whether it is the YAML as the user gave it.

        Returns ``(data, from_yaml)``: ``data`` is None without any file;
        ``from_yaml`` is True when no journal record is newer than the YAML
        (which may then be a plain pairs file given as the session).

        Journal records of another session file are ignored, with one
        warning line on stderr (also kept in :attr:`warning`): records of
        another ``session_id``, and records of a session whose YAML had been
        written but is gone (deleted to start over).  Records of a session
        whose YAML was never written (killed before the first save
        succeeded) are restored.
        """
        data: dict | None = None
        yaml_id: str | None = None
        has_yaml = self.path.exists()
        if has_yaml:
            data = read_yaml_mapping(self.path, "session file")
            try:
                self._compacted = self._seq = max(0, int(data.get(SEQ_KEY) or 0))
            except (TypeError, ValueError):
                raise CalibError(f"{self.path}: {SEQ_KEY} must be an integer") from None
            yaml_id = _yaml_session_id(data)
            if yaml_id is not None:
                self.session_id, self._filed = yaml_id, True
        records = decode_records(self._read_journal())
        if yaml_id is not None:
            ours = [r for r in records if r.session_id == yaml_id]
        elif has_yaml:  # a pairs file or an older session file: older journals, or a session never saved
            ours = [r for r in records if r.session_id is None or not r.filed]
        else:  # no file: only a session whose file was never written
            ours = [r for r in records if r.session_id is not None and not r.filed]
        ignored = len(records) - len(ours)
        if ignored:
            owner = f"{self.path.name} (session {yaml_id})" if yaml_id is not None else (
                f"{self.path.name}, which is not the session it was written for" if has_yaml
                else f"{self.path.name}, which no longer exists")
            self.warning = (f"ignored the session journal {self.journal_path} ({ignored} change(s)): it does not "
                            f"belong to {owner}; it is removed at the next save")
            print(f"ba-calib: warning: {self.warning}", file=sys.stderr, flush=True)
        newer = [r for r in ours if r.seq > self._seq]
        if not newer:
            return data, True
        latest = max(newer, key=lambda r: r.seq)
        self._seq, self._latest = latest.seq, latest.session
        if yaml_id is None and latest.session_id is not None:
            self.session_id = latest.session_id  # the unsaved session goes on under its own id
        return latest.session, False

    def _read_journal(self) -> bytes:
        try:
            fd = os.open(self.journal_path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            return b""
        except OSError as exc:
            raise CalibError(f"{self.journal_path}: cannot read the session journal: {one_line(exc)}") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise CalibError(f"{self.journal_path}: the session journal is not a regular file")
            if st.st_size > 4 * HARD_CAP_BYTES:
                raise CalibError(f"{self.journal_path}: the session journal is {st.st_size} bytes, too large")
            with os.fdopen(os.dup(fd), "rb") as f:
                return f.read()
        finally:
            os.close(fd)

    # ------------------------------------------------------------------ writing
    def append(self, data: dict) -> None:
        """Put ``data`` (the whole session, plain JSON-able) on disk before returning.

        The first change of a session whose YAML does not carry this
        store's id writes the YAML (with the id) instead of a journal line,
        and removes any journal left beside it; if the YAML cannot be
        written, the change goes to the journal (marked unfiled).

        Raises
        ------
        CalibError
            The journal cannot be written; the change must not be made.
        """
        if not self._filed and not self._claim_tried and self._claim(data):
            return
        with self._lock:
            if self._closed:
                raise CalibError(f"{self.path}: the session is closed")
            seq = self._seq + 1
            try:
                line = encode_record(seq, data, self.session_id, self._filed)
                fd = self._open_locked()
                view = memoryview(line)
                while view:
                    view = view[os.write(fd, view):]
                _fdatasync(fd)
            except (OSError, ValueError, TypeError) as exc:
                raise CalibError(f"{self.journal_path}: cannot save the change: {one_line(exc)}") from None
            self._seq, self._latest = seq, data
            self._records += 1
            self._new_bytes += len(line)
            self._bytes += len(line)
            self._last_append = time.monotonic()
            self._cond.notify_all()
            over_cap = self._bytes > HARD_CAP_BYTES
        self._ensure_thread()
        if over_cap:
            self.compact()

    def _claim(self, data: dict) -> bool:
        """Write ``data`` as the session YAML with this store's id, then drop the journal; False if it cannot."""
        with self._compact_lock, self._lock:
            if self._closed:
                raise CalibError(f"{self.path}: the session is closed")
            if self._filed or self._claim_tried:
                return False  # another thread's change claimed it (or tried) meanwhile
            self._claim_tried = True
            seq = self._seq + 1
            try:
                self._write_yaml(data, seq)
            except CalibError:
                return False  # the journal keeps the change; the compactor retries and reports
            self._seq, self._latest, self._compacted = seq, data, seq
            self._remove_journal_locked()
            return True

    def _write_yaml(self, data: dict, seq: int) -> None:
        """Replace the session YAML by ``data`` at ``seq``, with this store's id (CalibError if it cannot)."""
        # libyaml's dumper when present: the dump holds the GIL that the clicks need (20 ms -> 5 ms).
        text = yaml.dump({**data, SEQ_KEY: seq, ID_KEY: self.session_id},
                         Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper),
                         sort_keys=False, default_flow_style=None, width=100)
        try:
            write_bytes_atomic(self.path, text.encode("utf-8"))
        except (OSError, CalibError) as exc:
            raise CalibError(f"{self.path}: cannot save the session: {one_line(exc)}") from None
        self._filed = True
        self.compactions += 1

    def _remove_journal_locked(self) -> None:
        """Close and delete the journal: the YAML holds every change it held (or it was another session's)."""
        self._close_journal_locked()
        self._bytes = self._records = self._new_bytes = 0
        try:
            os.unlink(self.journal_path)
        except FileNotFoundError:
            pass
        except OSError as exc:
            print(f"ba-calib: cannot remove the session journal {self.journal_path}: {one_line(exc)}",
                  file=sys.stderr)

    def _open_locked(self) -> int:
        if self._fd is None:
            flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
            try:
                fd = os.open(self.journal_path, flags, 0o666)
            except OSError as exc:
                raise OSError(f"cannot open the session journal ({one_line(exc)})") from None
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                os.close(fd)
                raise OSError("the session journal is not a regular file")
            self._fd, self._bytes = fd, st.st_size
            fsync_folder(self.journal_path.parent)  # the journal's name survives a power cut too
        return self._fd

    def compact(self) -> None:
        """Write the newest appended session into the YAML; empty the journal if nothing newer came.

        Raises
        ------
        CalibError
            The session YAML cannot be written (the journal keeps the data).
        """
        with self._compact_lock:
            with self._lock:
                data, seq = self._latest, self._seq
            if data is None or seq <= self._compacted:
                self._truncate_if_current(seq)
                return
            with self._lock:  # what comes after this point waits for the next compaction
                self._records, self._new_bytes = 0, 0
            self._write_yaml(data, seq)
            self._compacted = seq
            self._truncate_if_current(seq)

    def _truncate_if_current(self, seq: int) -> None:
        with self._lock:
            if self._fd is None or self._seq != seq or self._bytes == 0:
                return  # a newer change is only in the journal: keep it
            try:
                os.ftruncate(self._fd, 0)
                _fdatasync(self._fd)
            except OSError as exc:
                raise CalibError(f"{self.journal_path}: cannot empty the session journal: {one_line(exc)}") from None
            self._bytes = 0

    def close(self) -> None:
        """Compact, remove the empty journal and stop the background thread.

        Raises
        ------
        CalibError
            The session YAML cannot be written (the journal is kept, so the
            next start restores every change).
        """
        with self._lock:
            self._closed = True
            self._cond.notify_all()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=10.0)
        try:
            self.compact()
        except BaseException:
            with self._lock:
                self._close_journal_locked()
            raise
        with self._lock:
            # The YAML holds every change (or there were none): no journal outlives this session,
            # also not one this store only read (restored from) or ignored.
            if self._seq <= self._compacted:
                self._remove_journal_locked()
            else:
                self._close_journal_locked()

    def _close_journal_locked(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    # --------------------------------------------------------------- background
    def _ensure_thread(self) -> None:
        if self._thread is None:
            with self._lock:
                if self._thread is None and not self._closed:
                    self._thread = threading.Thread(target=self._run, name="ba-calib-session-compactor", daemon=True)
                    self._thread.start()

    def _due_locked(self) -> float | None:
        """Seconds until the next compaction is due (0: now), or None if nothing waits."""
        if self._seq <= self._compacted:
            return None
        if self._records >= COMPACT_RECORDS or self._new_bytes >= COMPACT_BYTES:
            return 0.0
        return max(0.0, self._last_append + COMPACT_IDLE_S - time.monotonic())

    def _run(self) -> None:
        while True:
            with self._lock:
                while not self._closed:
                    due = self._due_locked()
                    if due == 0.0:
                        break
                    self._cond.wait(due)
                if self._closed:
                    return  # close() compacts in its own thread
            try:
                self.compact()
            except CalibError as exc:
                if self._on_error is not None:
                    try:
                        self._on_error(str(exc))
                    except Exception:
                        pass
                else:
                    print(f"ba-calib: {exc}", file=sys.stderr)
                with self._lock:
                    self._cond.wait(RETRY_S)


_OPEN_STORES: "weakref.WeakSet[SessionStore]" = weakref.WeakSet()


def compact_at_exit(store: SessionStore) -> None:
    """Fold ``store``'s journal into its session file at interpreter exit, if it is still open then."""
    _OPEN_STORES.add(store)


def forget_at_exit(store: SessionStore) -> None:
    """Undo :func:`compact_at_exit` (the store was closed)."""
    _OPEN_STORES.discard(store)


@atexit.register
def _compact_open_stores() -> None:
    """At interpreter exit, fold the journals into the session files (the data is safe either way)."""
    for store in list(_OPEN_STORES):
        try:
            store.compact()
        except Exception as exc:  # exiting anyway: say so, do not hide it
            print(f"ba-calib: {exc}", file=sys.stderr)


def peek_session(path: str | os.PathLike) -> dict | None:
    """The newest saved session at ``path`` (YAML or journal), read without opening it for writing; None: none.

    What :meth:`SessionStore.load` restores, for a caller that must know the session's shots before it
    loads their scans (:class:`app.serving.ShotServer`)."""
    path = Path(path)
    if not path.exists() and not path.with_name(path.name + JOURNAL_SUFFIX).exists():
        return None
    data, _ = SessionStore(path).load()
    return data
