"""The shots of :class:`app.state.AnnotationState`: which shot is shown, adding one, and restoring them.

A *shot* is a scan and the photo the rig took with it; every shot shares the camera and ``T_camera_lidar``.
Each pick belongs to one shot (:attr:`app.picks.Pick.shot`); the snapshot lists the shots' files
(:class:`app.picks.ShotFiles`), so adding a shot is undoable like any change of the picks.  The shot shown
(*active*) is saved with the session, as the view settings are, and is not an undoable step.

Pure Python plus numpy; no maths, no viser.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from calib_core.errors import CalibError

from .picks import Pick, ShotFiles, Snapshot, next_number, restore_session, session_shots
from .view_settings import ViewSettings


class StateShots:
    """Mixin of :class:`app.state.AnnotationState`: the shots, and the checks of clicks against a shot's scene
    (it uses the state's lock, snapshot and validity masks)."""

    def check_laser_cell(self, row: int, col: int, shot: int | None = None) -> tuple[int, int]:
        """``(row, col)`` as ints if the cell exists and has a return in ``shot`` (default: active), else CalibError."""
        valid = self._masks[self._active if shot is None else shot]
        h, w = valid.shape
        try:
            r, c = int(row), int(col)
        except (TypeError, ValueError):
            raise CalibError(f"laser cell must be two integers, got ({row!r}, {col!r})") from None
        if not (0 <= r < h and 0 <= c < w):
            raise CalibError(f"laser cell ({r}, {c}) is outside the {h}x{w} scan")
        if not valid[r, c]:
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

    @property
    def all_picks(self) -> tuple[Pick, ...]:
        """Every shot's picks, in creation order."""
        with self._lock:
            return self._snap.picks

    @property
    def shots(self) -> tuple[ShotFiles, ...]:
        """The shots' files (empty: one shot, files not recorded)."""
        with self._lock:
            return self._snap.shots

    @property
    def n_shots(self) -> int:
        with self._lock:
            return len(self._snap.shots) or 1

    @property
    def active_shot(self) -> int:
        """The shot the panes show and clicks go to (0-based)."""
        with self._lock:
            return self._active

    def add_shot(self, scan: Any, image: Any, depth_valid: np.ndarray) -> int:
        """Add a shot (its files and its scan's validity mask) as one undoable step; returns its index."""
        mask = np.asarray(depth_valid, dtype=bool)
        if mask.ndim != 2:
            raise CalibError(f"depth validity mask must be 2-D, got shape {mask.shape}")
        files = ShotFiles.of(scan, image)
        with self._lock:
            if files in self._snap.shots:
                raise CalibError(f"{files.scan} and {files.image} are already shot {self._snap.shots.index(files)}")
            k = len(self._snap.shots)
            self._masks[k:k + 1] = [mask]  # a slot freed by an undone shot is taken over
            self._commit_locked(Snapshot(self._snap.picks, self._snap.next_id, self._snap.shots + (files,)))
        self._notify()
        return k

    def set_active_shot(self, shot: int) -> None:
        """Show shot ``shot`` (0-based): clicks go to it; saved with the session, not an undoable step."""
        with self._lock:
            if isinstance(shot, bool) or not isinstance(shot, (int, np.integer)) or not 0 <= shot < self.n_shots:
                raise CalibError(f"no shot {shot!r}: the session has {self.n_shots} (0-based)")
            if int(shot) == self._active:
                return
            before = self._checkpoint_locked()
            self._active, self._selected = int(shot), None
            self._version += 1
            self._save_locked(before)
        self._notify()

    def _restore(self, data: dict, path: Path, given: tuple[ShotFiles, ...]) -> None:
        """Restore the session ``data`` read from ``path`` (the session YAML or its journal).

        The session's shots come first; shots ``given`` beyond them are added (a version-1 session: all)."""
        listed = session_shots(data, path)
        shots = listed + given[len(listed):]
        if len(shots) > len(self._masks):
            raise CalibError(f"{path}: the session lists {len(shots)} shots but {len(self._masks)} scan(s) are "
                             "loaded: open it with --shot SCAN IMAGE for each shot")
        snap, view = restore_session(data, path, self.check_laser_cell, self.check_pixel, len(shots) or 1)
        self._snap = Snapshot(snap.picks, next_number(snap.picks), shots)
        active = data.get("active_shot", 0)
        self._active = active if isinstance(active, int) and not isinstance(active, bool) else 0
        if view is not None:
            self._view = ViewSettings.from_dict(view, default=self._view)
