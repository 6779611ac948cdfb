"""Several shots, one calibration (issue 21): accuracy against the number of shots, leave-one-shot-out
against the true error, and the disagreeing-shot detector.

One rig, several scenes: the synthetic generator's rooms for seeds 0 (the sample) to 4, all seen
with the sample's ``T_camera_lidar`` (seed 0's, the paper's Table I pose), so every shot shares
one ground truth.  A shot's pairs are simulated clicks at real corners
(:func:`calib_core.synthetic.simulate_pairs`: 1 px camera noise, whole-cell laser picks).

Run::

    python -m bench.shots            # a few minutes on 2 cores; appends nothing
    python -m bench.shots --quick    # fewer trials, for a smoke run
    python -m bench.shots --write    # also replaces the section in docs/performance.md

Frames and units: ``T_camera_lidar`` maps lidar points into the camera frame, metres; rotation
errors are the angle of ``R_true^T R_est`` in degrees.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from bench.common import BENCH_SEED, REPO, load_scenes, log, pose_error
from calib_core.shots import Shot, solve_shots
from calib_core.synthetic import simulate_pairs
from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks
from calib_core.transforms import transform_points

SEEDS = (1, 2, 3, 4)
SECTION = "## Several shots, one calibration (issue 21, `bench.shots`)"
DOC = REPO / "docs" / "performance.md"
#: Camera-side click noise of the simulated pairs, px per axis.
CLICK_PX = 1.0


@dataclasses.dataclass
class RigScene:
    """A scene seen by the common rig: the scene with the rig's ``T_camera_lidar`` and its usable corners."""

    name: str
    scene: object  # SampleScene with T_camera_lidar replaced by the rig's
    corners_lidar: np.ndarray  # corners a pick reaches and the rig's camera sees inside its image circle
    up_lidar: np.ndarray  # the world's vertical axis in this scene's lidar frame


def rig_scenes(seeds=SEEDS) -> list[RigScene]:
    """The sample and the scenes of ``seeds``, all seen with the sample's ``T_camera_lidar``."""
    from calib_core.synthetic.render import image_circle_mask
    from calib_core.synthetic.picks import CIRCLE_MARGIN_PX
    from calib_core.synthetic.sample import IMAGE_CIRCLE_RADIUS_PX

    scenes = load_scenes(tuple(seeds))
    T_rig = scenes[0].scene.T_camera_lidar
    out = []
    for bs in scenes:
        sc = dataclasses.replace(bs.scene, T_camera_lidar=T_rig.copy())
        corners = np.asarray(sc.corners_lidar, dtype=np.float64)
        pix, ok = sc.camera.project(transform_points(T_rig, corners))
        ok &= np.all(np.isfinite(pix), axis=1)
        ok[ok] &= image_circle_mask(sc.camera, pix[ok], IMAGE_CIRCLE_RADIUS_PX - CIRCLE_MARGIN_PX)
        _, err = laser_picks(sc.depth, corners)
        ok &= err <= MAX_LASER_PICK_ERROR_M
        sc = dataclasses.replace(sc, corners_lidar=corners[ok])
        up = np.linalg.inv(bs.scene.T_world_lidar[:3, :3]) @ np.array([0.0, 0.0, 1.0])
        out.append(RigScene(bs.name, sc, corners[ok], up))
    return out


def rotation_about(axis: np.ndarray, deg: float) -> np.ndarray:
    """Rotation matrix of ``deg`` degrees about the unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def make_shot(rs: RigScene, n: int, rng: np.random.Generator, rotate_deg: float = 0.0) -> Shot:
    """``n`` simulated pairs in the scene, as a shot; ``rotate_deg`` turns its scan about the vertical
    (the scan taken while the rig was turned by that much from where the photo was taken)."""
    sc = rs.scene
    pairs = simulate_pairs(sc, n, rng, pixel_noise_px=CLICK_PX)
    shot = Shot.from_pairs(pairs, sc.depth, sc.camera, name=rs.name)
    if rotate_deg:
        R = rotation_about(rs.up_lidar, rotate_deg)
        shot.points_lidar = shot.points_lidar @ R.T
        shot.laser_cov_m2 = R @ shot.laser_cov_m2 @ R.T
    return shot


def fresh_click_error(rs: RigScene, T: np.ndarray, rng: np.random.Generator) -> float:
    """True error of ``T`` on a scene: every usable corner picked anew (its whole cell) and clicked anew
    (the true projection plus 1 px noise); the mean pixel distance between the click and the cell's
    point projected with ``T``."""
    sc = rs.scene
    rc, _ = laser_picks(sc.depth, rs.corners_lidar)
    cell_points = sc.depth.points[rc[:, 0], rc[:, 1]]
    true_px, _ = sc.camera.project(transform_points(sc.T_camera_lidar, rs.corners_lidar))
    clicks = true_px + rng.normal(0.0, CLICK_PX, true_px.shape)
    est, _ = sc.camera.project(transform_points(T, cell_points))
    d = np.linalg.norm(est - clicks, axis=1)
    return float(np.nanmean(d))


# ---------------------------------------------------------------------------- parts


def accuracy_vs_shots(scenes, trials: int, rng) -> list[dict]:
    """Rotation / translation error against the number of shots, at fixed total and per-shot pair counts."""
    T_true = scenes[0].scene.T_camera_lidar
    camera = scenes[0].scene.camera
    rows = []
    plans = (("total 30 pairs", {1: 30, 2: 15, 3: 10, 5: 6}), ("10 pairs per shot", {1: 10, 2: 10, 3: 10, 5: 10}))
    for mode, counts in plans:
        for n_shots, per in counts.items():
            rot, tra = [], []
            for t in range(trials):
                order = rng.permutation(len(scenes))[:n_shots]
                shots = [make_shot(scenes[i], per, rng) for i in order]
                res = solve_shots(shots, camera).result
                e = pose_error(res.T_camera_lidar, T_true)
                rot.append(e.rotation_deg)
                tra.append(100 * e.translation_norm_m)
            rows.append({"mode": mode, "shots": n_shots, "pairs_per_shot": per, "total": per * n_shots,
                         "rot_deg": float(np.mean(rot)), "trans_cm": float(np.mean(tra)),
                         "rot_p90": float(np.percentile(rot, 90)), "trans_p90": float(np.percentile(tra, 90))})
            log(f"  {mode}: {n_shots} shots x {per} pairs: rotation {rows[-1]['rot_deg']:.3f} deg, "
                f"translation {rows[-1]['trans_cm']:.2f} cm")
    return rows


def loso_vs_truth(scenes, trials: int, rng, n_shots: int = 3, per: int = 10) -> dict:
    """Leave-one-shot-out mean px against the true error of the held-out fit on that scene (fresh clicks)."""
    camera = scenes[0].scene.camera
    loso, truth, ratio = [], [], []
    for t in range(trials):
        order = rng.permutation(len(scenes))[:n_shots]
        shots = [make_shot(scenes[i], per, rng) for i in order]
        res = solve_shots(shots, camera, detect=False)
        for e in res.leave_one_shot_out:
            if e.T_camera_lidar is None:
                continue
            true_err = fresh_click_error(scenes[order[e.shot]], e.T_camera_lidar, rng)
            loso.append(e.mean_px)
            truth.append(true_err)
            ratio.append(e.mean_px / true_err)
    loso, truth = np.array(loso), np.array(truth)
    return {"n": len(loso), "loso_mean_px": float(loso.mean()), "true_mean_px": float(truth.mean()),
            "ratio_of_means": float(loso.mean() / truth.mean()), "median_ratio": float(np.median(ratio)),
            "corr": float(np.corrcoef(loso, truth)[0, 1])}


def detector(scenes, trials: int, clean_trials: int, rng, n_shots: int = 3, per: int = 10) -> dict:
    """Hit rate with one shot's scan rotated (0.5, 1, 2 deg), and false alarms on clean shots."""
    camera = scenes[0].scene.camera
    out = {"per": per, "rotated": [], "clean": None}
    for deg in (0.5, 1.0, 2.0):
        hits = wrong = 0
        est = []
        for t in range(trials):
            order = rng.permutation(len(scenes))[:n_shots]
            bad = int(rng.integers(n_shots))
            shots = [make_shot(scenes[i], per, rng, rotate_deg=deg if k == bad else 0.0) for k, i in enumerate(order)]
            res = solve_shots(shots, camera)
            hits += res.disagreeing == [bad]
            wrong += any(k != bad for k in res.disagreeing + res.undecided)
            est += [tt.rotation_deg for tt in res.tests if tt.shot == bad and bad in res.disagreeing]
        out["rotated"].append({"deg": deg, "trials": trials, "hit_rate": hits / trials, "wrong_named": wrong / trials,
                               "estimated_deg": float(np.median(est)) if est else float("nan")})
        log(f"  {per} pairs per shot, rotated {deg} deg: named {hits}/{trials}, another shot named in {wrong}")
    alarms = 0
    t0 = time.perf_counter()
    for t in range(clean_trials):
        order = rng.permutation(len(scenes))[:n_shots]
        shots = [make_shot(scenes[i], per, rng) for i in order]
        res = solve_shots(shots, camera)
        alarms += bool(res.disagreeing or res.undecided)
    per_solve_ms = 1e3 * (time.perf_counter() - t0) / max(clean_trials, 1)
    out["clean"] = {"trials": clean_trials, "false_alarm_rate": alarms / clean_trials, "alarms": alarms,
                    "ms_per_trial": per_solve_ms}
    log(f"  {per} pairs per shot, clean: a shot named in {alarms}/{clean_trials} trials")
    return out


TWO_SCENES = REPO.parent / "shared" / "data" / "pjlab_opencalib_two_scenes"


def read_calib_txt(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """K (3x3), D (k1 k2 p1 p2) and the published ``T_camera_lidar`` (4x4, metres) from the dataset's calib.txt
    (``K: 9 numbers``, ``D: ...``, ``T: 12 numbers``, row-major ``[R | t]``), read here apart from calib_core."""
    values = {}
    for line in Path(path).read_text().splitlines():
        key, _, rest = line.partition(":")
        values[key.strip()] = np.array(rest.split(), dtype=float)
    T = np.eye(4)
    T[:3] = values["T"].reshape(3, 4)
    return values["K"].reshape(3, 3), values["D"], T


def pair_rule():
    """tools/make_real_pairs.py (a script, not a package module) as a module: its ``select_pairs`` is the fixed rule
    (foreground corners, nearest first, farthest-point in the image)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_real_pairs", REPO / "tools" / "make_real_pairs.py")
    rule = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rule)
    return rule


def load_two_scenes():
    """The PJLab two-scene data: ``[(depth, camera, T_published), ...]`` for scene1 and scene2 (each read from its
    ``calib.txt``) and tools/make_real_pairs.py's pair rule (:func:`pair_rule`); None when the data is absent."""
    from calib_core.cameras.pinhole import PinholeCamera
    from calib_core.io.scan_readers import load_scan

    if not (TWO_SCENES / "scene1" / "calib.pcd").is_file():
        return None
    rule = pair_rule()
    scenes = []
    for name in ("scene1", "scene2"):
        K, D, T = read_calib_txt(TWO_SCENES / name / "calib.txt")
        scenes.append((load_scan(TWO_SCENES / name / "calib.pcd"), PinholeCamera(K, D, 1920, 1200), T))
    return scenes, rule


def rough_pairs(scenes, rule, draw: int, n: int = 3) -> list[list]:
    """Each scene's ``n`` rough pairs of noise draw ``draw``: the first ``n`` of the rule's farthest-point order,
    pixel = the published calibration's projection + N(0, 1 px) from ``default_rng(1000 + 2 draw + scene)``."""
    from calib_core.pairs import Pair

    out = []
    for k, (depth, cam, T) in enumerate(scenes):
        entries = rule.select_pairs(depth, cam, T, 1000 + 2 * draw + k)[:n]
        out.append([Pair(tuple(e["laser_rc"]), None, tuple(e["pixel"])) for e in entries])
    return out


def pjlab_two_scenes(draws: int = 40) -> dict | None:
    """The PJLab two-scene data (one rig): 3 pairs per scene (:func:`rough_pairs`); the joint solve against the
    published T, and whether one scene alone solves.  None when the data is absent."""
    from calib_core.errors import CalibError
    from calib_core.solve import calibrate
    from calib_core.transforms import rotation_angle_deg

    loaded = load_two_scenes()
    if loaded is None:
        return None
    scenes, rule = loaded
    T_pub = scenes[0][2]
    rot, trans, alone_errors = [], [], set()
    for draw in range(draws):
        shots = []
        for (depth, cam, _), pairs in zip(scenes, rough_pairs(scenes, rule, draw)):
            try:
                calibrate(pairs, depth, cam)
            except CalibError as exc:
                alone_errors.add(str(exc))
            shots.append(Shot.from_pairs(pairs, depth, cam))
        T_est = solve_shots(shots, scenes[0][1]).result.T_camera_lidar
        rot.append(rotation_angle_deg(T_est[:3, :3], T_pub[:3, :3]))
        trans.append(100 * np.linalg.norm(T_est[:3, 3] - T_pub[:3, 3]))
    rot, trans = np.array(rot), np.array(trans)
    return {"draws": draws, "rot_median": float(np.median(rot)), "rot_max": float(rot.max()),
            "trans_median": float(np.median(trans)), "trans_max": float(trans.max()),
            "within": float(np.mean((rot <= 0.5) & (trans <= 10.0))), "alone": sorted(alone_errors)}


# ---------------------------------------------------------------------------- report


def report(acc, loso, det, command: str, seconds: float, pjlab: dict | None = None) -> str:
    lines = [SECTION, "",
             f"Command: `{command}` ({seconds:.0f} s on this 2-core machine shared with other jobs).  One rig (the "
             "sample's `T_camera_lidar`), five rooms of the synthetic generator (seeds 0-4); each shot's pairs are "
             "simulated clicks at real corners (1 px camera noise, whole-cell laser picks, corners spread by "
             "farthest-point sampling).  The joint solve is `calib_core.shots.solve_shots`.", "",
             "### Accuracy against the number of shots", "",
             "| pairs | shots | pairs per shot | mean rotation error (deg) | 90th pct (deg) | mean translation error (cm) | 90th pct (cm) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in acc:
        lines.append(f"| {r['mode']} | {r['shots']} | {r['pairs_per_shot']} | {r['rot_deg']:.3f} | {r['rot_p90']:.3f} | "
                     f"{r['trans_cm']:.2f} | {r['trans_p90']:.2f} |")
    ok = abs(loso["ratio_of_means"] - 1.0) <= 0.2
    lines += ["", "### Leave-one-shot-out against the true error", "",
              "3 shots x 10 pairs.  Leave-one-shot-out: the mean pixel error of a shot's pairs under the pose fitted "
              "to the other two shots.  True error of that held-out pose on that scene: every usable corner of the "
              "scene picked and clicked anew (whole cell, true projection + 1 px), mean pixel distance to the "
              "corner's cell projected with the held-out pose.", "",
              "| held-out shots | leave-one-shot-out mean (px) | true error mean (px) | ratio | median per-shot ratio | "
              "correlation | target (ratio within 20 %) |", "|---:|---:|---:|---:|---:|---:|---|",
              f"| {loso['n']} | {loso['loso_mean_px']:.3f} | {loso['true_mean_px']:.3f} | {loso['ratio_of_means']:.3f} | "
              f"{loso['median_ratio']:.3f} | {loso['corr']:.2f} | {'PASS' if ok else 'MISS'} |",
              "", "### The disagreeing-shot detector", "",
              "3 shots; one shot's scan turned about the vertical by the angle below (its photo and scan not taken "
              "at the same instant on a turning rig).  A hit: that shot, and only it, is named and left out.  "
              "Family-wise level 1 % (`calib_core.shots.DEFAULT_ALPHA`).  The issue's target (>= 95 % at 1 deg) is "
              "judged at 20 pairs per shot: with 10 pairs per shot on this 640 x 480 omnidirectional camera (about "
              "0.5 deg per pixel) the rotation of a 10-pair shot and of the pose fitted to the two others are each "
              "uncertain by about 0.3 deg, so 1 deg is about 3 sigma of their difference and no test at a 1 % false-"
              "alarm level can name it reliably.", "",
              "'Another shot named': a clean shot named instead of the turned one, or, after the turned one was "
              "named, the two clean shots found to disagree with each other (status unreliable).", "",
              "| pairs per shot | scan rotated | trials | hit rate | another shot named | median estimated rotation (deg) | target |",
              "|---:|---:|---:|---:|---:|---:|---|"]
    for d in det:
        for r in d["rotated"]:
            target = ""
            if r["deg"] == 1.0 and d["per"] == 20:
                target = ("PASS" if r["hit_rate"] >= 0.95 else "MISS") + " (>= 95 %)"
            lines.append(f"| {d['per']} | {r['deg']:g} deg | {r['trials']} | {100 * r['hit_rate']:.1f} % | "
                         f"{100 * r['wrong_named']:.1f} % | {r['estimated_deg']:.2f} | {target} |")
    lines += ["", "| pairs per shot | clean trials | trials with a shot named | rate | target (<= 1 %) | ms per calibration with its tests |",
              "|---:|---:|---:|---:|---|---:|"]
    for d in det:
        c = d["clean"]
        lines.append(f"| {d['per']} | {c['trials']} | {c['alarms']} | {100 * c['false_alarm_rate']:.2f} % | "
                     f"{'PASS' if c['false_alarm_rate'] <= 0.01 else 'MISS'} | {c['ms_per_trial']:.0f} |")
    lines.append("")
    lines += ["### Two PJLab road scenes, one rig (`../shared/data/pjlab_opencalib_two_scenes`)", ""]
    if pjlab is None:
        lines += ["The data was not found; nothing measured.", ""]
    else:
        ok = pjlab["within"] >= 0.95
        lines += [
            f"3 pairs per scene, laser cells by `tools/make_real_pairs.py`'s fixed rule (the first three of its "
            "farthest-point order), pixels = the published calibration's projection + N(0, 1 px), "
            f"{pjlab['draws']} noise draws (`default_rng(1000 + 2 draw + scene)`; also `tests/test_shots.py`).  "
            "The target is met by the joint solve's distribution, not by every draw: a first single draw tried "
            "while writing the test (seeds 21 and 22) came out at 0.16 deg and 11.5 cm, which is why the test "
            "and this table use many draws.  Each scene alone: "
            + "; ".join(f"`{e}`" for e in pjlab["alone"]) + ".", "",
            "| joint solve, 3 + 3 pairs | rotation median (max), deg | translation median (max), cm | "
            "within 0.5 deg and 10 cm |", "|---|---:|---:|---:|",
            f"| against the published T | {pjlab['rot_median']:.3f} ({pjlab['rot_max']:.3f}) | "
            f"{pjlab['trans_median']:.2f} ({pjlab['trans_max']:.2f}) | {100 * pjlab['within']:.0f} % "
            f"({'PASS' if ok else 'MISS'}) |", ""]
    return "\n".join(lines)


def write_section(text: str, doc: Path = DOC, section: str = SECTION) -> None:
    """Replace a benchmark's section (the ``## `` heading ``section``, this one's by default) of
    ``docs/performance.md``, or append it; the rest stays."""
    old = doc.read_text()
    if section in old:
        start = old.index(section)
        nxt = old.find("\n## ", start + len(section))
        new = old[:start] + text.rstrip() + "\n" + ("" if nxt < 0 else old[nxt:])
    else:
        new = old.rstrip() + "\n\n" + text.rstrip() + "\n"
    doc.write_text(new)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer trials (a smoke run)")
    ap.add_argument("--write", action="store_true", help="replace the section in docs/performance.md")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rng = np.random.default_rng(BENCH_SEED)
    scenes = rig_scenes()
    log(f"{len(scenes)} scenes: " + ", ".join(f"{s.name} ({len(s.corners_lidar)} corners)" for s in scenes))
    acc_trials, loso_trials, det_trials, clean_trials = (6, 10, 20, 60) if args.quick else (30, 60, 100, 1000)
    log("accuracy against the number of shots")
    acc = accuracy_vs_shots(scenes, acc_trials, rng)
    log("leave-one-shot-out against the true error")
    loso = loso_vs_truth(scenes, loso_trials, rng)
    log(f"  ratio of means {loso['ratio_of_means']:.3f} over {loso['n']} held-out shots")
    log("disagreeing-shot detector")
    det = [detector(scenes, det_trials, clean_trials, rng, per=per) for per in (10, 20)]
    log("PJLab two scenes, 3 + 3 pairs")
    pjlab = pjlab_two_scenes()
    command = "python -m bench.shots" + (" --quick" if args.quick else "") + " --write"
    text = report(acc, loso, det, command, time.perf_counter() - t0, pjlab)
    print(text)
    if args.write:
        write_section(text)
        log(f"wrote the section into {DOC}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
