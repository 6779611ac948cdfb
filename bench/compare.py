"""Side by side: angular cost (eq. 7), pixel cost (eq. 6), OpenCV SQPnP + LM.

* On the scenes' own (omnidirectional) cameras the angular and pixel costs
  run on exactly the trials of :mod:`bench.accuracy`.  OpenCV's PnP cannot
  take rays more than 90 deg off the optical axis, so it is not run there.
* On a **pinhole variant** of every scene -- same scan, same corners, a
  :class:`calib_core.cameras.PinholeCamera` with the scene's true pose
  ``T_camera_lidar`` (same centre and orientation as the real camera) -- all
  three run on the same trials.  No pinhole image is rendered: a pair only
  needs the pixel of a corner, so the corners are projected with the pinhole
  model and only those in front of it and inside its image are used.  The
  corners' visibility from the camera centre was already checked by the scene
  (the centre is the same); the laser side is the same whole-cell pick.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np

from calib_core.cameras import PinholeCamera
from calib_core.pairs import resolve_pairs
from calib_core.transforms import transform_points

from .accuracy import PIXEL_NOISE_PX, TrialInput, TrialResult, summarize
from .common import BENCH_SEED, BenchScene, _check_points, log, parallel_map, pose_error

#: Pinhole variant: 1280 x 960 px, f = 640 px (90 deg horizontal field of view), no distortion.
PINHOLE_SIZE = (1280, 960)
PINHOLE_F_PX = 640.0


@dataclass
class PinholeScene:
    """Duck-typed stand-in for a SampleScene, seen by a pinhole camera.

    Has what :func:`calib_core.synthetic.simulate_pairs` and the scorers use.
    """

    depth: object
    camera: PinholeCamera
    T_camera_lidar: np.ndarray
    corners_lidar: np.ndarray


def pinhole_variant(bs: BenchScene) -> BenchScene:
    """The scene with a pinhole camera at the true pose; corners outside its view dropped."""
    w, h = PINHOLE_SIZE
    K = np.array([[PINHOLE_F_PX, 0.0, (w - 1) / 2.0], [0.0, PINHOLE_F_PX, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    cam = PinholeCamera(K, np.zeros(5), w, h)
    sc = bs.scene
    corners = np.asarray(sc.corners_lidar, dtype=np.float64).reshape(-1, 3)
    pix, valid = cam.project(transform_points(sc.T_camera_lidar, corners))
    # Keep a margin so that 1 px click noise never leaves the image.
    inner = valid & (pix[:, 0] > 3) & (pix[:, 0] < w - 4) & (pix[:, 1] > 3) & (pix[:, 1] < h - 4)
    ps = PinholeScene(sc.depth, cam, sc.T_camera_lidar, corners[inner])
    return BenchScene(bs.name + " (pinhole)", ps, _check_points(ps))


def make_pinhole_trials(scenes: list[BenchScene], n_values, trials: int) -> list[TrialInput]:
    """Seeded simulated pairs on the pinhole variants (scene indices as in ``scenes``)."""
    from calib_core.synthetic import simulate_pairs

    out = []
    for si, bs in enumerate(scenes):
        usable = len(bs.scene.corners_lidar)
        for n in n_values:
            if n > usable:
                continue
            for k in range(trials):
                rng = np.random.default_rng([BENCH_SEED, 500 + si, n, k])
                pairs = simulate_pairs(bs.scene, n, rng, pixel_noise_px=PIXEL_NOISE_PX)
                pts, brg, px = resolve_pairs(pairs, bs.scene.depth, bs.scene.camera)
                rc = np.array([p.laser_rc for p in pairs], dtype=np.int64)
                out.append(TrialInput(si, n, k, pts, brg, px, rc))
    return out


def solve_opencv(bs: BenchScene, tr: TrialInput) -> TrialResult:
    """OpenCV ``solvePnP(SOLVEPNP_SQPNP)`` then ``solvePnPRefineLM`` on one pinhole trial."""
    cam = bs.scene.camera
    obj = np.ascontiguousarray(tr.points_lidar, dtype=np.float64)
    img = np.ascontiguousarray(tr.pixels, dtype=np.float64)
    K, dist = cam.K, cam.dist
    t0 = time.perf_counter()
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_SQPNP)
    if ok:
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    dt = time.perf_counter() - t0
    if not ok:
        return TrialResult("opencv", False, dt, message="solvePnP(SQPNP) failed")
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    uv, _ = cam.project(transform_points(T, obj))
    res = np.linalg.norm(uv - img, axis=1)
    err = pose_error(T, bs.scene.T_camera_lidar, cam, bs.check_points_lidar)
    return TrialResult("opencv", True, dt, T, err, res)


def run_pinhole(pin_scenes: list[BenchScene], trials_in: list[TrialInput], methods=("angular", "pixel", "opencv"),
                workers: int = 1):
    """All methods on the pinhole trials: ``(results, summaries)`` keyed ``(scene, n, method)``."""
    from .accuracy import solve_trial

    def one(tr: TrialInput, method: str) -> TrialResult:
        bs = pin_scenes[tr.scene_index]
        return solve_opencv(bs, tr) if method == "opencv" else solve_trial(bs, tr, method)

    results: dict = {}
    for method in methods:
        t0 = time.perf_counter()
        out = parallel_map(lambda tr, m=method: one(tr, m), trials_in, workers)
        for tr, r in zip(trials_in, out):
            results.setdefault((tr.scene_index, tr.n, method), []).append(r)
        log(f"  pinhole, {method}: {len(trials_in)} solves in {time.perf_counter() - t0:.1f} s ({workers} processes)")
    return results, {k: summarize(v, k[1]) for k, v in results.items()}


def interleaved_times(scenes: list[BenchScene], trials_in: list[TrialInput], methods, per_n: int = 12,
                      pinhole: bool = False) -> dict:
    """Median solve time per ``(n, method)``, measured fairly.

    The accuracy runs use several processes on a shared machine, so their
    times are not comparable between methods.  Here a few trials per ``n``
    are solved again in one process, every method in turn on the same trial,
    so that load changes hit all methods alike.
    """
    from .accuracy import solve_trial

    per_scene = max(1, -(-per_n // len(scenes)))
    times: dict = {}
    for tr in trials_in:
        if tr.trial >= per_scene:
            continue
        bs = scenes[tr.scene_index]
        for m in methods:
            r = solve_opencv(bs, tr) if m == "opencv" else solve_trial(bs, tr, m)
            times.setdefault((tr.n, m), []).append(r.time_s)
    return {k: float(np.median(v)) for k, v in times.items()}
