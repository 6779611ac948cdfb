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
"""

from __future__ import annotations

import atexit
import json
import os
import stat
import sys
import threading
import time
import weakref
import zlib
from pathlib import Path
from typing import Callable

import yaml

from calib_core.errors import CalibError
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

_fdatasync = getattr(os, "fdatasync", os.fsync)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def encode_record(seq: int, data: dict) -> bytes:
    """One journal line: ``<crc32 hex> <json>\\n`` of ``{"seq": seq, "session": data}``."""
    body = json.dumps({"seq": int(seq), "session": data}, separators=(",", ":"), allow_nan=False).encode()
    return b"%08x %s\n" % (zlib.crc32(body), body)


def decode_records(raw: bytes) -> list[tuple[int, dict]]:
    """The intact ``(seq, session)`` records of a journal; torn or damaged lines are skipped."""
    out = []
    for line in raw.split(b"\n")[:-1]:  # the part after the last newline is torn
        crc, _, body = line.partition(b" ")
        try:
            if int(crc, 16) != zlib.crc32(body):
                continue
            rec = json.loads(body)
            seq, data = int(rec["seq"]), rec["session"]
        except (ValueError, KeyError, TypeError, RecursionError):
            continue
        if isinstance(data, dict):
            out.append((seq, data))
    return out


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
        #: Session YAML writes so far (compactions).
        self.compactions = 0

    # ------------------------------------------------------------------ reading
    def load(self) -> tuple[dict | None, bool]:
        """The newest saved session and whether it is the YAML as the user gave it.

        Returns ``(data, from_yaml)``: ``data`` is None without any file;
        ``from_yaml`` is True when no journal record is newer than the YAML
        (which may then be a plain pairs file given as the session).
        """
        data: dict | None = None
        if self.path.exists():
            data = read_yaml_mapping(self.path, "session file")
            try:
                self._compacted = self._seq = max(0, int(data.get(SEQ_KEY) or 0))
            except (TypeError, ValueError):
                raise CalibError(f"{self.path}: {SEQ_KEY} must be an integer") from None
        records = decode_records(self._read_journal())
        newer = [(s, d) for s, d in records if s > self._seq]
        if not newer:
            return data, True
        self._seq, latest = max(newer, key=lambda r: r[0])
        self._latest = latest
        return latest, False

    def _read_journal(self) -> bytes:
        try:
            fd = os.open(self.journal_path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            return b""
        except OSError as exc:
            raise CalibError(f"{self.journal_path}: cannot read the session journal: {_one_line(exc)}") from None
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

        Raises
        ------
        CalibError
            The journal cannot be written; the change must not be made.
        """
        with self._lock:
            if self._closed:
                raise CalibError(f"{self.path}: the session is closed")
            seq = self._seq + 1
            try:
                line = encode_record(seq, data)
                fd = self._open_locked()
                view = memoryview(line)
                while view:
                    view = view[os.write(fd, view):]
                _fdatasync(fd)
            except (OSError, ValueError, TypeError) as exc:
                raise CalibError(f"{self.journal_path}: cannot save the change: {_one_line(exc)}") from None
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

    def _open_locked(self) -> int:
        if self._fd is None:
            flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
            try:
                fd = os.open(self.journal_path, flags, 0o666)
            except OSError as exc:
                raise OSError(f"cannot open the session journal ({_one_line(exc)})") from None
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
            # libyaml's dumper when present: the dump holds the GIL that the clicks need (20 ms -> 5 ms).
            text = yaml.dump({**data, SEQ_KEY: seq}, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper),
                             sort_keys=False, default_flow_style=None, width=100)
            try:
                write_bytes_atomic(self.path, text.encode("utf-8"))
            except (OSError, CalibError) as exc:
                raise CalibError(f"{self.path}: cannot save the session: {_one_line(exc)}") from None
            self._compacted = seq
            self.compactions += 1
            self._truncate_if_current(seq)

    def _truncate_if_current(self, seq: int) -> None:
        with self._lock:
            if self._fd is None or self._seq != seq or self._bytes == 0:
                return  # a newer change is only in the journal: keep it
            try:
                os.ftruncate(self._fd, 0)
                _fdatasync(self._fd)
            except OSError as exc:
                raise CalibError(f"{self.journal_path}: cannot empty the session journal: {_one_line(exc)}") from None
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
        finally:
            with self._lock:
                if self._fd is not None:
                    empty = self._bytes == 0
                    os.close(self._fd)
                    self._fd = None
                    if empty:
                        try:
                            os.unlink(self.journal_path)
                        except OSError:
                            pass

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
