"""The compiled kernels' sections of the speed benchmark, alone: ``python -m bench.kernels``.

Runs the BA, JIT start-up and colourise sections of :mod:`bench.speed` on the
committed sample (the same inputs and seeds as ``python -m bench``) and prints
their medians with the load average, so the kernels can be re-measured in a
minute without the accuracy trials.

``--against COMMIT`` also times the BA images and colourising of an older
commit's ``calib_core`` (extracted with ``git archive``) in the same process,
alternating runs on identical inputs: on a shared machine that is the fair
comparison.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import BENCH_SEED, REPO, fmt_ms, load_scenes, log
from .speed import SpeedReport, ba_section, colorize_section, dense_cloud, jit_startup, solve_inputs, \
    spherical_room_depth


def _package_at(commit: str, into: str):
    """``calib_core`` of ``commit`` imported as ``calib_core_base`` from ``into``: (bearing_angle, overlays, lidar)."""
    tar = subprocess.run(["git", "archive", commit, "calib_core"], cwd=REPO, capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(into, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
    os.rename(Path(into) / "calib_core", Path(into) / "calib_core_base")
    sys.path.insert(0, into)
    import calib_core_base.bearing_angle as ba  # noqa: PLC0415 -- only importable now
    import calib_core_base.lidar as lidar
    import calib_core_base.overlays as ov

    return ba, ov, lidar


def _paired(fns: dict, rounds: int) -> dict:
    """Median and fastest wall time, and median process CPU time (all threads), seconds, alternating the calls."""
    wall = {k: [] for k in fns}
    cpu = {k: [] for k in fns}
    for f in fns.values():
        f()
    for _ in range(rounds):
        for k, f in fns.items():
            c0, t0 = time.process_time(), time.perf_counter()
            f()
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.process_time() - c0)
    return {k: (float(np.median(wall[k])), min(wall[k]), float(np.median(cpu[k]))) for k in fns}


def against(commit: str, bs, rounds: int) -> None:
    """Time BA images and colourising of ``commit`` and of this checkout, alternately, on the same inputs."""
    from calib_core import bearing_angle, overlays

    sc = bs.scene
    with tempfile.TemporaryDirectory(prefix="ba-calib-base-") as tmp:
        base_ba, base_ov, base_lidar = _package_at(commit, tmp)
        print(f"\n{commit} (base) against this checkout (new), alternating runs in one process:\n")
        print("| step | base median | new median | base fastest | new fastest | base CPU | new CPU | load |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|")

        def row(label, res):
            (bm, bf, bc), (nm, nf, nc) = res["base"], res["new"]
            print(f"| {label} | {fmt_ms(bm)} | {fmt_ms(nm)} | {fmt_ms(bf)} | {fmt_ms(nf)} | {fmt_ms(bc)} | {fmt_ms(nc)} "
                  f"| {os.getloadavg()[0]:.1f} |")

        for label, depth in (("BA 180x720 (sample)", sc.depth), ("BA 64x1800", spherical_room_depth(64, 1800)),
                             ("BA 128x2048", spherical_room_depth(128, 2048))):
            old = base_lidar.DepthMatrix(depth.range_m, depth.directions, depth.points, depth.valid, dict(depth.meta))
            row(label, _paired({"base": lambda d=old: base_ba.bearing_angle_images(d),
                                "new": lambda d=depth: bearing_angle.bearing_angle_images(d)}, 4 * rounds))
        rng = np.random.default_rng([BENCH_SEED, 9])
        for n in (10, 100, 1000):
            solve_inputs(bs, n, rng)
        for n, label in ((100_000, "100k"), (1_000_000, "1M")):
            cloud = dense_cloud(bs, n, rng)
            args = (cloud, sc.image, sc.camera, sc.T_camera_lidar)
            (c_old, h_old), (c_new, h_new) = base_ov.colorize_points(*args), overlays.colorize_points(*args)
            both = h_old & h_new
            diff = np.abs(c_old[both].astype(int) - c_new[both]).max() if both.any() else 0
            print(f"|  colorize {label}: same has_color for {np.mean(h_old == h_new):.2%} of the points, colours "
                  f"within {diff} gray level(s) |||||||")
            row(f"colorize {label}", _paired({"base": lambda a=args: base_ov.colorize_points(*a),
                                              "new": lambda a=args: overlays.colorize_points(*a)}, rounds))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.kernels", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repeats")
    p.add_argument("--only", nargs="*", choices=("ba", "jit", "colorize"), default=("ba", "jit", "colorize"),
                   help="sections to run (default: all)")
    p.add_argument("--against", metavar="COMMIT", help="also time this commit's BA images and colourising, paired")
    args = p.parse_args(argv)
    scale = 0.3 if args.quick else 1.0
    reps = lambda n: max(3, int(n * scale))  # noqa: E731
    bs = load_scenes(())[0]
    rep = SpeedReport()
    load_start = os.getloadavg()
    log(f"load average (1, 5, 15 min) at the start: {load_start[0]:.2f} {load_start[1]:.2f} {load_start[2]:.2f}, "
        f"{os.cpu_count()} cores")
    if "ba" in args.only:
        ba_section(rep, bs.scene, reps, scale)
    if "jit" in args.only:
        jit_startup(rep, runs=2 if args.quick else 3)
    if "colorize" in args.only:
        # The same cloud as run_speed, whose solve section draws from this generator first.
        rng = np.random.default_rng([BENCH_SEED, 9])
        for n in (10, 100, 1000):
            solve_inputs(bs, n, rng)
        colorize_section(bs, rep, rng, reps)
    print()
    print("| group | step | median | fastest | runs | notes |")
    print("|---|---|---:|---:|---:|---|")
    for t in rep.timings:
        unit = (lambda s: f"{s:.3f} s") if t.group == "jit" else fmt_ms
        print(f"| {t.group} | {t.label} | {unit(t.median_s)} | {unit(t.min_s)} | {t.runs} | {t.detail} |")
    if args.against:
        against(args.against, bs, 3 if args.quick else 9)
    load_end = os.getloadavg()
    print(f"\nload average (1, 5, 15 min) at the end: {load_end[0]:.2f} {load_end[1]:.2f} {load_end[2]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
