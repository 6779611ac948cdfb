"""Accuracy against ground truth vs the number of pairs (paper Fig. 6, Fig. 7, Table I).

Trials simulate a user: :func:`calib_core.synthetic.simulate_pairs` draws
``n`` pairs at real corners of the scene, clicks the camera pixel with 1 px
Gaussian noise and rounds the laser pick to a whole depth-matrix cell (whose
scan point carries the scanner's 1 cm range noise).  Each trial is solved with
:func:`calib_core.solve.solve_extrinsics` and compared with the scene's true
``T_camera_lidar``.

The Cramer-Rao check (:func:`cramer_rao_check`) has two parts:

* **pure click noise** -- fixed sets of laser points taken as exact, clicks =
  true projection + 1 px noise, many noise draws per set.  This is the setting
  in which the bound of :mod:`bench.crb` is exact to first order, so an
  efficient estimator's spread must match it.
* **realistic picking** -- the trials above; the bound then adds the laser-side
  noise (cell rounding + range noise) as an equivalent pixel covariance.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from calib_core.errors import CalibError
from calib_core.pairs import resolve_pairs

from .common import BENCH_SEED, BenchScene, PoseError, log, parallel_map, pose_error
from .crb import cell_pick_covariance, cramer_rao, radians_per_pixel

N_VALUES = tuple(range(4, 21))
PIXEL_NOISE_PX = 1.0
#: Range noise of the synthetic scanner (calib_core.synthetic.render, ``range_noise_m``).
RANGE_NOISE_M = 0.01
PARAM_NAMES = ("roll", "pitch", "yaw", "tx", "ty", "tz")


@dataclass
class TrialInput:
    """Solver input of one simulated calibration.

    Attributes
    ----------
    scene_index : int
    n : int
    trial : int
    points_lidar : (n, 3) metres
    bearings_camera : (n, 3) unit, camera frame
    pixels : (n, 2) clicked ``(u, v)``
    laser_rc : (n, 2) int or None
        Picked depth-matrix cells.
    """

    scene_index: int
    n: int
    trial: int
    points_lidar: np.ndarray
    bearings_camera: np.ndarray
    pixels: np.ndarray
    laser_rc: np.ndarray | None


@dataclass
class TrialResult:
    """Outcome of one solver on one trial (``ok`` False: it raised)."""

    method: str
    ok: bool
    time_s: float
    T_camera_lidar: np.ndarray | None = None
    error: PoseError | None = None
    residual_px: np.ndarray | None = None
    sigma_rpy_deg: np.ndarray | None = None
    sigma_translation_m: np.ndarray | None = None
    message: str = ""


def make_trials(scenes: list[BenchScene], n_values, trials: int, workers: int = 1) -> list[TrialInput]:
    """Seeded simulated pairs for every scene, ``n`` and trial index (``workers`` processes)."""
    from calib_core.synthetic import simulate_pairs

    def one(key):
        si, n, k = key
        bs = scenes[si]
        rng = np.random.default_rng([BENCH_SEED, si, n, k])
        pairs = simulate_pairs(bs.scene, n, rng, pixel_noise_px=PIXEL_NOISE_PX)
        pts, brg, px = resolve_pairs(pairs, bs.scene.depth, bs.scene.camera)
        rc = None
        if all(p.laser_rc is not None for p in pairs):
            rc = np.array([p.laser_rc for p in pairs], dtype=np.int64)
        return TrialInput(si, n, k, pts, brg, px, rc)

    t0 = time.perf_counter()
    keys = [(si, n, k) for si in range(len(scenes)) for n in n_values for k in range(trials)]
    out = parallel_map(one, keys, workers)
    log(f"  {len(out)} trials simulated in {time.perf_counter() - t0:.1f} s ({workers} processes)")
    return out


def solve_trial(bs: BenchScene, tr: TrialInput, cost: str) -> TrialResult:
    """Solve one trial with ``cost`` ("angular" or "pixel") and score it."""
    from calib_core.solve import solve_extrinsics

    cam = bs.scene.camera
    t0 = time.perf_counter()
    try:
        res = solve_extrinsics(tr.points_lidar, tr.bearings_camera, camera=cam, pixels=tr.pixels, cost=cost)
    except CalibError as exc:
        return TrialResult(cost, False, time.perf_counter() - t0, message=str(exc))
    dt = time.perf_counter() - t0
    err = pose_error(res.T_camera_lidar, bs.scene.T_camera_lidar, cam, bs.check_points_lidar)
    return TrialResult(
        cost, True, dt, res.T_camera_lidar, err, np.asarray(res.residual_px, float),
        np.asarray(res.sigma_rpy_deg, float), np.asarray(res.sigma_translation_m, float),
    )


@dataclass
class Summary:
    """Statistics of one method on one scene at one ``n`` (errors = estimate - truth).

    ``*_mean`` / ``*_std`` are over successful trials; ``residual_px_*`` over
    all pairs of all trials (the paper's "pixel error"); ``gt_px_*`` is the
    error against ground truth of the projected scene points.
    """

    n: int
    trials: int
    failures: int
    rpy_err_mean: np.ndarray
    rpy_err_std: np.ndarray
    t_err_mean: np.ndarray
    t_err_std: np.ndarray
    rot_err_mean: float
    rot_err_p95: float
    trans_err_mean: float
    trans_err_p95: float
    gt_px_mean: float
    gt_px_std: float
    residual_px_mean: float
    residual_px_std: float
    time_median_s: float
    messages: list[str] = field(default_factory=list)


def summarize(results: list[TrialResult], n: int) -> Summary:
    ok = [r for r in results if r.ok]
    nan3 = np.full(3, np.nan)
    if not ok:
        return Summary(n, len(results), len(results), nan3, nan3, nan3, nan3, *([np.nan] * 9),
                       messages=sorted({r.message for r in results}))
    rpy = np.array([r.error.rpy_deg for r in ok])
    t = np.array([r.error.translation_m for r in ok])
    rot = np.array([r.error.rotation_deg for r in ok])
    tn = np.array([r.error.translation_norm_m for r in ok])
    gpx = np.array([r.error.gt_pixel_px for r in ok])
    res = np.concatenate([r.residual_px for r in ok])
    res = res[np.isfinite(res)]
    return Summary(
        n, len(results), len(results) - len(ok),
        rpy.mean(0), rpy.std(0, ddof=1) if len(ok) > 1 else nan3,
        t.mean(0), t.std(0, ddof=1) if len(ok) > 1 else nan3,
        float(rot.mean()), float(np.percentile(rot, 95)), float(tn.mean()), float(np.percentile(tn, 95)),
        float(np.nanmean(gpx)), float(np.nanstd(gpx)), float(res.mean()), float(res.std()),
        float(np.median([r.time_s for r in results])),
        sorted({r.message for r in results if not r.ok}),
    )


def run_accuracy(scenes: list[BenchScene], trials_in: list[TrialInput], methods=("angular", "pixel"),
                 workers: int = 1, method_n_values: dict | None = None):
    """Solve every trial with every method (``workers`` processes).

    ``method_n_values`` optionally restricts a method to some ``n``.

    Returns
    -------
    results : dict[(scene_index, n, method)] -> list[TrialResult]
    summaries : dict[(scene_index, n, method)] -> Summary
    """
    results: dict = {}
    for method in methods:
        t0 = time.perf_counter()
        keep = (method_n_values or {}).get(method)
        todo = [tr for tr in trials_in if keep is None or tr.n in keep]
        out = parallel_map(lambda tr, m=method: solve_trial(scenes[tr.scene_index], tr, m), todo, workers)
        for tr, r in zip(todo, out):
            results.setdefault((tr.scene_index, tr.n, method), []).append(r)
        log(f"  {method} cost: {len(todo)} solves in {time.perf_counter() - t0:.1f} s ({workers} processes)")
    summaries = {k: summarize(v, k[1]) for k, v in results.items()}
    return results, summaries


# --------------------------------------------------------------- Cramer-Rao
@dataclass
class CrbRow:
    """Empirical spread vs bound for one experiment (six parameters each).

    Attributes
    ----------
    label : str
    method : str
    draws : int
        Successful solves.
    empirical_std : (6,)
        Standard deviation of the estimate over the draws: roll, pitch, yaw
        in degrees, tx, ty, tz in metres.
    empirical_rms : (6,)
        Root-mean-square error about the truth (includes bias), same units.
    bound : (6,)
        Our Cramer-Rao sigma (RMS over the sets / trials), same units.
    solver_sigma : (6,)
        The solver's own covariance (``pose_covariance`` at the truth with the
        equivalent isotropic angular noise), same units.
    noise_rad : float
        That equivalent angular noise, radians.
    floor : dict
        Mean errors an efficient unbiased estimator would reach under this
        noise model (errors drawn from the bound): ``rotation_deg``,
        ``translation_m``, ``gt_px``.
    """

    label: str
    method: str
    draws: int
    empirical_std: np.ndarray
    empirical_rms: np.ndarray
    bound: np.ndarray
    solver_sigma: np.ndarray
    noise_rad: float
    floor: dict[str, float] = field(default_factory=dict)

    @property
    def ratio(self) -> np.ndarray:
        """Empirical spread (std) over the bound."""
        return self.empirical_std / self.bound


def efficiency_floor(bs: BenchScene, covariances: list[np.ndarray], draws_each: int, seed: int) -> dict[str, float]:
    """Mean errors of an efficient unbiased estimator: pose errors drawn from the bounds.

    For each covariance (one per pair set), ``draws_each`` Gaussian pose
    errors ``dp ~ N(0, C)`` in (roll, pitch, yaw [rad], t [m]) are applied to
    the true pose and scored like a solver's estimate.
    """
    from calib_core.transforms import R_from_rpy_deg, make_T, rpy_deg_from_R

    T_true = bs.scene.T_camera_lidar
    p0 = np.concatenate([np.radians(rpy_deg_from_R(T_true[:3, :3])), T_true[:3, 3]])
    rng = np.random.default_rng([BENCH_SEED, 31, seed])
    rot, tr, px = [], [], []
    for C in covariances:
        L = np.linalg.cholesky(0.5 * (C + C.T))
        for dp in rng.standard_normal((draws_each, 6)) @ L.T:
            p = p0 + dp
            e = pose_error(make_T(R_from_rpy_deg(np.degrees(p[:3])), p[3:]), T_true, bs.scene.camera,
                           bs.check_points_lidar)
            rot.append(e.rotation_deg)
            tr.append(e.translation_norm_m)
            px.append(e.gt_pixel_px)
    return {"rotation_deg": float(np.mean(rot)), "translation_m": float(np.mean(tr)), "gt_px": float(np.nanmean(px))}


def _solver_sigma(T_true: np.ndarray, points_lidar: np.ndarray, noise_rad: float) -> np.ndarray:
    from calib_core.solve.refine import pose_covariance

    u = pose_covariance(T_true, points_lidar, noise_rad)
    return np.concatenate([u.sigma_rpy_deg, u.sigma_translation_m])


def _stats(errors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return errors.std(0, ddof=1), np.sqrt((errors**2).mean(0))


def cramer_rao_check(
    bs: BenchScene,
    sets: int,
    draws: int,
    n: int = 10,
    realistic_trials: list[TrialInput] | None = None,
    realistic_results: dict[str, list[TrialResult]] | None = None,
    methods=("angular", "pixel"),
    workers: int = 1,
) -> list[CrbRow]:
    """Empirical spread of the estimate vs the Cramer-Rao bound (see module docstring).

    Parameters
    ----------
    bs : BenchScene
    sets : int
        Fixed pair sets of the pure-click-noise experiment.
    draws : int
        Noise draws per set.
    n : int
        Pairs per set.
    realistic_trials, realistic_results : optional
        Trials of the accuracy sweep at this ``n`` and their results per
        method, for the realistic-picking rows.
    workers : int
        Processes for the solves.
    """
    from calib_core.solve import solve_extrinsics
    from calib_core.synthetic import simulate_pairs
    from calib_core.transforms import transform_points

    scene, cam = bs.scene, bs.scene.camera
    T_true = scene.T_camera_lidar
    rows: list[CrbRow] = []

    # --- pure click noise: exact laser points, 1 px Gaussian clicks.
    bounds, solver_sig, noise, jobs, covs = [], [], [], [], []
    for s in range(sets):
        rng = np.random.default_rng([BENCH_SEED, 77, s])
        pairs = simulate_pairs(scene, n, rng, pixel_noise_px=0.0)
        X, _, _ = resolve_pairs(pairs, scene.depth, cam)
        true_px, ok = cam.project(transform_points(T_true, X))
        if not ok.all():
            raise RuntimeError("a simulated corner does not project into the image under the true pose")
        b = cramer_rao(cam, T_true, X, PIXEL_NOISE_PX)
        covs.append(b.covariance)
        bounds.append(np.concatenate([b.sigma_rpy_deg, b.sigma_translation_m]) ** 2)
        # Isotropic angular noise equivalent to 1 px at these clicks (RMS over pairs and axes).
        nr = PIXEL_NOISE_PX * float(np.sqrt(np.mean(radians_per_pixel(cam, true_px) ** 2)))
        noise.append(nr)
        solver_sig.append(_solver_sigma(T_true, X, nr) ** 2)
        for _ in range(draws):
            clicks = true_px + rng.normal(0.0, PIXEL_NOISE_PX, true_px.shape)
            jobs.extend((m, X, clicks) for m in methods)

    def solve_draw(job):
        m, X, clicks = job
        try:
            res = solve_extrinsics(X, cam.bearing(clicks), camera=cam, pixels=clicks, cost=m)
        except CalibError:
            return m, None
        e = pose_error(res.T_camera_lidar, T_true)
        return m, np.concatenate([e.rpy_deg, e.translation_m])

    errs = {m: [] for m in methods}
    for m, e in parallel_map(solve_draw, jobs, workers):
        if e is not None:
            errs[m].append(e)
    bound = np.sqrt(np.mean(bounds, axis=0))
    ssig = np.sqrt(np.mean(solver_sig, axis=0))
    floor = efficiency_floor(bs, covs, max(20, 600 // len(covs)), 1)
    for m in methods:
        E = np.array(errs[m])
        std, rms = _stats(E)
        rows.append(CrbRow(f"pure 1 px click noise, exact laser points ({sets} sets x {draws} draws, n={n})",
                           m, len(E), std, rms, bound, ssig, float(np.mean(noise)), floor))

    # --- realistic picking: bound with the laser-side noise as pixel covariance.
    if realistic_trials and realistic_results:
        bounds, solver_sig, noise, covs = [], [], [], []
        for tr in realistic_trials:
            true_px, _ = cam.project(transform_points(T_true, tr.points_lidar))
            cov_l = None
            if tr.laser_rc is not None:
                cov_l = cell_pick_covariance(scene.depth, tr.laser_rc)
            b = cramer_rao(cam, T_true, tr.points_lidar, PIXEL_NOISE_PX, cov_l)
            covs.append(b.covariance)
            bounds.append(np.concatenate([b.sigma_rpy_deg, b.sigma_translation_m]) ** 2)
            # Equivalent isotropic angular noise: total pixel variance per axis times (rad/px)^2.
            from .crb import point_jacobian_px

            var_px = np.full(len(true_px), PIXEL_NOISE_PX**2)
            if cov_l is not None:
                Jx = point_jacobian_px(cam, T_true, tr.points_lidar)
                var_px = var_px + np.trace(Jx @ cov_l @ np.swapaxes(Jx, 1, 2), axis1=1, axis2=2) / 2.0
            rpp2 = np.mean(radians_per_pixel(cam, true_px) ** 2, axis=1)
            nr = float(np.sqrt(np.mean(var_px * rpp2)))
            noise.append(nr)
            solver_sig.append(_solver_sigma(T_true, tr.points_lidar, nr) ** 2)
        bound = np.sqrt(np.mean(bounds, axis=0))
        ssig = np.sqrt(np.mean(solver_sig, axis=0))
        floor = efficiency_floor(bs, covs, max(10, 600 // len(covs)), 2)
        for m, res_list in realistic_results.items():
            E = np.array([np.concatenate([r.error.rpy_deg, r.error.translation_m]) for r in res_list if r.ok])
            std, rms = _stats(E)
            rows.append(CrbRow(f"realistic picking: 1 px clicks + whole-cell laser picks (pick model) "
                               f"({len(realistic_trials)} trials, n={n})", m, len(E), std, rms, bound, ssig,
                               float(np.mean(noise)), floor))
    return rows
