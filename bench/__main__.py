"""``python -m bench``: run every benchmark and write docs/performance.md + docs/perf/*.png.

Options: ``--quick`` (fewer trials and repeats, a smoke run), ``--out DIR``
(where performance.md and perf/ go; default docs/, or bench/out/quick/ with
``--quick`` so a smoke run never overwrites the reference report), ``--seeds`` (extra
generated scenes besides the committed sample; generated once and cached in
bench/out/).
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


from . import startup
from .common import REPO, fmt_ms, log, sigma_coverage

#: Pair counts of the side-by-side comparison (a subset of the accuracy sweep, to keep the run short).
COMPARE_N = (4, 6, 10, 15, 20)


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _commit() -> str:
    try:
        h = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True)
        return h.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _kept_sections(path: Path) -> str:
    """The sections other benchmarks write into ``path`` themselves (``python -m bench.shots --write`` and the
    like, whose titles name their module): kept as they are, since this run does not re-measure them."""
    if not path.exists():
        return ""
    kept, keep = [], False
    for line in path.read_text().splitlines(keepends=True):
        if line.startswith("## "):
            keep = "`bench.shots" in line
        if keep:
            kept.append(line)
    return ("\n" + "".join(kept)) if kept else ""


def _status(ok: bool) -> str:
    return "PASS" if ok else "**MISS**"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer trials and repeats (smoke run, about a minute)")
    p.add_argument("--out", type=Path, default=None,
                   help="output folder (default: docs/; with --quick: bench/out/quick/, git-ignored)")
    p.add_argument("--seeds", type=int, nargs="*", default=None,
                   help="extra generated scenes (default: 1 2 3; --quick: 1)")
    p.add_argument("--no-guide", action="store_true",
                   help="skip the guided-picking benchmark (its own report, docs/guide_performance.md)")
    p.add_argument("--workers", type=int, default=2,
                   help="processes for the accuracy trials (default 2); speed is always timed in one process")
    args = p.parse_args(argv)
    if not args.quick:
        try:
            import matplotlib  # noqa: F401  (the committed report carries its plots)
        except ImportError:
            print("python -m bench: the full report needs matplotlib for its plots; "
                  "run `pip install -e .[bench]` first (or use --quick)", file=sys.stderr)
            return 2

    import os

    import cv2

    from . import accuracy, compare, organize, report, solve_vs_opencv, speed, startup
    from .common import load_scenes

    t_start = time.perf_counter()
    load_start = os.getloadavg()[0]
    quick = args.quick
    seeds = tuple(args.seeds) if args.seeds is not None else ((1,) if quick else (1, 2, 3))
    trials = 8 if quick else 50
    n_values = (4, 6, 8, 10, 14, 20) if quick else accuracy.N_VALUES
    crb_sets, crb_draws = (2, 40) if quick else (5, 100)
    out = (args.out or (REPO / "bench" / "out" / "quick" if quick else REPO / "docs")).resolve()
    perf = out / "perf"
    perf.mkdir(parents=True, exist_ok=True)

    log(f"ba-calib benchmarks ({'quick' if quick else 'full'} run), writing {out}")
    log("loading scenes ...")
    scenes = load_scenes(seeds)
    names = [s.name for s in scenes]
    log(f"scenes: {', '.join(names)}")

    # ---------------------------------------------------------- accuracy
    log(f"accuracy: n = {n_values[0]}..{n_values[-1]}, {trials} trials each, {len(scenes)} scenes")
    trials_in = accuracy.make_trials(scenes, n_values, trials, workers=args.workers)
    compare_n = tuple(n for n in COMPARE_N if n in n_values)
    omni_res, _ = accuracy.run_accuracy(scenes, trials_in, methods=("angular", "pixel"), workers=args.workers,
                                        method_n_values={"pixel": compare_n})

    log(f"Cramer-Rao check: {crb_sets} sets x {crb_draws} draws of pure click noise, plus the n = 10 trials")
    real10 = [t for t in trials_in if t.scene_index == 0 and t.n == 10]
    crb_rows = accuracy.cramer_rao_check(
        scenes[0], crb_sets, crb_draws, 10, real10,
        {m: omni_res[(0, 10, m)] for m in ("angular", "pixel")}, workers=args.workers,
    )

    # ---------------------------------------------------------- compare
    log("comparison on the pinhole variants ...")
    pin_scenes = [compare.pinhole_variant(s) for s in scenes]
    for s in pin_scenes:
        log(f"  {s.name}: {len(s.scene.corners_lidar)} corners in the pinhole view")
    pin_trials = compare.make_pinhole_trials(pin_scenes, compare_n, trials)
    pin_res, _ = compare.run_pinhole(pin_scenes, pin_trials, workers=args.workers)
    log("solve times per method, interleaved in one process ...")
    per_n = 6 if quick else 12
    omni_times = compare.interleaved_times(scenes, [t for t in trials_in if t.n in compare_n], ("angular", "pixel"),
                                           per_n)
    pin_times = compare.interleaved_times(pin_scenes, pin_trials, ("angular", "pixel", "opencv"), per_n)

    # ---------------------------------------------------------- speed
    log("speed ...")
    sp = speed.run_speed(scenes[0], quick=quick)
    log("organising clouds (KITTI, 2 M points) ...")
    org = organize.run(quick=quick)
    log("solve against OpenCV, OCam accuracy against the bound, sigma coverage (bench.solve_vs_opencv) ...")
    vs = solve_vs_opencv.run(quick)
    vs_md = solve_vs_opencv.write(vs, quick, perf / "solve_vs_opencv.md",
                                  "python -m bench" + (" --quick" if quick else ""))
    log("start-up: ba-calib on the sample to its first page (bench.startup) ...")
    try:
        su = startup.startup(runs=2 if quick else 3)
    except (RuntimeError, TimeoutError, OSError) as exc:
        log(f"  start-up failed: {exc}")
        su = None

    # ---------------------------------------------------------- targets (issue 12)
    s10 = report.pooled(omni_res, [0], 10, "angular")
    pure = [r for r in crb_rows if r.label.startswith("pure") and r.method == "angular"][0]
    targets = issue12_targets(sp, vs, su)
    log("profiling the missed speed targets ...")
    profiles = {}
    for label, _, _, ok, step, _ in targets:
        if ok or step is None:
            continue
        if step == "click":
            for title, text in sp.click_profiles.items():
                profiles[f"{label}: {title}"] = text
        elif step in sp.steps:
            profiles[label] = speed.profile_text(sp.steps[step], runs=3 if "colorize" in step else 10)

    # ---------------------------------------------------------- plots
    log("plots ...")
    have_plots = report.plot_fig6_fig7(perf / "fig6_translation.png", perf / "fig7_rotation.png", omni_res, scenes[0].scene, n_values)
    report.plot_errors_vs_n(perf / "errors_vs_n.png", omni_res, names, n_values, floor=pure.floor)
    report.plot_compare(perf / "compare.png", omni_res, range(len(scenes)), pin_res, range(len(pin_scenes)), compare_n,
                        omni_times, pin_times)
    report.plot_crb(perf / "crb.png", crb_rows)

    # ---------------------------------------------------------- markdown
    run_s = time.perf_counter() - t_start
    md = _markdown(
        quick=quick, scenes=scenes, pin_scenes=pin_scenes, n_values=n_values, trials=trials, omni_res=omni_res,
        pin_res=pin_res, omni_times=omni_times, pin_times=pin_times, per_n=per_n, compare_n=compare_n,
        crb_rows=crb_rows, crb_sets=crb_sets, crb_draws=crb_draws, sp=sp, targets=targets,
        profiles=profiles, have_plots=have_plots, run_s=run_s, cv2_version=cv2.__version__, cores=os.cpu_count(),
        load=(load_start, os.getloadavg()[0]), vs_md=vs_md,
    )
    md += "\n" + organize.markdown(org)
    md += _kept_sections(out / "performance.md")
    (out / "performance.md").write_text(md)
    log(f"wrote {out / 'performance.md'} and {perf}/*.png in {run_s:.0f} s")

    # ---------------------------------------------------------- guided picking (its own section file)
    from . import guide

    if args.no_guide:
        print()
        print(_targets_table(targets))
        return 0
    g_res = guide.run(scenes, 2 if quick else 7, args.workers, real_trials=3 if quick else 10)
    (out / "guide_performance.md").write_text(guide.markdown(g_res, scenes, "python -m bench" + (" --quick" if quick else "")) + "\n")
    log(f"wrote {out / 'guide_performance.md'}")
    print()
    print(_targets_table(targets))
    print()
    print(report.table_one(scenes[0].scene, s10))
    return 0


def _ms(s: float) -> str:
    return f"{1e3 * s:.3f} ms"


PARAM_NAMES = ("roll", "pitch", "yaw", "tx", "ty", "tz")


def issue12_targets(sp, vs: dict, su: dict | None) -> list[tuple]:
    """Rows ``(target, required, measured, ok, profile step or None, note)`` of issue 12's targets."""
    from .solve_vs_opencv import COVERAGE_MODELS, worst_ratio

    rows: list[tuple] = []
    by = {(r["camera"], r["n"]): r for r in vs["speed"]}
    for n, limit in ((10, 1e-4), (100, 2e-4), (1000, 1e-3)):
        r = by.get(("pinhole", n))
        if r is None:
            continue
        ratio = r["full"] / r["opencv"]
        rows.append((f"solve, pinhole, n = {n} (whole `solve_extrinsics`)", f"<= {_ms(limit)}, <= 1.0x OpenCV",
                     f"{_ms(r['full'])} = {ratio:.2f}x OpenCV ({_ms(r['opencv'])}); robust=False {_ms(r['norobust'])}",
                     r["full"] <= limit and ratio <= 1.0, None, "CPU-time medians, same pairs, same run"))
    for n, limit in ((10, 1.5e-4), (1000, 1.5e-3)):
        r = by.get(("OCam (sample)", n))
        if r is not None:
            rows.append((f"solve, OCam, n = {n}", f"<= {_ms(limit)}", _ms(r["full"]), r["full"] <= limit, None, ""))
    pin = vs["pin_rows"]
    if pin:
        worst = max(max(r["ours"][0] / r["opencv"][0], r["ours"][1] / r["opencv"][1]) for r in pin)
        rows.append(("accuracy, pinhole: mean errors / OpenCV's, n = " + ", ".join(str(r["n"]) for r in pin),
                     "<= 1.02", f"worst {worst:.3f}", worst <= 1.02, None, "rotation and translation"))
    omni = vs["omni_rows"]
    if omni:
        real = worst_ratio(omni)
        clicks = worst_ratio(omni, "ours_clicks", "bound_clicks")
        ns = ", ".join(str(r["n"]) for r in omni)
        rows.append((f"accuracy, OCam, realistic picks on the sample: mean errors / Cramer-Rao bound, n = {ns}", "<= 1.05",
                     f"worst {real:.3f}", real <= 1.05, None,
                     "the laser pick model fitted to ground truth (bench/pick_model.py); the pick errors are fixed "
                     "per corner of the one scene, so ratios scatter on both sides of 1"))
        pooled = vs.get("pooled_rows") or []
        if pooled:
            worst = worst_ratio(pooled)
            rows.append((f"accuracy, OCam, realistic picks on {pooled[0]['scenes']} held-out scenes: / bound, "
                         f"n = {', '.join(str(r['n']) for r in pooled)}", "<= 1.05", f"worst {worst:.3f}",
                         worst <= 1.05, None, f"{pooled[0]['trials']} trials per n, {pooled[0]['trials'] // pooled[0]['scenes']} on each scene (seeds 4-23, "
                         "not used to fit the pick model)"))
        rows.append((f"accuracy, OCam, clicks only (exact laser points): / bound, n = {ns}", "<= 1.05",
                     f"worst {clicks:.3f}", clicks <= 1.05, None, "the estimator alone"))
    for label, key, limit in (("BA images, 4 directions, 128x2048", "128x2048", 2e-3),
                              ("BA images, 4 directions, 64x1800", "64x1800", 1e-3)):
        t = sp.get("ba", key).median_s
        rows.append((label, f"<= {_ms(limit)}", _ms(t), t <= limit, f"ba {key}", ""))
    t = sp.get("colorize", "1M points").median_s
    rows.append(("colorize 1M points with the occlusion test", "<= 30 ms", f"{1e3 * t:.1f} ms", t <= 0.03,
                 "colorize 1M", ""))
    t = sp.get("click", "click to updated error and overlays").median_s
    rows.append(("server-side click to updated error and overlays", "<= 10 ms", f"{1e3 * t:.1f} ms", t <= 0.01,
                 "click", ""))
    cov = vs["coverage"]
    notes = {
        "clicks only": "the sample; exact laser points: the estimator's sigma alone",
        "model laser": "held-out scenes, laser errors drawn from the pick model: the noise the sigma assumes",
        "realistic": "held-out scenes, the whole-cell picks themselves, pooled over the scenes (one scan's pick "
                     "errors are fixed); per scene in the coverage section",
    }
    for model in COVERAGE_MODELS:
        c = cov.get(model)
        if not c:
            continue
        one_nominal, two_nominal = sigma_coverage(cov["n"])
        d1 = 100 * (c["one"] - one_nominal)
        d2 = 100 * (c["two"] - two_nominal)
        worst1, worst2 = d1[np.argmax(np.abs(d1))], d2[np.argmax(np.abs(d2))]
        rows.append((f"sigma coverage, {model}, n = {cov['n']}, {c['trials']} trials, 6 parameters",
                     f"1 and 2 sigma within +-3 points of {100 * one_nominal:.1f} / {100 * two_nominal:.1f} %",
                     f"1 sigma worst {worst1:+.1f} ({PARAM_NAMES[int(np.argmax(np.abs(d1)))]}), "
                     f"2 sigma worst {worst2:+.1f} ({PARAM_NAMES[int(np.argmax(np.abs(d2)))]})",
                     bool(np.abs(d1).max() <= 3 and np.abs(d2).max() <= 3), None,
                     f"{notes[model]}; binomial standard error {100 * np.sqrt(0.683 * 0.317 / c['trials']):.1f} "
                     "points at 1 sigma; + = sigma too wide (conservative), - = too narrow"))
    if su is not None:
        warm = float(np.median(su["warm_s"]))
        rows.append(("start-up: `ba-calib` on the sample serves its first page, warm numba cache",
                     f"<= {startup.TARGET_S:g} s", f"{warm:.2f} s (cold cache {su['cold_s']:.1f} s)",
                     warm <= startup.TARGET_S, None,
                     f"load {su['load'][0]:.1f} -> {su['load'][1]:.1f}"))
    return rows


def _targets_table(targets) -> str:
    lines = ["| target | required | measured | status | note |", "|---|---|---|---|---|"]
    for label, req, meas, ok, _, floor in targets:
        lines.append(f"| {label} | {req} | {meas} | {_status(ok)} | {floor} |")
    return "\n".join(lines)


def _markdown(*, quick, scenes, pin_scenes, n_values, trials, omni_res, pin_res, omni_times, pin_times, per_n,
              compare_n, crb_rows, crb_sets, crb_draws, sp,
              targets, profiles, have_plots, run_s, cv2_version, cores, load, vs_md) -> str:
    from . import report
    from calib_core.solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M

    from .accuracy import RANGE_NOISE_M
    from .compare import PINHOLE_F_PX, PINHOLE_SIZE

    idx_all = list(range(len(scenes)))
    s10 = report.pooled(omni_res, [0], 10, "angular")
    s10_all = report.pooled(omni_res, idx_all, 10, "angular")
    img = (lambda name, alt: f"![{alt}](perf/{name})\n") if have_plots else (lambda name, alt: "*(plots skipped: matplotlib is not installed; `pip install -e .[bench]`)*\n")
    L: list[str] = []
    a = L.append
    a("# Performance and accuracy\n")
    a("Generated by `python -m bench" + (" --quick" if quick else "") + "` (bench/) -- do not edit by hand. "
      f"Commit `{_commit()}`, {time.strftime('%Y-%m-%d')}, {_cpu()} ({cores} cores, shared), Python "
      f"{platform.python_version()}, numpy {np.__version__}, OpenCV {cv2_version}. Whole run: {run_s:.0f} s. "
      f"Load average (1 min) {load[0]:.1f} at the start and {load[1]:.1f} at the end: other jobs shared the cores.\n")
    if quick:
        a("> **Quick run**: few trials and repeats; numbers are a smoke test, not the reference.\n")
    took = "" if quick else f"{max(1, round(run_s / 60))} min here; "
    a("Reproduce with `pip install -e .[bench]` then `python -m bench` (" + took + "the first run also generates "
      "the 23 extra scenes (seeds 1-3 for accuracy, 4-23 held out for the sigma coverage), about 20-35 s each, "
      "cached in bench/out/). `python -m bench --quick` is a smoke run of "
      "about a minute and a half.\n")

    a("## Targets (issue 12)\n")
    a(_targets_table(targets) + "\n")
    a("Solve times are medians of the CPU time of this process per call (`time.process_time`, not inflated when "
      "other jobs preempt us; wall times are in the solve-against-OpenCV section), with OpenCV timed in the same "
      "run on the same pairs. Other speed figures are wall-time medians.\n")
    a("Speed figures are medians of repeated single-process runs on the machine above, shared with other jobs "
      "(the *fastest* column in the speed tables shows the least disturbed run). "
      "Accuracy figures are against the exact ground truth of the synthetic sample.\n")
    pure = [r for r in crb_rows if r.label.startswith("pure") and r.method == "angular"][0]
    from .crb import bound_table

    bt = {r["n"]: r for r in bound_table(ns=(10, 30, 50, 125), starts=10)}
    b10, ball = bt[10], bt[max(bt)]
    a("**What accuracy the data allow.** Issue 5's targets (0.1 deg, 1 cm at 10 pairs) are below what any unbiased "
      f"estimator can reach with 10 pairs and 1 px clicks on this camera: one pixel of the sample's 640x480 OCam image is about "
      f"{1e3 * pure.noise_rad:.1f} mrad ({np.degrees(pure.noise_rad):.2f} deg) at the clicked corners. The "
      "Cramer-Rao bound (`python -m bench.crb`), for 10 corners spread by farthest-point sampling, gives mean errors "
      f"of {b10['exact'][0]:.3f} deg and {100 * b10['exact'][1]:.2f} cm with exact laser points, and "
      f"**{b10['cell'][0]:.3f} deg and {100 * b10['cell'][1]:.2f} cm with the whole-cell laser pick** (the pick model "
      "fitted to ground truth: 0.37 cells along the rows and 0.52 along the columns across the beam, 1.5 cm along it), which is what a user clicking cells gets; the laser term alone (noise-free clicks) gives "
      f"{b10['laser only'][0]:.3f} deg and {100 * b10['laser only'][1]:.2f} cm. The estimator itself wastes nothing: "
      "its spread matches the bound (the Cramer-Rao row, PASS). More pairs help less than 1/sqrt(n) promises, "
      f"because added corners are less spread than the first ones: even all {ball['n']} corners of the scene give "
      f"{ball['exact'][0]:.3f} deg / {100 * ball['exact'][1]:.2f} cm (exact laser) and {ball['cell'][0]:.3f} deg / "
      f"{100 * ball['cell'][1]:.2f} cm (whole-cell laser), so 0.1 deg is out of reach on this scene with 1 px clicks "
      "and whole-cell picks at any n. It takes more precise clicks and laser picks (e.g. sub-pixel corners), or a "
      "camera with a finer angular resolution.\n")
    a("Cramer-Rao mean errors on the sample, 1 px clicks (rotation / translation; `python -m bench.crb`):\n")
    a("| n | exact laser | whole-cell laser pick (pick model) | laser term alone |\n|---:|---|---|---|")
    for r in bt.values():
        a(f"| {r['n']} | " + " | ".join(f"{r[k][0]:.3f} deg / {100 * r[k][1]:.2f} cm"
                                     for k in ("exact", "cell", "laser only")) + " |")
    a("")

    a("## Accuracy against the number of pairs (paper Fig. 6, Fig. 7, Table I)\n")
    a(f"Scenes: the committed sample (`sample_data/`, seed 0, the paper's Table I pose) and generated seeds "
      f"{', '.join(s.name.split()[-1] for s in scenes[1:]) or '(none)'} (`ba-calib sample --seed N`). For every scene, "
      f"n = {n_values[0]} .. {n_values[-1]} pairs, {trials} trials each. Each trial is "
      "`calib_core.synthetic.simulate_pairs`: corners of the scene seen by both sensors, chosen spread over the view "
      "(farthest-point sampling from a random first corner); the camera click is the true projection plus 1 px "
      "Gaussian noise per axis; the laser pick is a whole depth-matrix cell (the valid cell among the 3x3 around the "
      f"corner's beam whose measured point is nearest the corner), whose point carries the scan's {100 * RANGE_NOISE_M:.0f} cm "
      "range noise. Solved with `solve_extrinsics(..., cost=\"angular\")` (linear DLT start, or Quan-Lan / P3P for "
      "n < 6; compiled LM on eq. 7 with each residual whitened by the camera's pixel-to-angle Jacobian; gross "
      "outliers searched for by LO-MSAC over P3P).\n")
    a("Errors are estimate minus truth of `T_camera_lidar` (translation = the lidar origin in the camera frame; "
      "roll, pitch, yaw of R = Rz(yaw) Ry(pitch) Rx(roll)). *Rotation error* is the angle of R_true^T R_est; "
      "*translation error* the norm of the translation difference. Two pixel errors: the **reprojection residual at "
      "the clicked pairs** (what the paper's Table I reports, it contains the 1 px click noise itself) and the **pixel "
      "error against ground truth**: the mean image distance between the projections of about "
      f"{len(scenes[0].check_points_lidar)} scan points under "
      "the estimated and the true pose (what a user sees as misalignment of the overlays).\n")
    a("### Table I: n = 10 pairs, sample scene\n")
    a(f"Our estimate, {s10.trials} trials ({s10.failures} failed):\n")
    a(report.table_one(scenes[0].scene, s10) + "\n")
    a("The paper's Table I (real rig, 10 pairs, 10 trials, no ground truth: sigma is the spread of the estimates): "
      "T = (0.207, 0.042, 0.139) m with sigma (0.05, 0.017, 0.005) m; roll, pitch, yaw = (0.64, -1.24, 166.95) deg with "
      "sigma (0.21, 0.85, 1.08) deg; pixel error 1.6 +/- 1.2 px (640x480 omnidirectional image). The sample uses the "
      "same pose as ground truth.\n")
    a(f"All {len(scenes)} scenes pooled at n = 10: rotation error {s10_all.rot_err_mean:.4f} deg (p95 "
      f"{s10_all.rot_err_p95:.4f}), translation error {100 * s10_all.trans_err_mean:.3f} cm (p95 "
      f"{100 * s10_all.trans_err_p95:.3f}), pixel error vs truth {s10_all.gt_px_mean:.3f} px, residual "
      f"{s10_all.residual_px_mean:.2f} +/- {s10_all.residual_px_std:.2f} px.\n")
    a(img("fig6_translation.png", "Fig. 6: translation vs n"))
    a(img("fig7_rotation.png", "Fig. 7: rotation vs n"))
    a(img("errors_vs_n.png", "errors vs n, all scenes"))
    a("### Error against ground truth vs n (sample scene)\n")
    a(report.error_vs_n_table(omni_res, [0], n_values, "angular") + "\n")
    a(f"### Error against ground truth vs n (all {len(scenes)} scenes pooled)\n")
    a(report.error_vs_n_table(omni_res, idx_all, n_values, "angular") + "\n")
    fails = sorted({m for k, v in omni_res.items() for r in v if not r.ok for m in [r.message]})
    if fails:
        a("Solver refusals (CalibError) seen: " + "; ".join(f"`{m}`" for m in fails[:6]) + "\n")

    a("## Cramer-Rao check\n")
    a("The bound is computed in bench/crb.py, independently of the solver, for the pose parameters "
      "(roll, pitch, yaw, T_x, T_y, T_z) of `T_camera_lidar` at the true pose: F = sum_i J_i^T S_i^-1 J_i with J_i "
      "the derivative of the projected pixel of laser point i (central differences of `camera.project`, so the OCam "
      "model's non-uniform resolution is included) and S_i the pixel covariance of pair i. Two noise models:\n")
    a(f"1. **Pure click noise** (the bound the target refers to): S_i = (1 px)^2 I. The laser points are exact (the "
      f"points of the picked cells themselves), the clicks are their true projections plus 1 px Gaussian noise; "
      f"{crb_sets} fixed sets of 10 pairs on the sample x {crb_draws} noise draws each. Here the bound is the exact "
      "first-order bound, so an efficient estimator's spread must match it.\n"
      f"2. **Realistic picking** (the n = 10 trials above): S_i = (1 px)^2 I + J_X S_L J_X^T, where S_L models the "
      f"laser pick (`calib_core.solve.whiten.cell_pick_covariance`, the model the solve and the guide use): "
      f"{PICK_CELL_SIGMA[0]} cells 1-sigma along the row axis and {PICK_CELL_SIGMA[1]} along the column axis (a cell = the beam's angular step times the range) "
      f"plus ({100 * PICK_RANGE_SIGMA_M:.1f} cm)^2 along the beam, fitted to the picks' errors against the true corners "
      f"of the sample and seeds 1-3 (`python -m bench.pick_model`), mapped to pixels by "
      "J_X = d pixel / d X. This is a Gaussian stand-in for the real laser error, which is neither Gaussian nor "
      "independent between trials: a corner's picked cell and its range noise are fixed in the scan, and the "
      "farthest-point sampling reuses the same corners in many trials.\n")
    a("Columns: empirical sigma (spread about the mean), empirical RMS error about the truth (includes bias), our "
      "Cramer-Rao sigma (root of the mean bound variance over the sets / trials), their ratio, and the solver's own "
      "covariance (`calib_core.solve.refine.pose_covariance` at the true pose, with the isotropic angular noise "
      "equivalent to the pixel covariance at those pixels, as printed) for comparison.\n")
    a(report.crb_table(crb_rows))
    a(img("crb.png", "Cramer-Rao ratios"))

    a("## Comparison: angular cost vs pixel cost vs OpenCV\n")
    a("Same trials for every method. On the scenes' own omnidirectional camera: eq. 7 (angular, ours) and eq. 6 "
      "(pixel reprojection, `cost=\"pixel\"`). OpenCV's PnP cannot use rays beyond 90 deg from the axis, so it runs "
      f"only on a **pinhole variant** of every scene: a {PINHOLE_SIZE[0]}x{PINHOLE_SIZE[1]} undistorted pinhole, "
      f"f = {PINHOLE_F_PX:.0f} px, at the scene's true pose (same centre and axes as the OCam camera), with the same "
      "scan and laser picks; pairs are the scene corners that project inside its image, clicked with 1 px noise "
      "(`simulate_pairs` on that camera). OpenCV: `solvePnP(SOLVEPNP_SQPNP)` then `solvePnPRefineLM`. "
      "`solve_extrinsics` also computes the covariance, the residuals and an outlier check, OpenCV does not; "
      "the pixel cost runs the angular LM first and continues from its optimum.\n")
    a("Corners in the pinhole view: " + ", ".join(f"{s.name}: {len(s.scene.corners_lidar)}" for s in pin_scenes) + ".\n")
    a(f"Accuracy: n = {', '.join(map(str, compare_n))}, {trials} trials per scene and n. Time per solve: the "
      "trials above run in parallel processes on a shared machine, so for a fair comparison the times are "
      f"medians of a re-run of {per_n} trials per n in one process, every method in turn on the same trial.\n")
    for n in (6, 10, 20):
        if n not in compare_n:
            continue
        a(f"### n = {n}, omnidirectional camera, all scenes\n")
        a(report.compare_table(omni_res, idx_all, n, ("angular", "pixel"), omni_times) + "\n")
        a(f"### n = {n}, pinhole variant, all scenes\n")
        a(report.compare_table(pin_res, idx_all, n, ("angular", "pixel", "opencv"), pin_times) + "\n")
    a(img("compare.png", "comparison vs n"))

    a("## Speed of the live steps\n")
    groups = [("ba", "Bearing Angle images, 4 directions (`bearing_angle_images`)"),
              ("jit", "Compiled kernels: compile and cached start-up (`calib_core.warm_up`: cameras, BA, colouring; new process)"),
              ("solve", "Solve: initial pose + LM + covariance (`solve_extrinsics`)"),
              ("colorize", "Colourise with the occlusion test (`colorize_points`)"),
              ("panorama", "Panorama unwrap (`Panorama`)"),
              ("click", "Server-side click to updated error and overlays")]
    for g, title in groups:
        a(f"### {title}\n")
        a("| input | median | fastest | runs | notes |\n|---|---:|---:|---:|---|")
        for t in sp.timings:
            if t.group == g:
                a(f"| {t.label} | {fmt_ms(t.median_s)} | {fmt_ms(t.min_s)} | {t.runs} | {t.detail} |")
        a("")
        if g == "solve" and sp.solve_breakdown:
            a("Stages of the 10-pair solve, each timed alone through the package's functions:\n")
            a("| stage | median | fastest |\n|---|---:|---:|")
            for t in sp.solve_breakdown:
                a(f"| {t.label} | {fmt_ms(t.median_s)} | {fmt_ms(t.min_s)} |")
            a("")
    a(sp.click_note + " Breakdown (medians of each step alone):\n")
    a("| step | median | fastest |\n|---|---:|---:|")
    for t in sp.click_breakdown:
        a(f"| {t.label} | {fmt_ms(t.median_s)} | {fmt_ms(t.min_s)} |")
    a("")
    if profiles:
        a("## Profiles of the missed speed targets\n")
        a("cProfile (which adds overhead), times per call of the step. The click is profiled on the calling "
          "thread only (cProfile does not follow the live solver's worker thread, whose waiting shows as lock "
          "acquire time); the worker's main step, recolouring the display cloud, is profiled separately.\n")
        for label, text in profiles.items():
            a(f"### {label}\n")
            a(text + "\n")
    a("## Solve against OpenCV, JIT, OCam accuracy, sigma coverage (`bench.solve_vs_opencv`, this run)\n")
    a(vs_md.split("\n", 1)[1].replace("\n## ", "\n### "))
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    sys.exit(main())
