"""The whole common-case solve in one compiled call: checks, whitening, start, LM, outlier test, report figures.

:func:`calib_core.solve.solve_extrinsics` spends most of a 10-pair solve in
Python glue (one numpy or numba call costs microseconds).  :func:`solve_fused`
does in one call what the general path does in many, and says when it cannot
give the same answer; the caller then runs the general path, which raises
the input error, starts from Quan & Lan / P3P, runs the robust search, etc.

Status codes (``status`` output):

* :data:`OK` -- the figures are final;
* :data:`BAD_INPUT` -- an input check failed (the general path names it);
* :data:`GENERAL` -- something only the general path handles: a narrow cone of
  bearings (its exact width is needed), a failed DLT start (n < 6, coplanar),
  a camera probe that does not project, a failed LM;
* :data:`ROBUST` -- a residual exceeds the outlier threshold: the robust
  search must run (never hidden: the general path finds and reports them).

numba keys the disk cache of :func:`solve_fused` by this file only, while it
compiles in the kernels it calls (:mod:`.kernels`,
:mod:`calib_core.cameras.kernels`): after editing those, touch this file (or
delete its ``__pycache__/fused.*.nb*``), or a stale compiled copy is loaded.
An installed package gets new files, so new timestamps, on every upgrade.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from ..cameras.kernels import project_model
from .kernels import (
    _lm,
    bearing_frames,
    covariance,
    dlt_pose,
    finish,
    pair_checks,
    probe_jacobians,
    rotation_sigma_deg,
    rpy_sigmas,
    tangent_probes,
)

__all__ = ["solve_fused", "OK", "BAD_INPUT", "GENERAL", "ROBUST", "UNIT_CODES"]

OK, BAD_INPUT, GENERAL, ROBUST = 0, 1, 2, 3
#: Residual units by code (the ``unit`` output).
UNIT_CODES = ("noise", "px", "sigma", "rad")
#: median(|z|^2) = 2 ln 2 sigma^2 for a 2-D Gaussian (as in :mod:`.robust`).
_MEDIAN_CHI2_2 = 2.0 * math.log(2.0)

# Layout of the ``info`` output.
I_ITER, I_NOISE_SCALE, I_MEAN_PX, I_STD_PX, I_N_OFF, I_COND, I_ROT_SIGMA, I_UNIT = range(8)
INFO_SIZE = 8


@kernel
def _mean_std_finite(x):
    m = 0
    s = 0.0
    for i in range(x.shape[0]):
        if np.isfinite(x[i]):
            s += x[i]
            m += 1
    if m == 0:
        return np.nan, np.nan
    mean = s / m
    v = 0.0
    for i in range(x.shape[0]):
        if np.isfinite(x[i]):
            v += (x[i] - mean) ** 2
    return mean, math.sqrt(v / m)


@kernel
def _store_pose(T, R, t):
    for a in range(3):
        for b in range(3):
            T[a, b] = R[a, b]
        T[a, 3] = t[a]
        T[3, a] = 0.0
    T[3, 3] = 1.0


@kernel
def solve_fused(P, B, pixels, has_pixels, model, prm, table, whiten_cam, sig, has_sig, noise, T_init, has_init,
                robust, k_in, prior, floor, tfac, max_iter, same_point_m, same_bearing_rad, unit_tol,
                collinear_ratio, cone_cos, step_rad, T, T0, cov, H, stats, residual_deg, rpx, st, sr, info,
                inliers_out):
    """Solve ``T_camera_lidar`` when the general path would not branch; else say why (status).

    Parameters
    ----------
    P, B : (N, 3) float64 C arrays
        Laser points (lidar frame, m) and bearings (camera frame, norms near 1).
    pixels : (N, 2) float64
        Clicked pixels (read when ``has_pixels``).
    model, prm, table
        The camera's ``compiled_projection``; ``model < 0``: no camera (no pixel errors).
    whiten_cam : bool
        Whiten by the camera (the ``"angular"`` cost); False: eq. 7 as printed.
    sig : (N,) float64
        Pixel sigmas (read when ``has_sig``).
    noise : float
        Known angular noise (rad), or <= 0 when unknown.
    T_init : (4, 4) float64
        Start pose (read when ``has_init``), else the DLT start.
    robust : bool
        Flag a residual beyond ``k_in`` times the noise scale (status ROBUST).
    k_in, prior, floor : float
        Outlier threshold in sigmas, the expected scale of the whitened
        residuals (<= 0: none, the median sets it) and its floor.
    tfac : float
        Student-t factor for ``2 N - 6`` degrees of freedom.
    max_iter : int
    same_point_m, same_bearing_rad, unit_tol, collinear_ratio, cone_cos, step_rad : float
        The thresholds of :mod:`.checks` (``cone_cos`` = cos of the cone width
        below which the general path must measure the cone) and of :mod:`.whiten`.

    T, T0, cov, H, stats, residual_deg, rpx, st, sr, info, inliers_out : arrays, written
        (outputs are passed in: boxing a dozen arrays on return would cost more than the solve).

    Returns
    -------
    status : int
        Outputs below are final only for :data:`OK`.
    T, T0 : (4, 4) final and start poses
    cov : (6, 6) covariance of ``(delta, t)``
    H : (6, 6) normal matrix
    stats : (7,) as :func:`.kernels.finish`
    residual_deg : (N,) geodesic angles, degrees
    rpx : (N,) pixel errors (NaN where not projectable or no camera)
    sigma_t, sigma_rpy : (3,) m, deg
    info : (INFO_SIZE,) iterations, noise scale, mean/std px, pairs off the image,
        condition number, rotation sigma (deg), unit code
    """
    n = P.shape[0]
    info[:] = np.nan
    # 1. Input checks (their messages come from the general path).
    bad_p, bad_b, norms, same_p, same_b, sv, cos_min = pair_checks(P, B, same_point_m, same_bearing_rad)
    if bad_p >= 0 or bad_b >= 0 or same_p[0] >= 0 or same_b[0] >= 0:
        return BAD_INPUT
    for i in range(n):
        if not (norms[i] >= 1e-12) or abs(norms[i] - 1.0) > unit_tol:
            return BAD_INPUT
    if sv[1] < collinear_ratio * sv[0]:
        return BAD_INPUT
    if has_pixels:
        for i in range(n):
            if not (np.isfinite(pixels[i, 0]) and np.isfinite(pixels[i, 1])):
                return BAD_INPUT
    if not (cos_min <= cone_cos):
        return GENERAL
    Bn = np.empty((n, 3))
    for i in range(n):
        for k in range(3):
            Bn[i, k] = B[i, k] / norms[i]
    F = bearing_frames(Bn)
    # 2. Whitening.
    W = np.zeros((n, 2, 2))
    if noise > 0.0:
        unit = 0
        for i in range(n):
            W[i, 0, 0] = W[i, 1, 1] = 1.0 / noise
    elif model >= 0 and whiten_cam:
        unit = 2 if has_sig else 1
        probes = tangent_probes(F, step_rad)
        uv = np.empty((4 * n, 2))
        ok_probe = np.empty(4 * n, dtype=np.bool_)
        project_model(model, prm, table, probes, uv, ok_probe)
        A, ok = probe_jacobians(uv, step_rad)
        for i in range(n):
            if not ok[i]:
                return GENERAL
        if has_sig:
            for i in range(n):
                for a in range(2):
                    for b in range(2):
                        W[i, a, b] = A[i, a, b] / sig[i]
        else:
            W = A
    else:
        unit = 3
        for i in range(n):
            s = sig[i] if has_sig else 1.0
            W[i, 0, 0] = W[i, 1, 1] = 1.0 / s
    info[I_UNIT] = unit
    # 3. Start and LM on all pairs.
    if has_init:
        R0 = np.ascontiguousarray(T_init[:3, :3])
        t0 = np.ascontiguousarray(T_init[:3, 3])
    else:
        R0, t0, ok_dlt = dlt_pose(P, Bn)
        if not ok_dlt:
            return GENERAL
    _store_pose(T0, R0, t0)
    R, t, it, lm_status, H_lm, cost = _lm(R0, t0, P, F, W, max_iter)
    if lm_status < 0:
        return GENERAL
    for a in range(3):
        for b in range(3):
            if not np.isfinite(R[a, b]):
                return GENERAL
        if not np.isfinite(t[a]):
            return GENERAL
    # 4. Report figures on all pairs (H is the LM's, at this very pose), then the outlier test as the
    # general path: the robust search when any residual is beyond the threshold.
    inliers = np.ones(n, dtype=np.bool_)
    z, theta, _, ssr, stats_in = finish(R, t, P, F, W, inliers, False)
    inliers_out[:] = True
    if robust:
        r2 = np.empty(n)
        r2max = 0.0
        for i in range(n):
            r2[i] = z[i, 0] ** 2 + z[i, 1] ** 2
            if not (r2[i] < r2max):
                r2max = r2[i] if np.isfinite(r2[i]) else np.inf
        if prior > 0.0:
            scale_ref = max(prior, floor)
        else:
            scale_ref = math.sqrt(np.median(r2) / _MEDIAN_CHI2_2) * (1.0 + 5.0 / max(n - 3.0, 1.0))
            scale_ref = max(scale_ref, floor)
        if r2max >= (k_in * scale_ref) ** 2:
            return ROBUST
    # 5. Covariance.
    H[:, :] = H_lm
    H_in = H_lm
    stats[:] = stats_in
    for i in range(n):
        residual_deg[i] = math.degrees(theta[i])
    dof = 2 * n - 6
    noise_scale = math.sqrt(ssr / dof) if dof > 0 else np.nan
    if noise > 0.0:
        sigma = 1.0
    elif dof > 0:
        sigma = noise_scale * tfac
    elif prior > 0.0:
        sigma = prior
    else:
        sigma = np.inf
    cov_in, cond = covariance(H_in, sigma)
    cov[:, :] = cov_in
    st_in, sr_in = rpy_sigmas(R, cov_in)
    st[:] = st_in
    sr[:] = sr_in
    info[I_ITER] = it
    info[I_NOISE_SCALE] = noise_scale
    info[I_COND] = cond
    info[I_ROT_SIGMA] = rotation_sigma_deg(cov_in)
    _store_pose(T, R, t)
    # 6. Pixel errors.
    n_off = 0
    rpx[:] = np.nan
    if model >= 0:
        clicked = pixels
        if not has_pixels:
            clicked = np.empty((n, 2))
            valid_b = np.empty(n, dtype=np.bool_)
            project_model(model, prm, table, Bn, clicked, valid_b)
            for i in range(n):
                if not valid_b[i]:
                    clicked[i, 0] = clicked[i, 1] = np.nan
        Pc = np.empty((n, 3))
        for i in range(n):
            for a in range(3):
                Pc[i, a] = R[a, 0] * P[i, 0] + R[a, 1] * P[i, 1] + R[a, 2] * P[i, 2] + t[a]
        uv_p = np.empty((n, 2))
        valid_p = np.empty(n, dtype=np.bool_)
        project_model(model, prm, table, Pc, uv_p, valid_p)
        for i in range(n):
            e = math.hypot(uv_p[i, 0] - clicked[i, 0], uv_p[i, 1] - clicked[i, 1])
            if valid_p[i] and np.isfinite(e):
                rpx[i] = e
            else:
                rpx[i] = np.nan
                n_off += 1
        info[I_MEAN_PX], info[I_STD_PX] = _mean_std_finite(rpx)
    info[I_N_OFF] = n_off
    return OK
