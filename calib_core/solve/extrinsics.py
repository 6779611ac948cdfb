"""The solve itself: :func:`solve_extrinsics` (the pipeline of :mod:`calib_core.solve`) and its warm-up."""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from ..errors import CalibError
from .bearing_pnp import initial_pose
from .checks import (
    CONDITION_WARNING,
    MIN_PAIRS,
    conditioning_warning,
    validate_initial_T,
    validate_pairs,
    validate_pixels,
)
from .kernels import (
    fit_and_report,
    fit_and_report_probes,
    fit_pose,
    fit_pose_laser,
    pixel_errors,
    pose_report,
    pose_report_points,
    probe_jacobians_all,
    whitened_residuals,
)
from .quality import Quality, geometry_reasons, orientation_notes
from .refine import (
    LM_MAX_ITER,
    lm_failure,
    pixel_jacobian,
    pixel_residuals,
    pose_covariance,
    refine_angular,
    refine_pose,
)
from .result import CalibrationResult
from .robust import inlier_k, robust_fit, robust_scale
from .edges import check_edge_deg, edge_tangent_jacobian, slide_along_edges
from .whiten import STEP_RAD, check_pixel_sigma, click_whitening_inputs, laser_tangent_covariance, whitening

__all__ = ["COSTS", "NOISY_FACTOR", "PRIOR_PX", "solve_extrinsics", "student_t_factor", "warm_up"]


#: Costs: "angular" = eq. 7 whitened by the camera (default), "geodesic" = eq. 7 as printed
#: (every ray weighed alike), "pixel" = eq. 6.
COSTS = ("angular", "geodesic", "pixel")
#: Floor of the noise scale (whitened units: px, sigmas, or radians without a camera).
_MIN_SCALE = {"px": 1e-3, "sigma": 1e-3, "noise": 1e-3, "rad": 1e-6}
#: Expected sigma per axis of a pair's pixel error (1 px click + the laser pick), px or sigmas.
PRIOR_PX = 1.5
#: Residual scale above this many times :data:`PRIOR_PX` gives a warning.
NOISY_FACTOR = 3.0


def _pixel_errors(camera: Any, points_camera: np.ndarray, pixels: np.ndarray,
                  inliers: np.ndarray, edges: np.ndarray | None = None) -> tuple[np.ndarray, float, float, int]:
    """Pixel errors (NaN where not projectable) of the laser points in the camera frame (metres), their mean
    and std over the inliers, and how many inliers have none (:func:`.kernels.pixel_errors`).  An edge pair's
    (``edges`` not NaN, degrees) is its distance across the edge (:func:`.edges.slide_along_edges`)."""
    projected, valid = camera.project(points_camera)
    projected = np.ascontiguousarray(projected, dtype=np.float64)
    pixels = slide_along_edges(projected, pixels, edges)
    return pixel_errors(projected, np.ascontiguousarray(valid, dtype=bool),
                        np.ascontiguousarray(pixels, dtype=np.float64), inliers)


@functools.lru_cache(maxsize=256)
def student_t_factor(dof: int) -> float:
    """Half-width of the 68.27 % Student-t interval with ``dof`` degrees of freedom, in sigmas.

    ``t_ppf(Phi(1), dof)``: the factor that makes +-1 reported sigma cover
    68.27 % when sigma is estimated from ``dof`` residual degrees of freedom.
    """
    from scipy.special import stdtrit  # (scipy.stats would add 1.4 s to the first solve's imports)

    return float(stdtrit(dof, 0.5 * (1.0 + math.erf(1.0 / math.sqrt(2.0)))))


def _check_pair_ids(pair_ids: object, n: int) -> list[int] | range:
    if pair_ids is None:
        return range(n)  # indexed like the list, without building it
    ids = np.asarray(pair_ids)
    if ids.shape != (n,) or not np.issubdtype(ids.dtype, np.integer):
        raise CalibError(f"pair_ids must be {n} whole numbers, one per pair, got {ids.dtype} of shape {ids.shape}")
    if len(set(ids.tolist())) != n:
        raise CalibError("pair_ids must be unique")
    return [int(i) for i in ids]


def _ids_text(ids: list[int]) -> str:
    shown = ", ".join(str(i) for i in ids[:8])
    return shown + (f" and {len(ids) - 8} more" if len(ids) > 8 else "")


_EYE3, _ZERO3, _NO_H, _EYE4 = np.eye(3), np.zeros(3), np.zeros((6, 6)), np.eye(4)
_NO_A, _NO_S, _NO_L = np.zeros((0, 2, 2)), np.zeros(0), np.zeros((0, 3, 3))  # fit_and_report without the laser term


def _pose_matrix(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = _EYE4.copy()  # (a copy of a template: np.eye costs more than the rest of this)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _corner_start(points: np.ndarray, bearings: np.ndarray, edges: np.ndarray, *, camera: Any,
                  pixels: np.ndarray | None, sigmas: np.ndarray | None, laser_cov: np.ndarray | None,
                  robust: bool) -> np.ndarray:
    """The start of a solve with edge pairs: the pose solved from its corner pairs alone (the closed-form
    starts use the bearings, and an edge pair's clicked bearing is anywhere along its edge)."""
    corner = np.isnan(edges)
    if corner.sum() < MIN_PAIRS:
        raise CalibError(
            f"edge pairs need at least {MIN_PAIRS} corner pairs to start from ({int(corner.sum())} of {len(edges)} "
            "pairs are corner pairs); add corner pairs or give an initial pose")
    try:
        start = solve_extrinsics(
            points[corner], bearings[corner], camera=camera, pixels=None if pixels is None else pixels[corner],
            pixel_sigma=None if sigmas is None else sigmas[corner],
            laser_cov_m2=None if laser_cov is None else laser_cov[corner], robust=robust)
    except CalibError as exc:
        raise CalibError(f"the corner pairs alone (the start for the edge pairs) cannot be solved: {exc}") from None
    return start.T_camera_lidar


def solve_extrinsics(
    points_lidar: np.ndarray,
    bearings_camera: np.ndarray,
    *,
    camera: Any = None,
    pixels: np.ndarray | None = None,
    cost: str = "angular",
    initial_T_camera_lidar: np.ndarray | None = None,
    noise_rad: float | None = None,
    pixel_sigma: np.ndarray | None = None,
    laser_cov_m2: np.ndarray | None = None,
    pair_ids: np.ndarray | list[int] | None = None,
    robust: bool = True,
    shared_ratio: float = 0.0,
    pixel_edge_deg: np.ndarray | None = None,
) -> CalibrationResult:
    """Estimate ``T_camera_lidar`` from n >= 4 laser-point / bearing pairs.

    Parameters
    ----------
    points_lidar : (N, 3) array_like
        Laser points in the lidar frame, metres.
    bearings_camera : (N, 3) array_like
        Unit bearings of the clicked pixels in the OpenCV camera frame; any
        direction on the sphere (also more than 90 deg off axis).
    camera : CameraModel, optional
        Whitens the angular residuals, and gives pixel residuals; needed for
        ``cost="pixel"``.
    pixels : (N, 2) array_like, optional
        Clicked ``(u, v)`` pixels.  With a camera but without pixels, the
        pixels of the bearings (``camera.project(bearings)``) are used.
    cost : {"angular", "geodesic", "pixel"}
        ``"angular"``: paper eq. 7 with each residual whitened by the
        camera's pixel-to-angle Jacobian (default; without a camera it is eq.
        7 as printed).  ``"geodesic"``: eq. 7 as printed, every ray weighed
        alike.  ``"pixel"``: reprojection error, eq. 6, for comparisons; it
        starts from the angular optimum.
    initial_T_camera_lidar : (4, 4) array_like, optional
        Start the refinement here instead of the closed-form initial pose.
    noise_rad : float, optional
        Known click noise (std of the bearing error along each tangent
        direction, radians).  The residuals are then divided by it (no camera
        whitening) and the covariance is ``(J^T J)^-1`` (the Cramer-Rao
        bound); otherwise the noise is estimated from the residuals.
    pixel_sigma : (N,) array_like, optional
        1-sigma of each click in pixels (a pair's ``precision_px``): weights
        the residuals (``1 / pixel_sigma``) and sets the expected noise for
        the outlier test.  None: all pairs alike, 1 px.  Without a camera it
        only sets relative weights.
    laser_cov_m2 : (N, 3, 3) array_like, optional
        Covariance of each laser point, metres^2, lidar frame (e.g. a
        whole-cell pick, :func:`calib_core.solve.whiten.cell_pick_covariance`).
        Its effect on the bearing, at the current pose, is added to the click
        noise in the whitening.  Needs a camera; None: laser points exact.
    pair_ids : (N,) array_like of int, optional
        Ids of the pairs, used in messages and in ``outlier_ids``; default
        their positions.  ``outliers`` always holds positions.
    robust : bool
        Find and leave out gross outliers (default).  False fits all pairs.
    shared_ratio : float
        Variance of the part of the pairs' errors that they share (a pose-like error the fit absorbs
        whole, so the residuals cannot show it), as a ratio to the independent part's: the covariance,
        the sigmas and the quality's uncertainty checks are taken ``1 + shared_ratio`` times wider
        (:data:`calib_core.solve.whiten.BY_EYE_SHARED_RATIO` for picks by eye, which
        :func:`calib_core.solve.calibrate` uses).  Default 0: the errors are independent (simulated
        clicks, a known ``noise_rad``).
    pixel_edge_deg : (N,) array_like, optional
        Edge pairs (:attr:`calib_core.pairs.Pair.edge_deg`): the angle (degrees from +u towards +v) of
        the straight image edge a pair's pixel lies on and may slide along; NaN for an ordinary (corner)
        pair.  The click's covariance is then ``sigma^2 (n n^T + k^2 t t^T)`` px^2 (``t`` the edge's
        direction, ``n`` its normal, ``k`` = :data:`calib_core.solve.edges.EDGE_SLIDE`).  Edge pairs need
        ``cost="angular"`` with a camera and no ``noise_rad``, and, without ``initial_T_camera_lidar``, at
        least 4 corner pairs: the start is solved from the corner pairs alone (an edge pair's bearing is
        not its laser point's).

    Returns
    -------
    CalibrationResult
        ``residual_px``, ``mean_px`` and ``std_px`` of an edge pair count its distance ACROSS the edge,
        ``|(projected - clicked) . n|``: the along-edge offset is no error.  Always check ``result.quality.status``: ``"unreliable"`` means the
        pose must not be used (the reasons say why).

    Raises
    ------
    CalibError
        Degenerate or malformed input (see
        :func:`calib_core.solve.checks.validate_pairs`), a missing camera or
        pixels for ``cost="pixel"``, or a failed refinement (with the reason).
    """
    if cost not in COSTS:
        raise CalibError(f"unknown cost {cost!r}; use one of {', '.join(COSTS)}")
    whiten_camera = camera if cost != "geodesic" else None
    by_camera = whiten_camera is not None and noise_rad is None  # whitening by the camera's tangent Jacobian
    # The checks, the bearings' frames and (by_camera) the probes of the camera's tangent Jacobian in one call.
    points, bearings, warnings, frames, probes = validate_pairs(points_lidar, bearings_camera,
                                                                STEP_RAD if by_camera else 0.0)
    n = len(points)
    ids = _check_pair_ids(pair_ids, n)
    sigmas = check_pixel_sigma(pixel_sigma, n)
    laser_cov = None
    if laser_cov_m2 is not None:
        laser_cov = np.ascontiguousarray(laser_cov_m2, dtype=np.float64)
        if laser_cov.shape != (n, 3, 3) or not math.isfinite(float(laser_cov.sum())):  # (a NaN or inf spreads)
            raise CalibError(f"laser_cov_m2 must be {n} finite 3x3 covariances, got shape {laser_cov.shape}")
    given_ratio = shared_ratio
    try:
        shared_ratio = float(shared_ratio)
    except (TypeError, ValueError):
        shared_ratio = math.nan
    if not (math.isfinite(shared_ratio) and shared_ratio >= 0):
        raise CalibError(f"shared_ratio must be a number >= 0, got {given_ratio!r}")
    if noise_rad is not None and not (np.isfinite(noise_rad) and noise_rad > 0):
        raise CalibError(f"noise_rad must be a positive number, got {noise_rad!r}")
    if pixels is not None:
        pixels = validate_pixels(pixels, n)
    if cost == "pixel":
        if camera is None or pixels is None:
            raise CalibError("cost='pixel' needs a camera and the clicked pixels")
    edges = check_edge_deg(pixel_edge_deg, n)
    if edges is not None and not (by_camera and cost == "angular"):
        raise CalibError("edge pairs (pixel_edge_deg) need cost='angular' with a camera and no noise_rad: "
                         "their weight comes from the camera's pixels")

    # 1. Whitening, computed once per solve (its laser term, which depends on the pose, inside the LM).
    tangent = []  # tangent_to_pixel of the camera at the bearings: pose-free, computed once
    all_ok = False
    given = None if initial_T_camera_lidar is None else validate_initial_T(initial_T_camera_lidar)
    if edges is not None and given is None:
        given = _corner_start(points, bearings, edges, camera=camera, pixels=pixels, sigmas=sigmas,
                              laser_cov=laser_cov, robust=robust)
    use_dlt = given is None
    R_in = _EYE3 if use_dlt else np.ascontiguousarray(given[:3, :3])
    t_in = _ZERO3 if use_dlt else np.ascontiguousarray(given[:3, 3])
    fused = None  # fit_and_report's outputs when the call below made them
    if by_camera:
        uv = np.ascontiguousarray(whiten_camera.project(probes)[0], dtype=np.float64)
        if cost != "pixel" and edges is None:
            # The camera's tangent Jacobian (whiten.tangent_to_pixel), and where every pair has one, step 2 and
            # (fit_and_report) steps 3-4 below, in one compiled call; the expected noise as for all_ok below.
            laser = laser_cov is not None
            dof = 2 * n - 6
            A, ok, all_ok, *fused = fit_and_report_probes(
                points, bearings, frames, uv, STEP_RAD, _NO_S if sigmas is None else np.ascontiguousarray(sigmas),
                laser_cov if laser else _NO_L, laser, R_in, t_in, use_dlt, LM_MAX_ITER, robust,
                (inlier_k(n) * max(PRIOR_PX, _MIN_SCALE["px"])) ** 2, student_t_factor(dof) if dof > 0 else 1.0,
                float(PRIOR_PX))
            if not all_ok:
                fused = None
        else:
            A, ok, all_ok = probe_jacobians_all(uv, STEP_RAD)
            if edges is not None:
                # M^-1 A: the click's covariance sigma^2 (n n^T + k^2 t t^T) through all that follows (.edges).
                A = edge_tangent_jacobian(A, edges)
        tangent.append((A, ok))

    def whiten(T_at: np.ndarray | None) -> tuple[np.ndarray, str]:
        lt = None
        if laser_cov is not None and T_at is not None and whiten_camera is not None:
            lt = laser_tangent_covariance(T_at, points, frames, laser_cov)
        return whitening(n, camera=whiten_camera, frames=frames, pixel_sigma=sigmas, noise_rad=noise_rad,
                         laser_tangent_cov=lt, tangent=tangent[0] if tangent else None)

    # whitening()'s common case (W = A, px) without its call, and none where fit_and_report_probes had it.
    if fused is not None and fused[7]:  # (its report is done: no further use for W)
        W, unit = None, "px" if sigmas is None else "sigma"
    else:
        W, unit = (tangent[0][0], "px") if all_ok and sigmas is None else whiten(None)
    # Expected scale of the whitened residuals, for the outlier test: the known noise, or the
    # click noise plus the laser pick (whole-cell picks add about 1 px; measured 0.76 px on the sample).
    prior = {"px": PRIOR_PX, "sigma": PRIOR_PX, "noise": 1.0}.get(unit)
    floor = _MIN_SCALE[unit]

    laser_term = laser_cov is not None and whiten_camera is not None
    # The clicks' whitening inputs, from which the LM re-whitens with the laser term inside its one
    # compiled call (fit_pose_laser); None where the laser term cannot enter (known noise_rad, no
    # projectable probe), as in whitening().
    clicks = None
    if laser_term and tangent and noise_rad is None:
        # (sigmas None: 1 px each, the ones made where they are used)
        clicks = ((tangent[0][0], None if sigmas is None else np.ascontiguousarray(sigmas)) if all_ok
                  else click_whitening_inputs(tangent[0], sigmas))

    # 2. Initial pose (the linear DLT on the bearings when it applies, n >= 6 and not coplanar, else
    # Quan & Lan / P3P) and LM on all pairs, in one compiled call (fit_pose, or fit_pose_laser with the
    # laser term: the LM re-whitens at each pose it tries, until it is near the optimum).
    def fit(T_start: np.ndarray | None, W: np.ndarray, laser: bool
            ) -> tuple[np.ndarray, int, np.ndarray | None, np.ndarray, np.ndarray, str, np.ndarray | None]:
        """LM from ``T_start`` (None: from the DLT, or the closed-form start where it does not apply).

        ``(T, iterations, H, z, T_start, start method, W)``, ``W`` the laser term's whitening it ended
        with (None: not re-whitened); a failed LM keeps ``T_start`` (H None), or raises when ``robust`` is off.
        """
        method = "given"
        use_dlt = T_start is None
        R_in = _EYE3 if use_dlt else np.ascontiguousarray(T_start[:3, :3])
        t_in = _ZERO3 if use_dlt else np.ascontiguousarray(T_start[:3, 3])
        W_new = None
        if laser:
            R, t, R0, t0, it, status, H, z, W_new = fit_pose_laser(
                points, bearings, frames, clicks[0], np.ones(n) if clicks[1] is None else clicks[1], laser_cov, R_in,
                t_in, use_dlt, LM_MAX_ITER)
        else:
            R, t, R0, t0, it, status, H, z = fit_pose(points, bearings, frames, W, R_in, t_in, use_dlt, LM_MAX_ITER)
        if use_dlt:
            if status == -3:
                # Quan & Lan / P3P: the start where the linear DLT does not apply (n < 6, coplanar points).
                T_closed, method, init_cost = initial_pose(points, bearings)
                if not np.isfinite(init_cost):
                    raise CalibError("no initial pose found from these pairs (all closed-form solutions failed)")
                out = fit(T_closed, W, laser)
                return out[:5] + (method,) + out[6:]
            T_start, method = _pose_matrix(R0, t0), "dlt"
        failure = lm_failure(status, R, t) if status < 0 else None  # (fit_pose: -2 for a non-finite pose)
        if failure and laser:
            return fit(T_start, W, False)[:5] + (method, None)  # the laser term then as below, after this LM
        if failure:
            if not robust:
                raise CalibError(failure)
            z, _ = whitened_residuals(np.ascontiguousarray(T_start[:3, :3]), np.ascontiguousarray(T_start[:3, 3]),
                                      points, frames, W)
            return T_start, 0, None, z, T_start, method, None
        return _pose_matrix(R, t), int(it), H, z, T_start, method, W_new

    # The common case in one compiled call (fit_and_report): the LM from the DLT or the given start and,
    # where no residual calls for the outlier search, the report at its optimum (steps 3-4 below skipped).
    # Elsewhere (no prior noise scale, the pixel cost, a failed LM or DLT: the closed-form start) fit()
    # does it step by step.
    fused_report = None
    fitted = None
    if fused is None and cost != "pixel" and prior is not None and (clicks is not None or not laser_term):
        laser = clicks is not None
        dof = 2 * n - 6
        fused = fit_and_report(
            points, bearings, frames, W, clicks[0] if laser else _NO_A,
            clicks[1] if laser and clicks[1] is not None else _NO_S, laser_cov if laser else _NO_L, laser, R_in, t_in,
            use_dlt, LM_MAX_ITER, robust, (inlier_k(n) * max(prior, floor)) ** 2, noise_rad is not None,
            student_t_factor(dof) if dof > 0 else 1.0, float(prior))
    if fused is not None:
        T_f, T_start_f, it_f, status_f, H_f, z_f, W_f, done, *fused_report = fused
        if status_f >= 0:
            fitted = (T_f, int(it_f), H_f, z_f, T_start_f if use_dlt else given, "dlt" if use_dlt else "given",
                      W_f if clicks is not None else None)
        if not done:
            fused_report = None
    # H_at_T: the LM's normal matrix while T is the LM's optimum on all pairs with this W (else None).
    T, iterations, H_at_T, z, T_init, method, W_laser = fit(given, W, clicks is not None) if fitted is None else fitted
    if W_laser is not None:
        W = W_laser
    elif laser_term and fused_report is None:  # (fit_and_report's report: W has no further use)
        # The laser term depends on the pose: whiten at the first optimum and refine once more (where
        # the fused LM did not run or failed).
        W, unit = whiten(T)
        T, more, H_at_T, z, _, _, _ = fit(T, W, False)
        iterations += more
    if fused_report is not None:  # (fit_and_report did steps 3 and 4: no outlier search, all pairs in)
        inliers, hypotheses, searched, idx, n_in = np.ones(n, dtype=bool), 0, False, np.arange(n), n
        theta, H, stats, noise_scale, cov, condition, sigma_t, sigma_rpy, sigma_rotation, *points_camera = fused_report
    else:
        r2 = z[:, 0] ** 2 + z[:, 1] ** 2

        # 3. Outliers: only searched for when some residual is far above the noise scale.
        # With a prior (expected click noise), any pair beyond it is suspect; without one, the
        # median residual sets the scale.  A noisier-than-expected set just takes the robust path.
        inliers = np.ones(n, dtype=bool)
        hypotheses = 0
        searched = False
        scale_ref = max(prior, floor) if prior is not None else max(robust_scale(r2), floor)
        if robust and r2.max() >= (inlier_k(n) * scale_ref) ** 2:
            fit = robust_fit(points, bearings, frames, W, prior, T[:3, :3], T[:3, 3], min_scale=floor)
            hypotheses, searched = fit.hypotheses, True
            iterations += fit.iterations
            H_at_T = None
            if fit.inliers.sum() >= 3:
                inliers = fit.inliers
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = fit.R, fit.t
            if laser_cov is not None and whiten_camera is not None:
                # The laser term depends on the pose: whiten at the robust pose and refine once more.
                W, unit = whiten(T)
                keep = np.flatnonzero(inliers)
                if keep.size >= 3:
                    T, more = refine_angular(T, points[keep], frames[keep], W[keep])
                    iterations += more
        idx = np.flatnonzero(inliers) if searched else np.arange(n)  # (no search ran: all pairs are in)
        n_in = idx.size
        if cost == "pixel" and n_in >= 3:
            bad = np.nonzero(~np.all(np.isfinite(pixels[idx]), axis=1))[0]
            if bad.size:
                raise CalibError(f"cost='pixel': pairs {bad.tolist()} have no finite pixel")
            T, more = refine_pose(
                T, points[idx], bearings[idx], cost="pixel", camera=camera, pixels=pixels[idx],
                pixel_sigma=None if sigmas is None else sigmas[idx],
            )
            iterations += more

        # 4. Covariance on the inliers: Student-t sigma from the residuals, or the known noise.
        R_hat, t_hat = T[:3, :3].copy(), T[:3, 3].copy()
        dof = 2 * n_in - 6
        lm_at_T = H_at_T is not None and cost != "pixel" and n_in == n  # the LM's H and z are at T, with this W
        H_known, ssr_known = (H_at_T, -1.0) if lm_at_T else (None, -1.0)
        if cost == "pixel":
            x_opt = np.concatenate([np.zeros(3), t_hat])
            inv_s = 1.0 if sigmas is None else np.repeat(1.0 / sigmas[idx], 2)[:, None]
            J = pixel_jacobian(x_opt, R_hat, points[idx], pixels[idx], camera) * inv_s
            rp = pixel_residuals(x_opt, R_hat, points[idx], pixels[idx], camera).ravel() * np.ravel(inv_s)
            J = np.where(np.isfinite(J), J, 0.0)
            H_known, ssr_known = J.T @ J, float(np.nansum(rp**2))
            if noise_rad is not None:
                warnings.append("noise_rad is ignored with cost='pixel'; sigma comes from the pixel residuals")
        report = pose_report_points if camera is not None else pose_report  # (+ the points in the camera frame)
        theta, H, stats, noise_scale, cov, condition, sigma_t, sigma_rpy, sigma_rotation, *points_camera = report(
            R_hat, t_hat, points, frames, W, inliers, _NO_H if H_known is None else H_known, H_known is not None,
            ssr_known, noise_rad is not None and cost != "pixel", student_t_factor(dof) if dof > 0 else 1.0,
            float(prior) if prior is not None else math.inf,  # no redundancy: the expected noise
            *((z,) if lm_at_T else ()),
        )
    noise_scale = float(noise_scale)
    if shared_ratio:
        # The shared part moves the pose as the independent part does, shared_ratio times as much in variance
        # (whiten.BY_EYE_SHARED_RATIO): every figure of the uncertainty widens alike, before the quality checks.
        widen = 1.0 + shared_ratio
        cov, sigma_t, sigma_rpy = cov * widen, sigma_t * math.sqrt(widen), sigma_rpy * math.sqrt(widen)
        sigma_rotation = sigma_rotation * math.sqrt(widen)

    # 5. Report.
    residual_deg = np.degrees(theta)
    if camera is not None:
        if pixels is None:
            projected, valid = camera.project(bearings)
            pixels = np.where(np.asarray(valid, dtype=bool)[:, None], np.asarray(projected, dtype=np.float64), np.nan)
        residual_px, mean_px, std_px, n_off = _pixel_errors(camera, points_camera[0], pixels, inliers, edges)
        if n_off:
            off = np.flatnonzero(~np.isfinite(residual_px[idx]))
            warnings.append(
                f"pairs {_ids_text([ids[idx[i]] for i in off])} do not reproject into the image; their pixel error is NaN"
            )
    else:
        residual_px, mean_px, std_px = np.full(n, np.nan), math.nan, math.nan
    mean_deg, std_deg = math.degrees(stats[0]), math.degrees(stats[1])
    outliers = np.flatnonzero(~inliers).tolist() if searched else []
    outlier_ids = [ids[i] for i in outliers]

    unreliable: list[str] = []
    if outliers:
        if n_in < MIN_PAIRS:
            unreliable.append(f"only {n_in} of {n} pairs agree on one pose; at least {MIN_PAIRS} are needed")
        elif 2 * n_in <= n:
            unreliable.append(
                f"only {n_in} of {n} pairs agree on one pose: with half of the pairs or more left out, "
                "no consensus can be trusted"
            )
        worst = sorted(outliers, key=lambda i: -residual_deg[i])[:5]
        sizes = ", ".join(
            f"{residual_px[i]:.1f} px" if np.isfinite(residual_px[i]) else f"{residual_deg[i]:.2f} deg" for i in worst
        )
        warnings.insert(
            0,
            f"pairs {_ids_text(outlier_ids)} left out as outliers (largest errors {sizes}); check these clicks",
        )
    if not condition <= CONDITION_WARNING:
        weak = conditioning_warning(H)
        if weak:
            warnings.append(weak)
    cov_t = np.asarray(cov, dtype=np.float64)[3:, 3:]
    worst_t = math.sqrt(max(float(np.linalg.eigvalsh(cov_t)[-1]), 0.0)) if np.isfinite(cov_t).all() else math.inf
    bad_geo, weak_geo = geometry_reasons(stats[3:6], n_in, sigma_rotation, sigma_t, float(stats[2]), worst_t,
                                         goal=shared_ratio > 0)
    unreliable += bad_geo
    warnings += weak_geo
    if unit == "px" and np.isfinite(noise_scale) and noise_scale > NOISY_FACTOR * prior:
        warnings.append(
            f"the pairs fit to {noise_scale:.1f} px (1 sigma per axis), over {NOISY_FACTOR:g}x the {PRIOR_PX:g} px "
            "expected of clicks and laser picks: check the camera model and the picks")
    notes = orientation_notes(T[:3, :3])  # about the output's form, not the calibration's quality
    quality = Quality.from_reasons(unreliable, warnings)
    return CalibrationResult(
        T_camera_lidar=T,
        initial_T_camera_lidar=T_init,
        covariance_6x6=cov,
        sigma_translation_m=sigma_t,
        sigma_rpy_deg=sigma_rpy,
        residual_deg=residual_deg,
        residual_px=residual_px,
        mean_px=mean_px,
        std_px=std_px,
        mean_deg=mean_deg,
        std_deg=std_deg,
        n_pairs=n,
        warnings=list(quality.reasons) + notes,
        outliers=outliers,
        outlier_ids=outlier_ids,
        inliers=inliers,
        quality=quality,
        iterations=iterations,
        cost_name=cost,
        initial_method=method,
        noise_scale=noise_scale,
        residual_unit=unit,
        hypotheses=hypotheses,
    )


def warm_up() -> float:
    """Compile (or load from numba's cache) every solve kernel; returns the seconds it took.

    The first call of a numba kernel compiles it (seconds) or loads it from
    the on-disk cache (``cache=True``, milliseconds); call this once in a
    background thread at start-up so that the first click never waits.
    """
    import time

    from .._jit import compiling

    t0 = time.perf_counter()
    with compiling():
        from ..cameras.pinhole import PinholeCamera  # whitening through a camera

        rng = np.random.default_rng(0)
        d = rng.normal(size=(8, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        points = d * rng.uniform(2, 8, (8, 1))
        bearings = d.copy()
        bearings[0] = -bearings[0]  # one outlier: runs the robust path too
        solve_extrinsics(points, bearings)  # DLT start, LM, robust search (P3P), report
        solve_extrinsics(points[1:6], d[1:6])  # 5 pairs: Quan & Lan start (rigid fit)
        cam = PinholeCamera(np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]]), np.zeros(5), 640, 480)
        front = d.copy()
        front[:, 2] = np.abs(front[:, 2]) + 1.0
        front /= np.linalg.norm(front, axis=1, keepdims=True)
        solve_extrinsics(front * 4.0, front, camera=cam, laser_cov_m2=np.broadcast_to(1e-4 * np.eye(3), (8, 3, 3)))
        pose_covariance(np.eye(4), points, 1e-3)
    return time.perf_counter() - t0

