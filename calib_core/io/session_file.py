"""The annotation session file: the format check the app runs before restoring one.

Layout (written by ``app/state.py``)::

    format: ba-calib-session
    version: 1
    next_id: 12                  # id the next new pick gets
    pairs:                       # picks, complete or not
      - id: 3
        laser_rc: [row, col]     # and/or laser_xyz: [x, y, z]
        pixel: [u, v]            # optional while the pick is incomplete
    view: {...}                  # UI settings, a mapping
    journal_seq: 57              # the journal record this file holds (app/session_store.py)
    session_id: 3f2a...          # the id every line of <file>.journal repeats (a journal of another file is ignored)

:func:`parse_session` is pure: it takes the mapping read from the file and
returns checked values, or raises a one-line :class:`CalibError`.  Whether the
cells and pixels fit the scene is the app's check (it knows the scene).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CalibError
from ..pairs import MAX_COORDINATE_M, MAX_PAIRS, MAX_PIXEL, VALUES_PER_PAIR, parse_edge_deg, parse_laser_rc
from .input_files import MAX_SESSION_BYTES
from .yaml_files import finite_vector, read_yaml_mapping

SESSION_FORMAT = "ba-calib-session"
#: The newest session version this code reads.
SESSION_VERSION = 2  # 2: shots (``shots:``, each pick's ``shot``); 1: one shot
#: Ids and ``next_id`` are below this (they are stored as 32-bit integers by the UI).
MAX_ID = 2**31 - 1


@dataclass(frozen=True)
class SessionPick:
    """One checked session entry; any of the three locations may be missing (an incomplete pick)."""

    id: int
    laser_rc: tuple[int, int] | None
    laser_xyz: tuple[float, float, float] | None
    pixel: tuple[float, float] | None


@dataclass(frozen=True)
class SessionData:
    """A checked session: picks in file order, the next free id (above every pick id), the view settings."""

    picks: tuple[SessionPick, ...]
    next_id: int
    view: dict[str, Any]


def _whole(value: Any, where: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise CalibError(f"{where}: expected a whole number from {low} to {high}, got {value!r}"[:300])
    return value


def is_session(data: Any) -> bool:
    """True when ``data`` (a mapping read from YAML) says it is a session file (else it may be a pairs file)."""
    return isinstance(data, dict) and data.get("format") == SESSION_FORMAT


def parse_session(data: dict[str, Any], where: str, max_pairs: int = MAX_PAIRS) -> SessionData:
    """Check a session mapping and return its values.

    Parameters
    ----------
    data : dict
        The mapping read from the session file (``format: ba-calib-session``).
    where : str
        Names the file in errors.
    max_pairs : int
        Most picks accepted.

    Raises
    ------
    CalibError
        Wrong format or a newer version, a bad ``next_id``, malformed or
        duplicate picks, a ``view`` that is not a mapping.
    """
    if not is_session(data):
        raise CalibError(f"{where}: not a ba-calib session (expected 'format: {SESSION_FORMAT}')")
    version = data.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise CalibError(f"{where}: 'version' must be a whole number >= 1, got {version!r}"[:300])
    if version > SESSION_VERSION:
        raise CalibError(f"{where}: session version {version} is newer than this ba-calib reads ({SESSION_VERSION}); update ba-calib")
    entries = data.get("pairs")
    if entries is None:
        entries = []
    if not isinstance(entries, list):
        raise CalibError(f"{where}: 'pairs' must be a list")
    if len(entries) > max_pairs:
        raise CalibError(f"{where}: {len(entries):,} pairs; the cap is {max_pairs:,} pairs")
    picks = []
    seen: set[int] = set()
    for i, e in enumerate(entries):
        at = f"{where}: pair {i}"
        if not isinstance(e, dict) or "id" not in e:
            raise CalibError(f"{at}: expected a mapping with an id")
        unknown = set(e) - {"id", "laser_rc", "laser_xyz", "pixel", "source", "precision_px", "check", "shot",
                                "edge_deg"}
        if unknown:
            raise CalibError(f"{at}: unknown key(s) {sorted(map(str, unknown))}"[:300])
        pick_id = _whole(e["id"], f"{at} id", 0, MAX_ID)
        if "shot" in e:
            _whole(e["shot"], f"{at} shot", 0, MAX_ID)
        if e.get("edge_deg") is not None:  # (the app reads it back; refused here when not an angle)
            parse_edge_deg(e["edge_deg"], at)
        if pick_id in seen:
            raise CalibError(f"{at}: duplicate id {pick_id}")
        seen.add(pick_id)
        rc = None if e.get("laser_rc") is None else parse_laser_rc(e["laser_rc"], f"{at} laser_rc")
        xyz = None if e.get("laser_xyz") is None else tuple(finite_vector(e["laser_xyz"], 3, f"{at} laser_xyz", MAX_COORDINATE_M))
        px = None if e.get("pixel") is None else tuple(finite_vector(e["pixel"], 2, f"{at} pixel", MAX_PIXEL))
        picks.append(SessionPick(pick_id, rc, xyz, px))  # type: ignore[arg-type]
    next_id = data.get("next_id")
    next_id = 1 if next_id is None else _whole(next_id, f"{where}: next_id", 1, MAX_ID)
    next_id = max([next_id] + [p.id + 1 for p in picks])
    if next_id > MAX_ID:
        raise CalibError(f"{where}: pair ids reach {next_id - 1}; at most {MAX_ID - 1}")
    view = data.get("view")
    view = {} if view is None else view
    if not isinstance(view, dict):
        raise CalibError(f"{where}: 'view' must be a mapping")
    return SessionData(tuple(picks), next_id, dict(view))


def read_session_mapping(path: str | os.PathLike) -> dict[str, Any]:
    """The mapping in a session file, read within the session size limits (see :mod:`calib_core.io.yaml_files`)."""
    return read_yaml_mapping(path, "session file", max_bytes=MAX_SESSION_BYTES, max_values=1000 + VALUES_PER_PAIR * MAX_PAIRS)


def check_session_file(path: str | os.PathLike) -> None:
    """Check what the app would restore from ``path``, before it starts.

    Nothing to check when ``path`` does not exist (a new session).  A file
    saying ``format: ba-calib-session`` must pass :func:`parse_session`; any
    other file is read as a plain pairs file (the app starts from its pairs).

    Raises
    ------
    CalibError
        The file cannot be restored; one line naming it.
    """
    from ..pairs import load_pairs_yaml

    path = Path(path)
    if not path.exists():
        return
    data = read_session_mapping(path)
    if is_session(data):
        parse_session(data, str(path))
    else:
        load_pairs_yaml(path)
