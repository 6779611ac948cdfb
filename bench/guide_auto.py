"""Tuning the auto-accept gate against the truth: ``python -m bench.guide_auto [--trials N]``.

Simulated guided sessions (bench/guide_sim.py, shipped D-optimal order) on
the sample and seeds 1 and 2; at 10, 20 and 30 guided pairs every current
proposal (up to 200) is judged by :func:`calib_core.guide.auto_accept.auto_accept`
under each gate of :data:`GATES`.  A pass is *wrong* when the proposed cell
is on no true corner (or on one already paired), or the image corner it found
is more than 2 px from the corner's true projection
(:data:`bench.guide_sim.AUTO_WRONG_PX`).  Prints, per gate and scene, the
passes, the wrong ones and their share.
"""

from __future__ import annotations

import argparse

import numpy as np

from calib_core.guide.auto_accept import AutoGate
from calib_core.guide.image_corners import CornerGate

from .common import BENCH_SEED, load_scenes, log
from .guide_sim import guided_run

#: Gates compared: the shipped default and neighbours of it (why it is set where it is).
GATES = {
    "shipped default": AutoGate(),
    "old strict (before tuning)": AutoGate(max_ellipse_px=6.0, min_laser_strength=1.0,
                                           corner=CornerGate(min_strength=0.02, min_ratio=0.4, isolation=0.2,
                                                             isolation_radius_px=6.0),
                                           min_contrast=5.0, max_offset_sigma=3.0),
    "isolation 0.5": AutoGate(corner=CornerGate(min_strength=0.03, min_ratio=0.3, isolation=0.5,
                                                isolation_radius_px=6.0)),
    "offset <= 3 sigma": AutoGate(max_offset_sigma=3.0),
    "with colour test (>= 1)": AutoGate(min_contrast=1.0),
}


def collect(scenes, trials: int, checkpoints=(10, 20, 30), gates=GATES, first_trial: int = 0) -> dict:
    """gate -> scene name -> list of (wrong, px error) of every pass."""
    out = {g: {bs.name: [] for bs in scenes} for g in gates}
    for si, bs in enumerate(scenes):
        for t in range(first_trial, first_trial + trials):
            seed = bs.scene.seed
            r = guided_run(bs.scene, np.random.default_rng([BENCH_SEED, 17, seed, t]), checkpoints=checkpoints,
                           auto_gates=gates, max_actions=300)
            for g in gates:
                out[g][bs.name].extend(r.auto.get(g, []))
        log(f"auto: {bs.name} done")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.guide_auto", description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=3, help="sessions per scene")
    p.add_argument("--seeds", type=int, nargs="*", default=[1, 2], help="extra scenes besides the sample")
    p.add_argument("--first-trial", type=int, default=0,
                   help="first session index (the defaults were tuned on sessions 0..2 of the sample, seeds 1, 2)")
    a = p.parse_args(argv)
    scenes = load_scenes(tuple(a.seeds))
    res = collect(scenes, a.trials, first_trial=a.first_trial)
    print(f"Auto-accept (`python -m bench.guide_auto --trials {a.trials} --seeds {' '.join(map(str, a.seeds))} "
          f"--first-trial {a.first_trial}`): every proposal at 10, 20, 30 guided pairs, {a.trials} sessions per scene.\n")
    print("| gate | scene | passes | wrong | wrong share |\n|---|---|---:|---:|---:|")
    for g, per in res.items():
        for name, v in list(per.items()) + [("all", [x for vv in per.values() for x in vv])]:
            w = sum(x[0] for x in v)
            print(f"| {g} | {name} | {len(v)} | {w} | " + (f"{100 * w / len(v):.1f} % |" if v else "- |"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
