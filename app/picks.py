"""Picks (pairs under construction), the undoable snapshot of them, and reading them back from a session file.

Pure Python plus numpy; no maths, no viser.
"""

from __future__ import annotations

import colorsys
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

from calib_core.errors import CalibError
from calib_core.io.yaml_files import finite_vector
from calib_core.pairs import PAIR_SOURCES, Pair, load_pairs_yaml, tag_fields

SESSION_FORMAT = "ba-calib-session"
#: Version 2 lists the shots (``shots:``) and each pick's ``shot``; version 1 (one shot) is still read.
SESSION_VERSION = 2
READABLE_VERSIONS = (1, 2)


@functools.lru_cache(maxsize=4096)  # called per pick and redraw
def pair_color(pick_id: int) -> tuple[int, int, int]:
    """A stable, well-separated RGB colour for a pick id (golden-ratio hues)."""
    hue = (0.08 + 0.61803398875 * int(pick_id)) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 1.0)
    return int(round(255 * r)), int(round(255 * g)), int(round(255 * b))


@dataclass(frozen=True)
class Pick:
    """One pair, possibly incomplete."""

    id: int  # the number on the markers (1, 2, ...); a new pick takes the one above the highest (next_number)
    laser_rc: tuple[int, int] | None = None  # depth-matrix cell (row, col), 0-based
    laser_xyz: tuple[float, float, float] | None = None  # laser point, lidar frame, metres (imported pairs only)
    pixel: tuple[float, float] | None = None  # (u, v) in the original camera image, top-left pixel's centre 0
    # How the pair was made (calib_core.pairs.PAIR_SOURCES): "clicked" (unguided), "guided" (a click on a guided
    # proposal) or "auto" (accepted without a click).
    source: str = "clicked"
    precision_px: float | None = None  # 1-sigma of the pixel in px, when known (None: the solve's default)
    check: bool = False  # a check pair: left out of the fit, its error reported apart (Verify panel)
    # The photo end lies on a straight image edge at this angle (degrees from +u towards +v): it may slide
    # along the edge; None: a corner pair (calib_core.pairs.Pair.edge_deg).
    edge_deg: float | None = None
    shot: int = 0  # the shot (scan and photo) the pick belongs to, 0-based (ShotFiles)

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
        return Pair(self.laser_rc, None if self.laser_rc is not None else self.laser_xyz, self.pixel,  # type: ignore[arg-type]
                    id=int(self.id), source=self.source, precision_px=self.precision_px,
                    check=bool(self.check), edge_deg=self.edge_deg)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": int(self.id)}
        out["laser_rc"] = None if self.laser_rc is None else [int(v) for v in self.laser_rc]
        out["laser_xyz"] = None if self.laser_xyz is None else [float(v) for v in self.laser_xyz]
        out["pixel"] = None if self.pixel is None else [float(v) for v in self.pixel]
        out.update(tag_fields(self.source, self.precision_px, self.check, edge_deg=self.edge_deg))
        out["shot"] = int(self.shot)
        return out


@dataclass(frozen=True)
class ShotFiles:
    """One shot of the session: a scan and the photo taken with it by the rig (paths as strings)."""

    scan: str
    image: str

    def to_dict(self) -> dict[str, str]:
        return {"scan": self.scan, "image": self.image}

    @classmethod
    def of(cls, scan: Any, image: Any) -> "ShotFiles":
        """The shot of these files, by absolute path (a session names the same files from any folder)."""
        return cls(str(Path(scan).absolute()), str(Path(image).absolute()))


@dataclass(frozen=True)
class Snapshot:
    """The undoable part of the state: the picks of every shot and the shots' files."""

    picks: tuple[Pick, ...] = ()
    next_id: int = 1
    shots: tuple[ShotFiles, ...] = ()


def session_shots(data: dict, where: Any) -> tuple[ShotFiles, ...]:
    """The ``shots:`` list of session ``data`` (empty for a version-1 session or a pairs file), checked."""
    entries = data.get("shots") if data.get("format") == SESSION_FORMAT else None
    if entries is None:
        return ()
    if not isinstance(entries, list):
        raise CalibError(f"{where}: 'shots' must be a list of {{scan, image}}")
    out = []
    for k, e in enumerate(entries):
        if not (isinstance(e, dict) and isinstance(e.get("scan"), str) and isinstance(e.get("image"), str)):
            raise CalibError(f"{where}: shot {k}: expected a mapping with the scan and image file names")
        out.append(ShotFiles(e["scan"], e["image"]))
    return tuple(out)


def session_data(snap: Snapshot, view: dict, active_shot: int) -> dict[str, Any]:
    """What the session file holds (plain data)."""
    return {
        "format": SESSION_FORMAT,
        "version": SESSION_VERSION,
        "next_id": int(snap.next_id),
        "shots": [s.to_dict() for s in snap.shots],
        "active_shot": int(active_shot),
        "pairs": [p.to_dict() for p in snap.picks],
        "view": view,
    }


def new_ends(checked: Sequence[Pick], existing: Sequence[Pick]) -> list[Pick]:
    """The picks of ``checked`` whose ends are not already in ``existing`` (nor earlier in ``checked``)."""
    seen = {(p.laser_rc, p.laser_xyz, p.pixel) for p in existing}
    out = []
    for p in checked:
        ends = (p.laser_rc, p.laser_xyz, p.pixel)
        if ends not in seen:  # an exact duplicate adds nothing
            seen.add(ends)
            out.append(p)
    return out


def pick_tags(entry: dict, where: str) -> dict[str, Any]:
    """The ``source``, ``precision_px`` and ``edge_deg`` of a session entry, checked (absent: the defaults)."""
    out: dict[str, Any] = {}
    source = entry.get("source", "clicked")
    if source not in PAIR_SOURCES:
        raise CalibError(f"{where}: source must be one of {', '.join(PAIR_SOURCES)}, got {source!r}")
    out["source"] = source
    if entry.get("precision_px") is not None:
        (sigma,) = finite_vector([entry["precision_px"]], 1, f"{where} precision_px")
        if not 0.0 < sigma <= 1000.0:
            raise CalibError(f"{where}: precision_px must be a positive number of pixels, got {sigma}")
        out["precision_px"] = float(sigma)
    if entry.get("edge_deg") is not None:
        (deg,) = finite_vector([entry["edge_deg"]], 1, f"{where} edge_deg")
        out["edge_deg"] = float(deg) % 180.0
    return out


def checked_picks(pairs: Sequence[Pair], check_cell: Callable, check_pixel: Callable) -> list[Pick]:
    """The picks ``pairs`` would become (id -1 where the pair has none); CalibError names the first bad pair."""
    checked = []
    for i, p in enumerate(pairs):
        name = f"imported pair {i}" if p.id is None else f"imported pair {p.id}"
        try:
            rc = None if p.laser_rc is None else check_cell(*p.laser_rc)
            xyz = None if p.laser_xyz is None else tuple(finite_vector(p.laser_xyz, 3, "laser_xyz"))
            if rc is None and xyz is None:
                raise CalibError("no laser end")
            uv = check_pixel(*p.pixel)
        except CalibError as exc:
            raise CalibError(f"{name}: {exc}") from None
        checked.append(Pick(-1 if p.id is None else int(p.id), laser_rc=rc, laser_xyz=None if rc is not None else xyz,
                            pixel=uv, source=p.source, precision_px=p.precision_px, check=bool(p.check),
                            edge_deg=p.edge_deg))
    return checked


def restore_session(data: dict, path: Path, check_cell: Callable, check_pixel: Callable, n_shots: int = 1
                    ) -> tuple[Snapshot, dict | None]:
    """The picks (and view settings, None for a plain pairs file) of session ``data`` read from ``path``.

    ``check_cell(row, col, shot=k)`` and ``check_pixel(u, v)`` raise CalibError for ends not of that shot's
    scene; ``n_shots`` is how many shots there are (a pick's ``shot`` must be below it).  The snapshot's
    ``shots`` are the session's (empty for a version-1 session or a pairs file: they hold one shot).
    """
    if data.get("format") != SESSION_FORMAT:
        # A plain pairs file given as the session: start from its pairs.
        pairs = load_pairs_yaml(path)
        file_ids = [p.id for p in pairs]
        keep_ids = None not in file_ids and len(set(file_ids)) == len(file_ids)
        picks = []
        for i, p in enumerate(pairs):
            try:
                if p.laser_rc is not None:
                    check_cell(*p.laser_rc, shot=0)
                check_pixel(*p.pixel)
            except CalibError as exc:
                raise CalibError(f"{path}: pair {i}: {exc} (pairs from another scene?)") from None
            # The file's ids when every pair has a distinct one: one id in the UI, files and messages.
            pid = p.id if keep_ids else i + 1
            picks.append(Pick(pid, laser_rc=p.laser_rc, laser_xyz=p.laser_xyz, pixel=p.pixel, source=p.source,
                              precision_px=p.precision_px, check=bool(p.check), edge_deg=p.edge_deg))
        return Snapshot(tuple(picks), max([len(picks)] + [p.id for p in picks]) + 1), None
    if data.get("version") not in READABLE_VERSIONS:
        raise CalibError(f"{path}: session version {data.get('version')!r} is not supported "
                         f"(this ba-calib reads versions {', '.join(map(str, READABLE_VERSIONS))})")
    shots = session_shots(data, path)
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
        except (TypeError, ValueError, OverflowError):
            raise CalibError(f"{where}: id must be an integer") from None
        rc = e.get("laser_rc")
        xyz = e.get("laser_xyz")
        px = e.get("pixel")
        rc_f = None if rc is None else finite_vector(rc, 2, f"{where} laser_rc")
        if rc_f is not None and any(float(v) != round(float(v)) for v in rc_f):
            raise CalibError(f"{where}: laser_rc must be two integers (row, column), got {list(rc)}")
        rc_t = None if rc_f is None else tuple(int(round(float(v))) for v in rc_f)
        xyz_t = None if xyz is None else tuple(finite_vector(xyz, 3, f"{where} laser_xyz"))
        px_t = None if px is None else tuple(finite_vector(px, 2, f"{where} pixel"))
        shot = e.get("shot", 0)
        if isinstance(shot, bool) or not isinstance(shot, int) or not 0 <= shot < n_shots:
            raise CalibError(f"{where}: shot must be a shot number from 0 to {n_shots - 1}, got {shot!r}")
        # A session written for another scene must not inject invalid picks.
        try:
            if rc_t is not None:
                check_cell(*rc_t, shot=shot)
            if px_t is not None:
                check_pixel(*px_t)
        except CalibError as exc:
            raise CalibError(f"{where}: {exc} (session from another scene?)") from None
        check = e.get("check", False)
        if not isinstance(check, bool):
            raise CalibError(f"{where}: check must be true or false, got {check!r}")
        picks.append(Pick(pick_id, rc_t, xyz_t, px_t, check=check, shot=shot, **pick_tags(e, where)))  # type: ignore[arg-type]
    ids = [p.id for p in picks]
    if len(set(ids)) != len(ids):
        raise CalibError(f"{path}: duplicate pair ids")
    try:
        next_id = max([int(data.get("next_id") or 1)] + [i + 1 for i in ids])
    except (TypeError, ValueError, OverflowError):
        raise CalibError(f"{path}: next_id must be an integer, got {data.get('next_id')!r}") from None
    view = data.get("view") or {}
    if not isinstance(view, dict):
        raise CalibError(f"{path}: 'view' must be a mapping")
    return Snapshot(tuple(picks), next_id, shots), dict(view)


def next_number(picks: Sequence[Pick]) -> int:
    """The number a new pick gets: one more than the highest existing one (1 when there is none).

    So a pick that was started and then dropped or undone (a declined guided
    proposal) leaves no gap: the next pair made gets its number.  Deleting a
    pair below the highest keeps the others' numbers (and colours) as they are.
    """
    return max((int(p.id) for p in picks), default=0) + 1


def joins_newest_step(undo: Sequence[Snapshot], current: Snapshot, new: Snapshot) -> bool:
    """Does the change ``current`` -> ``new`` join the newest undo step ``undo[-1]`` instead of making its own?

    Yes for a re-click of a half-made pair's end (its laser cell or pixel clicked again, the pair still
    incomplete) when the newest step made or changed only that half pair: one undo then drops the half pair,
    not each re-click in turn.
    """
    changed = set(current.picks) ^ set(new.picks)
    ids = {p.id for p in changed}
    if (not undo or len(ids) != 1 or any(p.complete for p in changed) or len(current.picks) != len(new.picks)
            or not current.shots == new.shots == undo[-1].shots):
        return False
    (pick_id,) = ids
    before = undo[-1].picks
    return not any(p.complete for p in before if p.id == pick_id) and (
        [p for p in before if p.id != pick_id] == [p for p in current.picks if p.id != pick_id])


def amends_newest_step(undo: Sequence[Snapshot], current: Snapshot, new: Snapshot, pick_id: int) -> bool:
    """Does the change ``current`` -> ``new`` of pick ``pick_id`` finish the newest undo step instead of making its own?

    Yes when neither that step nor this change touched any other pick: the guide setting a guided click's
    precision right after the click moved the pixel (run 5: one Ctrl+Z took back only the precision, a second
    the pixel).  One undo then takes back the click and its tags together.
    """
    if not undo or not current.shots == new.shots == undo[-1].shots:
        return False
    def others(snap: Snapshot) -> list[Pick]:
        return [p for p in snap.picks if p.id != pick_id]
    return others(undo[-1]) == others(current) == others(new)
