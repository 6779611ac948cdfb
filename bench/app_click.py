"""Server-side click-to-update of the loupe workflow on the sample: ``python -m bench.app_click [--reps N]``.

A real :class:`app.server.CalibrationApp` (viser on a free local port, no browser) is driven by
:class:`app_driver.AppDriver`, one pair at a time as a person picks it through the loupes:

* ``BA full click``: a click on a full BA image (state change, markers, both loupes re-framed: the BA
  loupe on the click, the camera loupe on the predicted pixel);
* ``BA loupe click``: the wanted cell in the BA loupe (replaces the rough cell, re-frames the camera loupe);
* ``camera loupe click``: the pixel in the camera loupe, which completes the pair; its time runs to the
  new solve shown (errors, table, 2-D overlays: :meth:`LiveSolveCoordinator.last_click_to_update`).

Each action's time is from the handler's call to the action applied (the page would show it).  The target
is <= 20 ms per action.  The machine is shared: the wall-time medians are printed, with the minimum, and
beside them CPU times, which other processes' load hardly changes: the click handler's own thread
(``app.actions.last_action_timing``; the camera click's solve runs in the solver thread after it) and the whole
server process (all threads, including the live solve and the follow-up projection for predictions).

Several shots (issue 21, ``--shots 5``, first): 5 shots of one rig (the sample and 4 synthetic rooms), 12 pairs
imported into each of the first 4, then the last shot's 12 picked through the loupes (49..60 pairs in the joint
solve).  Timed: click to the joint fit shown (target <= 10 ms), click to the shots' checks shown (they follow
in the solver's next job), and the solver thread's CPU for each.  ``--shots-in-one-job`` runs the old live
path (fit and checks in one job) for a before/after comparison; ``--shots-only`` skips the one-shot case.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TARGET_S = 0.020
#: Issue 21: the joint live solve of 5 shots and 60 pairs, click to solve shown.
SHOTS_TARGET_S = 0.010


def run(reps: int = 12) -> dict[str, list[float]]:
    from app.server import CalibrationApp

    if str(REPO / "tests") not in sys.path:  # the test driver lives in tests/app_driver (not in the wheel)
        sys.path.insert(0, str(REPO / "tests"))
    from app_driver import AppDriver
    from calib_core.synthetic import load_sample, simulate_pairs

    sample = REPO / "sample_data"
    scene = load_sample(sample)
    pairs = simulate_pairs(scene, 4 + reps, np.random.default_rng(1), pixel_noise_px=0.0)
    times: dict[str, list[float]] = {"BA full click": [], "BA loupe click": [], "camera loupe click (to solve shown)": []}
    cpu: dict[str, list[float]] = {k: [] for k in times}
    worker: dict[str, list[float]] = {k: [] for k in times}  # the action worker's own thread CPU
    with tempfile.TemporaryDirectory() as tmp:
        app = CalibrationApp(sample / "scan.npz", sample / "image.png", sample / "camera.yaml",
                             session_path=Path(tmp) / "session.yaml", port=0)
        try:
            d = AppDriver(app)
            for k, pair in enumerate(pairs):
                row, col = pair.laser_rc
                key = app.ba_keys[k % len(app.ba_keys)]
                c0, t0 = time.process_time(), time.perf_counter()
                d.click_cell(key, min(row + 2, app.depth.shape[0] - 1), col - 3)
                c1, t1 = time.process_time(), time.perf_counter()
                w1 = app.actions.last_action_timing[1]
                d.click_loupe_cell(row, col)
                c2, t2 = time.process_time(), time.perf_counter()
                w2 = app.actions.last_action_timing[1]
                if app.live.bundle is None:  # before the first solve (a rough pose may exist): untimed
                    d.click_camera(*pair.pixel)
                    d.wait_idle()
                    continue
                d.click_loupe_camera(*pair.pixel)
                d.wait_idle()
                c3 = time.process_time()
                worker["BA full click"].append(w1)
                worker["BA loupe click"].append(w2)
                worker["camera loupe click (to solve shown)"].append(app.actions.last_action_timing[1])
                cpu["BA full click"].append(c1 - c0)
                cpu["BA loupe click"].append(c2 - c1)
                cpu["camera loupe click (to solve shown)"].append(c3 - c2)  # includes the cloud worker's follow-up
                times["BA full click"].append(t1 - t0)
                times["BA loupe click"].append(t2 - t1)
                times["camera loupe click (to solve shown)"].append(app.live.last_click_to_update())
        finally:
            app.stop()
    return times, cpu, worker


def write_rig_shots(out_dir: Path, n_shots: int = 5) -> tuple[list, list[tuple[Path, Path]]]:
    """``n_shots`` scenes of one rig as files (the sample and the bench's synthetic rooms, all seen with the
    sample's ``T_camera_lidar``: :func:`bench.shots.rig_scenes`): ``(rig scenes, [(scan, photo), ...])``.

    The photos are the scenes' own renders (only the clicks' timing is measured here, not their look)."""
    from bench.shots import SEEDS, rig_scenes
    from calib_core.io.images import save_image_rgb
    from calib_core.lidar import save_depth_npz

    scenes = rig_scenes(SEEDS[:n_shots - 1])
    files = []
    for k, rs in enumerate(scenes):
        scan, image = out_dir / f"scan{k}.npz", out_dir / f"image{k}.png"
        save_depth_npz(scan, rs.scene.depth)
        save_image_rgb(image, rs.scene.image)
        files.append((scan, image))
    return scenes, files


def run_shots(per_shot: int = 12, n_shots: int = 5) -> tuple[dict[str, list[float]], int]:
    """Click-to-update of the joint live solve: ``n_shots`` shots (:class:`app.serving.ShotServer`), every shot
    but the last with ``per_shot`` pairs imported, then the last shot's ``per_shot`` pairs picked through the
    loupes (the last click makes ``n_shots * per_shot`` pairs in the joint solve).

    Returns ``({"camera loupe click (to solve shown)": seconds, "checks shown": seconds}, pairs at the end)``:
    the first is what the page shows first (the joint solve), the second is when the shots' checks
    (leave-one-shot-out, the disagreement test) follow, both from the start of the change."""
    from app.serving import ShotServer

    if str(REPO / "tests") not in sys.path:
        sys.path.insert(0, str(REPO / "tests"))
    from app_driver import AppDriver
    from calib_core.synthetic import simulate_pairs

    times: dict[str, list[float]] = {"camera loupe click (to solve shown)": [], "checks shown": [],
                                     "solver CPU: first solve shown": [], "solver CPU: shot checks": []}
    with tempfile.TemporaryDirectory() as tmp:
        scenes, files = write_rig_shots(Path(tmp), n_shots)
        rng = np.random.default_rng(2)
        pairs = [simulate_pairs(rs.scene, per_shot, rng, pixel_noise_px=0.5) for rs in scenes]
        server = ShotServer(files, REPO / "sample_data" / "camera.yaml", session_path=Path(tmp) / "session.yaml",
                            port=0)
        try:
            for k in range(n_shots - 1):  # before any page: the state alone
                server.state.set_active_shot(k)
                server.state.import_pairs(pairs[k])
            app = server.load(n_shots - 1)
            d = AppDriver(app)
            app.wait_idle(120)
            for k, pair in enumerate(pairs[-1]):
                row, col = pair.laser_rc
                d.click_cell(app.ba_keys[k % len(app.ba_keys)], min(row + 2, app.depth.shape[0] - 1), col - 3)
                d.click_loupe_cell(row, col)
                cpu: dict = {}
                app.live.solve_cpu = cpu  # the solver thread's CPU per job kind (app.live_coordinator)
                d.click_loupe_camera(*pair.pixel)
                d.wait_idle()
                times["camera loupe click (to solve shown)"].append(app.live.last_click_to_update())
                first = cpu.get("joint fit", cpu.get("solve"))
                if first is not None:
                    times["solver CPU: first solve shown"].append(first)
                if "shot checks" in cpu:
                    times["solver CPU: shot checks"].append(cpu["shot checks"])
                checked = getattr(app.live, "last_checks_shown", None)
                if checked is not None:
                    times["checks shown"].append(checked() or float("nan"))
            n_end = sum(1 for p in app.state.all_picks if p.complete)
        finally:
            server.stop()
    return times, n_end


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=12, help="pairs timed after the first 4")
    parser.add_argument("--shots", type=int, default=5, help="shots of the several-shot case (0: skip it)")
    parser.add_argument("--shots-in-one-job", action="store_true",
                        help="the joint fit and the shots' checks in one solve job (the old live path, for 'before')")
    parser.add_argument("--shots-only", action="store_true", help="only the several-shot case")
    args = parser.parse_args()
    import os

    if args.shots_in_one_job:
        import app.live_coordinator

        app.live_coordinator.CHECKS_FOLLOW = False

    if args.shots:
        shot_times, n_end = run_shots(12, args.shots)
        print(f"load average (1 min) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print(f"joint live solve, {args.shots} shots, clicks {n_end - 11}..{n_end} pairs in all "
              f"(target <= {1e3 * SHOTS_TARGET_S:.0f} ms server-side to the solve shown):")
        for name, ts in shot_times.items():
            if ts:
                print(f"  {name:38s} median {1e3 * float(np.median(ts)):6.1f} ms, min {1e3 * min(ts):6.1f} ms, "
                      f"max {1e3 * max(ts):6.1f} ms ({len(ts)} clicks)")
        med = float(np.median(shot_times["camera loupe click (to solve shown)"]))
        print(f"  wall time: {'PASS' if med <= SHOTS_TARGET_S else 'FAIL'} (median {1e3 * med:.1f} ms)")
        if args.shots_only:
            return 0
    times, cpu, worker = run(args.reps)

    print(f"load average (1 min) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (shared machine: times scale with it)")
    print(f"click-to-update on the sample through the loupes (target <= {1e3 * TARGET_S:.0f} ms server-side):")
    worst, worst_cpu = 0.0, 0.0
    for name, ts in times.items():
        med = float(np.median(ts))
        worst = max(worst, med)
        worst_cpu = max(worst_cpu, float(np.median(worker[name])))
        print(f"  {name:38s} median {1e3 * med:6.1f} ms, min {1e3 * min(ts):6.1f} ms, max {1e3 * max(ts):6.1f} ms "
              f"({len(ts)} clicks); CPU median: click handler {1e3 * float(np.median(worker[name])):5.1f} ms, "
              f"whole process {1e3 * float(np.median(cpu[name])):5.1f} ms")
    print(f"wall time: {'PASS' if worst <= TARGET_S else 'FAIL'} (worst median {1e3 * worst:.1f} ms); click handler CPU: "
          f"{'PASS' if worst_cpu <= TARGET_S else 'FAIL'} (worst median {1e3 * worst_cpu:.1f} ms)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
