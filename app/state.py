"""Annotation state of the browser app: the point pairs the user is picking.

A *pick* is one correspondence under construction: a laser end (a depth-matrix
cell ``(row, col)``, or a lidar-frame point ``laser_xyz`` for imported pairs)
and a camera end (a pixel ``(u, v)`` in the ORIGINAL camera image).  Either end
may still be missing while the user clicks; the two clicks can come in either
order.

Every change goes through :class:`AnnotationState`, which

* checks the input (invalid laser cell, pixel outside the image ->
  :class:`calib_core.errors.CalibError` with a one-line message),
* keeps an undo/redo history of whole snapshots (every change is undoable,
  including *clear all* and *import*),
* saves the session atomically after every change (temporary file, then
  ``os.replace``), so that closing the tab or killing the server loses no
  click, and restores it on start; with ``background_save`` (what the app
  uses) a :class:`SessionWriter` thread does the write, off the click path,
  always writing the newest state (a change is on disk a bounded time later:
  the writer's delay, 0.1 s in the app, plus one write;
  :meth:`AnnotationState.flush_session` and :meth:`AnnotationState.close`
  write at once),
* is thread-safe: viser runs callbacks on a thread pool, and two browser tabs
  share one state.

This module is pure Python plus numpy; it holds no maths and knows nothing
about viser.
"""

from __future__ import annotations

import atexit
import colorsys
import os
import sys
import threading
import time
import weakref
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from calib_core.errors import CalibError
from calib_core.io.atomic import write_yaml_atomic
from calib_core.io.yaml_files import finite_vector, read_yaml_mapping
from calib_core.pairs import Pair, load_pairs_yaml, save_pairs_yaml

SESSION_FORMAT = "ba-calib-session"
SESSION_VERSION = 1
MAX_HISTORY = 500
#: After a failed session write the writer retries this often (seconds) until it succeeds.
SAVE_RETRY_S = 1.0


def pair_color(pick_id: int) -> tuple[int, int, int]:
    """A stable, well-separated RGB colour for a pick id (golden-ratio hues)."""
    hue = (0.08 + 0.61803398875 * int(pick_id)) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 1.0)
    return int(round(255 * r)), int(round(255 * g)), int(round(255 * b))


@dataclass(frozen=True)
class Pick:
    """One pair, possibly incomplete.

    Attributes
    ----------
    id : int
        Stable number shown on the markers (1, 2, ...); never reused.
    laser_rc : (row, col) or None
        Depth-matrix cell, 0-based.
    laser_xyz : (x, y, z) or None
        Laser point in the lidar frame, metres (imported pairs only).
    pixel : (u, v) or None
        Pixel in the original camera image, (column, row), top-left centre 0.
    """

    id: int
    laser_rc: tuple[int, int] | None = None
    laser_xyz: tuple[float, float, float] | None = None
    pixel: tuple[float, float] | None = None

    @property
    def has_laser(self) -> bool:
        return self.laser_rc is not None or self.laser_xyz is not None

    @property
    def complete(self) -> bool:
        return self.has_laser and self.pixel is not None

    @property
    def color(self) -> tuple[int, int, int]:
        return pair_color(self.id)

    def to_pair(self) -> Pair:
        """The :class:`calib_core.pairs.Pair` of a complete pick."""
        if not self.complete:
            raise CalibError(f"pair {self.id} is incomplete")
        return Pair(self.laser_rc, None if self.laser_rc is not None else self.laser_xyz, self.pixel)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": int(self.id)}
        out["laser_rc"] = None if self.laser_rc is None else [int(v) for v in self.laser_rc]
        out["laser_xyz"] = None if self.laser_xyz is None else [float(v) for v in self.laser_xyz]
        out["pixel"] = None if self.pixel is None else [float(v) for v in self.pixel]
        return out


@dataclass(frozen=True)
class Snapshot:
    """The undoable part of the state."""

    picks: tuple[Pick, ...] = ()
    next_id: int = 1


Listener = Callable[["AnnotationState"], None]

_OPEN_WRITERS: "weakref.WeakSet[SessionWriter]" = weakref.WeakSet()


@atexit.register
def _flush_open_writers() -> None:
    """At interpreter exit, write what the writers still hold (their threads are daemons)."""
    for writer in list(_OPEN_WRITERS):
        try:
            writer.flush()
        except Exception as exc:  # exiting anyway: say so, do not hide it
            print(f"ba-calib: {exc}", file=sys.stderr)


class SessionWriter:
    """A background thread that keeps a session file equal to the newest submitted data.

    :meth:`submit` only stores the data and wakes the thread, which writes it
    atomically (:func:`calib_core.io.atomic.write_yaml_atomic`: temporary
    file, fsync, ``os.replace``).  Data submitted while a write is running
    replaces older unwritten data, so the file always ends at the newest
    state and the thread never falls behind.  A failed write is kept and
    retried every :data:`SAVE_RETRY_S` seconds (or at once when newer data
    comes); ``on_error(message)`` is called on the writer thread.
    Pending data is written by :meth:`flush`, :meth:`close` and at
    interpreter exit.

    Parameters
    ----------
    path : path-like
        The session file.
    on_error : callable, optional
        ``on_error(message)`` after a failed write (one line).
    delay_s : float
        Wait this long after the first unwritten submission before writing
        (submissions meanwhile are merged), so that the write (YAML dump,
        fsync) does not compete with the work a change triggers.  Data is
        on disk at most ``delay_s`` + one write after it was submitted.
    """

    def __init__(self, path: str | os.PathLike, on_error: Callable[[str], None] | None = None,
                 delay_s: float = 0.0) -> None:
        self.path = Path(path)
        self._on_error = on_error
        self._delay_s = max(0.0, float(delay_s))
        self._due = 0.0  # monotonic time the pending data is to be written
        self._cond = threading.Condition()
        self._write_lock = threading.Lock()  # one write at a time, in submission order
        self._pending: Any = None
        self._has_pending = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="ba-calib-session-writer", daemon=True)
        self._thread.start()
        _OPEN_WRITERS.add(self)

    def submit(self, data: Any) -> None:
        """Queue ``data`` (plain YAML-able, not changed afterwards) to be written; never blocks for a write."""
        with self._cond:
            if self._closed:
                raise RuntimeError("the session writer is closed")
            if not self._has_pending:
                self._due = time.monotonic() + self._delay_s
            self._pending, self._has_pending = data, True
            self._cond.notify_all()

    def flush(self) -> None:
        """Write pending data now, in the calling thread, and wait for a write in progress.

        Raises
        ------
        CalibError
            The session file cannot be written (the data stays pending).
        """
        self._write_pending()

    def close(self) -> None:
        """:meth:`flush`, then stop the thread (it is stopped even if the flush raises)."""
        try:
            self.flush()
        finally:
            with self._cond:
                self._closed = True
                self._cond.notify_all()
            self._thread.join(timeout=5.0)
            _OPEN_WRITERS.discard(self)

    def _write_pending(self) -> bool:
        # Taking the data under the write lock keeps writes in submission order:
        # an older snapshot can never land after a newer one.
        with self._write_lock:
            with self._cond:
                if not self._has_pending:
                    return False
                data, self._has_pending = self._pending, False
                self._pending = None
            try:
                write_yaml_atomic(self.path, data)
            except Exception as exc:
                with self._cond:
                    if not self._has_pending:  # nothing newer: keep this one for the retry
                        self._pending, self._has_pending = data, True
                raise CalibError(f"{self.path}: cannot save the session: {' '.join(str(exc).split())}") from None
            return True

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._has_pending or self._closed)
                while self._has_pending and not self._closed and time.monotonic() < self._due:
                    self._cond.wait(self._due - time.monotonic())
                if self._closed:
                    return  # close() flushed in its own thread
            try:
                self._write_pending()
            except CalibError as exc:
                if self._on_error is not None:
                    try:
                        self._on_error(str(exc))
                    except Exception:
                        pass
                else:
                    print(f"ba-calib: {exc}", file=sys.stderr)
                with self._cond:  # retry later, or at once when newer data or close() comes
                    self._cond.wait(SAVE_RETRY_S)


class AnnotationState:
    """Thread-safe pairs under construction, with undo/redo and a session file.

    Parameters
    ----------
    depth_valid : (H, W) bool array
        Which depth-matrix cells have a laser return (clicks elsewhere are
        refused).
    image_size : (width, height)
        Size of the original camera image in pixels.
    session_path : path-like, optional
        Session file, written after every change and read on start.  If it
        exists it is restored (a plain pairs YAML is accepted too).
    background_save : bool
        Write the session file in a :class:`SessionWriter` thread instead of
        inside every change (which then costs no disk time; the write starts
        at once).  Call :meth:`close` (or :meth:`flush_session`) before
        reading the file or exiting; interpreter exit also flushes.
    on_save_error : callable, optional
        With ``background_save``: ``on_save_error(message)`` after a failed
        background write (it is retried).  Without, a failed write raises
        from the change.
    save_delay_s : float
        With ``background_save``: the writer's ``delay_s`` (see
        :class:`SessionWriter`).
    """

    def __init__(
        self,
        depth_valid: np.ndarray,
        image_size: tuple[int, int],
        session_path: str | os.PathLike | None = None,
        *,
        background_save: bool = False,
        on_save_error: Callable[[str], None] | None = None,
        save_delay_s: float = 0.0,
    ) -> None:
        self._valid = np.asarray(depth_valid, dtype=bool)
        if self._valid.ndim != 2:
            raise CalibError(f"depth validity mask must be 2-D, got shape {self._valid.shape}")
        self._width, self._height = int(image_size[0]), int(image_size[1])
        self._lock = threading.RLock()
        self._snap = Snapshot()
        self._undo: list[Snapshot] = []
        self._redo: list[Snapshot] = []
        self._selected: int | None = None
        self._view: dict[str, Any] = {}
        self._version = 0
        self._listeners: list[Listener] = []
        self.session_path = None if session_path is None else Path(session_path)
        if self.session_path is not None and self.session_path.exists():
            self._restore(self.session_path)
        self._writer: SessionWriter | None = None
        if background_save and self.session_path is not None:
            self._writer = SessionWriter(self.session_path, on_error=on_save_error, delay_s=save_delay_s)

    # ------------------------------------------------------------------ queries
    @property
    def version(self) -> int:
        """Increases by one with every change (pairs, selection or view)."""
        with self._lock:
            return self._version

    @property
    def picks(self) -> tuple[Pick, ...]:
        """All picks, in creation order (an immutable snapshot)."""
        with self._lock:
            return self._snap.picks

    @property
    def selected(self) -> int | None:
        """Id of the selected pick, or None."""
        with self._lock:
            return self._selected

    @property
    def can_undo(self) -> bool:
        with self._lock:
            return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        with self._lock:
            return bool(self._redo)

    def get(self, pick_id: int) -> Pick:
        """The pick with this id, or a :class:`CalibError`."""
        with self._lock:
            for p in self._snap.picks:
                if p.id == pick_id:
                    return p
        raise CalibError(f"no pair number {pick_id}")

    def complete_picks(self) -> list[Pick]:
        """The picks with both ends, in creation order."""
        return [p for p in self.picks if p.complete]

    def pairs(self) -> list[Pair]:
        """The complete picks as :class:`calib_core.pairs.Pair` (solver input)."""
        return [p.to_pair() for p in self.complete_picks()]

    def pending(self) -> Pick | None:
        """The newest incomplete pick (the one the next click completes), if any."""
        with self._lock:
            return self._pending_locked()

    def view_settings(self) -> dict[str, Any]:
        """A copy of the saved view settings (panorama on/off, overlays ...)."""
        with self._lock:
            return dict(self._view)

    # ------------------------------------------------------------- validation
    def check_laser_cell(self, row: int, col: int) -> tuple[int, int]:
        """``(row, col)`` as ints if the cell exists and has a return, else CalibError."""
        h, w = self._valid.shape
        try:
            r, c = int(row), int(col)
        except (TypeError, ValueError):
            raise CalibError(f"laser cell must be two integers, got ({row!r}, {col!r})") from None
        if not (0 <= r < h and 0 <= c < w):
            raise CalibError(f"laser cell ({r}, {c}) is outside the {h}x{w} scan")
        if not self._valid[r, c]:
            raise CalibError(f"laser cell ({r}, {c}) has no laser return; click on a valid (non-black) cell")
        return r, c

    def check_pixel(self, u: float, v: float) -> tuple[float, float]:
        """``(u, v)`` as floats if inside the original camera image, else CalibError."""
        try:
            uf, vf = float(u), float(v)
        except (TypeError, ValueError):
            raise CalibError(f"pixel must be two numbers, got ({u!r}, {v!r})") from None
        if not (np.isfinite(uf) and np.isfinite(vf)):
            raise CalibError(f"pixel ({uf}, {vf}) is not finite")
        if not (-0.5 <= uf <= self._width - 0.5 and -0.5 <= vf <= self._height - 0.5):
            raise CalibError(f"pixel ({uf:.1f}, {vf:.1f}) is outside the {self._width}x{self._height} camera image")
        return uf, vf

    # ---------------------------------------------------------------- changes
    # Public mutators take the lock, change the snapshot, save the session and
    # then notify listeners after releasing the lock.
    def add_laser(self, row: int, col: int) -> int:
        """Record a click on a BA image; returns the id of the pick it went to.

        It completes the newest incomplete pick.  If that pick already has a
        laser end (two BA clicks in a row) the end is replaced; if there is no
        incomplete pick a new one starts.
        """
        rc = self.check_laser_cell(row, col)
        with self._lock:
            out = self._add_locked(laser_rc=rc)
        self._notify()
        return out

    def add_pixel(self, u: float, v: float) -> int:
        """Record a click on the camera image (original-image pixel); returns the pick id.

        Symmetric to :meth:`add_laser`.
        """
        uv = self.check_pixel(u, v)
        with self._lock:
            out = self._add_locked(pixel=uv)
        self._notify()
        return out

    def click_laser(self, row: int, col: int) -> int:
        """A BA click as the UI routes it: moves the selected pick's laser end, else :meth:`add_laser`."""
        rc = self.check_laser_cell(row, col)
        with self._lock:
            if self._selected is not None:
                out = self._move_locked(self._selected, laser_rc=rc)
            else:
                out = self._add_locked(laser_rc=rc)
        self._notify()
        return out

    def click_pixel(self, u: float, v: float) -> int:
        """A camera click as the UI routes it: moves the selected pick's pixel, else :meth:`add_pixel`."""
        uv = self.check_pixel(u, v)
        with self._lock:
            if self._selected is not None:
                out = self._move_locked(self._selected, pixel=uv)
            else:
                out = self._add_locked(pixel=uv)
        self._notify()
        return out

    def move_laser(self, pick_id: int, row: int, col: int) -> int:
        """Set the laser end of pick ``pick_id`` to a cell."""
        rc = self.check_laser_cell(row, col)
        with self._lock:
            out = self._move_locked(pick_id, laser_rc=rc)
        self._notify()
        return out

    def move_pixel(self, pick_id: int, u: float, v: float) -> int:
        """Set the camera end of pick ``pick_id`` to an original-image pixel."""
        uv = self.check_pixel(u, v)
        with self._lock:
            out = self._move_locked(pick_id, pixel=uv)
        self._notify()
        return out

    def delete(self, pick_id: int) -> None:
        """Remove pick ``pick_id`` (its number is not reused)."""
        with self._lock:
            self.get(pick_id)
            picks = tuple(p for p in self._snap.picks if p.id != pick_id)
            self._commit_locked(Snapshot(picks, self._snap.next_id))
        self._notify()

    def clear(self) -> None:
        """Remove every pick (undoable)."""
        with self._lock:
            if not self._snap.picks:
                return
            self._commit_locked(Snapshot((), self._snap.next_id))
        self._notify()

    def import_pairs(self, pairs: Sequence[Pair], replace_existing: bool = False) -> list[int]:
        """Add pairs (e.g. from a pairs YAML) as one undoable step; returns the new ids.

        If any pair's laser cell or pixel is invalid for this scene a
        :class:`CalibError` names it and nothing is added.
        """
        checked = []
        for i, p in enumerate(pairs):
            try:
                rc = None if p.laser_rc is None else self.check_laser_cell(*p.laser_rc)
                xyz = None if p.laser_xyz is None else tuple(finite_vector(p.laser_xyz, 3, "laser_xyz"))
                if rc is None and xyz is None:
                    raise CalibError("no laser end")
                uv = self.check_pixel(*p.pixel)
            except CalibError as exc:
                raise CalibError(f"imported pair {i}: {exc}") from None
            checked.append((rc, xyz, uv))
        with self._lock:
            base = () if replace_existing else self._snap.picks
            next_id = self._snap.next_id
            new = []
            for rc, xyz, uv in checked:
                new.append(Pick(next_id, laser_rc=rc, laser_xyz=None if rc is not None else xyz, pixel=uv))
                next_id += 1
            self._commit_locked(Snapshot(base + tuple(new), next_id))
        self._notify()
        return [p.id for p in new]

    def import_pairs_file(self, path: str | os.PathLike, replace_existing: bool = False) -> list[int]:
        """:meth:`import_pairs` from a pairs YAML file (:func:`calib_core.pairs.load_pairs_yaml`)."""
        return self.import_pairs(load_pairs_yaml(path), replace_existing=replace_existing)

    def export_pairs_file(self, path: str | os.PathLike) -> int:
        """Write the complete pairs as a pairs YAML (atomic); returns how many."""
        pairs = self.pairs()
        save_pairs_yaml(path, pairs)
        return len(pairs)

    def undo(self) -> bool:
        """Step back one change; False if there is nothing to undo."""
        with self._lock:
            if not self._undo:
                return False
            self._redo.append(self._snap)
            self._snap = self._undo.pop()
            self._after_change_locked()
        self._notify()
        return True

    def redo(self) -> bool:
        """Re-apply the last undone change; False if there is nothing to redo."""
        with self._lock:
            if not self._redo:
                return False
            self._undo.append(self._snap)
            self._snap = self._redo.pop()
            self._after_change_locked()
        self._notify()
        return True

    def select(self, pick_id: int | None) -> None:
        """Select a pick (later clicks move its ends) or None for adding new pairs."""
        with self._lock:
            if pick_id is not None:
                self.get(pick_id)
            if self._selected == pick_id:
                return
            self._selected = pick_id
            self._version += 1
        self._notify()

    def set_view(self, **settings: Any) -> None:
        """Update saved view settings (plain YAML-able values); saved with the session."""
        with self._lock:
            changed = {k: v for k, v in settings.items() if self._view.get(k, object()) != v}
            if not changed:
                return
            self._view.update(changed)
            self._version += 1
            self._save_locked()
        self._notify()

    # -------------------------------------------------------------- listeners
    def subscribe(self, listener: Listener) -> None:
        """Call ``listener(state)`` after every change (outside the lock, on the changing thread)."""
        with self._lock:
            self._listeners.append(listener)

    # ---------------------------------------------------------------- session
    def session_dict(self) -> dict[str, Any]:
        """The session as plain data (what the session file holds)."""
        with self._lock:
            return {
                "format": SESSION_FORMAT,
                "version": SESSION_VERSION,
                "next_id": int(self._snap.next_id),
                "pairs": [p.to_dict() for p in self._snap.picks],
                "view": dict(self._view),
            }

    def save_session(self, path: str | os.PathLike | None = None) -> None:
        """Write the session file atomically (to ``path`` or the session path); returns when it is on disk."""
        with self._lock:
            target = Path(path) if path is not None else self.session_path
            if target is None:
                return
            writer = self._writer
            if writer is None or target != self.session_path:
                write_yaml_atomic(target, self.session_dict())
                return
            writer.submit(self.session_dict())
        writer.flush()

    def flush_session(self) -> None:
        """Return once every change so far is in the session file (no-op without a session file).

        Raises
        ------
        CalibError
            The session file cannot be written.
        """
        writer = self._writer
        if writer is not None:
            writer.flush()

    def close(self) -> None:
        """Flush the session file and stop the background writer; later changes are saved synchronously."""
        with self._lock:  # held, so that no change is saved synchronously before the writer's last write
            writer, self._writer = self._writer, None
            if writer is not None:
                writer.close()

    # -------------------------------------------------------------- internals
    def _pending_locked(self) -> Pick | None:
        for p in reversed(self._snap.picks):
            if not p.complete:
                return p
        return None

    def _add_locked(self, laser_rc=None, pixel=None) -> int:
        target = self._pending_locked()
        if target is None:
            new = Pick(self._snap.next_id, laser_rc=laser_rc, pixel=pixel)
            self._commit_locked(Snapshot(self._snap.picks + (new,), self._snap.next_id + 1))
            return new.id
        return self._move_locked(target.id, laser_rc=laser_rc, pixel=pixel)

    def _move_locked(self, pick_id: int, laser_rc=None, pixel=None) -> int:
        old = self.get(pick_id)
        new = old
        if laser_rc is not None:
            new = replace(new, laser_rc=laser_rc, laser_xyz=None)
        if pixel is not None:
            new = replace(new, pixel=pixel)
        picks = tuple(new if p.id == pick_id else p for p in self._snap.picks)
        self._commit_locked(Snapshot(picks, self._snap.next_id))
        return pick_id

    def _commit_locked(self, snap: Snapshot) -> None:
        if snap == self._snap:
            return
        self._undo.append(self._snap)
        del self._undo[:-MAX_HISTORY]
        self._redo.clear()
        self._snap = snap
        self._after_change_locked()

    def _after_change_locked(self) -> None:
        ids = {p.id for p in self._snap.picks}
        if self._selected is not None and self._selected not in ids:
            self._selected = None
        self._version += 1
        self._save_locked()

    def _save_locked(self) -> None:
        if self.session_path is None:
            return
        if self._writer is not None:
            # Submitted under the lock: the writer sees the changes in order.
            self._writer.submit(self.session_dict())
        else:
            write_yaml_atomic(self.session_path, self.session_dict())

    def _notify(self) -> None:
        for listener in list(self._listeners):
            listener(self)

    def _restore(self, path: Path) -> None:
        data = read_yaml_mapping(path, "session file")
        if data.get("format") != SESSION_FORMAT:
            # A plain pairs file given as the session: start from its pairs.
            pairs = load_pairs_yaml(path)
            picks = []
            for i, p in enumerate(pairs):
                try:
                    if p.laser_rc is not None:
                        self.check_laser_cell(*p.laser_rc)
                    self.check_pixel(*p.pixel)
                except CalibError as exc:
                    raise CalibError(f"{path}: pair {i}: {exc} (pairs from another scene?)") from None
                picks.append(Pick(i + 1, laser_rc=p.laser_rc, laser_xyz=p.laser_xyz, pixel=p.pixel))
            self._snap = Snapshot(tuple(picks), len(picks) + 1)
            return
        entries = data.get("pairs") or []
        if not isinstance(entries, list):
            raise CalibError(f"{path}: 'pairs' must be a list")
        picks = []
        for i, e in enumerate(entries):
            where = f"{path}: pair {i}"
            if not isinstance(e, dict) or "id" not in e:
                raise CalibError(f"{where}: expected a mapping with an id")
            try:
                pick_id = int(e["id"])
            except (TypeError, ValueError):
                raise CalibError(f"{where}: id must be an integer") from None
            rc = e.get("laser_rc")
            xyz = e.get("laser_xyz")
            px = e.get("pixel")
            rc_t = None if rc is None else tuple(int(v) for v in finite_vector(rc, 2, f"{where} laser_rc"))
            xyz_t = None if xyz is None else tuple(finite_vector(xyz, 3, f"{where} laser_xyz"))
            px_t = None if px is None else tuple(finite_vector(px, 2, f"{where} pixel"))
            # A session written for another scene must not inject invalid picks.
            try:
                if rc_t is not None:
                    self.check_laser_cell(*rc_t)
                if px_t is not None:
                    self.check_pixel(*px_t)
            except CalibError as exc:
                raise CalibError(f"{where}: {exc} (session from another scene?)") from None
            picks.append(Pick(pick_id, rc_t, xyz_t, px_t))  # type: ignore[arg-type]
        ids = [p.id for p in picks]
        if len(set(ids)) != len(ids):
            raise CalibError(f"{path}: duplicate pair ids")
        next_id = max([int(data.get("next_id") or 1)] + [i + 1 for i in ids])
        view = data.get("view") or {}
        if not isinstance(view, dict):
            raise CalibError(f"{path}: 'view' must be a mapping")
        self._snap = Snapshot(tuple(picks), next_id)
        self._view = dict(view)
