"""The solve against OpenCV, side by side in one run, on identical pairs (issue 12).

``python -m bench.solve_vs_opencv [--quick] [--out FILE]`` prints the tables and
writes them as markdown (default ``docs/perf/solve_vs_opencv.md``).
``python -m bench.solve_vs_opencv --only-speed`` measures the speed section alone (seconds) and
replaces that section in the existing report, saying when and at what load it was measured;
the other sections keep the figures of their own run.

Sections
--------
1. **JIT**: numba compile time of every solve kernel (fresh cache directory,
   in a subprocess) and the start-up with a warm cache (second subprocess).
2. **Speed**: pinhole (1280x960, f = 640 px, OpenCV's model) and the sample's
   OCam camera, n = 10 / 100 / 1000 pairs.  Per trial the same pairs go to

   * ``solve_extrinsics`` -- the whole public solve: input checks, whitening
     (one ``camera.project``), DLT start, compiled LM, outlier check,
     covariance, quality verdict, pixel residuals (one more ``camera.project``);
   * the same with a laser-point covariance per pair (``laser_cov_m2``, 1 cm
     per axis): what the app and ``calibrate()`` pass for whole-cell picks (the
     LM re-whitens at each pose it tries until near the optimum, in the same
     compiled call: ``fit_pose_laser``);
   * OpenCV ``solvePnP(SOLVEPNP_SQPNP)`` + ``solvePnPRefineLM`` (pinhole only:
     OpenCV has no OCam model).

   Methods alternate within each trial so that load changes hit all alike;
   figures are medians.  The robust search is timed separately, with 10 %
   gross outliers.
3. **Accuracy**: simulated clicks (``simulate_pairs``: 1 px clicks, whole-cell
   laser picks) on the sample scene.  Pinhole variant (``bench.compare``):
   ours vs OpenCV on the same pairs.  OCam: ours vs the Cramer-Rao bound of
   ``bench.crb`` with the laser term (the realistic bound).
4. **Sigma coverage**: the share of trials whose error lies within the
   reported 1 sigma and 2 sigma, per parameter (nominal 68.3 % and, as the Student-t
   widened sigma of 10 pairs puts it, 94.3 %: :func:`bench.common.sigma_coverage`).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np


from .common import BENCH_SEED, REPO, log, sigma_coverage

PIN_SIZE = (1280, 960)
PIN_F = 640.0
PARAMS = ("roll", "pitch", "yaw", "tx", "ty", "tz")
#: The coverage checks, in report order (see :func:`coverage`).
COVERAGE_MODELS = ("clicks only", "model laser", "realistic")
#: Trials per noise model of the coverage check: the binomial standard error of a 68 % share is
#: 1.5 points at 1000 trials (2.7 at 300, as large as the +-3 point tolerance).
COVERAGE_TRIALS = 1000
#: Trials per held-out scene of the pooled checks (20 scenes: 2000 trials).
COVERAGE_TRIALS_PER_SCENE = 100
#: Trials per held-out scene and n of the pooled accuracy check (20 scenes: 400 per n).  The mean
#: error's standard error is about 2.5 % of it at 400 trials (5 % at 100, as wide as the target's margin).
POOLED_TRIALS_PER_SCENE = 20


# ------------------------------------------------------------------ JIT
_JIT_SNIPPET = (
    "import time; t0 = time.perf_counter(); import calib_core.solve as s; t1 = time.perf_counter(); "
    "w = s.warm_up(); t2 = time.perf_counter(); w2 = s.warm_up(); "
    "print(f'{t1 - t0:.4f} {w:.4f} {w2:.4f}')"
)


def jit_times() -> dict:
    """Import, first warm-up (compile or cache load) and second warm-up, cold cache then warm cache."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="ba-calib-numba-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(REPO))
        for label in ("cold cache (compile)", "warm cache"):
            proc = subprocess.run([sys.executable, "-c", _JIT_SNIPPET], capture_output=True, text=True, env=env,
                                  cwd=REPO, timeout=900)
            if proc.returncode != 0:
                raise RuntimeError(proc.stderr)
            imp, first, second = (float(x) for x in proc.stdout.split())
            out[label] = (imp, first, second)
    return out


# ------------------------------------------------------------------ speed
def pinhole_camera():
    from calib_core.cameras import PinholeCamera

    w, h = PIN_SIZE
    K = np.array([[PIN_F, 0.0, (w - 1) / 2.0], [0.0, PIN_F, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return PinholeCamera(K, np.zeros(5), w, h)


def random_pairs(camera, n: int, rng: np.random.Generator, T: np.ndarray, noise_px: float = 1.0):
    """Pixels spread over the image (inside its valid rays), points 2-15 m deep, clicks with 1 px noise."""
    px, brg = np.empty((0, 2)), np.empty((0, 3))
    while len(px) < n:
        cand = np.column_stack([rng.uniform(10, camera.width - 10, 2 * n), rng.uniform(10, camera.height - 10, 2 * n)])
        b = camera.bearing(cand)
        ok = np.isfinite(b).all(axis=1)
        px, brg = np.concatenate([px, cand[ok]]), np.concatenate([brg, b[ok]])
    px, brg = px[:n], brg[:n]
    pc = brg * rng.uniform(2.0, 15.0, (n, 1))
    pl = (pc - T[:3, 3]) @ T[:3, :3]
    clicked = px + rng.normal(0.0, noise_px, px.shape)
    return np.ascontiguousarray(pl), np.ascontiguousarray(camera.bearing(clicked)), clicked


def _opencv(camera, pl, px):
    ok, rvec, tvec = cv2.solvePnP(pl, px, camera.K, camera.dist, flags=cv2.SOLVEPNP_SQPNP)
    if ok:
        rvec, tvec = cv2.solvePnPRefineLM(pl, px, camera.K, camera.dist, rvec, tvec)
    return ok, rvec, tvec


def _clock(fn, reps: int) -> tuple[float, float]:
    """Median wall time and median CPU time of this process (seconds) over ``reps`` calls.

    On a shared machine a call that spans several scheduler time slices is
    preempted by other jobs, which inflates its wall time; the process's CPU
    time (``time.process_time``, all threads) is not, so it is the fairer figure.
    """
    wall, cpu = [], []
    for _ in range(reps):
        c0 = time.process_time()
        t0 = time.perf_counter()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu))


def speed(quick: bool) -> list[dict]:
    from calib_core.solve import solve_extrinsics
    from calib_core.synthetic import load_sample

    rows = []
    T = np.eye(4)
    T[:3, 3] = [0.1, -0.05, 0.2]
    cams = [("pinhole", pinhole_camera()), ("OCam (sample)", load_sample(REPO / "sample_data").camera)]
    for cam_name, cam in cams:
        for n in (10, 100, 1000):
            # Many short trials: a median over few of them moved by 50 % between runs on this shared machine.
            trials = (4 if quick else 40) if n < 1000 else (3 if quick else 16)
            reps = 7 if n < 1000 else 5
            rng = np.random.default_rng([BENCH_SEED, 12, n])
            t: dict = {k: [] for k in ("full", "norobust", "laser", "opencv", "robust")}
            laser_cov = np.broadcast_to(1e-4 * np.eye(3), (n, 3, 3))
            for _ in range(trials):
                pl, brg, px = random_pairs(cam, n, rng, T)
                t["full"].append(_clock(lambda: solve_extrinsics(pl, brg, camera=cam, pixels=px), reps))
                t["norobust"].append(_clock(lambda: solve_extrinsics(pl, brg, camera=cam, pixels=px, robust=False), reps))
                t["laser"].append(_clock(lambda: solve_extrinsics(pl, brg, camera=cam, pixels=px,
                                                                  laser_cov_m2=laser_cov), reps))
                if cam_name == "pinhole":
                    t["opencv"].append(_clock(lambda: _opencv(cam, pl, px), reps))
                # 10 % gross outliers (at least one): stray clicks 30-80 px off.
                bad = rng.choice(n, max(1, n // 10), replace=False)
                px_bad = px.copy()
                px_bad[bad] += rng.choice([-1, 1], (len(bad), 2)) * rng.uniform(30, 80, (len(bad), 2))
                brg_bad = cam.bearing(px_bad)
                inside = (px_bad >= 0).all(axis=1) & (px_bad[:, 0] <= cam.width - 1) & (px_bad[:, 1] <= cam.height - 1)
                good = np.isfinite(brg_bad).all(axis=1) & inside  # strays that left the image are dropped
                t["robust"].append(_clock(lambda: solve_extrinsics(pl[good], brg_bad[good], camera=cam,
                                                                   pixels=px_bad[good]), max(1, reps - 2)))
            row = {"camera": cam_name, "n": n, "trials": trials}
            for k, v in t.items():
                arr = np.array(v) if v else np.full((1, 2), np.nan)
                row[k], row[k + "_wall"] = float(np.median(arr[:, 1])), float(np.median(arr[:, 0]))
            rows.append(row)
            log(f"  speed {cam_name} n={n} (CPU time): full {1e3 * row['full']:.3f} ms, robust=False "
                f"{1e3 * row['norobust']:.3f} ms, laser term {1e3 * row['laser']:.3f} ms, "
                f"opencv {1e3 * row['opencv']:.3f} ms, robust (10 % outliers) {1e3 * row['robust']:.3f} ms; wall: "
                f"full {1e3 * row['full_wall']:.3f}, laser term {1e3 * row['laser_wall']:.3f}, "
                f"opencv {1e3 * row['opencv_wall']:.3f}")
    return rows


# ------------------------------------------------------------------ accuracy
def accuracy(quick: bool) -> tuple[list[dict], list[dict]]:
    from calib_core.errors import CalibError
    from calib_core.pairs import resolve_pairs
    from calib_core.solve import calibrate, solve_extrinsics
    from calib_core.synthetic import simulate_pairs
    from calib_core.transforms import transform_points

    from .common import load_scenes, pose_error
    from .compare import pinhole_variant
    from .crb import cell_pick_covariance, cramer_rao, mean_error_of_bound

    trials = 20 if quick else 100
    scenes = load_scenes(())
    omni = scenes[0]
    pin = pinhole_variant(omni)
    pin_rows, omni_rows = [], []
    rng_b = np.random.default_rng(0)
    from calib_core.transforms import rpy_deg_from_R

    rpy_true = rpy_deg_from_R(omni.scene.T_camera_lidar[:3, :3])
    for n in (6, 10, 20, 50):
        errs: dict = {"ours": [], "opencv": [], "ours_omni": [], "bound": [], "ours_clicks": [], "bound_clicks": []}
        for k in range(trials):
            # Pinhole: the same pairs to both.
            # The 90 deg pinhole view holds 40 corners of the sample, some sharing a depth cell: at most 30 pairs.
            n_pin = min(n, 30)
            if n_pin >= 6:
                pairs = simulate_pairs(pin.scene, n_pin, np.random.default_rng([BENCH_SEED, 77, n, k]),
                                       pixel_noise_px=1.0)
                pts, _, px = resolve_pairs(pairs, pin.scene.depth, pin.scene.camera)
                try:
                    res = calibrate(pairs, pin.scene.depth, pin.scene.camera)
                    e = pose_error(res.T_camera_lidar, pin.scene.T_camera_lidar)
                    errs["ours"].append((e.rotation_deg, e.translation_norm_m))
                except CalibError:
                    errs["ours"].append((np.nan, np.nan))
                ok, rvec, tvec = _opencv(pin.scene.camera, np.ascontiguousarray(pts), np.ascontiguousarray(px))
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
                e = pose_error(T, pin.scene.T_camera_lidar)
                errs["opencv"].append((e.rotation_deg, e.translation_norm_m) if ok else (np.nan, np.nan))
            # OCam: ours against the realistic Cramer-Rao bound of the same pairs.
            pairs = simulate_pairs(omni.scene, n, np.random.default_rng([BENCH_SEED, 78, n, k]), pixel_noise_px=1.0)
            res = calibrate(pairs, omni.scene.depth, omni.scene.camera)
            e = pose_error(res.T_camera_lidar, omni.scene.T_camera_lidar)
            errs["ours_omni"].append((e.rotation_deg, e.translation_norm_m))
            rc = np.array([p.laser_rc for p in pairs])
            pts = omni.scene.depth.points[rc[:, 0], rc[:, 1]]
            bound = cramer_rao(omni.scene.camera, omni.scene.T_camera_lidar, pts, 1.0,
                               cell_pick_covariance(omni.scene.depth, rc))
            errs["bound"].append(mean_error_of_bound(bound.covariance, rpy_true, rng_b, 1000 if quick else 4000))
            # Clicks only: the picked cells' points are the laser points (exact), clicks = their true
            # projections + 1 px noise; the bound without a laser term.  Tests the estimator alone.
            crng = np.random.default_rng([BENCH_SEED, 81, n, k])
            uv, ok = omni.scene.camera.project(transform_points(omni.scene.T_camera_lidar, pts))
            clicked = uv + crng.normal(0.0, 1.0, uv.shape)
            b = omni.scene.camera.bearing(clicked)
            if ok.all() and np.isfinite(b).all():
                res = solve_extrinsics(pts, b, camera=omni.scene.camera, pixels=clicked)
                e = pose_error(res.T_camera_lidar, omni.scene.T_camera_lidar)
                errs["ours_clicks"].append((e.rotation_deg, e.translation_norm_m))
                bound0 = cramer_rao(omni.scene.camera, omni.scene.T_camera_lidar, pts, 1.0, None)
                errs["bound_clicks"].append(mean_error_of_bound(bound0.covariance, rpy_true, rng_b,
                                                                1000 if quick else 4000))
        m = {k: np.nanmean(np.array(v), axis=0) if v else np.array([np.nan, np.nan]) for k, v in errs.items()}
        fails = int(np.sum(np.isnan(np.array(errs["ours"])[:, 0]))) if errs["ours"] else 0
        pin_rows.append({"n": min(n, 30), "trials": len(errs["ours"]), "fails": fails, "ours": m["ours"],
                         "opencv": m["opencv"]})
        omni_rows.append({"n": n, "trials": trials, "ours": m["ours_omni"], "bound": m["bound"],
                          "clicks_trials": len(errs["ours_clicks"]), "ours_clicks": m["ours_clicks"],
                          "bound_clicks": m["bound_clicks"]})
        log(f"  accuracy n={n}: pinhole ours {m['ours'][0]:.4f} deg {100 * m['ours'][1]:.3f} cm vs opencv "
            f"{m['opencv'][0]:.4f} deg {100 * m['opencv'][1]:.3f} cm; OCam ours {m['ours_omni'][0]:.4f} deg "
            f"{100 * m['ours_omni'][1]:.3f} cm vs bound {m['bound'][0]:.4f} deg {100 * m['bound'][1]:.3f} cm; "
            f"clicks only: ours/bound {m['ours_clicks'][0] / m['bound_clicks'][0]:.3f} (rot), "
            f"{m['ours_clicks'][1] / m['bound_clicks'][1]:.3f} (trans)")
    return pin_rows, omni_rows


def pooled_accuracy(quick: bool, per_scene: int = POOLED_TRIALS_PER_SCENE) -> list[dict]:
    """Realistic picks on the held-out scenes (seeds 4-23): ours against the Cramer-Rao bound, pooled.

    The sample's rows above reuse one scan, whose pick errors are fixed, so its ratio to the bound
    scatters with that scan's particular errors; here each n takes ``per_scene`` trials on each of
    20 scans that the pick model was not fitted to (``simulate_pairs``, ``calibrate``, the bound
    with the package's pick model for each trial's cells).
    """
    from calib_core.errors import CalibError
    from calib_core.solve import calibrate
    from calib_core.synthetic import simulate_pairs
    from calib_core.transforms import rpy_deg_from_R

    from .common import load_scenes, pose_error
    from .crb import cell_pick_covariance, cramer_rao, mean_error_of_bound
    from .pick_model import HELD_OUT_SEEDS

    seeds = HELD_OUT_SEEDS[:2] if quick else HELD_OUT_SEEDS
    scenes = load_scenes(tuple(seeds))[1:]
    rng_b = np.random.default_rng(1)
    rows = []
    for n in (6, 10, 20, 50):
        ours, bound, fails = [], [], 0
        for si, bs in enumerate(scenes):
            sc = bs.scene
            rpy_true = rpy_deg_from_R(sc.T_camera_lidar[:3, :3])
            for k in range(2 if quick else per_scene):
                pairs = simulate_pairs(sc, n, np.random.default_rng([BENCH_SEED, 82, n, si, k]), pixel_noise_px=1.0)
                try:
                    res = calibrate(pairs, sc.depth, sc.camera)
                except CalibError:
                    fails += 1
                    continue
                e = pose_error(res.T_camera_lidar, sc.T_camera_lidar)
                ours.append((e.rotation_deg, e.translation_norm_m))
                rc = np.array([p.laser_rc for p in pairs])
                b = cramer_rao(sc.camera, sc.T_camera_lidar, sc.depth.points[rc[:, 0], rc[:, 1]], 1.0,
                               cell_pick_covariance(sc.depth, rc))
                bound.append(mean_error_of_bound(b.covariance, rpy_true, rng_b, 1000 if quick else 4000))
        rows.append({"n": n, "trials": len(ours), "fails": fails, "scenes": len(scenes),
                     "ours": np.mean(ours, axis=0), "bound": np.mean(bound, axis=0)})
        r = rows[-1]
        log(f"  pooled accuracy n={n} ({r['trials']} trials on {len(scenes)} held-out scenes): ours "
            f"{r['ours'][0]:.4f} deg {100 * r['ours'][1]:.3f} cm vs bound {r['bound'][0]:.4f} deg "
            f"{100 * r['bound'][1]:.3f} cm")
    return rows


def laser_model_check() -> tuple[float, float, int]:
    """RMS (m) of the real whole-cell laser pick error across the camera's line of sight, against the
    RMS the bound's laser model (the package's pick model, ``cell_pick_covariance``) predicts; over every
    corner of the sample with a pick.  A bound whose model understates the error cannot be reached."""
    from calib_core.synthetic.picks import laser_picks

    from .common import load_scenes
    from .crb import cell_pick_covariance

    sc = load_scenes(())[0].scene
    rc, err = laser_picks(sc.depth, sc.corners_lidar)
    ok = np.isfinite(err)
    rc, corners = rc[ok], sc.corners_lidar[ok]
    R, t = sc.T_camera_lidar[:3, :3], sc.T_camera_lidar[:3, 3]
    u = corners @ R.T + t
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    across = np.eye(3)[None] - u[:, :, None] * u[:, None, :]  # projector across the line of sight
    d = (sc.depth.points[rc[:, 0], rc[:, 1]] - corners) @ R.T
    actual = np.einsum("nij,nj->ni", across, d)
    S = np.einsum("ij,njk,lk->nil", R, cell_pick_covariance(sc.depth, rc), R)
    modelled = np.einsum("nij,njk,nkl->nil", across, S, across)
    return (float(np.sqrt(np.mean(np.sum(actual**2, axis=1)))),
            float(np.sqrt(np.mean(np.trace(modelled, axis1=1, axis2=2)))), int(ok.sum()))


# ------------------------------------------------------------------ coverage
def coverage(quick: bool, n: int = 10) -> dict:
    """Share of trials within the reported 1 and 2 sigma, per parameter, OCam scenes, n pairs.

    Three noise models, each with its own trials:

    * *clicks only* -- the sample; the picked cells' points taken as exact, clicks = their true
      projections + 1 px noise, solved with ``solve_extrinsics``: the estimator's sigma alone.
    * *model laser* -- the held-out scenes (seeds 4-23, not used to fit the pick model), 1 px
      clicks, each laser point the true corner plus a draw of the pick model's Gaussian: the full
      noise the reported sigma assumes (:func:`bench.pick_model.coverage`, ``laser="model"``).
    * *realistic* -- the same scenes and clicks with the careful whole-cell picks themselves
      (``simulate_pairs``), solved with ``calibrate``: what a user meets.  Pooled over the scenes,
      because one scan's pick errors are fixed and its trials reuse its corners.
    """
    from calib_core.pairs import resolve_pairs
    from calib_core.solve import solve_extrinsics
    from calib_core.synthetic import simulate_pairs
    from calib_core.transforms import transform_points

    from .common import load_scenes, within_sigma
    from .pick_model import HELD_OUT_SEEDS
    from .pick_model import coverage as pooled_coverage

    trials = 60 if quick else COVERAGE_TRIALS
    sc = load_scenes(())[0].scene
    T_true = sc.T_camera_lidar
    out = {"n": n}
    within = np.zeros((2, 6))
    used = 0
    for k in range(trials):
        rng = np.random.default_rng([BENCH_SEED, 80, n, k])
        pairs = simulate_pairs(sc, n, rng, pixel_noise_px=1.0)
        pts, _, _ = resolve_pairs(pairs, sc.depth, sc.camera)
        uv, ok = sc.camera.project(transform_points(T_true, pts))
        clicked = uv + rng.normal(0.0, 1.0, uv.shape)
        b = sc.camera.bearing(clicked)
        if not (ok.all() and np.isfinite(b).all()):
            continue
        res = solve_extrinsics(pts, b, camera=sc.camera, pixels=clicked)
        if res.quality.status == "unreliable":
            continue
        within += within_sigma(res, T_true)
        used += 1
    out["clicks only"] = {"trials": used, "one": within[0] / used, "two": within[1] / used, "where": "the sample"}
    seeds = HELD_OUT_SEEDS[:2] if quick else HELD_OUT_SEEDS
    per_scene = 30 if quick else COVERAGE_TRIALS_PER_SCENE
    where = f"seeds {seeds[0]}-{seeds[-1]}, {per_scene} trials each"
    for key, laser in (("model laser", "model"), ("realistic", "picks")):
        out[key] = dict(pooled_coverage(seeds, per_scene, n, laser=laser), where=where)
    return out


# ------------------------------------------------------------------ report
def _vs_bound(ours, bound) -> str:
    """Four table cells: rotation (deg) ours / bound, ratio, translation (cm) ours / bound, ratio."""
    return (f"{ours[0]:.4f} / {bound[0]:.4f} | {ours[0] / bound[0]:.3f} | {100 * ours[1]:.3f} / {100 * bound[1]:.3f} | "
            f"{ours[1] / bound[1]:.3f}")


def worst_ratio(rows, ours: str = "ours", bound: str = "bound") -> float:
    """The largest ratio, rotation or translation, of ``row[ours]`` to ``row[bound]`` over ``rows``."""
    return max(max(r[ours][0] / r[bound][0], r[ours][1] / r[bound][1]) for r in rows)


def markdown(jit, sp, pin_rows, omni_rows, cov, load, quick, cmd, laser=None, pooled_rows=()) -> str:
    L = ["# Solve against OpenCV (issue 12)\n",
         f"Generated by `{cmd}` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
         f"OpenCV {cv2.__version__}, numpy {np.__version__}. "
         f"Load average (1 min) {load[0]:.1f} at the start and {load[1]:.1f} at the end on "
         f"{os.cpu_count()} cores shared with other jobs: absolute times are noisy; the methods alternate "
         "within each trial, so their ratios are fairer than the absolute figures. All times are medians.\n"]
    if quick:
        L.append("> **Quick run**: few trials; a smoke test, not the reference.\n")
    L.append("## JIT compile and start-up\n")
    L.append("| cache | import calib_core.solve | first warm_up() | second warm_up() |\n|---|---:|---:|---:|")
    for label, (imp, first, second) in jit.items():
        L.append(f"| {label} | {imp:.2f} s | {first:.2f} s | {1e3 * second:.2f} ms |")
    L.append("\n`warm_up()` compiles (cold cache) or loads (warm cache, `cache=True`) every solve kernel; the app "
             "calls it in a background thread at start so that no click waits for a compile.\n")
    L += speed_section(sp)
    L.append("\n## Accuracy on the pinhole variant: ours vs OpenCV, same pairs\n")
    L.append("Mean rotation error (deg) and translation error (cm) against the ground truth; ours = `calibrate` "
             "(whitened angular cost with the laser-pick term, robust). Pairs: `simulate_pairs` on the sample's pinhole "
             "variant (`bench.compare.pinhole_variant`: 1280x960, f = 640 px, at the true pose); its view holds 40 "
             "corners, some of which share a depth cell, so the largest n is 30. *fails*: trials our solve refused "
             "(CalibError).\n")
    L.append("| n | trials | fails | ours rot | OpenCV rot | ratio | ours trans | OpenCV trans | ratio |\n"
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in pin_rows:
        o, c = r["ours"], r["opencv"]
        L.append(f"| {r['n']} | {r['trials']} | {r['fails']} | {o[0]:.4f} | {c[0]:.4f} | {o[0] / c[0]:.3f} | {100 * o[1]:.3f} | "
                 f"{100 * c[1]:.3f} | {o[1] / c[1]:.3f} |")
    L.append("\n## Accuracy on the OCam sample: ours vs the Cramer-Rao bound\n")
    L.append("*realistic*: `simulate_pairs` (1 px clicks, whole-cell laser picks) solved with `calibrate`; bound: "
             "`bench.crb.cramer_rao` at the true pose for each trial's pairs, 1 px clicks plus the package's laser "
             "pick model (`cell_pick_covariance`, the one the solve whitens with). *clicks only*: the same picked cells' points "
             "as exact laser points, clicks = their true projections + 1 px noise, solved with `solve_extrinsics`; "
             "bound without a laser term. Mean errors of a bound by sampling its Gaussian.\n")
    L.append("| n | trials | realistic: ours rot / bound | ratio | ours trans / bound (cm) | ratio | clicks only: "
             "trials | ours rot / bound | ratio | ours trans / bound (cm) | ratio |\n"
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in omni_rows:
        o, b, oc, bc = r["ours"], r["bound"], r["ours_clicks"], r["bound_clicks"]
        L.append(f"| {r['n']} | {r['trials']} | {_vs_bound(o, b)} | {r['clicks_trials']} | {_vs_bound(oc, bc)} |")
    if pooled_rows:
        r0 = pooled_rows[0]
        L.append(f"\n**Realistic picks pooled over {r0['scenes']} held-out scenes** (seeds 4-23, none used to fit the "
                 f"pick model; `pooled_accuracy`): the same check on scans other than the sample, "
                 f"{r0['trials'] // r0['scenes']} trials on each, because one scan's pick errors are fixed and its "
                 "ratio to the bound scatters with them.\n")
        L.append("| n | trials | fails | ours rot / bound | ratio | ours trans / bound (cm) | ratio |\n"
                 "|---:|---:|---:|---:|---:|---:|---:|")
        for r in pooled_rows:
            o, b = r["ours"], r["bound"]
            L.append(f"| {r['n']} | {r['trials']} | {r['fails']} | {_vs_bound(o, b)} |")
    if laser is not None:
        L.append(f"\nThe laser pick model against the sample's real pick error: across the camera's line of sight "
                 f"the whole-cell picks of the sample's {laser[2]} pickable corners are off by {100 * laser[0]:.2f} cm "
                 f"RMS, the model predicts {100 * laser[1]:.2f} cm. The clicks-only rows, where the bound's noise "
                 "model is the data's by construction, test the estimator alone.\n")
    one_nom, two_nom = sigma_coverage(cov["n"])
    L.append(f"\n## Sigma coverage (OCam scenes, n = {cov['n']})\n")
    L.append("Share of trials whose error is within the reported sigma (Student-t widened, see "
             f"`CalibrationResult.sigma_rpy_deg`). Nominal: {100 * one_nom:.1f} % and {100 * two_nom:.1f} %: the "
             f"sigma is widened by the Student-t factor of {2 * cov['n'] - 6} degrees of freedom so that 1 sigma covers "
             "68.27 %, and 2 such sigmas then cover the t distribution's share, less than the normal 95.45 % "
             "(`bench.common.sigma_coverage`). Tolerance of the target +-3 points "
             f"({100 * one_nom - 3:.1f}-{100 * one_nom + 3:.1f} % and {100 * two_nom - 3:.1f}-{100 * two_nom + 3:.1f} %). "
             "1 px clicks in all three. *clicks only*: the sample, the picked cells' "
             "points as exact laser points, clicks = their true projections + 1 px noise (`solve_extrinsics`): the "
             "estimator's sigma alone. *model laser*: the held-out scenes (seeds 4-23, none used to fit the pick "
             "model), each laser point the true corner plus a draw of the pick model's Gaussian "
             "(`cell_pick_covariance`), solved with that covariance: the noise the sigma assumes. *realistic*: the "
             "same scenes, corners and clicks with the careful whole-cell picks themselves (`simulate_pairs`, "
             "`calibrate`), what a user meets; pooled over the scenes because one scan's pick errors are fixed and "
             "its trials reuse its corners (per-scene shares below); every scene and trial draws its own random "
             "stream. Binomial standard error of a share over "
             f"{cov.get('realistic', {}).get('trials', 0)} independent trials: "
             f"{100 * np.sqrt(0.683 * 0.317 / max(cov.get('realistic', {}).get('trials', 1), 1)):.1f} points at 1 sigma "
             f"and {100 * np.sqrt(0.954 * 0.046 / max(cov.get('realistic', {}).get('trials', 1), 1)):.1f} at 2 sigma; "
             "trials that share a scan's pick errors (realistic) are less independent than that.\n")
    L.append("| noise | scenes | trials | | " + " | ".join(PARAMS) + " |\n|---|---|---:|---|" + "---:|" * 6)
    for model in COVERAGE_MODELS:
        c = cov.get(model)
        if not c:
            continue
        for i, label in ((0, "within 1 sigma"), (1, "within 2 sigma")):
            vals = c["one"] if i == 0 else c["two"]
            L.append(f"| {model} | {c.get('where', '')} | {c['trials']} | {label} | "
                     + " | ".join(f"{100 * v:.1f} %" for v in vals) + " |")
    for model in ("realistic", "model laser"):
        c = cov.get(model)
        if c and c.get("scenes"):
            L.append(f"\nPer scene, {model} (within 1 sigma / within 2 sigma, %):\n")
            L.append("| scene | trials | " + " | ".join(PARAMS) + " |\n|---|---:|" + "---|" * 6)
            for name, used, one, two in c["scenes"]:
                L.append(f"| {name} | {used} | " + " | ".join(f"{100 * a:.1f} / {100 * b:.1f}" for a, b in zip(one, two))
                         + " |")
    return "\n".join(L) + "\n"


SPEED_HEADING = "## Speed, same pairs to every method"


def speed_section(sp: list[dict]) -> list[str]:
    """The markdown lines of the speed section (heading included)."""
    L = [f"{SPEED_HEADING}\n"]
    L.append("Median CPU time of this process per solve (`time.process_time`: not inflated when other jobs preempt "
             "us); the median wall times follow in brackets.\n")
    L.append("*whole*: the public `solve_extrinsics(points, bearings, camera=, pixels=)` with its defaults: input "
             "checks, whitening, DLT start, LM, the outlier test (the robust LO-MSAC search runs only when a residual "
             "exceeds the threshold: never on these clean pairs), covariance, quality verdict, pixel residuals. "
             "*robust=False*: the same without the outlier test. *with `laser_cov_m2`*: the same with a laser-point "
             "covariance per pair (1 cm per axis), as the app and `calibrate()` pass for whole-cell picks (the LM "
             "re-whitens at each pose it tries until near the optimum, in its one compiled call). *10 % outliers*: the whole solve on pairs with 10 % "
             "stray clicks (30-80 px off), where the robust search runs and finds them.\n")
    L.append("| camera | n | trials | `solve_extrinsics` (whole) | robust=False | with `laser_cov_m2` (as the app) | "
             "OpenCV SQPnP + RefineLM | whole / OpenCV | with laser / OpenCV | whole, 10 % outliers (robust search) |")
    L.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in sp:
        def ms(k):
            return f"{1e3 * r[k]:.3f} ms ({1e3 * r[k + '_wall']:.3f})" if np.isfinite(r[k]) else "n/a (no OCam model)"
        ratio_full = r["full"] / r["opencv"] if np.isfinite(r["opencv"]) else float("nan")
        ratio_laser = r["laser"] / r["opencv"] if np.isfinite(r["opencv"]) else float("nan")
        L.append(f"| {r['camera']} | {r['n']} | {r['trials']} | {ms('full')} | {ms('norobust')} | {ms('laser')} | "
                 f"{ms('opencv')} | "
                 f"{ratio_full:.2f} | {ratio_laser:.2f} | {ms('robust')} |")
    return L


def replace_speed_section(md: str, sp: list[dict], load: tuple[float, float], cmd: str) -> str:
    """``md`` (a whole report) with its speed section measured anew; the other sections as they were."""
    start = md.index(SPEED_HEADING)
    end = md.find("\n## ", start + len(SPEED_HEADING))
    end = len(md) if end < 0 else end + 1
    L = speed_section(sp)
    L.insert(1, f"This section alone was measured anew by `{cmd}` on "
                f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} (load average (1 min) {load[0]:.1f} at the "
                f"start and {load[1]:.1f} at the end, {os.cpu_count()} shared cores); the other sections are from the "
                "run named at the top.\n")
    return md[:start] + "\n".join(L) + "\n\n" + md[end:].lstrip("\n")


def run(quick: bool, skip=()) -> dict:
    """Every section; ``{"jit", "speed", "pin_rows", "omni_rows", "coverage", "laser", "load"}``."""
    load0 = os.getloadavg()[0]
    from calib_core.solve import warm_up

    log(f"warm_up: {warm_up():.2f} s")
    out = {"jit": {} if "jit" in skip else jit_times()}
    log(f"jit: {out['jit']}")
    out["speed"] = [] if "speed" in skip else speed(quick)
    out["pin_rows"], out["omni_rows"] = ([], []) if "accuracy" in skip else accuracy(quick)
    out["pooled_rows"] = [] if "accuracy" in skip else pooled_accuracy(quick)
    out["laser"] = laser_model_check()
    out["coverage"] = {"n": 10} if "coverage" in skip else coverage(quick)
    for model in COVERAGE_MODELS:
        if model in out["coverage"]:
            c = out["coverage"][model]
            log(f"coverage {model} ({c['trials']} trials): 1 sigma {np.round(100 * c['one'], 1)}, "
                f"2 sigma {np.round(100 * c['two'], 1)}")
    out["load"] = (load0, os.getloadavg()[0])
    return out


def write(res: dict, quick: bool, out: Path, cmd: str) -> str:
    md = markdown(res["jit"], res["speed"], res["pin_rows"], res["omni_rows"], res["coverage"], res["load"], quick,
                  cmd, res.get("laser"), res.get("pooled_rows", ()))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(md)
    log(f"wrote {out}")
    return md


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.solve_vs_opencv", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--skip", nargs="*", default=[], choices=["jit", "speed", "accuracy", "coverage"])
    p.add_argument("--only-speed", action="store_true",
                   help="measure the speed section alone and replace it in the existing report (--out or the default)")
    args = p.parse_args(argv)
    out = args.out or (REPO / "bench" / "out" / "quick" / "solve_vs_opencv.md" if args.quick
                       else REPO / "docs" / "perf" / "solve_vs_opencv.md")
    if args.only_speed:
        from calib_core.solve import warm_up

        warm_up()
        load0 = os.getloadavg()[0]
        sp = speed(args.quick)
        cmd = "python -m bench.solve_vs_opencv --only-speed" + (" --quick" if args.quick else "")
        md = replace_speed_section(out.read_text(), sp, (load0, os.getloadavg()[0]), cmd)
        out.write_text(md)
        log(f"wrote the speed section of {out}")
        print("\n".join(speed_section(sp)))
        return 0
    res = run(args.quick, args.skip)
    cmd = "python -m bench.solve_vs_opencv" + (" --quick" if args.quick else "")
    print(write(res, args.quick, out, cmd))
    return 0


if __name__ == "__main__":
    sys.exit(main())
