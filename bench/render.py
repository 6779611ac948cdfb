"""Speed of the scan rendered from the camera (``calib_core.render``): ``python -m bench.render``.

Times :func:`calib_core.render.render_from_camera` (and the range shading) on the real scans the app
shows beside their photos -- KITTI 000002 (HDL-64E, 1242 x 375 pinhole) and PJLab auto_calib (64 beams,
1920 x 1200 pinhole with distortion), read from ``../shared/data`` when present -- and on the committed
sample (OCam, 640 x 480).  Prints the median and fastest of a few runs with the load average: the app
needs a render well under 0.5 s.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from .common import REPO, SAMPLE_DIR, log

SHARED = REPO.parent / "shared" / "data"


def _scenes():
    """(name, depth, camera, T_camera_lidar) of every scene whose files are present."""
    from calib_core.cameras import load_camera
    from calib_core.io.extrinsic_formats import load_extrinsics_any
    from calib_core.io.kitti_calib import read_kitti_camera2
    from calib_core.io.scan_readers import load_scan

    kitti = SHARED / "kitti_object_000002"
    if (kitti / "velodyne" / "000002.bin").is_file():
        _, T = read_kitti_camera2(kitti / "calib" / "000002.txt")
        yield ("KITTI 000002", load_scan(kitti / "velodyne" / "000002.bin"),
               load_camera(REPO / "real_data" / "kitti_000002_camera.yaml"), T)
    pjlab = SHARED / "pjlab_opencalib_lidar2camera" / "auto_calib"
    if (pjlab / "calib.pcd").is_file():
        yield ("PJLab auto_calib", load_scan(pjlab / "calib.pcd"), load_camera(pjlab / "center_camera-intrinsic.json"),
               load_extrinsics_any(pjlab / "top_center_lidar-to-center_camera-extrinsic.json"))
    yield ("sample (OCam)", load_scan(SAMPLE_DIR / "scan.npz"), load_camera(SAMPLE_DIR / "camera.yaml"),
           load_extrinsics_any(SAMPLE_DIR / "ground_truth.yaml"))


def _time(fn, rounds: int) -> tuple[float, float, float]:
    """Median and fastest wall time and median process CPU time of ``fn()``, seconds.

    The render runs on one thread: on a machine shared with other processes its CPU time is what it
    would take alone.
    """
    fn()  # compile or load the kernels, warm the caches
    wall, cpu = [], []
    for _ in range(rounds):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), min(wall), float(np.median(cpu))


def run(rounds: int = 5) -> list[dict]:
    from calib_core.render import render_from_camera, shade_render

    rows = []
    for name, depth, camera, T in _scenes():
        render = render_from_camera(depth, camera, T)
        med, best, cpu = _time(lambda: render_from_camera(depth, camera, T), rounds)
        shade_med, _, shade_cpu = _time(lambda: shade_render(render, depth, "range"), rounds)
        rows.append({"scene": name, "image": f"{camera.width}x{camera.height}",
                     "points": int(depth.valid.sum()), "shown": float(render.has_return.mean()),
                     "render_s": med, "render_best_s": best, "render_cpu_s": cpu,
                     "shade_s": shade_med, "shade_cpu_s": shade_cpu})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.render", description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5, help="timed runs per scene (default 5)")
    args = parser.parse_args(argv)
    log(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"{'scene':18} {'image':>10} {'points':>8} {'shown':>7} {'render: median':>15} {'fastest':>8} "
          f"{'cpu':>7} {'shade: median':>14} {'cpu':>6}")
    for r in run(args.rounds):
        print(f"{r['scene']:18} {r['image']:>10} {r['points']:8d} {100 * r['shown']:6.1f}% "
              f"{1000 * r['render_s']:13.0f}ms {1000 * r['render_best_s']:6.0f}ms {1000 * r['render_cpu_s']:5.0f}ms "
              f"{1000 * r['shade_s']:12.0f}ms {1000 * r['shade_cpu_s']:4.0f}ms")
    log(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
