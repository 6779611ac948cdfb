"""The compiled kernels' sections of the speed benchmark, alone: ``python -m bench.kernels``.

Runs the BA, JIT start-up and colourise sections of :mod:`bench.speed` on the
committed sample (the same inputs and seeds as ``python -m bench``) and prints
their medians with the load average, so the kernels can be re-measured in a
minute without the accuracy trials.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from .common import BENCH_SEED, fmt_ms, load_scenes, log
from .speed import SpeedReport, ba_section, colorize_section, jit_startup, solve_inputs


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.kernels", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repeats")
    p.add_argument("--only", nargs="*", choices=("ba", "jit", "colorize"), default=("ba", "jit", "colorize"),
                   help="sections to run (default: all)")
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
    load_end = os.getloadavg()
    print()
    print("| group | step | median | fastest | runs | notes |")
    print("|---|---|---:|---:|---:|---|")
    for t in rep.timings:
        unit = (lambda s: f"{s:.3f} s") if t.group == "jit" else fmt_ms
        print(f"| {t.group} | {t.label} | {unit(t.median_s)} | {unit(t.min_s)} | {t.runs} | {t.detail} |")
    print(f"\nload average (1, 5, 15 min) at the end: {load_end[0]:.2f} {load_end[1]:.2f} {load_end[2]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
