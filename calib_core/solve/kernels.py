"""Compiled kernels of the angular solve (numba, ``cache=True``).

One implementation of each hot path (there is no pure-numpy twin):

* :func:`whitened_residuals` -- the whitened log-map residual of every pair;
* :func:`normal_equations` -- ``H = J^T J``, ``g = J^T z`` and the cost at a pose;
* :func:`jacobian` -- the ``(2N, 6)`` whitened Jacobian (covariance, tests);
* :func:`lm_refine` -- Levenberg-Marquardt on the 6x6 normal equations;
* :func:`score_poses` -- squared whitened residuals of many candidate poses (RANSAC);
* :func:`dlt_pose` -- a linear initial pose from the bearings (n >= 6).

Residual of pair i (paper eq. 7, smooth at 0): with ``y = F_i (R p_i + t)``
(``F_i`` rows ``e1, e2, b_i``), ``theta = atan2(|y_12|, y_3)`` and
``r_i = theta / sin(theta) * y_12 / |y|``, so ``|r_i| = theta``.  The whitened
residual is ``z_i = W_i r_i`` with ``W_i`` (2x2) from
:mod:`calib_core.solve.whiten`.  Pose updates are left perturbations,
``R <- exp([delta]_x) R``, ``t <- t + dt``; the Jacobian is taken at
``delta = 0``, columns ``(delta_x, delta_y, delta_z, t_x, t_y, t_z)``.
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable
from .._jit import tiered_kernel as kernel

__all__ = [
    "whitened_residuals",
    "normal_equations",
    "jacobian",
    "lm_refine",
    "score_poses",
    "dlt_pose",
    "so3_exp",
]


@kernel
def so3_exp(phi):
    """``exp([phi]_x)`` (Rodrigues), with the Taylor series near 0."""
    x, y, z = phi[0], phi[1], phi[2]
    th2 = x * x + y * y + z * z
    if th2 < 1e-8:
        c = 1.0 - th2 / 2.0 + th2 * th2 / 24.0
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        c = math.cos(th)
        a = math.sin(th) / th
        b = (1.0 - c) / th2
    R = np.empty((3, 3))
    R[0, 0] = c + b * x * x
    R[0, 1] = b * x * y - a * z
    R[0, 2] = b * x * z + a * y
    R[1, 0] = b * x * y + a * z
    R[1, 1] = c + b * y * y
    R[1, 2] = b * y * z - a * x
    R[2, 0] = b * x * z - a * y
    R[2, 1] = b * y * z + a * x
    R[2, 2] = c + b * z * z
    return R


#: Below this ratio |y_12| / y_3 the residual's factor ``theta / |y_12|`` comes from its series (no atan2).
_SERIES_X = 0.05


@kernel
def _pair(R, t, P, F, W, i, out_z, out_J, want_J):
    """Whitened residual (2,) of pair ``i`` into ``out_z`` and, if asked, its Jacobian (2, 6) into ``out_J``.

    Whole arrays and an index rather than row views: numba's views cost as
    much as the arithmetic here.  Returns the geodesic angle (radians).  With ``rho = |y_12|``, the residual
    is ``r = phi y_12``, ``phi = atan2(rho, y_3) / rho``; ``dr/dy = [phi I +
    kappa y_12 y_12^T | -y_12 / |y|^2]`` with ``kappa = (y_3 / |y|^2 - phi) / rho^2``.
    Near the axis (``x = rho / y_3 < 0.05``, every pair of a converging solve)
    both come from their series in ``x^2`` (relative error < 1e-14), without atan2.
    """
    p0, p1, p2 = P[i, 0], P[i, 1], P[i, 2]
    a0 = R[0, 0] * p0 + R[0, 1] * p1 + R[0, 2] * p2
    a1 = R[1, 0] * p0 + R[1, 1] * p1 + R[1, 2] * p2
    a2 = R[2, 0] * p0 + R[2, 1] * p1 + R[2, 2] * p2
    P0, P1, P2 = a0 + t[0], a1 + t[1], a2 + t[2]
    y0 = F[i, 0, 0] * P0 + F[i, 0, 1] * P1 + F[i, 0, 2] * P2
    y1 = F[i, 1, 0] * P0 + F[i, 1, 1] * P1 + F[i, 1, 2] * P2
    y2 = F[i, 2, 0] * P0 + F[i, 2, 1] * P1 + F[i, 2, 2] * P2
    rho2 = y0 * y0 + y1 * y1
    n2 = rho2 + y2 * y2
    if y2 > 0.0 and rho2 < (_SERIES_X * _SERIES_X) * (y2 * y2):
        x2 = rho2 / (y2 * y2)
        inv = 1.0 / y2
        # atan(x) / x and (1 / (1 + x^2) - atan(x) / x) / x^2, to x^8.
        f = 1.0 - x2 * (1.0 / 3.0 - x2 * (1.0 / 5.0 - x2 * (1.0 / 7.0 - x2 * (1.0 / 9.0))))
        q = -2.0 / 3.0 + x2 * (4.0 / 5.0 - x2 * (6.0 / 7.0 - x2 * (8.0 / 9.0 - x2 * (10.0 / 11.0))))
        phi = f * inv
        kappa = q * inv * inv * inv
        theta = f * math.sqrt(rho2) * inv
    else:
        rho = math.sqrt(rho2)
        theta = math.atan2(rho, y2)
        if rho > 0.0:
            phi = theta / rho
            kappa = (y2 / n2 - phi) / rho2
        else:  # on the axis, behind: no direction to rotate in
            phi = 0.0
            kappa = 0.0
    wy0 = W[i, 0, 0] * y0 + W[i, 0, 1] * y1
    wy1 = W[i, 1, 0] * y0 + W[i, 1, 1] * y1
    out_z[0] = phi * wy0
    out_z[1] = phi * wy1
    if want_J:
        # dz/dP = W dr/dy F = phi W F_12 + (W y_12) v^T, v = kappa F_12^T y_12 - F_3 / |y|^2.
        inv_n2 = 1.0 / n2
        for k in range(3):
            v = kappa * (y0 * F[i, 0, k] + y1 * F[i, 1, k]) - F[i, 2, k] * inv_n2
            out_J[0, 3 + k] = phi * (W[i, 0, 0] * F[i, 0, k] + W[i, 0, 1] * F[i, 1, k]) + wy0 * v
            out_J[1, 3 + k] = phi * (W[i, 1, 0] * F[i, 0, k] + W[i, 1, 1] * F[i, 1, k]) + wy1 * v
        # d(exp(delta) R p)/d delta = -[R p]_x: a row d times -[a]_x is a x d.
        for row in range(2):
            d0, d1, d2 = out_J[row, 3], out_J[row, 4], out_J[row, 5]
            out_J[row, 0] = a1 * d2 - a2 * d1
            out_J[row, 1] = a2 * d0 - a0 * d2
            out_J[row, 2] = a0 * d1 - a1 * d0
    return theta


@kernel
def whitened_residuals(R, t, P, F, W):
    """Whitened residuals ``(N, 2)`` and geodesic angles ``(N,)`` (radians) at pose ``(R, t)``."""
    n = P.shape[0]
    z = np.empty((n, 2))
    theta = np.empty(n)
    Jdummy = np.empty((2, 6))
    zi = np.empty(2)
    for i in range(n):
        theta[i] = _pair(R, t, P, F, W, i, zi, Jdummy, False)
        z[i, 0], z[i, 1] = zi[0], zi[1]
    return z, theta


@kernel
def jacobian(R, t, P, F, W):
    """Whitened Jacobian ``(2N, 6)`` at ``(R, t)`` w.r.t. ``(delta, t)`` (left perturbation, delta = 0)."""
    n = P.shape[0]
    J = np.empty((2 * n, 6))
    z = np.empty(2)
    for i in range(n):
        _pair(R, t, P, F, W, i, z, J[2 * i : 2 * i + 2], True)
    return J


@kernel
def normal_equations(R, t, P, F, W):
    """``H = J^T J`` (6, 6), ``g = J^T z`` (6,) and ``cost = sum |z_i|^2`` at ``(R, t)``."""
    return _normal_equations_into(R, t, P, F, W, np.empty((P.shape[0], 2)))


@kernel
def _normal_equations_into(R, t, P, F, W, Z):
    """:func:`normal_equations`, also writing the whitened residuals into ``Z`` (N, 2).

    The 21 distinct entries of ``H`` and the 6 of ``g`` are summed in scalars (registers),
    not in arrays: about half the time per pair."""
    h00 = h01 = h02 = h03 = h04 = h05 = h11 = h12 = h13 = h14 = h15 = h22 = h23 = h24 = h25 = h33 = h34 = h35 = h44 = h45 = h55 = 0.0
    g0 = g1 = g2 = g3 = g4 = g5 = 0.0
    cost = 0.0
    z = np.empty(2)
    J = np.empty((2, 6))
    for i in range(P.shape[0]):
        _pair(R, t, P, F, W, i, z, J, True)
        z0, z1 = z[0], z[1]
        Z[i, 0], Z[i, 1] = z0, z1
        cost += z0 * z0 + z1 * z1
        u0, u1, u2, u3, u4, u5 = J[0, 0], J[0, 1], J[0, 2], J[0, 3], J[0, 4], J[0, 5]
        v0, v1, v2, v3, v4, v5 = J[1, 0], J[1, 1], J[1, 2], J[1, 3], J[1, 4], J[1, 5]
        g0 += u0 * z0 + v0 * z1
        g1 += u1 * z0 + v1 * z1
        g2 += u2 * z0 + v2 * z1
        g3 += u3 * z0 + v3 * z1
        g4 += u4 * z0 + v4 * z1
        g5 += u5 * z0 + v5 * z1
        h00 += u0 * u0 + v0 * v0
        h01 += u0 * u1 + v0 * v1
        h02 += u0 * u2 + v0 * v2
        h03 += u0 * u3 + v0 * v3
        h04 += u0 * u4 + v0 * v4
        h05 += u0 * u5 + v0 * v5
        h11 += u1 * u1 + v1 * v1
        h12 += u1 * u2 + v1 * v2
        h13 += u1 * u3 + v1 * v3
        h14 += u1 * u4 + v1 * v4
        h15 += u1 * u5 + v1 * v5
        h22 += u2 * u2 + v2 * v2
        h23 += u2 * u3 + v2 * v3
        h24 += u2 * u4 + v2 * v4
        h25 += u2 * u5 + v2 * v5
        h33 += u3 * u3 + v3 * v3
        h34 += u3 * u4 + v3 * v4
        h35 += u3 * u5 + v3 * v5
        h44 += u4 * u4 + v4 * v4
        h45 += u4 * u5 + v4 * v5
        h55 += u5 * u5 + v5 * v5
    H = np.empty((6, 6))
    H[0, 0] = h00
    H[0, 1] = H[1, 0] = h01
    H[0, 2] = H[2, 0] = h02
    H[0, 3] = H[3, 0] = h03
    H[0, 4] = H[4, 0] = h04
    H[0, 5] = H[5, 0] = h05
    H[1, 1] = h11
    H[1, 2] = H[2, 1] = h12
    H[1, 3] = H[3, 1] = h13
    H[1, 4] = H[4, 1] = h14
    H[1, 5] = H[5, 1] = h15
    H[2, 2] = h22
    H[2, 3] = H[3, 2] = h23
    H[2, 4] = H[4, 2] = h24
    H[2, 5] = H[5, 2] = h25
    H[3, 3] = h33
    H[3, 4] = H[4, 3] = h34
    H[3, 5] = H[5, 3] = h35
    H[4, 4] = h44
    H[4, 5] = H[5, 4] = h45
    H[5, 5] = h55
    g = np.array([g0, g1, g2, g3, g4, g5])
    return H, g, cost


@kernel
def lm_refine(R0, t0, P, F, W, max_iter):
    """Levenberg-Marquardt on the whitened angular cost: ``(R, t, iterations, status, H)`` of :func:`_lm`."""
    R, t, it, status, H, _ = _lm(R0, t0, P, F, W, max_iter)
    return R, t, it, status, H


@kernel
def _lm(R0, t0, P, F, W, max_iter):
    """Levenberg-Marquardt on the whitened angular cost.

    Each iteration solves ``(H + lam diag(H)) dx = -g`` (Marquardt's scaling,
    so radians and metres need no common unit), accepts the step if the cost
    drops and then lowers ``lam``, else raises it.  Stops when the predicted
    or actual decrease is at the cost's rounding level, the step is
    negligible, or after ``max_iter`` normal-equation evaluations.

    Returns
    -------
    R : (3, 3), t : (3,)
    iterations : int
        Normal-equation evaluations.
    status : int
        1 converged, 0 iteration limit, -1 singular normal equations, -2 non-finite cost.
    H : (6, 6)
        The normal matrix ``J^T J`` at the returned pose (the covariance needs no second pass).
    Z : (N, 2)
        The whitened residuals at the returned pose (the outlier test needs no second pass).
    """
    R = R0.copy()
    t = t0.copy()
    Z = np.empty((P.shape[0], 2))
    H, g, cost = _normal_equations_into(R, t, P, F, W, Z)
    if not np.isfinite(cost):
        return R, t, 1, -2, H, Z
    R, t, it, status, H, Z, _ = _lm_loop(R, t, P, F, W, H, g, cost, Z, 1, max_iter, _NO_C, _NO_S, False)
    return R, t, it, status, H, Z


#: Placeholders of :func:`_lm_loop`'s laser arguments where it does not re-whiten.
_NO_C = np.zeros((0, 3))
_NO_S = np.zeros((0, 3, 3))
#: With the laser term (:func:`fit_pose_laser`) the LM re-whitens at every pose it tries until a step's
#: predicted decrease is below this share of the cost; the whitening is then kept (the pose is within about
#: ``sqrt(REWHITEN_GD * cost)`` whitened units, a thousandth of its sigma, of the optimum; the whitening's
#: change over that is far below rounding of the estimate) and the LM converges as without the laser term.
REWHITEN_GD = 1e-6


@kernel
def _lm_loop(R, t, P, F, W, H, g, cost, Z, it, max_iter, C, S, rewhiten):
    """The iterations of :func:`_lm` from a pose whose normal equations ``H, g, cost`` and residuals ``Z``
    (with the whitening ``W``) are known (``it`` evaluations so far).

    ``rewhiten``: every pose tried gets its own whitening with the laser term (:func:`laser_whitening_at`
    from the click covariances ``C`` and laser covariances ``S``; a step is taken when the cost with the
    new pose's whitening is below the current one's), until a step's predicted decrease is below
    :data:`REWHITEN_GD` of the cost; from there on ``W`` is kept.  Returns ``(R, t, it, status, H, Z, W)``,
    status as :func:`_lm`, ``W`` the whitening of ``H`` and ``Z``.
    """
    lam = 1e-4
    Z_new = np.empty((P.shape[0], 2))
    W_new = W.copy() if rewhiten else W
    A = np.empty((6, 6))
    L = np.empty((6, 6))
    dx = np.empty(6)
    while it < max_iter:
        for a in range(6):
            for b in range(6):
                A[a, b] = H[a, b]
            A[a, a] = H[a, a] * (1.0 + lam) + 1e-300
        ok = _cholesky(A, L)
        if ok:
            for a in range(6):
                dx[a] = -g[a]
            _chol_solve_inplace(L, dx)
        else:
            if lam > 1e12:
                return R, t, it, -1, H, Z, W
            lam *= 10.0
            continue
        # Predicted decrease -g.dx: at the noise floor of the cost nothing is left to gain
        # (comparing costs there only measures rounding).
        gd = 0.0
        for a in range(6):
            gd -= g[a] * dx[a]
        if gd <= 1e-13 * cost or cost <= 1e-300:
            return R, t, it, 1, H, Z, W
        if rewhiten and gd <= REWHITEN_GD * cost:
            rewhiten = False  # near the optimum: keep this whitening
        R_new = so3_exp(dx[:3]) @ R
        t_new = t + dx[3:]
        # One pass gives the new cost and, if the step is taken, the next normal equations.
        if rewhiten:
            _laser_whitening_into(R_new, t_new, P, F, C, S, W_new)
            H_new, g_new, cost_new = _normal_equations_into(R_new, t_new, P, F, W_new, Z_new)
        else:
            H_new, g_new, cost_new = _normal_equations_into(R_new, t_new, P, F, W, Z_new)
        it += 1
        step = 0.0
        scale = 0.0
        for a in range(3):
            step += dx[a] * dx[a]
        for a in range(3, 6):
            step += dx[a] * dx[a]
            scale += t[a - 3] * t[a - 3]
        small_step = math.sqrt(step) <= 1e-11 * (1.0 + math.sqrt(scale))
        if np.isfinite(cost_new) and cost_new <= cost:
            decrease = cost - cost_new
            R, t, H, g, cost = R_new, t_new, H_new, g_new, cost_new
            Z, Z_new = Z_new, Z
            if rewhiten:
                W, W_new = W_new, W
            lam = max(lam / 10.0, 1e-12)
            if small_step or decrease <= 1e-11 * cost or cost <= 1e-300:
                return R, t, it, 1, H, Z, W
        else:
            if small_step:
                return R, t, it, 1, H, Z, W
            lam *= 10.0
            if lam > 1e16:
                return R, t, it, 1, H, Z, W  # no descent direction left: a minimum to rounding
    return R, t, it, 0, H, Z, W


@kernel
def fit_pose_laser(P, B, F, A, s, S, R0, t0, use_dlt, max_iter):
    """:func:`fit_pose` with the laser term of the whitening, in one call.

    The laser term depends on the pose: the LM whitens each pose it tries with the click covariances
    (:func:`click_covariance` of the camera's ``A`` (N, 2, 2), px/rad, and the click sigmas ``s`` (N,),
    px) plus the laser covariances ``S`` (N, 3, 3), m^2, seen from
    that pose (:func:`laser_whitening_at`), until it is near the optimum (:data:`REWHITEN_GD`), and
    keeps that whitening to converge.  The estimate is the pose that is optimal with the whitening at
    itself, the fixed point that the former two solves (click whitening, then re-whitened at that
    optimum and solved again) approached to a small fraction of its sigma.

    Returns
    -------
    As :func:`fit_pose`, then ``W (N, 2, 2)``: the whitening at the end (status -2 also where the laser
    term is not finite at the start: a point at the camera centre).
    """
    n = P.shape[0]
    if use_dlt:
        R_start, t_start, ok = dlt_pose(P, B)
        if not ok:
            return R_start, t_start, R_start, t_start, 0, -3, np.zeros((6, 6)), np.zeros((n, 2)), np.zeros((n, 2, 2))
    else:
        R_start, t_start = R0.copy(), t0.copy()
    C = click_covariance(A, s)
    W = laser_whitening_at(R_start, t_start, P, F, C, S)
    Z = np.empty((n, 2))
    H, g, cost = _normal_equations_into(R_start, t_start, P, F, W, Z)
    if not np.isfinite(cost):
        return R_start, t_start, R_start, t_start, 1, -2, H, Z, W
    R, t, it, status, H, Z, W = _lm_loop(R_start.copy(), t_start.copy(), P, F, W, H, g, cost, Z, 1, max_iter,
                                         C, S, True)
    if not np.isfinite(R.sum() + t.sum()):
        status = -2
    return R, t, R_start, t_start, it, status, H, Z, W


@kernel
def _pose_4x4(R, t):
    T = np.eye(4)
    for r in range(3):
        for c in range(3):
            T[r, c] = R[r, c]
        T[r, 3] = t[r]
    return T


@kernel
def fit_and_report(P, B, F, W, A, s, S, laser, R0, t0, use_dlt, max_iter, robust, threshold_sq, known_noise,
                   t_factor, prior_sigma):
    """The fit of :func:`calib_core.solve.solve_extrinsics` and, where nothing else is left to do, its report,
    in one call: :func:`fit_pose_laser` (``laser``; the click inputs ``A``, ``s`` (empty: 1 px each) and laser
    covariances ``S``)
    or :func:`fit_pose` (the whitening ``W``), then, when the LM succeeded and no whitened residual
    reaches the outlier threshold (``|z_i|^2 >= threshold_sq``, only looked at when ``robust``),
    :func:`pose_report_points` of all pairs at the optimum with the LM's normal matrix and residuals.

    Returns
    -------
    T, T_start : (4, 4) the optimum and the start (as 4x4 ``T_camera_lidar``)
    iterations, status, H, z : as :func:`fit_pose`
    W_end : (N, 2, 2) the whitening of ``H`` and ``z`` (``W`` itself without the laser term)
    done : bool
        The report below was computed (else it is None and the caller goes on: a failed LM, or an
        outlier search to run).  With ``done``, ``H``, ``z`` and ``W_end`` are None (the caller has no
        further use for them, and each array returned to Python costs about as much as a pass
        through 100 pairs).
    theta, H, stats, noise_scale, cov, condition, sigma_t, sigma_rpy, sigma_rotation, points_camera :
        as :func:`pose_report_points`.
    """
    n = P.shape[0]
    if laser:
        if s.shape[0] != n:
            s = np.ones(n)
        R, t, R_s, t_s, it, status, H, Z, W_end = fit_pose_laser(P, B, F, A, s, S, R0, t0, use_dlt, max_iter)
    else:
        R, t, R_s, t_s, it, status, H, Z = fit_pose(P, B, F, W, R0, t0, use_dlt, max_iter)
        W_end = W
    done = status >= 0
    if done and robust:
        # The caller's test, ``max |z_i|^2 >= threshold_sq`` with numpy's max: a NaN makes it false.
        above = False
        for i in range(n):
            r2 = Z[i, 0] ** 2 + Z[i, 1] ** 2
            if r2 != r2:
                above = False
                break
            if r2 >= threshold_sq:
                above = True
        done = not above
    T, T_start = _pose_4x4(R, t), _pose_4x4(R_s, t_s)
    if not done:
        return (T, T_start, it, status, H, Z, W_end, False, None, None, None, None, None, None, None, None, None,
                None)
    theta, H_r, stats, noise_scale, cov, condition, sigma_t, sigma_rpy, sigma_rot, X = pose_report_points(
        R, t, P, F, W_end, np.ones(n, dtype=np.bool_), H, True, -1.0, known_noise, t_factor, prior_sigma, Z)
    return (T, T_start, it, status, None, None, None, True, theta, H_r, stats, noise_scale, cov, condition, sigma_t,
            sigma_rpy, sigma_rot, X)


@kernel
def fit_and_report_probes(P, B, F, uv, h, s, S, laser, R0, t0, use_dlt, max_iter, robust, threshold_sq, t_factor,
                          prior_sigma):
    """:func:`probe_jacobians_all` of the probes' pixels ``uv`` (step ``h`` radians), then, when every pair
    has its Jacobian ``A``, :func:`fit_and_report` whitened by the camera: ``W_i = A_i / s_i`` (``s`` the click
    sigmas, px; empty: 1 px each), with the laser term when ``laser``.

    Returns
    -------
    A, ok, all_ok : as :func:`probe_jacobians_all`
    then :func:`fit_and_report`'s outputs (all None, status -4, when not ``all_ok``: the caller whitens
    the pairs without a Jacobian its own way).
    """
    A, ok, all_ok = probe_jacobians_all(uv, h)
    if not all_ok:
        return (A, ok, False, None, None, 0, -4, None, None, None, False, None, None, None, None, None, None, None,
                None, None, None)
    n = P.shape[0]
    if s.shape[0] == n:
        W = np.empty((n, 2, 2))
        for i in range(n):
            for a in range(2):
                for b in range(2):
                    W[i, a, b] = A[i, a, b] / s[i]
    else:
        W = A
    return (A, ok, True) + fit_and_report(P, B, F, W, A, s, S, laser, R0, t0, use_dlt, max_iter, robust, threshold_sq,
                                          False, t_factor, prior_sigma)


@kernel
def score_poses(Rs, ts, P, F, W):
    """Squared whitened residual norms ``(K, N)`` of K candidate poses ``Rs (K, 3, 3)``, ``ts (K, 3)``."""
    K = Rs.shape[0]
    n = P.shape[0]
    out = np.empty((K, n))
    z = np.empty(2)
    Jd = np.empty((2, 6))
    for k in range(K):
        Rk, tk = Rs[k], ts[k]
        for i in range(n):
            _pair(Rk, tk, P, F, W, i, z, Jd, False)
            out[k, i] = z[0] * z[0] + z[1] * z[1]
    return out


@kernel
def _det3(A):
    return (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]) - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
            + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))


@kernel
def _polar3(A):
    """Rotation nearest to ``A`` (3x3, ``det A > 0``) and the mean of its singular values.

    Higham's scaled Newton iteration ``X <- (z X + X^-T / z) / 2`` on the
    orthogonal polar factor (quadratic convergence; a DLT block is close to a
    scaled rotation, so a handful of steps); mean singular value
    ``trace(R^T A) / 3``.  ``(I, 0)`` if ``A`` is singular.
    """
    X = A.copy()
    Y = np.empty((3, 3))
    for _ in range(50):
        d = _det3(X)
        if not (d > 0.0 and np.isfinite(d)):
            return np.eye(3), 0.0
        # X^-T = cofactor matrix / det.
        Y[0, 0] = (X[1, 1] * X[2, 2] - X[1, 2] * X[2, 1]) / d
        Y[0, 1] = (X[1, 2] * X[2, 0] - X[1, 0] * X[2, 2]) / d
        Y[0, 2] = (X[1, 0] * X[2, 1] - X[1, 1] * X[2, 0]) / d
        Y[1, 0] = (X[0, 2] * X[2, 1] - X[0, 1] * X[2, 2]) / d
        Y[1, 1] = (X[0, 0] * X[2, 2] - X[0, 2] * X[2, 0]) / d
        Y[1, 2] = (X[0, 1] * X[2, 0] - X[0, 0] * X[2, 1]) / d
        Y[2, 0] = (X[0, 1] * X[1, 2] - X[0, 2] * X[1, 1]) / d
        Y[2, 1] = (X[0, 2] * X[1, 0] - X[0, 0] * X[1, 2]) / d
        Y[2, 2] = (X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0]) / d
        z = abs(d) ** (-1.0 / 3.0)
        change = 0.0
        for a in range(3):
            for b in range(3):
                new = 0.5 * (z * X[a, b] + Y[a, b] / z)
                change = max(change, abs(new - X[a, b]))
                X[a, b] = new
        if change <= 4e-16 * 8.0:
            break
    scale = 0.0
    for a in range(3):
        for b in range(3):
            scale += X[a, b] * A[a, b]
    return X, scale / 3.0


@kernel
def _cholesky(A, L):
    """Lower Cholesky factor of a symmetric positive-definite ``A`` into ``L``; False if it is not."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    return True


@kernel
def _chol_solve_inplace(L, x):
    n = L.shape[0]
    for i in range(n):
        s = x[i]
        for k in range(i):
            s -= L[i, k] * x[k]
        x[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]


@kernel
def _null_vector(M):
    """Unit eigenvector of the smallest eigenvalue of a PSD ``M``, and False if a second one is near zero.

    Inverse iteration on ``M + delta I`` (``delta = 1e-13 trace M``, so the
    Cholesky factor exists even for noise-free data): the wanted vector grows
    by ``lambda_1 / lambda_0`` per step, thousands for a DLT, so a few steps
    give it to rounding.  The second eigenvalue is then estimated the same
    way on the complement (a Rayleigh quotient); below ``1e-10 trace M`` the
    null space is at least 2-D (degenerate).  A few microseconds, where
    LAPACK's ``eigh`` of a 12x12 takes over ten.
    """
    n = M.shape[0]
    tr = 0.0
    for a in range(n):
        tr += M[a, a]
    x = np.ones(n)
    if not (tr > 0.0 and np.isfinite(tr)):
        return x, False
    Ms = M.copy()
    for a in range(n):
        Ms[a, a] += 1e-13 * tr
    L = np.empty((n, n))
    if not _cholesky(Ms, L):
        return x, False
    for a in range(n):
        x[a] = 1.0 + 0.1 * a  # not orthogonal to the null vector (a generic start)
    for _ in range(6):
        _chol_solve_inplace(L, x)
        nx = math.sqrt(np.dot(x, x))
        x /= nx
    # Second eigenvalue: inverse iteration orthogonal to x.
    y = np.empty(n)
    for a in range(n):
        y[a] = 1.0 if a % 2 == 0 else -0.5 - 0.05 * a
    lam1 = 0.0
    for _ in range(8):
        d = np.dot(y, x)
        y -= d * x
        ny = math.sqrt(np.dot(y, y))
        if not ny > 0.0:
            return x, False
        y /= ny
        _chol_solve_inplace(L, y)
    d = np.dot(y, x)
    y -= d * x
    ny2 = np.dot(y, y)
    if not ny2 > 0.0:
        return x, False
    lam1 = np.dot(y, M @ y) / ny2
    return x, lam1 > 1e-10 * tr


@kernel
def dlt_pose(P, B):
    """Linear pose from n >= 6 bearings: ``b_i x (R p_i + t) = 0`` solved for the 12 entries of ``[R | t]``.

    The points are centred and scaled first (Hartley's normalisation), the
    null vector of ``A^T A`` (12x12) is taken, its 3x3 block is projected onto
    SO(3) and the scale and sign are fixed so that the points lie in front
    along their bearings.

    Returns
    -------
    R : (3, 3), t : (3,)
    ok : bool
        False for fewer than 6 pairs or a degenerate (e.g. coplanar) set.
    """
    n = P.shape[0]
    R = np.eye(3)
    t = np.zeros(3)
    if n < 6:
        return R, t, False
    mu = np.zeros(3)
    for i in range(n):
        mu += P[i]
    mu /= n
    spread = 0.0
    for i in range(n):
        for k in range(3):
            spread += (P[i, k] - mu[k]) ** 2
    spread = math.sqrt(spread / n)
    if not spread > 0.0:
        return R, t, False
    # Each pair adds ([b]_x^T [b]_x) kron (q q^T), q = (p_normalised, 1): with K = |b|^2 I - b b^T,
    # block (r, c) of the 12x12 (rows of [R | t]) gains K[r, c] q q^T.  All three rows of b x X = 0
    # (they span the same constraints as two of them) make K simple: 60 products per pair.
    acc = np.zeros((6, 10))  # block pairs (00, 11, 22, 01, 02, 12) x the 10 distinct entries of q q^T
    Q = np.empty(10)
    for i in range(n):
        q0 = (P[i, 0] - mu[0]) / spread
        q1 = (P[i, 1] - mu[1]) / spread
        q2 = (P[i, 2] - mu[2]) / spread
        Q[0], Q[1], Q[2], Q[3] = q0 * q0, q0 * q1, q0 * q2, q0
        Q[4], Q[5], Q[6] = q1 * q1, q1 * q2, q1
        Q[7], Q[8], Q[9] = q2 * q2, q2, 1.0
        b0, b1, b2 = B[i, 0], B[i, 1], B[i, 2]
        bb = b0 * b0 + b1 * b1 + b2 * b2
        k00, k11, k22 = bb - b0 * b0, bb - b1 * b1, bb - b2 * b2
        k01, k02, k12 = -b0 * b1, -b0 * b2, -b1 * b2
        for e in range(10):
            qe = Q[e]
            acc[0, e] += k00 * qe
            acc[1, e] += k11 * qe
            acc[2, e] += k22 * qe
            acc[3, e] += k01 * qe
            acc[4, e] += k02 * qe
            acc[5, e] += k12 * qe
    M = np.empty((12, 12))
    for blk in range(6):
        if blk < 3:
            r, c = blk, blk
        elif blk == 3:
            r, c = 0, 1
        elif blk == 4:
            r, c = 0, 2
        else:
            r, c = 1, 2
        e = 0
        for u in range(4):
            for v in range(u, 4):
                val = acc[blk, e]
                M[4 * r + u, 4 * c + v] = val
                M[4 * r + v, 4 * c + u] = val
                M[4 * c + u, 4 * r + v] = val
                M[4 * c + v, 4 * r + u] = val
                e += 1
    x, ok = _null_vector(M)
    if not ok:
        return R, t, False  # a second null vector: degenerate configuration
    A = np.empty((3, 3))
    tt = np.empty(3)
    for r in range(3):
        for c in range(3):
            A[r, c] = x[4 * r + c]
        tt[r] = x[4 * r + 3]
    sgn = 1.0
    if _det3(A) < 0.0:
        sgn = -1.0
        A = -A
    Rn, scale = _polar3(A)
    if not scale > 0.0:
        return R, t, False
    tt = tt * (sgn / scale)
    # Points must lie in front along their bearings.
    front = 0
    for i in range(n):
        q0 = (P[i, 0] - mu[0]) / spread
        q1 = (P[i, 1] - mu[1]) / spread
        q2 = (P[i, 2] - mu[2]) / spread
        d = 0.0
        for r in range(3):
            d += B[i, r] * (Rn[r, 0] * q0 + Rn[r, 1] * q1 + Rn[r, 2] * q2 + tt[r])
        if d > 0.0:
            front += 1
    if 2 * front < n:
        return R, t, False
    # Undo the normalisation: X_c = Rn (p - mu) / s + tt  ->  scaled by s: R = Rn, t = s tt - Rn mu.
    R = Rn
    for r in range(3):
        t[r] = spread * tt[r] - (Rn[r, 0] * mu[0] + Rn[r, 1] * mu[1] + Rn[r, 2] * mu[2])
    return R, t, True


@kernel
def bearing_frames(B):
    """Rows ``e1, e2, b`` of an orthonormal right-handed frame per unit bearing, ``(N, 3, 3)``.

    ``e1 = b x a / |b x a|`` with ``a`` the coordinate axis least aligned with
    ``b`` (never parallel), ``e2 = b x e1``.
    """
    n = B.shape[0]
    F = np.empty((n, 3, 3))
    for i in range(n):
        b0, b1, b2 = B[i, 0], B[i, 1], B[i, 2]
        ab0, ab1, ab2 = abs(b0), abs(b1), abs(b2)
        if ab0 <= ab1 and ab0 <= ab2:
            e0, e1_, e2_ = 0.0, b2, -b1  # b x (1, 0, 0)
        elif ab1 <= ab2:
            e0, e1_, e2_ = -b2, 0.0, b0  # b x (0, 1, 0)
        else:
            e0, e1_, e2_ = b1, -b0, 0.0  # b x (0, 0, 1)
        inv = 1.0 / math.sqrt(e0 * e0 + e1_ * e1_ + e2_ * e2_)
        e0, e1_, e2_ = e0 * inv, e1_ * inv, e2_ * inv
        F[i, 0, 0], F[i, 0, 1], F[i, 0, 2] = e0, e1_, e2_
        F[i, 1, 0] = b1 * e2_ - b2 * e1_
        F[i, 1, 1] = b2 * e0 - b0 * e2_
        F[i, 1, 2] = b0 * e1_ - b1 * e0
        F[i, 2, 0], F[i, 2, 1], F[i, 2, 2] = b0, b1, b2
    return F


@kernel
def finish(R, t, P, F, W, inliers, want_H=True, Z_lm=None):
    """Everything the report needs at the final pose, in one pass.

    ``want_H=False`` skips the normal matrix (zeros): for a caller that has it
    at this pose already (the LM's last one).  ``Z_lm``: the whitened residuals
    at this pose with this ``W`` when the caller has them (the LM's): the angles
    then come from them (``theta_i = |W_i^-1 z_i|``) without a pass through the pairs' geometry.

    Returns
    -------
    z : (N, 2) whitened residuals of every pair
    theta : (N,) geodesic angles, radians
    H : (6, 6) normal matrix of the inliers
    ssr : float, sum of the inliers' squared whitened residuals
    stats : (7,) over the inliers: mean and std of theta (rad), median distance of the points
        from the camera (m), and the singular values of the centred laser points (descending),
        then their count
    """
    n = P.shape[0]
    z = np.empty((n, 2))
    theta = np.empty(n)
    H = np.zeros((6, 6))
    ssr = 0.0
    Ji = np.empty((2, 6))
    m = 0
    for i in range(n):
        if inliers[i]:
            m += 1
    ranges = np.empty(m)
    mu = np.zeros(3)
    zi = np.empty(2)
    k = 0
    for i in range(n):
        if Z_lm is not None and not want_H:
            # r = W^-1 z, and |r| = theta (the log map's norm).
            z0, z1 = Z_lm[i, 0], Z_lm[i, 1]
            det = W[i, 0, 0] * W[i, 1, 1] - W[i, 0, 1] * W[i, 1, 0]
            r0 = (W[i, 1, 1] * z0 - W[i, 0, 1] * z1) / det
            r1 = (W[i, 0, 0] * z1 - W[i, 1, 0] * z0) / det
            theta[i] = math.sqrt(r0 * r0 + r1 * r1)
            zi[0], zi[1] = z0, z1
        # Constant Jacobian flags: a flag known only at run time keeps _pair from being inlined (5x slower).
        elif inliers[i] and want_H:
            theta[i] = _pair(R, t, P, F, W, i, zi, Ji, True)
        else:
            theta[i] = _pair(R, t, P, F, W, i, zi, Ji, False)
        z[i, 0], z[i, 1] = zi[0], zi[1]
        if inliers[i]:
            ssr += z[i, 0] * z[i, 0] + z[i, 1] * z[i, 1]
            for a in range(6 if want_H else 0):
                for b in range(a, 6):
                    H[a, b] += Ji[0, a] * Ji[0, b] + Ji[1, a] * Ji[1, b]
            d2 = 0.0
            for r in range(3):
                c = R[r, 0] * P[i, 0] + R[r, 1] * P[i, 1] + R[r, 2] * P[i, 2] + t[r]
                d2 += c * c
                mu[r] += P[i, r]
            ranges[k] = math.sqrt(d2)
            k += 1
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    stats = np.full(7, np.nan)
    stats[6] = m
    if m == 0:
        return z, theta, H, ssr, stats
    mu /= m
    mean = 0.0
    C = np.zeros((3, 3))
    for i in range(n):
        if inliers[i]:
            mean += theta[i]
            for a in range(3):
                for b in range(3):
                    C[a, b] += (P[i, a] - mu[a]) * (P[i, b] - mu[b])
    mean /= m
    var = 0.0
    for i in range(n):
        if inliers[i]:
            var += (theta[i] - mean) ** 2
    stats[0] = mean
    stats[1] = math.sqrt(var / m)
    stats[2] = np.median(ranges)
    w, _ = sym_eigh(C)
    for a in range(3):
        stats[3 + a] = math.sqrt(max(w[2 - a], 0.0))
    return z, theta, H, ssr, stats


@kernel
def fit_pose(P, B, F, W, R0, t0, use_dlt, max_iter):
    """The start and the LM of :func:`calib_core.solve.solve_extrinsics` in one call.

    Start: :func:`dlt_pose` on the bearings ``B`` when ``use_dlt``, else ``(R0, t0)``; then
    :func:`lm_refine` on the whitened angular cost.

    Returns
    -------
    R, t : the optimum; R_start, t_start : the start
    iterations : int
    status : int
        As :func:`lm_refine` (-2 also for a non-finite optimum); -3 when the DLT start failed (fewer than 6
        pairs, coplanar points).
    H : (6, 6) normal matrix at ``(R, t)``
    z : (N, 2) whitened residuals at ``(R, t)`` (for the outlier test)
    """
    if use_dlt:
        R_start, t_start, ok = dlt_pose(P, B)
        if not ok:
            return R_start, t_start, R_start, t_start, 0, -3, np.zeros((6, 6)), np.zeros((P.shape[0], 2))
    else:
        R_start, t_start = R0.copy(), t0.copy()
    R, t, it, status, H, z = _lm(R_start, t_start, P, F, W, max_iter)
    if not np.isfinite(R.sum() + t.sum()):
        status = -2  # as lm_failure: the caller need not look at the pose
    return R, t, R_start, t_start, it, status, H, z


@kernel
def pose_report(R, t, P, F, W, inliers, H_given, have_H, ssr_given, known_noise, t_factor, prior_sigma, Z_lm=None):
    """The figures of the final pose in one call: :func:`finish`, the residual scale, the covariance and sigmas.

    Parameters
    ----------
    H_given : (6, 6), have_H : bool
        The normal matrix at this pose when the caller has it (the LM's; the pixel cost's).
    ssr_given : float
        Sum of squared residuals to use instead of the angular one (the pixel cost's); < 0: none.
    known_noise : bool
        The residuals are in units of a known noise: sigma = 1 (the covariance is the Cramer-Rao bound).
    t_factor : float
        Student-t factor of ``2 m - 6`` degrees of freedom (m inliers), widening the estimated sigma.
    prior_sigma : float
        Sigma when there is no redundancy (``2 m <= 6``): the expected noise, or inf.
    Z_lm : (N, 2), optional
        The LM's whitened residuals at this pose (with ``have_H``): see :func:`finish`.

    Returns
    -------
    theta : (N,) geodesic angles, rad; H : (6, 6); stats : (7,) as :func:`finish`
    noise_scale : float, ``sqrt(SSR / (2 m - 6))`` (NaN without redundancy)
    cov : (6, 6), condition : float, as :func:`covariance`
    sigma_t : (3,) m; sigma_rpy : (3,) deg; sigma_rotation : float, deg (:func:`rotation_sigma_deg`)
    """
    z, theta, H, ssr, stats = finish(R, t, P, F, W, inliers, not have_H, Z_lm)
    if have_H:
        H = H_given
    if ssr_given >= 0.0:
        ssr = ssr_given
    dof = 2 * int(stats[6]) - 6
    noise_scale = math.sqrt(ssr / dof) if dof > 0 else np.nan
    if known_noise:
        sigma = 1.0
    elif dof > 0:
        sigma = noise_scale * t_factor
    else:
        sigma = prior_sigma
    cov, condition = covariance(H, sigma)
    sigma_t, sigma_rpy = rpy_sigmas(R, cov)
    return theta, H, stats, noise_scale, cov, condition, sigma_t, sigma_rpy, rotation_sigma_deg(cov)


@kernel
def pose_report_points(R, t, P, F, W, inliers, H_given, have_H, ssr_given, known_noise, t_factor, prior_sigma,
                       Z_lm=None):
    """:func:`pose_report`, then the laser points in the camera frame ``R P + t`` (N, 3), metres (for
    the pixel residuals), in one call."""
    out = pose_report(R, t, P, F, W, inliers, H_given, have_H, ssr_given, known_noise, t_factor, prior_sigma, Z_lm)
    n = P.shape[0]
    X = np.empty((n, 3))
    for i in range(n):
        for r in range(3):
            X[i, r] = R[r, 0] * P[i, 0] + R[r, 1] * P[i, 1] + R[r, 2] * P[i, 2] + t[r]
    return out + (X,)


@kernel
def sym_eigh(S):
    """Eigenvalues (ascending) and unit eigenvectors (columns) of a small symmetric matrix.

    Cyclic Jacobi rotations (Golub & Van Loan, sec. 8.5) until the off-diagonal part is at
    rounding: accurate to rounding like LAPACK's ``eigh``, and for the 3x3 and 6x6 matrices of the
    solve several times faster (no workspace, no copies, no call into LAPACK).
    """
    n = S.shape[0]
    A = S.copy()
    V = np.eye(n)
    for _ in range(30):
        off = 0.0
        total = 0.0
        for p in range(n):
            total += A[p, p] * A[p, p]
            for q in range(p + 1, n):
                off += A[p, q] * A[p, q]
        if not off > 1e-34 * (total + 2.0 * off):
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                if abs(theta) > 1e150:
                    tan = 0.5 / theta
                else:
                    tan = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(tan * tan + 1.0)
                sn = tan * c
                for k in range(n):  # A P, then P^T (A P), and V P, with P the rotation in the (p, q) plane
                    akp, akq = A[k, p], A[k, q]
                    A[k, p] = c * akp - sn * akq
                    A[k, q] = sn * akp + c * akq
                for k in range(n):
                    apk, aqk = A[p, k], A[q, k]
                    A[p, k] = c * apk - sn * aqk
                    A[q, k] = sn * apk + c * aqk
                for k in range(n):
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p] = c * vkp - sn * vkq
                    V[k, q] = sn * vkp + c * vkq
    w = np.empty(n)
    for p in range(n):
        w[p] = A[p, p]
    order = np.argsort(w)
    w_sorted = np.empty(n)
    V_sorted = np.empty((n, n))
    for j in range(n):
        w_sorted[j] = w[order[j]]
        for k in range(n):
            V_sorted[k, j] = V[k, order[j]]
    return w_sorted, V_sorted


@kernel
def rotation_sigma_deg(cov):
    """1-sigma of the rotation along its worst axis, degrees: ``sqrt(max eig(cov[:3, :3]))``.

    Independent of how the rotation is written (roll/pitch/yaw sigmas blow up near gimbal lock
    even when the rotation itself is well determined).
    """
    C = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            if not np.isfinite(cov[a, b]):
                return np.inf
            C[a, b] = cov[a, b]
    w, _ = sym_eigh(C)
    return math.degrees(math.sqrt(max(w[2], 0.0)))


@kernel
def rpy_sigmas(R, cov):
    """1-sigma of ``t`` (m) and of roll, pitch, yaw (deg) from the covariance of ``(delta, t)`` at ``R``.

    ``d(rpy)/d(delta) = M^-1``: for a left perturbation ``exp([delta]) R`` of ``R = Rz Ry Rx``,
    ``delta = M (roll, pitch, yaw)`` with columns ``Rz Ry e_x``, ``Rz e_y``, ``e_z``; inf at gimbal lock
    or for an infinite covariance.
    """
    st = np.empty(3)
    sr = np.full(3, np.inf)
    for a in range(3):
        st[a] = math.sqrt(cov[3 + a, 3 + a]) if cov[3 + a, 3 + a] >= 0.0 else np.nan
    cp = math.hypot(R[0, 0], R[1, 0])
    if cp < 1e-9:
        return st, sr
    for a in range(3):
        for b in range(3):
            if not np.isfinite(cov[a, b]):
                return st, sr
    cy, sy = R[0, 0] / cp, R[1, 0] / cp
    # G = M^-1 of M = [[R00, -sy, 0], [R10, cy, 0], [R20, 0, 1]], by cofactors (det M = R00 cy + R10 sy).
    det = R[0, 0] * cy + R[1, 0] * sy
    G = np.empty((3, 3))
    G[0, 0], G[0, 1], G[0, 2] = cy / det, sy / det, 0.0
    G[1, 0], G[1, 1], G[1, 2] = -R[1, 0] / det, R[0, 0] / det, 0.0
    G[2, 0], G[2, 1], G[2, 2] = -R[2, 0] * cy / det, -R[2, 0] * sy / det, 1.0
    for a in range(3):  # diag(G C G^T), written out (tiny, and no layout warnings)
        acc = 0.0
        for b in range(3):
            for c in range(3):
                acc += G[a, b] * cov[b, c] * G[a, c]
        sr[a] = math.degrees(math.sqrt(abs(acc)))
    return st, sr


@kernel
def covariance(H, sigma):
    """``sigma^2 H^-1`` via the Jacobi-scaled eigen-decomposition; ``(cov, condition)``.

    ``cov`` is all inf when ``H`` is singular (smallest scaled eigenvalue
    below 1e-14 of the largest); ``condition`` is the scaled condition number.
    """
    cov = np.full((6, 6), np.inf)
    d = np.empty(6)
    for a in range(6):
        if not (H[a, a] > 0.0) or not np.isfinite(H[a, a]):
            return cov, np.inf
        d[a] = math.sqrt(H[a, a])
    S = np.empty((6, 6))
    for a in range(6):
        for b in range(6):
            S[a, b] = H[a, b] / (d[a] * d[b])
    w, V = sym_eigh(S)
    cond = w[5] / w[0] if w[0] > 0.0 else np.inf
    if not (w[0] > 1e-14 * w[5]) or not np.isfinite(sigma):
        return cov, cond
    s2 = sigma * sigma
    for a in range(6):
        for b in range(6):
            acc = 0.0
            for k in range(6):
                acc += V[a, k] * V[b, k] / w[k]
            cov[a, b] = s2 * acc / (d[a] * d[b])
    return cov, cond


@register_jitable(inline="always")
def _row_distance(X, i, j, angular):
    """Distance between rows ``i`` and ``j`` of ``X`` (N, 3): the angle between them (radians) when ``angular``
    (unit vectors, atan2 of the cross and dot products: exact at small angles), else the Euclidean distance."""
    if angular:
        c0 = X[i, 1] * X[j, 2] - X[i, 2] * X[j, 1]
        c1 = X[i, 2] * X[j, 0] - X[i, 0] * X[j, 2]
        c2 = X[i, 0] * X[j, 1] - X[i, 1] * X[j, 0]
        dot = X[i, 0] * X[j, 0] + X[i, 1] * X[j, 1] + X[i, 2] * X[j, 2]
        return math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), dot)
    return math.sqrt((X[i, 0] - X[j, 0]) ** 2 + (X[i, 1] - X[j, 1]) ** 2 + (X[i, 2] - X[j, 2]) ** 2)


@kernel
def _first_close(X, radius, angular):
    """First pair ``(i, j)`` (i < j in sorted-by-x scan order) closer than ``radius``; (-1, -1) if none.

    A sweep along x: only points within ``radius`` in x are compared, so
    spread-out data costs O(n log n).  ``angular``: the distance is the angle
    between unit vectors (never below their chord, so the sweep stays exact).
    """
    n = X.shape[0]
    order = np.argsort(X[:, 0])
    for a in range(n):
        i = order[a]
        for c in range(a + 1, n):
            j = order[c]
            if X[j, 0] - X[i, 0] > radius:
                break
            if _row_distance(X, i, j, angular) <= radius:
                return min(i, j), max(i, j)
    return -1, -1


@kernel
def _any_close(X, radius, angular):
    """Whether two rows of ``X`` lie within ``radius`` (the distance of :func:`_first_close`), in O(n) for
    spread-out data, without a sort.

    The rows go into buckets along x at least ``radius`` wide (a counting sort); two rows within
    ``radius`` differ by at most that in x (the angle between unit vectors is never below their chord),
    so they lie in the same bucket or in adjacent ones: each row is compared with the later rows of its
    bucket and with the rows of the next bucket.  Rows with the same x all share a bucket (O(n^2), as the
    sweep of :func:`_first_close`).
    """
    n = X.shape[0]
    lo = hi = X[0, 0]
    for i in range(n):
        lo = min(lo, X[i, 0])
        hi = max(hi, X[i, 0])
    # The 1e-4 margin keeps rows within radius in adjacent buckets whatever the division rounds.
    width = max((hi - lo) / n, radius) * 1.0001
    if not width > 0.0:
        width = 1.0  # all rows at one x and a zero radius: one bucket
    nb = int((hi - lo) / width) + 2  # the last bucket stays empty: every bucket has a next one
    start = np.zeros(nb + 1, np.int64)
    bucket = np.empty(n, np.int64)
    for i in range(n):
        b = int((X[i, 0] - lo) / width)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(nb):
        start[b + 1] += start[b]
    fill = start[:nb].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    for b in range(nb - 1):
        end_next = start[b + 2]
        for a in range(start[b], start[b + 1]):
            i = order[a]
            for c in range(a + 1, end_next):
                j = order[c]
                if _row_distance(X, i, j, angular) <= radius:
                    return True
    return False


@kernel
def pair_checks(P, B, same_point_m, same_bearing_rad, unit_tolerance):
    """The degeneracy figures of :func:`calib_core.solve.checks.validate_pairs` in one pass.

    Returns
    -------
    bad_point, bad_bearing : int
        First pair with a non-finite laser point / bearing, or -1.
    zero_bearing, off_unit : int
        First pair whose bearing norm is below 1e-12 / more than ``unit_tolerance`` off 1, or -1.
    off_norm : float
        The bearing norm of pair ``off_unit`` (NaN if none).
    U : (N, 3) the bearings divided by their norms
    same_point_0, same_point_1, same_bearing_0, same_bearing_1 : int
        A pair of pairs with the same laser point / bearing, or -1, -1.
    sv0, sv1 : float
        The largest two singular values of the centred laser points (0 when a check above failed).
    cos_min_to_mean : float
        Smallest cosine between a unit bearing and the normalised bearing sum
        (NaN if the sum vanishes).

    Scalars rather than small arrays: each array returned to Python costs more than these checks at 10 pairs.
    """
    n = P.shape[0]
    bad_point = -1
    bad_bearing = -1
    zero_bearing = -1
    off_unit = -1
    off_norm = np.nan
    U = np.empty((n, 3))
    sp0 = sp1 = sb0 = sb1 = -1
    sv0 = sv1 = 0.0
    cos_min = np.nan
    # Scalars, not row views (``mu += P[i]``): numba's views cost more than the sums here.
    m0 = m1 = m2 = s0 = s1 = s2 = 0.0
    for i in range(n):
        p0, p1, p2 = P[i, 0], P[i, 1], P[i, 2]
        b0, b1, b2 = B[i, 0], B[i, 1], B[i, 2]
        if bad_point < 0 and not (np.isfinite(p0) and np.isfinite(p1) and np.isfinite(p2)):
            bad_point = i
        if bad_bearing < 0 and not (np.isfinite(b0) and np.isfinite(b1) and np.isfinite(b2)):
            bad_bearing = i
        norm = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        if zero_bearing < 0 and norm < 1e-12:
            zero_bearing = i
        if off_unit < 0 and abs(norm - 1.0) > unit_tolerance:
            off_unit = i
            off_norm = norm
        if norm > 0.0:  # a division, not a reciprocal's product: the bearings numpy's ``B / norms`` gives
            u0, u1, u2 = b0 / norm, b1 / norm, b2 / norm
        else:
            u0 = u1 = u2 = 0.0
        U[i, 0], U[i, 1], U[i, 2] = u0, u1, u2
        m0 += p0
        m1 += p1
        m2 += p2
        s0 += u0
        s1 += u1
        s2 += u2
    if bad_point >= 0 or bad_bearing >= 0 or zero_bearing >= 0 or off_unit >= 0:
        return bad_point, bad_bearing, zero_bearing, off_unit, off_norm, U, sp0, sp1, sb0, sb1, sv0, sv1, cos_min
    # The bucket test finds whether any pair is too close; only then does the sorted sweep name the
    # first such pair (its two argsorts cost more than all the other checks at 1000 pairs).
    if _any_close(P, same_point_m, False):
        sp0, sp1 = _first_close(P, same_point_m, False)
    if _any_close(U, same_bearing_rad, True):
        sb0, sb1 = _first_close(U, same_bearing_rad, True)
    m0, m1, m2 = m0 / n, m1 / n, m2 / n
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for i in range(n):
        d0, d1, d2 = P[i, 0] - m0, P[i, 1] - m1, P[i, 2] - m2
        c00 += d0 * d0
        c01 += d0 * d1
        c02 += d0 * d2
        c11 += d1 * d1
        c12 += d1 * d2
        c22 += d2 * d2
    C = np.array([[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]])
    w, _ = sym_eigh(C)
    sv0, sv1 = math.sqrt(max(w[2], 0.0)), math.sqrt(max(w[1], 0.0))
    sn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if sn > 0.0:
        cos_min = 1.0
        for i in range(n):
            c = (U[i, 0] * s0 + U[i, 1] * s1 + U[i, 2] * s2) / sn
            if c < cos_min:
                cos_min = c
    return bad_point, bad_bearing, zero_bearing, off_unit, off_norm, U, sp0, sp1, sb0, sb1, sv0, sv1, cos_min


@kernel
def pair_checks_frames(P, B, same_point_m, same_bearing_rad, unit_tolerance, h):
    """:func:`pair_checks`, then, when its first four checks passed, :func:`bearing_frames` of the unit
    bearings and (``h > 0``) their :func:`tangent_probes` at step ``h`` radians, in one call (empty arrays
    where not computed)."""
    out = pair_checks(P, B, same_point_m, same_bearing_rad, unit_tolerance)
    if out[0] < 0 and out[1] < 0 and out[2] < 0 and out[3] < 0:
        F = bearing_frames(out[5])
        probes = tangent_probes(F, h) if h > 0.0 else np.empty((0, 3))
    else:
        F = np.empty((0, 3, 3))
        probes = np.empty((0, 3))
    return out + (F, probes)


@kernel
def _rigid_fit_one(src, dst, out):
    """Least-squares rigid ``T_dst_src`` of (N, 3) point sets into ``out`` (4, 4): Arun's SVD with
    Umeyama's reflection fix (see :mod:`calib_core.solve.rigid`)."""
    n = src.shape[0]
    ms = np.zeros(3)
    md = np.zeros(3)
    for i in range(n):
        for k in range(3):
            ms[k] += src[i, k]
            md[k] += dst[i, k]
    ms /= n
    md /= n
    H = np.zeros((3, 3))
    for i in range(n):
        for a in range(3):
            for b in range(3):
                H[a, b] += (src[i, a] - ms[a]) * (dst[i, b] - md[b])
    U, _, Vt = np.linalg.svd(H)
    V = np.ascontiguousarray(Vt.T)
    Ut = np.ascontiguousarray(U.T)
    R = V @ Ut
    if np.linalg.det(R) < 0.0:
        for a in range(3):
            V[a, 2] = -V[a, 2]
        R = V @ Ut
    for a in range(3):
        for b in range(3):
            out[a, b] = R[a, b]
        out[a, 3] = md[a] - (R[a, 0] * ms[0] + R[a, 1] * ms[1] + R[a, 2] * ms[2])
        out[3, a] = 0.0
    out[3, 3] = 1.0


@kernel
def rigid_fit_batch(src, dst):
    """:func:`_rigid_fit_one` over a batch: ``src, dst (M, N, 3)`` -> ``(M, 4, 4)``."""
    M = src.shape[0]
    out = np.empty((M, 4, 4))
    for m in range(M):
        _rigid_fit_one(src[m], dst[m], out[m])
    return out


@kernel
def _cubic_largest_root(A, B, C):
    """Largest real root of ``m^3 + A m^2 + B m + C`` (Cardano / trigonometric form, Newton-polished)."""
    P = B - A * A / 3.0
    Q = 2.0 * A * A * A / 27.0 - A * B / 3.0 + C
    D = (Q / 2.0) ** 2 + (P / 3.0) ** 3
    if D > 0.0:
        sq = math.sqrt(D)
        u = -Q / 2.0 + sq
        v = -Q / 2.0 - sq
        z = math.copysign(abs(u) ** (1.0 / 3.0), u) + math.copysign(abs(v) ** (1.0 / 3.0), v)
    else:
        rr = math.sqrt(max(-P / 3.0, 0.0))
        arg = (-Q / 2.0) / (rr**3) if rr > 0.0 else 0.0
        z = 2.0 * rr * math.cos(math.acos(min(max(arg, -1.0), 1.0)) / 3.0)
    m = z - A / 3.0
    for _ in range(2):
        f = ((m + A) * m + B) * m + C
        df = (3.0 * m + 2.0 * A) * m + B
        if df != 0.0:
            m -= f / df
    return m


@kernel
def _quartic_real_roots(c4, c3, c2, c1, c0, out):
    """Real roots of ``c4 x^4 + ... + c0`` by Ferrari's method, Newton-polished; returns their count.

    A close complex pair (noise can split a double root) counts as one real root at its real part,
    when its imaginary part is below 1e-2 (1 + |real part|).
    """
    a, b, c, d = c3 / c4, c2 / c4, c1 / c4, c0 / c4
    p = b - 3.0 * a * a / 8.0
    q = c - a * b / 2.0 + a * a * a / 8.0
    r = d - a * c / 4.0 + a * a * b / 16.0 - 3.0 * a**4 / 256.0
    k = 0
    quad = np.empty((2, 2))  # y^2 + B y + C
    if abs(q) < 1e-14 * (1.0 + abs(p) ** 1.5 + abs(r) ** 0.75):
        disc = p * p - 4.0 * r
        sq = math.sqrt(max(disc, 0.0))
        for y2 in ((-p + sq) / 2.0, (-p - sq) / 2.0):
            if y2 >= 0.0:
                out[k] = math.sqrt(y2) - a / 4.0
                out[k + 1] = -math.sqrt(y2) - a / 4.0
                k += 2
    else:
        m = _cubic_largest_root(p, p * p / 4.0 - r, -q * q / 8.0)
        if not m > 0.0:
            return 0
        s = math.sqrt(2.0 * m)
        quad[0, 0], quad[0, 1] = s, p / 2.0 + m - q / (2.0 * s)
        quad[1, 0], quad[1, 1] = -s, p / 2.0 + m + q / (2.0 * s)
        for j in range(2):
            Bq, Cq = quad[j, 0], quad[j, 1]
            disc = Bq * Bq - 4.0 * Cq
            if disc >= 0.0:
                sq = math.sqrt(disc)
                out[k] = (-Bq + sq) / 2.0 - a / 4.0
                out[k + 1] = (-Bq - sq) / 2.0 - a / 4.0
                k += 2
            else:
                re = -Bq / 2.0 - a / 4.0
                if math.sqrt(-disc) / 2.0 <= 1e-2 * (1.0 + abs(re)):
                    out[k] = re
                    k += 1
    for i in range(k):
        x = out[i]
        for _ in range(2):
            f = (((c4 * x + c3) * x + c2) * x + c1) * x + c0
            df = ((4.0 * c4 * x + 3.0 * c3) * x + 2.0 * c2) * x + c1
            if df == 0.0:
                break
            step = f / df
            if not np.isfinite(step) or abs(step) > 1e-2 * (1.0 + abs(x)):
                break  # Newton leaving the root's basin (a near-double root): keep the closed form
            x -= step
        out[i] = x
    return k


@kernel
def _triangle_pose(p, pc, out):
    """Rigid ``T`` with ``pc = R p + t`` for two congruent triangles (3, 3), from their edge frames."""
    Fl = np.empty((3, 3))
    Fc = np.empty((3, 3))
    for X, Fr in ((p, Fl), (pc, Fc)):
        e1 = X[1] - X[0]
        e1 = e1 / math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
        w = X[2] - X[0]
        e3 = np.array([e1[1] * w[2] - e1[2] * w[1], e1[2] * w[0] - e1[0] * w[2], e1[0] * w[1] - e1[1] * w[0]])
        e3 = e3 / math.sqrt(e3[0] ** 2 + e3[1] ** 2 + e3[2] ** 2)
        e2 = np.array([e3[1] * e1[2] - e3[2] * e1[1], e3[2] * e1[0] - e3[0] * e1[2], e3[0] * e1[1] - e3[1] * e1[0]])
        for k in range(3):
            Fr[k, 0], Fr[k, 1], Fr[k, 2] = e1[k], e2[k], e3[k]
    R = Fc @ np.ascontiguousarray(Fl.T)
    for a in range(3):
        for b in range(3):
            out[a, b] = R[a, b]
        cp = (pc[0, a] + pc[1, a] + pc[2, a]) / 3.0
        cl = 0.0
        for b in range(3):
            cl += R[a, b] * (p[0, b] + p[1, b] + p[2, b]) / 3.0
        out[a, 3] = cp - cl
        out[3, a] = 0.0
    out[3, 3] = 1.0


@kernel
def p3p_grunert(P, B):
    """All P3P poses of M triples (Grunert, in the notation of Haralick et al. 1994, Sec. 2).

    ``s1, s2, s3`` are the depths, ``a = |p2 - p3|``, ``b = |p1 - p3|``, ``c = |p1 - p2|``.  With
    ``s2 = u s1`` and ``s3 = v s1`` the law of cosines gives a quartic in ``v`` (their eq. 9), solved in
    closed form (Ferrari, :func:`_quartic_real_roots`); ``s2`` is taken from whichever of the c-equation
    roots and Grunert's ``u`` (eq. 8) best satisfies the a-equation.  Only positive depths are kept: the
    points lie in front along their bearings.  The pose comes from the two triangles' edge frames
    (:func:`_triangle_pose`).

    Parameters
    ----------
    P : (M, 3, 3) ndarray
        M triples of laser points, lidar frame, metres.
    B : (M, 3, 3) ndarray
        Their unit bearings, camera frame.

    Returns
    -------
    T : (K, 4, 4) ndarray
        Up to four poses ``T_camera_lidar`` per triple.
    tri : (K,) int ndarray
        The triple each pose comes from.
    """
    M = P.shape[0]
    Ts = np.empty((4 * M, 4, 4))
    tri = np.empty(4 * M, dtype=np.int64)
    K = 0
    roots = np.empty(4)
    pc = np.empty((3, 3))
    for m in range(M):
        p = P[m]
        b = B[m]
        a2 = (p[1, 0] - p[2, 0]) ** 2 + (p[1, 1] - p[2, 1]) ** 2 + (p[1, 2] - p[2, 2]) ** 2
        b2 = (p[0, 0] - p[2, 0]) ** 2 + (p[0, 1] - p[2, 1]) ** 2 + (p[0, 2] - p[2, 2]) ** 2
        c2 = (p[0, 0] - p[1, 0]) ** 2 + (p[0, 1] - p[1, 1]) ** 2 + (p[0, 2] - p[1, 2]) ** 2
        if not (a2 > 0.0 and b2 > 0.0 and c2 > 0.0):
            continue
        ca = b[1, 0] * b[2, 0] + b[1, 1] * b[2, 1] + b[1, 2] * b[2, 2]
        cb = b[0, 0] * b[2, 0] + b[0, 1] * b[2, 1] + b[0, 2] * b[2, 2]
        cg = b[0, 0] * b[1, 0] + b[0, 1] * b[1, 1] + b[0, 2] * b[1, 2]
        q = (a2 - c2) / b2
        pp = (a2 + c2) / b2
        A4 = (q - 1) ** 2 - 4 * c2 / b2 * ca**2
        A3 = 4 * (q * (1 - q) * cb - (1 - pp) * ca * cg + 2 * c2 / b2 * ca**2 * cb)
        A2 = 2 * (q**2 - 1 + 2 * q**2 * cb**2 + 2 * (b2 - c2) / b2 * ca**2 - 4 * pp * ca * cb * cg
                  + 2 * (b2 - a2) / b2 * cg**2)
        A1 = 4 * (-q * (1 + q) * cb + 2 * a2 / b2 * cg**2 * cb - (1 - pp) * ca * cg)
        A0 = (1 + q) ** 2 - 4 * a2 / b2 * cg**2
        big = max(abs(A4), abs(A3), abs(A2), abs(A1), abs(A0))
        if not (abs(A4) > 1e-12 * big):
            continue  # a vanishing leading coefficient sends a root to infinity
        nroots = _quartic_real_roots(A4, A3, A2, A1, A0, roots)
        for ri in range(nroots):
            v = roots[ri]
            if not v > 0.0:
                continue
            s1 = math.sqrt(b2 / max(1.0 + v * v - 2.0 * v * cb, 1e-300))
            s3 = v * s1
            disc = math.sqrt(max(c2 - s1 * s1 * (1.0 - cg * cg), 0.0))
            den = 2.0 * (cg - v * ca)
            best, best_res = -1.0, np.inf
            for cand_k in range(3):
                if cand_k == 0:
                    s2 = s1 * cg + disc
                elif cand_k == 1:
                    s2 = s1 * cg - disc
                else:
                    if den == 0.0:
                        continue
                    s2 = ((-1.0 + q) * v * v - 2.0 * q * cb * v + 1.0 + q) / den * s1
                if not (s2 > 0.0 and np.isfinite(s2)):
                    continue
                res = abs(s2 * s2 + s3 * s3 - 2.0 * s2 * s3 * ca - a2)
                if res < best_res:
                    best, best_res = s2, res
            if best < 0.0 or not (s1 > 0.0 and np.isfinite(s1)):
                continue
            for k in range(3):
                pc[0, k] = s1 * b[0, k]
                pc[1, k] = best * b[1, k]
                pc[2, k] = s3 * b[2, k]
            _triangle_pose(p, pc, Ts[K])  # the depths reproduce the triangle: its frame gives R exactly
            ok = True
            for a in range(3):
                for c in range(4):
                    if not np.isfinite(Ts[K, a, c]):
                        ok = False
            if ok:
                tri[K] = m
                K += 1
    return Ts[:K], tri[:K]


@kernel
def tangent_probes(F, h):
    """Directions ``b +- h e1``, ``b +- h e2`` of every bearing frame, stacked ``(4N, 3)`` in that order."""
    n = F.shape[0]
    out = np.empty((4 * n, 3))
    for i in range(n):
        for k in range(3):
            out[i, k] = F[i, 2, k] + h * F[i, 0, k]
            out[n + i, k] = F[i, 2, k] - h * F[i, 0, k]
            out[2 * n + i, k] = F[i, 2, k] + h * F[i, 1, k]
            out[3 * n + i, k] = F[i, 2, k] - h * F[i, 1, k]
    return out


@kernel
def probe_jacobians_all(uv, h):
    """:func:`probe_jacobians`, then whether every pair's is ``ok``."""
    A, ok = probe_jacobians(uv, h)
    all_ok = True
    for i in range(ok.shape[0]):
        if not ok[i]:
            all_ok = False
    return A, ok, all_ok


@kernel
def probe_jacobians(uv, h):
    """``d pixel / d tangent`` ``(N, 2, 2)`` from the pixels of :func:`tangent_probes`, and ``ok (N,)``:
    finite with a non-zero determinant."""
    n = uv.shape[0] // 4
    A = np.empty((n, 2, 2))
    ok = np.empty(n, dtype=np.bool_)
    for i in range(n):
        for r in range(2):
            A[i, r, 0] = (uv[i, r] - uv[n + i, r]) / (2.0 * h)
            A[i, r, 1] = (uv[2 * n + i, r] - uv[3 * n + i, r]) / (2.0 * h)
        det = A[i, 0, 0] * A[i, 1, 1] - A[i, 0, 1] * A[i, 1, 0]
        ok[i] = np.isfinite(det) and det != 0.0
    return A, ok


@kernel
def laser_bearing_cov(R, t, P, F, S):
    """``Sigma_i = E_i R S_i R^T E_i^T / |R p_i + t|^2`` (N, 2, 2), rad^2: a laser point's covariance
    ``S_i`` (N, 3, 3), m^2, seen as the error of its bearing (``E_i`` the first two rows of ``F_i``);
    see :func:`calib_core.solve.whiten.laser_tangent_covariance`."""
    n = P.shape[0]
    out = np.empty((n, 2, 2))
    for i in range(n):
        out[i, 0, 0], out[i, 0, 1], out[i, 1, 0], out[i, 1, 1] = _laser_bearing_cov_pair(R, t, P, F, S, i)
    return out


@kernel
def _laser_bearing_cov_pair(R, t, P, F, S, i):
    """:func:`laser_bearing_cov` of pair ``i``: ``(Sigma_00, Sigma_01, Sigma_10, Sigma_11)``, in scalars."""
    d2 = 0.0
    for r in range(3):
        c = R[r, 0] * P[i, 0] + R[r, 1] * P[i, 1] + R[r, 2] * P[i, 2] + t[r]
        d2 += c * c
    # A = E_i R (2x3), then A S_i (2x3).
    a00 = F[i, 0, 0] * R[0, 0] + F[i, 0, 1] * R[1, 0] + F[i, 0, 2] * R[2, 0]
    a01 = F[i, 0, 0] * R[0, 1] + F[i, 0, 1] * R[1, 1] + F[i, 0, 2] * R[2, 1]
    a02 = F[i, 0, 0] * R[0, 2] + F[i, 0, 1] * R[1, 2] + F[i, 0, 2] * R[2, 2]
    a10 = F[i, 1, 0] * R[0, 0] + F[i, 1, 1] * R[1, 0] + F[i, 1, 2] * R[2, 0]
    a11 = F[i, 1, 0] * R[0, 1] + F[i, 1, 1] * R[1, 1] + F[i, 1, 2] * R[2, 1]
    a12 = F[i, 1, 0] * R[0, 2] + F[i, 1, 1] * R[1, 2] + F[i, 1, 2] * R[2, 2]
    b00 = a00 * S[i, 0, 0] + a01 * S[i, 1, 0] + a02 * S[i, 2, 0]
    b01 = a00 * S[i, 0, 1] + a01 * S[i, 1, 1] + a02 * S[i, 2, 1]
    b02 = a00 * S[i, 0, 2] + a01 * S[i, 1, 2] + a02 * S[i, 2, 2]
    b10 = a10 * S[i, 0, 0] + a11 * S[i, 1, 0] + a12 * S[i, 2, 0]
    b11 = a10 * S[i, 0, 1] + a11 * S[i, 1, 1] + a12 * S[i, 2, 1]
    b12 = a10 * S[i, 0, 2] + a11 * S[i, 1, 2] + a12 * S[i, 2, 2]
    inv_d2 = 1.0 / d2
    return ((b00 * a00 + b01 * a01 + b02 * a02) * inv_d2, (b00 * a10 + b01 * a11 + b02 * a12) * inv_d2,
            (b10 * a00 + b11 * a01 + b12 * a02) * inv_d2, (b10 * a10 + b11 * a11 + b12 * a12) * inv_d2)


@kernel
def click_covariance(A, s):
    """``s_i^2 A_i^-1 A_i^-T`` as ``(c00, c10, c11)`` (N, 3), rad^2: a click's covariance in the tangent
    plane (``A_i`` px/rad, ``s_i`` px)."""
    n = A.shape[0]
    C = np.empty((n, 3))
    for i in range(n):
        a00, a01, a10, a11 = A[i, 0, 0], A[i, 0, 1], A[i, 1, 0], A[i, 1, 1]
        det = a00 * a11 - a01 * a10
        # J = s A^-1
        j00, j01 = a11 / det * s[i], -a01 / det * s[i]
        j10, j11 = -a10 / det * s[i], a00 / det * s[i]
        C[i, 0] = j00 * j00 + j01 * j01
        C[i, 1] = j10 * j00 + j11 * j01
        C[i, 2] = j10 * j10 + j11 * j11
    return C


@kernel
def _whiten_2x2(c00, c10, c11, W, i):
    """``W[i] = chol(C)^-1`` of the 2x2 covariance ``C`` (lower triangular; ``W^T W = C^-1``)."""
    w00 = 1.0 / math.sqrt(c00)  # 1 / l00
    l10 = c10 * w00
    w11 = 1.0 / math.sqrt(max(c11 - l10 * l10, 1e-300))  # 1 / l11
    W[i, 0, 0] = w00
    W[i, 0, 1] = 0.0
    W[i, 1, 1] = w11
    W[i, 1, 0] = -l10 * w00 * w11


@kernel
def laser_whitening(A, s, L):
    """``W_i = chol(C_i)^-1`` (N, 2, 2) with ``C_i = s_i^2 A_i^-1 A_i^-T + L_i``: the click's covariance in
    the tangent plane (``A_i`` px/rad, ``s_i`` px) plus the laser term ``L_i`` (rad^2); ``W^T W = C^-1``
    (:func:`calib_core.solve.whiten.whitening`)."""
    n = A.shape[0]
    C = click_covariance(A, s)
    W = np.empty((n, 2, 2))
    for i in range(n):
        _whiten_2x2(C[i, 0] + L[i, 0, 0], C[i, 1] + L[i, 1, 0], C[i, 2] + L[i, 1, 1], W, i)
    return W


@kernel
def laser_whitening_at(R, t, P, F, C, S):
    """:func:`laser_whitening` at the pose ``(R, t)``, from the click covariances ``C`` (N, 3) of
    :func:`click_covariance` and the laser covariances ``S`` (N, 3, 3), m^2: the laser term of
    :func:`laser_bearing_cov` computed pair by pair, without its array."""
    W = np.empty((P.shape[0], 2, 2))
    _laser_whitening_into(R, t, P, F, C, S, W)
    return W


@kernel
def _laser_whitening_into(R, t, P, F, C, S, W):
    """:func:`laser_whitening_at` into ``W``."""
    for i in range(P.shape[0]):
        l00, _, l10, l11 = _laser_bearing_cov_pair(R, t, P, F, S, i)
        _whiten_2x2(C[i, 0] + l00, C[i, 1] + l10, C[i, 2] + l11, W, i)


@kernel
def pixel_errors(projected, valid, pixels, inliers):
    """Pixel error of every pair and its mean and std over the inliers, in one pass.

    Parameters
    ----------
    projected : (N, 2) projected laser points, px; valid : (N,) bool, projectable into the image
    pixels : (N, 2) clicked pixels, px; inliers : (N,) bool

    Returns
    -------
    err : (N,) px, NaN where the point does not project or the pixel is not finite
    mean, std : float, over the inliers' finite errors (NaN if none)
    n_off : int, inliers without a finite error
    """
    n = pixels.shape[0]
    err = np.empty(n)
    total = 0.0
    m = 0
    n_off = 0
    for i in range(n):
        e = math.hypot(projected[i, 0] - pixels[i, 0], projected[i, 1] - pixels[i, 1])
        if not (valid[i] and np.isfinite(e)):
            e = np.nan
        err[i] = e
        if inliers[i]:
            if e == e:
                total += e
                m += 1
            else:
                n_off += 1
    if m == 0:
        return err, np.nan, np.nan, n_off
    mean = total / m
    var = 0.0
    for i in range(n):
        if inliers[i] and err[i] == err[i]:
            var += (err[i] - mean) ** 2
    return err, mean, math.sqrt(var / m), n_off
