"""Annotation state of the browser app: the point pairs the user is picking, and the view settings.

A *pick* (:class:`app.picks.Pick`) is one correspondence under construction; its two clicks can come in
either order.  Every change goes through :class:`AnnotationState`, which

* checks the input (invalid laser cell, pixel outside the image, bad view setting -> one-line CalibError),
* keeps an undo/redo history of whole snapshots of the picks (*clear all* and *import* included; the view
  settings are not part of it),
* puts every change on disk before it returns, so before any listener shows it (:class:`app.session_store.SessionStore`:
  a change that cannot be saved is refused and undone), and restores the session on start,
* is thread-safe: viser runs callbacks on a thread pool, and two browser tabs share one state,
* holds several *shots* (a scan and a photo each, one rig): every pick belongs to one; the panes show the
  *active* shot, whose picks :attr:`AnnotationState.picks` are (:attr:`AnnotationState.all_picks`: every shot's).

Pure Python plus numpy; no maths, no viser.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from calib_core.errors import CalibError
from calib_core.pairs import PAIR_SOURCES, Pair, load_pairs_yaml, save_pairs_yaml

from .picks import (Pick, ShotFiles, Snapshot, amends_newest_step, checked_picks, joins_newest_step, new_ends,
                    next_number, session_data)
from .session_store import SessionStore, compact_at_exit, forget_at_exit
from .state_shots import StateShots
from .view_settings import ViewSettings

MAX_HISTORY = 500


Listener = Callable[["AnnotationState"], None]


class AnnotationState(StateShots):
    """Thread-safe pairs under construction, with undo/redo and a session file.

    Parameters
    ----------
    depth_valid : (H, W) bool array, or a list of them (one per shot)
        Which depth-matrix cells have a laser return (clicks elsewhere are refused).
    image_size : (width, height)
        Size of the original camera image in pixels.
    session_path : path-like, optional
        Session file, saved (journal first) inside every change and read on
        start, together with its journal.  If it exists it is restored (a
        plain pairs YAML is accepted too).  Call :meth:`close` (or
        :meth:`flush_session`) before reading the YAML itself.
    on_save_error : callable, optional
        ``on_save_error(message)`` after a failed background compaction of
        the journal into the YAML (retried; no change is lost meanwhile).
        A change whose journal line cannot be written raises CalibError and
        is not made.
    default_view : ViewSettings, optional
        The view settings of a new session, and the fallback of every setting
        a session file lacks or holds a bad value for.
    shots : sequence of ShotFiles
        The shots' files, in the order of ``depth_valid``; a session that lists shots keeps its own first.
    active_shot : int, optional
        The shot shown (default: the session's, else 0).
    """

    def __init__(
        self,
        depth_valid: np.ndarray,
        image_size: tuple[int, int],
        session_path: str | os.PathLike | None = None,
        *,
        on_save_error: Callable[[str], None] | None = None,
        default_view: ViewSettings | None = None,
        shots: Sequence[ShotFiles] = (),
        active_shot: int | None = None,
    ) -> None:
        masks = list(depth_valid) if isinstance(depth_valid, (list, tuple)) else [depth_valid]
        self._masks = [np.asarray(m, dtype=bool) for m in masks]
        for m in self._masks:
            if m.ndim != 2:
                raise CalibError(f"depth validity mask must be 2-D, got shape {m.shape}")
        self._active = 0
        self._width, self._height = int(image_size[0]), int(image_size[1])
        self._lock = threading.RLock()
        self._snap = Snapshot(shots=tuple(shots))
        self._undo: list[Snapshot] = []
        self._redo: list[Snapshot] = []
        self._selected: int | None = None
        self._view = ViewSettings() if default_view is None else default_view
        self._version = 0
        self._change_started: float | None = None
        self._listeners: list[Listener] = []
        self.session_path = None if session_path is None else Path(session_path)
        self._store: SessionStore | None = None
        if self.session_path is not None:
            store = SessionStore(self.session_path, on_error=on_save_error)
            data, from_yaml = store.load()
            if data is not None:
                self._restore(data, self.session_path if from_yaml else store.journal_path, tuple(shots))
            self._store = store
            compact_at_exit(store)
        # The shot shown: ``active_shot``, else the session's, within the shots.
        self._active = min(max(self._active if active_shot is None else int(active_shot), 0), self.n_shots - 1)

    # ------------------------------------------------------------------ queries
    @property
    def version(self) -> int:
        """Increases by one with every change (pairs, selection or view)."""
        with self._lock:
            return self._version

    @property
    def picks(self) -> tuple[Pick, ...]:
        """The active shot's picks, in creation order (an immutable snapshot)."""
        with self._lock:
            return tuple(p for p in self._snap.picks if p.shot == self._active)

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

    @property
    def last_change_started(self) -> float | None:
        """``time.perf_counter()`` when the newest saved change began (before its disk write), or None."""
        return self._change_started

    @property
    def view(self) -> ViewSettings:
        """The view settings (panorama on/off, overlays ...): the one copy the app reads."""
        with self._lock:
            return self._view

    # ---------------------------------------------------------------- changes
    # Public mutators take the lock, change the snapshot, save the session and
    # then notify listeners after releasing the lock.
    def add_laser(self, row: int, col: int) -> int:
        """Record a click on a BA image; returns the id of the pick it went to.

        It completes the newest incomplete pick.  If that pick already has a
        laser end (two BA clicks in a row) the end is replaced; if there is no
        incomplete pick a new one starts.
        """
        return self._changed(self._add_locked, laser_rc=self.check_laser_cell(row, col))

    def add_pixel(self, u: float, v: float) -> int:
        """Record a click on the camera image (original-image pixel); returns the pick id.

        Symmetric to :meth:`add_laser`.
        """
        return self._changed(self._add_locked, pixel=self.check_pixel(u, v))

    def click_laser(self, row: int, col: int) -> int:
        """A BA click as the UI routes it: moves the selected pick's laser end, else :meth:`add_laser`."""
        return self._changed(self._click_locked, laser_rc=self.check_laser_cell(row, col))

    def click_pixel(self, u: float, v: float, **tags: Any) -> int:
        """A camera click as the UI routes it: moves the selected pick's pixel, else :meth:`add_pixel`.
        ``tags``: ``edge_deg`` (the photo end lies on an edge at this angle, degrees; None: a corner)."""
        return self._changed(self._click_locked, pixel=self.check_pixel(u, v), **_pixel_tags(tags))

    def start_pick(self, row: int, col: int, *, source: str = "guided", precision_px: float | None = None) -> int:
        """A new pick with only its laser end, tagged (guided "Next pair"); the next camera click completes it.
        Refused (CalibError) while another pick is incomplete: that click would complete the other one."""
        rc = self.check_laser_cell(row, col)
        if source not in PAIR_SOURCES:
            raise CalibError(f"source must be one of {', '.join(PAIR_SOURCES)}, got {source!r}")
        with self._lock:
            if (pending := self._pending_locked()) is not None:
                raise CalibError(f"pair {pending.id} is not finished; complete it or undo it first")
            new = Pick(self._snap.next_id, laser_rc=rc, source=source, precision_px=precision_px, shot=self._active)
            self._commit_locked(self._with(self._snap.picks + (new,)))
        self._notify()
        return new.id

    def move_laser(self, pick_id: int, row: int, col: int) -> int:
        """Set the laser end of pick ``pick_id`` to a cell."""
        return self._changed(self._move_locked, pick_id, laser_rc=self.check_laser_cell(row, col))

    def move_pixel(self, pick_id: int, u: float, v: float, *, same_step: bool = False, **tags: Any) -> int:
        """Set the camera end of pick ``pick_id`` to an original-image pixel (and ``precision_px``, ``source``,
        ``edge_deg`` if given).

        With ``same_step`` the change joins the newest undo step when that step changed only this pick (the
        guide tagging the click it just saw: one undo takes back both)."""
        return self._changed(self._move_locked, pick_id, pixel=self.check_pixel(u, v), amend=same_step,
                             **{k: tags[k] for k in ("precision_px", "source", "edge_deg") if k in tags})

    def delete(self, pick_id: int) -> None:
        """Remove pick ``pick_id`` (its number is reused only if it was the highest: see :func:`next_number`)."""
        with self._lock:
            self.get(pick_id)
            self._commit_locked(self._with(tuple(p for p in self._snap.picks if p.id != pick_id)))
        self._notify()

    def set_check(self, pick_id: int, check: bool) -> None:
        """Mark pick ``pick_id`` as a check pair (left out of the fit, error reported apart) or not; undoable."""
        with self._lock:
            old = self.get(pick_id)
            if old.check != bool(check):
                self._commit_locked(self._with(tuple(replace(p, check=bool(check)) if p.id == pick_id else p
                                                     for p in self._snap.picks)))
        self._notify()

    def clear(self) -> None:
        """Remove every pick of the active shot (undoable)."""
        with self._lock:
            others = tuple(p for p in self._snap.picks if p.shot != self._active)
            if len(others) == len(self._snap.picks):
                return
            self._commit_locked(self._with(others))
        self._notify()

    def check_import(self, pairs: Sequence[Pair]) -> list[Pick]:
        """The picks ``pairs`` would become (ids not yet given); CalibError names the first pair not of this scene."""
        return checked_picks(pairs, self.check_laser_cell, self.check_pixel)

    def count_duplicates(self, pairs: Sequence[Pair]) -> int:
        """How many of ``pairs`` are exact duplicates of a pick here (or of an earlier one of ``pairs``)."""
        return len(pairs) - len(new_ends(self.check_import(pairs), self.picks))  # of the active shot

    def import_pairs(self, pairs: Sequence[Pair], replace_existing: bool = False) -> list[int]:
        """Add pairs (e.g. from a pairs YAML) to the active shot as one undoable step; returns the ids added.

        Exact duplicates (same laser end and pixel as a pick already here, or
        as an earlier imported pair) are skipped.  A pair keeps the ``id`` it
        has in the file unless that id is taken.  With ``replace_existing``
        the imported pairs replace all picks (undo brings them back).  If any
        pair's laser cell or pixel is invalid for this scene a
        :class:`CalibError` names it and nothing is added.
        """
        checked = self.check_import(pairs)
        with self._lock:
            kept = tuple(p for p in self._snap.picks if not (replace_existing and p.shot == self._active))
            next_id = next_number(kept)
            used = {p.id for p in kept}  # ids are unique across shots
            new = []
            for p in new_ends(checked, [p for p in kept if p.shot == self._active]):
                pid = p.id if p.id >= 0 and p.id not in used else next_id
                used.add(pid)
                next_id = max(next_id, pid + 1)
                new.append(replace(p, id=pid, shot=self._active))
            if not new and not replace_existing:
                return []
            self._commit_locked(self._with(kept + tuple(new)))
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
        return self._step(back=True)

    def redo(self) -> bool:
        """Re-apply the last undone change; False if there is nothing to redo."""
        return self._step(back=False)

    def _step(self, back: bool) -> bool:
        with self._lock:
            source, target = (self._undo, self._redo) if back else (self._redo, self._undo)
            if not source:
                return False
            before = self._checkpoint_locked()
            target.append(self._snap)
            self._snap = source.pop()
            self._after_change_locked(before)
        self._notify()
        return True

    def select(self, pick_id: int | None) -> None:
        """Select a pick of the active shot (later clicks move its ends) or None for adding new pairs."""
        with self._lock:
            if pick_id is not None and self.get(pick_id).shot != self._active:
                raise CalibError(f"pair {pick_id} is in shot {self.get(pick_id).shot}; show that shot to select it")
            if self._selected == pick_id:
                return
            self._selected = pick_id
            self._version += 1
        self._notify()

    def set_view(self, **changes: Any) -> ViewSettings:
        """Change view settings (:meth:`ViewSettings.changed`: CalibError on an unknown name or a bad value).

        Saved with the session, not an undoable step.  Returns the new settings.
        """
        with self._lock:
            new = self._view.changed(**changes)
            if new == self._view:
                return new
            before = self._checkpoint_locked()
            self._view = new
            self._version += 1
            self._save_locked(before)
        self._notify()
        return new

    # -------------------------------------------------------------- listeners
    def subscribe(self, listener: Listener) -> None:
        """Call ``listener(state)`` after every change (outside the lock, on the changing thread)."""
        with self._lock:
            self._listeners.append(listener)

    def clear_listeners(self) -> None:
        """Forget every listener (the app they drew was stopped; the state lives on for the next shot's)."""
        with self._lock:
            self._listeners = []

    # ---------------------------------------------------------------- session
    def session_dict(self) -> dict[str, Any]:
        """The session as plain data (what the session file holds)."""
        with self._lock:
            return session_data(self._snap, self._view.to_dict(), self._active)

    def flush_session(self) -> None:
        """Return once every change so far is in the session file (no-op without a session file).

        Raises
        ------
        CalibError
            The session file cannot be written.
        """
        store = self._store
        if store is not None:
            store.compact()

    def close(self) -> None:
        """Bring the session YAML up to date and close the journal; later changes are not saved.

        Raises
        ------
        CalibError
            The session YAML cannot be written (the journal keeps every change for the next start).
        """
        with self._lock:
            store, self._store = self._store, None
        if store is not None:
            forget_at_exit(store)
            store.close()

    # -------------------------------------------------------------- internals
    def _changed(self, change: Callable[..., int], *args: Any, **kwargs: Any) -> int:
        """``change(*args, **kwargs)`` under the lock, then the listeners told; returns what ``change`` returns."""
        with self._lock:
            out = change(*args, **kwargs)
        self._notify()
        return out

    def _click_locked(self, laser_rc=None, pixel=None, **tags: Any) -> int:
        if self._selected is not None:
            return self._move_locked(self._selected, laser_rc=laser_rc, pixel=pixel, **tags)
        return self._add_locked(laser_rc=laser_rc, pixel=pixel, **tags)

    def _with(self, picks: tuple[Pick, ...]) -> Snapshot:
        return Snapshot(picks, self._snap.next_id, self._snap.shots)

    def _pending_locked(self) -> Pick | None:
        for p in reversed(self._snap.picks):
            if not p.complete and p.shot == self._active:
                return p
        return None

    def _add_locked(self, laser_rc=None, pixel=None, **tags: Any) -> int:
        target = self._pending_locked()
        if target is None:
            new = Pick(self._snap.next_id, laser_rc=laser_rc, pixel=pixel, shot=self._active, **tags)
            self._commit_locked(self._with(self._snap.picks + (new,)))
            return new.id
        return self._move_locked(target.id, laser_rc=laser_rc, pixel=pixel, **tags)

    def _move_locked(self, pick_id: int, laser_rc=None, pixel=None, amend: bool = False, **tags: Any) -> int:
        old = self.get(pick_id)
        if old.shot != self._active:  # its ends were checked against the active shot's scan
            raise CalibError(f"pair {pick_id} is in shot {old.shot}; show that shot to move it")
        new = replace(old, **tags)
        if laser_rc is not None:
            new = replace(new, laser_rc=laser_rc, laser_xyz=None)
        if pixel is not None:
            new = replace(new, pixel=pixel)
        self._commit_locked(self._with(tuple(new if p.id == pick_id else p for p in self._snap.picks)),
                            amend=pick_id if amend else None)
        return pick_id

    def _commit_locked(self, snap: Snapshot, amend: int | None = None) -> None:
        # Numbers follow the picks that exist: one dropped or undone (a declined proposal) frees its number.
        snap = Snapshot(snap.picks, next_number(snap.picks), snap.shots)
        if snap == self._snap:
            return
        before = self._checkpoint_locked()
        joins = joins_newest_step(self._undo, self._snap, snap) or (
            amend is not None and amends_newest_step(self._undo, self._snap, snap, amend))
        self._undo += [] if joins else [self._snap]
        del self._undo[:-MAX_HISTORY]
        self._redo = []
        self._snap = snap
        self._after_change_locked(before)

    def _checkpoint_locked(self) -> tuple:
        # Taken at the start of every saved change: also when the change began (for timing hooks).
        self._change_started = time.perf_counter()
        return (self._snap, list(self._undo), list(self._redo), self._selected, self._view, self._version,
                self._active)

    def _after_change_locked(self, before: tuple) -> None:
        self._active = min(self._active, self.n_shots - 1)  # an undone shot that was shown
        ids = {p.id for p in self._snap.picks if p.shot == self._active}
        if self._selected is not None and self._selected not in ids:
            self._selected = None
        self._version += 1
        self._save_locked(before)

    def _save_locked(self, before: tuple) -> None:
        """Put the changed state on disk (under the lock: in order); if that fails, undo the change and raise."""
        if self._store is None:
            return
        try:
            self._store.append(self.session_dict())
        except CalibError as exc:
            self._snap, self._undo, self._redo, self._selected, self._view, self._version, self._active = before
            raise CalibError(f"{exc} (the change was not made)") from None

    def _notify(self) -> None:
        for listener in list(self._listeners):
            listener(self)


def _pixel_tags(tags: dict[str, Any]) -> dict[str, Any]:
    """The tags a camera click may carry: ``edge_deg`` only (degrees, folded into [0, 180); None: a corner)."""
    unknown = set(tags) - {"edge_deg"}
    if unknown:
        raise CalibError(f"a camera click takes no {', '.join(sorted(unknown))}")
    if "edge_deg" in tags and tags["edge_deg"] is not None:
        deg = float(tags["edge_deg"])
        if not np.isfinite(deg):
            raise CalibError(f"edge_deg must be a finite angle in degrees, got {tags['edge_deg']!r}")
        return {"edge_deg": deg % 180.0}
    return dict(tags)
