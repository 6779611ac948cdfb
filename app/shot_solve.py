"""The joint solve of a session's shots, for the app (issue 21).

Each shot's pairs are resolved in that shot's own scan (:meth:`calib_core.shots.Shot.from_pairs`) and all
of them go into :func:`calib_core.shots.solve_shots`: one ``T_camera_lidar`` (lidar frame into the OpenCV
camera frame, metres) from every shot's pairs, with leave-one-shot-out and the disagreeing-shot test.
The Verify numbers of a joint solve are :func:`calib_core.verify.verify_calibration` of all shots' pairs,
a shot left out as disagreeing counted as check pairs (as :func:`calib_core.shots.shots_extrinsics_document`
does).  No maths here: grouping, calls into :mod:`calib_core`, and the text the panels show.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from calib_core.io.atomic import write_yaml_atomic, yaml_bytes
from calib_core.pairs import Pair
from calib_core.shots import Shot, ShotsResult, shots_extrinsics_document, solve_shots
from calib_core.transforms import transform_points

from .ui_common import SolveBundle, _fmt, md_escape


@dataclass(eq=False)
class JointSolve:
    """A joint solve of several shots: the result, the shots it was made of, each row's shot."""

    solved: ShotsResult
    shots: list[Shot]  # one per shot of the session, in shot order (a shot without pairs is empty)
    shot_of: np.ndarray  # (N,) int: each pair's shot (SolveBundle.pick_ids order: shot, then creation order)


def shot_name(files: Any) -> str:
    """How the app names a shot: its scan's and photo's file names."""
    return f"{Path(files.scan).name} + {Path(files.image).name}"


def by_shot(ids: Sequence[int], pairs: Sequence[Pair], shot_of: Sequence[int]) -> tuple[list, list, np.ndarray]:
    """``ids``, ``pairs`` and ``shot_of`` in the joint solve's row order: shot, then the given order."""
    order = np.argsort(np.asarray(shot_of, dtype=np.int64), kind="stable")
    return [ids[i] for i in order], [pairs[i] for i in order], np.asarray(shot_of, dtype=np.int64)[order]


def make_shots(pairs: Sequence[Pair], shot_of: np.ndarray, depths: Sequence[Any], camera: Any,
               names: Sequence[str] = (), cache: dict | None = None) -> list[Shot]:
    """One :class:`calib_core.shots.Shot` per scan of ``depths``, holding its pairs (``shot_of``: each pair's).

    ``cache`` (a dict the caller keeps) holds each shot's last resolved pairs: a click changes one shot, and
    the others' pairs are not resolved again (their scans, pairs and names are the key)."""
    out = []
    for k, depth in enumerate(depths):
        mine = [p for p, s in zip(pairs, shot_of) if s == k]
        name = names[k] if k < len(names) else f"shot {k}"
        key = (id(depth), id(camera), name, tuple(mine))
        hit = None if cache is None else cache.get(k)
        if hit is not None and hit[0] == key:
            out.append(hit[1])
            continue
        shot = Shot.from_pairs(mine, depth, camera, name=name)
        if cache is not None:
            cache[k] = (key, shot)
        out.append(shot)
    return out


def grouped_shots(app: Any, ids: Sequence[int], pairs: Sequence[Pair], shot_of: Sequence[int],
                  cache: dict | None = None) -> tuple[list, list, np.ndarray, list[Shot]]:
    """``ids``, ``pairs`` and ``shot_of`` in the joint solve's row order (:func:`by_shot`), and one
    :class:`calib_core.shots.Shot` per shot of ``app``'s session holding its pairs (:func:`make_shots`)."""
    ids, pairs, shot_of = by_shot(ids, pairs, shot_of)
    names = [shot_name(f) for f in app.state.shots]
    return ids, pairs, shot_of, make_shots(pairs, shot_of, [sc.depth for sc in app.shot_scenes], app.camera, names,
                                           cache)


def joint_bundle(app: Any, ids: Sequence[int], pairs: Sequence[Pair], shot_of: Sequence[int], *,
                 checks: bool = True, cache: dict | None = None) -> SolveBundle:
    """The live solve of every shot's pairs: a :class:`SolveBundle` whose rows are in shot order.

    The clicked pixels and moved laser points of other shots than the one shown are NaN: the panes of the
    shown shot draw only its own pairs; the table, the quality and Verify count them all.  ``checks=False``:
    the joint fit alone, shown first (never ``ok``: :data:`calib_core.shots.UNCHECKED_REASON`);
    :func:`checked_bundle` adds the shots' checks.  ``cache``: as for :func:`make_shots`.
    """
    t0 = time.perf_counter()
    ids, pairs, shot_of, shots = grouped_shots(app, ids, pairs, shot_of, cache)
    return _bundle(app, ids, pairs, shot_of, shots, solve_shots(shots, app.camera, checks=checks), t0)


def checked_bundle(app: Any, bundle: SolveBundle) -> SolveBundle:
    """``bundle`` (a joint fit of :func:`joint_bundle` with ``checks=False``) with the shots' checks:
    leave-one-shot-out and the disagreement test, which may leave a shot out and so move the pose."""
    t0 = time.perf_counter()
    joint = bundle.shots
    solved = solve_shots(joint.shots, app.camera)
    return _bundle(app, bundle.pick_ids, bundle.pairs, joint.shot_of, joint.shots, solved,
                   t0 - bundle.seconds)


def _bundle(app: Any, ids: Sequence[int], pairs: Sequence[Pair], shot_of: np.ndarray, shots: list[Shot],
            solved: ShotsResult, t0: float) -> SolveBundle:
    T = solved.result.T_camera_lidar
    points = np.concatenate([s.points_lidar for s in shots]).reshape(-1, 3)
    pixels = np.concatenate([s.pixels for s in shots]).reshape(-1, 2).copy()
    points_camera = transform_points(T, points) if len(points) else np.empty((0, 3))
    elsewhere = shot_of != app.active_shot
    pixels[elsewhere] = np.nan
    points_camera[elsewhere] = np.nan
    edges = app.scene_data.edge_points_lidar
    return SolveBundle(
        pick_ids=list(ids), pairs=list(pairs), result=solved.result, pixels=pixels, points_camera=points_camera,
        edges_camera=transform_points(T, edges) if len(edges) else np.empty((0, 3)),
        seconds=time.perf_counter() - t0, shots=JointSolve(solved, shots, shot_of),
    )


def joint_export(app: Any, joint: JointSolve) -> tuple[bytes, Path | None]:
    """Export of a joint solve: the YAML to download (camera inline), also written to ``app.output_path``
    (camera named relative to it) when set; as :meth:`app.export_panel.ExportPanel.export_extrinsics`.
    A joint fit whose shots were not checked yet is checked first (the file always has them)."""
    if not joint.solved.checked:
        joint = JointSolve(solve_shots(joint.shots, app.camera), joint.shots, joint.shot_of)
    if app.output_path is not None:
        doc, _ = shots_extrinsics_document(joint.solved, joint.shots, app.camera, base_dir=app.output_path.parent)
        write_yaml_atomic(app.output_path, doc)
    doc, _ = shots_extrinsics_document(joint.solved, joint.shots, app.camera)
    return yaml_bytes(doc), app.output_path


def shots_markdown(joint: JointSolve, active: int) -> str:
    """Verify's per-shot table: pairs, error under the joint pose, leave-one-shot-out, the disagreement test."""
    solved = joint.solved
    loso = {e.shot: e for e in solved.leave_one_shot_out}
    tests = {t.shot: t for t in solved.tests}
    lines = [f"**{len(solved.shots)} shots, one calibration.** Leave-one-shot-out: each shot's pairs under the "
             "pose fitted to the other shots alone (a scene the fit has not seen)."]
    for k in solved.disagreeing:
        lines.append(f"**Shot {k} disagrees with the others** ({md_escape(solved.shots[k].name)}): left out of the "
                     "fit. Usually its photo and scan were not taken at the same instant, or the rig moved.")
    if solved.undecided:
        lines.append("**Shots " + " and ".join(str(k) for k in solved.undecided) + " disagree**, and with two "
                     "shots it cannot be told which one is off: add a third shot.")
    rows = ["| shot | pairs | error px | left out px | left out deg | offset deg | |",
            "|---:|---:|---:|---:|---:|---:|:---|"]
    for rep in solved.shots:
        e, t = loso.get(rep.index), tests.get(rep.index)
        flag = ("disagrees, left out" if rep.index in solved.disagreeing else
                "disagrees" if rep.index in solved.undecided else "")
        shown = " (shown)" if rep.index == active else ""
        loso_px = _fmt(e.mean_px, 2) if e is not None and math.isfinite(e.mean_px) else "-"
        loso_deg = _fmt(e.mean_deg, 3) if e is not None and math.isfinite(e.mean_deg) else "-"
        offset = _fmt(t.rotation_deg, 3) if t is not None and math.isfinite(t.rotation_deg) else "-"
        err = _fmt(rep.mean_px, 2) if math.isfinite(rep.mean_px) else "-"
        rows.append(f"| {rep.index}{shown} | {rep.n_pairs} | {err} | {loso_px} | {loso_deg} | {offset} | {flag} |")
    notes = [f"Shot {e.shot}, leave-one-shot-out: {md_escape(e.note)}" for e in solved.leave_one_shot_out if e.note]
    return "  \n".join(lines) + "\n\n" + "\n".join(rows) + ("\n\n" + "  \n".join(notes) if notes else "")


def pairs_in_3d(app: Any) -> tuple[np.ndarray, list[str], np.ndarray]:
    """What the 3-D pane marks: every shot's pairs' laser points (lidar frame, metres; NaN where the cell has
    no return), their labels (the pair number; ``S<shot>·<id>`` with several shots) and shots.

    All shots share the rig's lidar frame, so every shot's pairs are drawn together: the spread the joint solve
    sees (the cloud shown is the shown shot's scan)."""
    picks = [p for p in app.state.all_picks if p.laser_rc is not None or p.laser_xyz is not None]
    several = len(app.shot_scenes) > 1
    points = np.full((len(picks), 3), np.nan)
    for i, p in enumerate(picks):  # a few tens of pairs: one lookup each
        if p.laser_xyz is not None:
            points[i] = p.laser_xyz
        elif p.shot < len(app.shot_scenes):
            depth = app.shot_scenes[p.shot].depth
            r, c = p.laser_rc
            if 0 <= r < depth.shape[0] and 0 <= c < depth.shape[1] and depth.valid[r, c]:
                points[i] = depth.points[r, c]
    labels = [f"S{p.shot}\u00b7{p.id}" if several else str(p.id) for p in picks]
    return points, labels, np.array([p.shot for p in picks], np.int64)
