"""Shared pieces of the benchmarks: scenes, seeded trials, error measures, timing.

Frames and units follow :mod:`calib_core`: ``T_camera_lidar`` maps lidar
points to the OpenCV camera frame, metres; roll, pitch, yaw in degrees with
``R = Rz(yaw) Ry(pitch) Rx(roll)``.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from calib_core.transforms import rpy_deg_from_R, rotation_angle_deg, transform_points

REPO = Path(__file__).resolve().parents[1]
SAMPLE_DIR = REPO / "sample_data"
#: Generated scenes are cached here (git-ignored): making one takes up to a minute.
CACHE_DIR = REPO / "bench" / "out"

#: Seed of every random draw of the benchmarks (trials, noise, timing inputs).
BENCH_SEED = 20070101


def log(msg: str) -> None:
    """Progress line with a wall-clock stamp."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


# --------------------------------------------------------------------- scenes
@dataclass
class BenchScene:
    """A scene used by the benchmarks.

    Attributes
    ----------
    name : str
        ``"sample"`` (the committed sample_data/) or ``"seed N"``.
    scene : calib_core.synthetic.SampleScene
    check_points_lidar : (M, 3) float64
        Laser points that the true pose projects into the image, used to
        measure the pixel error of an estimate against ground truth, metres.
    """

    name: str
    scene: Any
    check_points_lidar: np.ndarray = field(repr=False)


def _check_points(scene, max_points: int = 2000) -> np.ndarray:
    """A fixed subsample of the scan points visible under the true pose."""
    depth = scene.depth
    pts = depth.points[depth.valid]
    _, ok = scene.camera.project(transform_points(scene.T_camera_lidar, pts))
    pts = pts[ok]
    rng = np.random.default_rng(BENCH_SEED)
    if len(pts) > max_points:
        pts = pts[np.sort(rng.choice(len(pts), max_points, replace=False))]
    return pts


def generator_version() -> str:
    """Short hash of the scene generator's source: a changed generator invalidates the cache."""
    h = hashlib.sha256()
    for f in sorted((REPO / "calib_core" / "synthetic").glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:10]


def load_scenes(extra_seeds: tuple[int, ...], cache_dir: Path = CACHE_DIR) -> list[BenchScene]:
    """The committed sample plus generated scenes for ``extra_seeds`` (cached on disk).

    A generated scene is written once with :func:`calib_core.synthetic.write_sample`
    into ``cache_dir/scene_seed<N>_<generator hash>/`` and read back with
    ``load_sample`` on later runs.
    """
    from calib_core.synthetic import load_sample, write_sample

    version = generator_version()

    def cached(seed: int):
        d = Path(cache_dir) / f"scene_seed{seed}_{version}"
        done = d / ".complete"
        if not done.exists():
            log(f"generating scene seed {seed} into {d} (cached for later runs) ...")
            t0 = time.perf_counter()
            d.mkdir(parents=True, exist_ok=True)
            write_sample(d, seed=seed)
            done.write_text("ok\n")
            log(f"  scene seed {seed} generated in {time.perf_counter() - t0:.1f} s")
        return load_sample(d)

    if (SAMPLE_DIR / "corners.yaml").exists():
        sample = load_sample(SAMPLE_DIR)
    else:  # sample_data/ is write_sample(..., seed=0): regenerate it rather than fail
        log(f"{SAMPLE_DIR} is incomplete: using a regenerated seed 0 instead")
        sample = cached(0)
    out = [BenchScene("sample", sample, _check_points(sample))]
    for seed in extra_seeds:
        s = cached(seed)
        out.append(BenchScene(f"seed {seed}", s, _check_points(s)))
    return out


# ------------------------------------------------------------- error measures
def wrap_deg(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-180, 180) degrees."""
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class PoseError:
    """Errors of an estimated ``T_camera_lidar`` against the truth.

    Attributes
    ----------
    rpy_deg : (3,)
        Estimated minus true roll, pitch, yaw, degrees (wrapped).
    translation_m : (3,)
        Estimated minus true translation of ``T_camera_lidar``, metres
        (the lidar origin in the camera frame).
    rotation_deg : float
        Angle of ``R_true^T R_est``, degrees.
    translation_norm_m : float
        Norm of ``translation_m``.
    gt_pixel_px : float
        Mean image distance between the projections of the scene's check
        points under the estimate and under the truth, pixels.
    """

    rpy_deg: np.ndarray
    translation_m: np.ndarray
    rotation_deg: float
    translation_norm_m: float
    gt_pixel_px: float


def pose_error(T_est: np.ndarray, T_true: np.ndarray, camera=None, check_points_lidar=None) -> PoseError:
    """Compare an estimate with the truth (see :class:`PoseError`)."""
    d_rpy = wrap_deg(rpy_deg_from_R(T_est[:3, :3]) - rpy_deg_from_R(T_true[:3, :3]))
    d_t = T_est[:3, 3] - T_true[:3, 3]
    px = float("nan")
    if camera is not None and check_points_lidar is not None and len(check_points_lidar):
        uv_true, ok_true = camera.project(transform_points(T_true, check_points_lidar))
        uv_est, ok_est = camera.project(transform_points(T_est, check_points_lidar))
        d = np.linalg.norm(uv_est - uv_true, axis=1)
        # A point pushed out of the image by a bad estimate counts with its raw distance
        # when the model still gives a pixel; a point with no pixel at all counts as missing.
        d = d[ok_true & np.isfinite(d)]
        px = float(d.mean()) if d.size else float("nan")
    return PoseError(d_rpy, d_t, rotation_angle_deg(T_est[:3, :3], T_true[:3, :3]), float(np.linalg.norm(d_t)), px)


def within_sigma(result, T_true: np.ndarray) -> np.ndarray:
    """``(2, 6)`` bool: is each error (roll, pitch, yaw, tx, ty, tz of :func:`pose_error`) within 1 and 2 of
    ``result``'s reported sigma (``sigma_rpy_deg``, ``sigma_translation_m``)?  One trial of a coverage check."""
    e = pose_error(result.T_camera_lidar, T_true)
    err = np.abs(np.concatenate([e.rpy_deg, e.translation_m]))
    sig = np.concatenate([result.sigma_rpy_deg, result.sigma_translation_m])
    return err <= np.array([[1.0], [2.0]]) * sig


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (for a server the bench starts)."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# ---------------------------------------------------------------------- timing
def time_median(fn: Callable[[], Any], repeats: int, warmup: int = 1, min_total_s: float = 0.0) -> tuple[float, int, float]:
    """Median and minimum wall time of ``fn()`` in seconds, and the number of timed runs.

    Runs ``warmup`` untimed calls first.  With ``min_total_s`` it keeps going
    past ``repeats`` until that much time has been spent (short steps get
    more runs, so their median is stable).  The minimum is the best case on
    a shared machine; the median is what the targets are judged on.
    """
    for _ in range(warmup):
        fn()
    times = []
    t_start = time.perf_counter()
    while len(times) < repeats or (time.perf_counter() - t_start < min_total_s and len(times) < 2000):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), len(times), float(np.min(times))


def fmt_ms(seconds: float) -> str:
    """Seconds as a millisecond string with 3 significant digits."""
    ms = 1e3 * seconds
    if not np.isfinite(ms):
        return "failed"
    if ms >= 100:
        return f"{ms:.0f} ms"
    if ms >= 10:
        return f"{ms:.1f} ms"
    return f"{ms:.2f} ms"


# ------------------------------------------------------------ parallel trials
_WORKER_CONTEXT: dict[str, Any] = {}


def _call_in_worker(args):
    fn_name, item = args
    return _WORKER_CONTEXT[fn_name](item)


def parallel_map(fn: Callable[[Any], Any], items: list, workers: int) -> list:
    """``[fn(x) for x in items]``, in ``workers`` forked processes when ``workers > 1``.

    ``fn`` may be a closure: it is handed to the workers by fork, not pickled.
    Results come back in order.
    """
    if workers <= 1 or len(items) < 2:
        return [fn(x) for x in items]
    import multiprocessing as mp

    key = f"fn{id(fn)}"
    _WORKER_CONTEXT[key] = fn
    try:
        with mp.get_context("fork").Pool(workers) as pool:
            return pool.map(_call_in_worker, [(key, x) for x in items], chunksize=max(1, len(items) // (8 * workers)))
    finally:
        _WORKER_CONTEXT.pop(key, None)


def sigma_coverage(n_pairs: int) -> tuple[float, float]:
    """Shares of solves whose error lies within 1 and 2 reported sigma, when the noise is estimated.

    The reported sigma is widened by :func:`calib_core.solve.extrinsics.student_t_factor` of ``2 n - 6``
    degrees of freedom, so +-1 sigma covers 68.27 %; +-2 such sigmas cover ``P(|t| < 2 factor)``, less than
    the normal 95.45 % because the t distribution's tails are heavier (94.30 % at 10 pairs, 92.8 % at 6).
    With known noise (``noise_rad``) the shares are the normal ones.
    """
    from scipy.special import stdtr

    from calib_core.solve.extrinsics import student_t_factor

    dof = 2 * int(n_pairs) - 6
    f = student_t_factor(dof)
    return float(2 * stdtr(dof, f) - 1), float(2 * stdtr(dof, 2 * f) - 1)
