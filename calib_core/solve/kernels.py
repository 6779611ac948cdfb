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
from numba import njit

__all__ = [
    "whitened_residuals",
    "normal_equations",
    "jacobian",
    "lm_refine",
    "score_poses",
    "dlt_pose",
    "so3_exp",
]

_JIT = dict(cache=True, nogil=True, fastmath=False)


@njit(**_JIT)
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


@njit(**_JIT)
def _pair(R, t, p, F, W, out_z, out_J, want_J):
    """Whitened residual (2,) of one pair into ``out_z`` and, if asked, its Jacobian (2, 6) into ``out_J``.

    Returns the geodesic angle (radians).
    """
    a0 = R[0, 0] * p[0] + R[0, 1] * p[1] + R[0, 2] * p[2]
    a1 = R[1, 0] * p[0] + R[1, 1] * p[1] + R[1, 2] * p[2]
    a2 = R[2, 0] * p[0] + R[2, 1] * p[1] + R[2, 2] * p[2]
    P0, P1, P2 = a0 + t[0], a1 + t[1], a2 + t[2]
    y0 = F[0, 0] * P0 + F[0, 1] * P1 + F[0, 2] * P2
    y1 = F[1, 0] * P0 + F[1, 1] * P1 + F[1, 2] * P2
    y2 = F[2, 0] * P0 + F[2, 1] * P1 + F[2, 2] * P2
    s_unit = math.hypot(y0, y1)
    norm = math.hypot(s_unit, y2)
    inv = 1.0 / norm if norm > 0.0 else 1.0
    theta = math.atan2(s_unit, y2)
    s = s_unit * inv
    c = y2 * inv
    w0, w1 = y0 * inv, y1 * inv
    if theta < 1e-3:
        th2 = theta * theta
        g = 1.0 + th2 / 6.0 + 7.0 * th2 * th2 / 360.0
        h = -2.0 / 3.0 - th2 / 5.0
    else:
        g = theta / s
        h = (c * s - theta) / (s * s * s)
    r0, r1 = g * w0, g * w1
    out_z[0] = W[0, 0] * r0 + W[0, 1] * r1
    out_z[1] = W[1, 0] * r0 + W[1, 1] * r1
    if want_J:
        # dr/dy (2x3, frame coordinates) = [g I + h w w^T | -w] / |P|; dr/dP = dr/dy F.
        D00 = (g + h * w0 * w0) * inv
        D01 = h * w0 * w1 * inv
        D02 = -w0 * inv
        D10 = D01
        D11 = (g + h * w1 * w1) * inv
        D12 = -w1 * inv
        # Whitened: W D.
        E00 = W[0, 0] * D00 + W[0, 1] * D10
        E01 = W[0, 0] * D01 + W[0, 1] * D11
        E02 = W[0, 0] * D02 + W[0, 1] * D12
        E10 = W[1, 0] * D00 + W[1, 1] * D10
        E11 = W[1, 0] * D01 + W[1, 1] * D11
        E12 = W[1, 0] * D02 + W[1, 1] * D12
        for k in range(3):
            out_J[0, 3 + k] = E00 * F[0, k] + E01 * F[1, k] + E02 * F[2, k]
            out_J[1, 3 + k] = E10 * F[0, k] + E11 * F[1, k] + E12 * F[2, k]
        # d(exp(delta) R p)/d delta = -[R p]_x: a row d times -[a]_x is a x d.
        for row in range(2):
            d0, d1, d2 = out_J[row, 3], out_J[row, 4], out_J[row, 5]
            out_J[row, 0] = a1 * d2 - a2 * d1
            out_J[row, 1] = a2 * d0 - a0 * d2
            out_J[row, 2] = a0 * d1 - a1 * d0
    return theta


@njit(**_JIT)
def whitened_residuals(R, t, P, F, W):
    """Whitened residuals ``(N, 2)`` and geodesic angles ``(N,)`` (radians) at pose ``(R, t)``."""
    n = P.shape[0]
    z = np.empty((n, 2))
    theta = np.empty(n)
    Jdummy = np.empty((2, 6))
    for i in range(n):
        theta[i] = _pair(R, t, P[i], F[i], W[i], z[i], Jdummy, False)
    return z, theta


@njit(**_JIT)
def jacobian(R, t, P, F, W):
    """Whitened Jacobian ``(2N, 6)`` at ``(R, t)`` w.r.t. ``(delta, t)`` (left perturbation, delta = 0)."""
    n = P.shape[0]
    J = np.empty((2 * n, 6))
    z = np.empty(2)
    for i in range(n):
        _pair(R, t, P[i], F[i], W[i], z, J[2 * i : 2 * i + 2], True)
    return J


@njit(**_JIT)
def normal_equations(R, t, P, F, W):
    """``H = J^T J`` (6, 6), ``g = J^T z`` (6,) and ``cost = sum |z_i|^2`` at ``(R, t)``."""
    H = np.zeros((6, 6))
    g = np.zeros(6)
    cost = 0.0
    z = np.empty(2)
    Ji = np.empty((2, 6))
    for i in range(P.shape[0]):
        _pair(R, t, P[i], F[i], W[i], z, Ji, True)
        cost += z[0] * z[0] + z[1] * z[1]
        for a in range(6):
            g[a] += Ji[0, a] * z[0] + Ji[1, a] * z[1]
            for b in range(a, 6):
                H[a, b] += Ji[0, a] * Ji[0, b] + Ji[1, a] * Ji[1, b]
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    return H, g, cost


@njit(**_JIT)
def _cost(R, t, P, F, W):
    z = np.empty(2)
    Jd = np.empty((2, 6))
    cost = 0.0
    for i in range(P.shape[0]):
        _pair(R, t, P[i], F[i], W[i], z, Jd, False)
        cost += z[0] * z[0] + z[1] * z[1]
    return cost


@njit(**_JIT)
def _cholesky_solve(A, b):
    """Solve ``A x = b`` for a symmetric positive-definite 6x6 ``A``; ok False if it is not."""
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return b * 0.0, False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    y = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x, True


@njit(**_JIT)
def lm_refine(R0, t0, P, F, W, max_iter):
    """Levenberg-Marquardt on the whitened angular cost.

    Each iteration solves ``(H + lam diag(H)) dx = -g`` (Marquardt's scaling,
    so radians and metres need no common unit), accepts the step if the cost
    drops and then lowers ``lam``, else raises it.  Stops when the step or
    the relative cost decrease is below 1e-12 or after ``max_iter``
    iterations.

    Returns
    -------
    R : (3, 3), t : (3,)
    iterations : int
        Normal-equation evaluations.
    status : int
        1 converged, 0 iteration limit, -1 singular normal equations, -2 non-finite cost.
    """
    R = R0.copy()
    t = t0.copy()
    lam = 1e-4
    H, g, cost = normal_equations(R, t, P, F, W)
    if not np.isfinite(cost):
        return R, t, 1, -2
    it = 1
    A = np.empty((6, 6))
    while it < max_iter:
        for a in range(6):
            for b in range(6):
                A[a, b] = H[a, b]
            A[a, a] = H[a, a] * (1.0 + lam) + 1e-300
        dx, ok = _cholesky_solve(A, -g)
        if not ok:
            if lam > 1e12:
                return R, t, it, -1
            lam *= 10.0
            continue
        # Predicted decrease -g.dx: at the noise floor of the cost nothing is left to gain
        # (comparing costs there only measures rounding).
        gd = 0.0
        for a in range(6):
            gd -= g[a] * dx[a]
        if gd <= 1e-13 * cost or cost <= 1e-300:
            return R, t, it, 1
        R_new = so3_exp(dx[:3]) @ R
        t_new = t + dx[3:]
        cost_new = _cost(R_new, t_new, P, F, W)
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
            R, t = R_new, t_new
            lam = max(lam / 10.0, 1e-12)
            H, g, cost = normal_equations(R, t, P, F, W)
            it += 1
            if small_step or decrease <= 1e-11 * cost or cost <= 1e-300:
                return R, t, it, 1
        else:
            if small_step:
                return R, t, it, 1
            lam *= 10.0
            if lam > 1e16:
                return R, t, it, 1  # no descent direction left: a minimum to rounding
    return R, t, it, 0


@njit(**_JIT)
def score_poses(Rs, ts, P, F, W):
    """Squared whitened residual norms ``(K, N)`` of K candidate poses ``Rs (K, 3, 3)``, ``ts (K, 3)``."""
    K = Rs.shape[0]
    n = P.shape[0]
    out = np.empty((K, n))
    z = np.empty(2)
    Jd = np.empty((2, 6))
    for k in range(K):
        for i in range(n):
            _pair(Rs[k], ts[k], P[i], F[i], W[i], z, Jd, False)
            out[k, i] = z[0] * z[0] + z[1] * z[1]
    return out


@njit(**_JIT)
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
    M = np.zeros((12, 12))
    row = np.empty(8)
    for i in range(n):
        q0 = (P[i, 0] - mu[0]) / spread
        q1 = (P[i, 1] - mu[1]) / spread
        q2 = (P[i, 2] - mu[2]) / spread
        b0, b1, b2 = B[i, 0], B[i, 1], B[i, 2]
        # x = (r00 r01 r02 t0 | r10 r11 r12 t1 | r20 r21 r22 t2); X_c = M q.
        # rows of [b]_x X_c = 0: (b1 X2 - b2 X1), (b2 X0 - b0 X2), (b0 X1 - b1 X0).
        for eq in range(3):
            # The row has 8 non-zeros: blocks ia and ib of the unknowns, (q, 1) scaled by ca and cb.
            if eq == 0:
                ca, ia, cb, ib = b1, 2, -b2, 1
            elif eq == 1:
                ca, ia, cb, ib = b2, 0, -b0, 2
            else:
                ca, ia, cb, ib = b0, 1, -b1, 0
            row[0], row[1], row[2], row[3] = ca * q0, ca * q1, ca * q2, ca
            row[4], row[5], row[6], row[7] = cb * q0, cb * q1, cb * q2, cb
            for a in range(8):
                ga = 4 * ia + a if a < 4 else 4 * ib + a - 4
                ra = row[a]
                for b in range(8):
                    gb = 4 * ia + b if b < 4 else 4 * ib + b - 4
                    M[ga, gb] += ra * row[b]
    w, V = np.linalg.eigh(M)
    if not (w[1] > 1e-10 * w[11]):
        return R, t, False  # a second null vector: degenerate configuration
    x = V[:, 0]
    A = np.empty((3, 3))
    tt = np.empty(3)
    for r in range(3):
        for c in range(3):
            A[r, c] = x[4 * r + c]
        tt[r] = x[4 * r + 3]
    U, S, Vt = np.linalg.svd(A)
    scale = (S[0] + S[1] + S[2]) / 3.0
    if not scale > 0.0:
        return R, t, False
    Rn = U @ Vt
    sgn = 1.0
    if np.linalg.det(Rn) < 0.0:
        sgn = -1.0
        Rn = -Rn
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


@njit(**_JIT)
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


@njit(**_JIT)
def finish(R, t, P, F, W, inliers):
    """Everything the report needs at the final pose, in one pass.

    Returns
    -------
    z : (N, 2) whitened residuals of every pair
    theta : (N,) geodesic angles, radians
    H : (6, 6) normal matrix of the inliers
    ssr : float, sum of the inliers' squared whitened residuals
    """
    n = P.shape[0]
    z = np.empty((n, 2))
    theta = np.empty(n)
    H = np.zeros((6, 6))
    ssr = 0.0
    Ji = np.empty((2, 6))
    for i in range(n):
        theta[i] = _pair(R, t, P[i], F[i], W[i], z[i], Ji, inliers[i])
        if inliers[i]:
            ssr += z[i, 0] * z[i, 0] + z[i, 1] * z[i, 1]
            for a in range(6):
                for b in range(a, 6):
                    H[a, b] += Ji[0, a] * Ji[0, b] + Ji[1, a] * Ji[1, b]
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    return z, theta, H, ssr


@njit(**_JIT)
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
    w, V = np.linalg.eigh(S)
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


@njit(**_JIT)
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
            if angular:
                c0 = X[i, 1] * X[j, 2] - X[i, 2] * X[j, 1]
                c1 = X[i, 2] * X[j, 0] - X[i, 0] * X[j, 2]
                c2 = X[i, 0] * X[j, 1] - X[i, 1] * X[j, 0]
                dot = X[i, 0] * X[j, 0] + X[i, 1] * X[j, 1] + X[i, 2] * X[j, 2]
                dist = math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), dot)
            else:
                dist = math.sqrt((X[i, 0] - X[j, 0]) ** 2 + (X[i, 1] - X[j, 1]) ** 2 + (X[i, 2] - X[j, 2]) ** 2)
            if dist <= radius:
                return min(i, j), max(i, j)
    return -1, -1


@njit(**_JIT)
def pair_checks(P, B, same_point_m, same_bearing_rad):
    """The degeneracy figures of :func:`calib_core.solve.checks.validate_pairs` in one pass.

    Returns
    -------
    bad_point, bad_bearing : int
        First pair with a non-finite laser point / bearing, or -1.
    bad_norm : int
        First pair whose bearing norm is off 1 (checked by the caller's tolerance), -1 if all finite.
    norms : (N,) bearing norms
    same_point, same_bearing : (2,) int
        A pair of pairs with the same laser point / bearing, or (-1, -1).
    singular : (3,) singular values of the centred laser points, descending
    cos_min_to_mean : float
        Smallest cosine between a unit bearing and the normalised bearing sum
        (NaN if the sum vanishes).
    """
    n = P.shape[0]
    bad_point = -1
    bad_bearing = -1
    norms = np.empty(n)
    for i in range(n):
        if bad_point < 0 and not (np.isfinite(P[i, 0]) and np.isfinite(P[i, 1]) and np.isfinite(P[i, 2])):
            bad_point = i
        if bad_bearing < 0 and not (np.isfinite(B[i, 0]) and np.isfinite(B[i, 1]) and np.isfinite(B[i, 2])):
            bad_bearing = i
        norms[i] = math.sqrt(B[i, 0] ** 2 + B[i, 1] ** 2 + B[i, 2] ** 2)
    same_p = np.full(2, -1)
    same_b = np.full(2, -1)
    sv = np.zeros(3)
    cos_min = np.nan
    if bad_point >= 0 or bad_bearing >= 0:
        return bad_point, bad_bearing, norms, same_p, same_b, sv, cos_min
    U = np.empty((n, 3))
    for i in range(n):
        inv = 1.0 / norms[i] if norms[i] > 0.0 else 0.0
        for k in range(3):
            U[i, k] = B[i, k] * inv
    same_p[0], same_p[1] = _first_close(P, same_point_m, False)
    same_b[0], same_b[1] = _first_close(U, same_bearing_rad, True)
    mu = np.zeros(3)
    for i in range(n):
        mu += P[i]
    mu /= n
    C = np.zeros((3, 3))
    for i in range(n):
        for a in range(3):
            for b in range(3):
                C[a, b] += (P[i, a] - mu[a]) * (P[i, b] - mu[b])
    w = np.linalg.eigvalsh(C)
    for k in range(3):
        sv[k] = math.sqrt(max(w[2 - k], 0.0))
    s = np.zeros(3)
    for i in range(n):
        s += U[i]
    sn = math.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
    if sn > 0.0:
        cos_min = 1.0
        for i in range(n):
            c = (U[i, 0] * s[0] + U[i, 1] * s[1] + U[i, 2] * s[2]) / sn
            if c < cos_min:
                cos_min = c
    return bad_point, bad_bearing, norms, same_p, same_b, sv, cos_min
