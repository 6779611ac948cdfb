"""Compiled per-point loops of the camera models' ``project`` and ``bearing``.

One fused pass per point (transform to the model's variables, the model,
the in-image test, the stores), arithmetic in float64 whatever the storage
type (except OCam on float32 points: see :func:`ocam_project`); no
temporaries, so the same kernel serves a 10-pair solve (a few microseconds
per call) and a million-point colouring.  The models
(:mod:`.pinhole`, :mod:`.fisheye`, :mod:`.ocam`) hold the parameters and
pack the scalars into one float64 vector per call (one argument to type-check
instead of a dozen); the layouts of those vectors are the ``_P_*`` / ``_F_*``
/ ``_O_*`` indices below.

Semantics shared by every ``project`` kernel: a point the model cannot
project gets NaN pixels and ``valid = False``; otherwise ``valid`` is the
in-image test ``-0.5 <= u <= W - 0.5``, ``-0.5 <= v <= H - 0.5`` on the
stored (possibly float32) pixel.  ``bearing`` kernels write NaN rays where
the pixel has no ray.
"""

from __future__ import annotations

import math

import numpy as np

from numba.extending import register_jitable

from .._jit import tiered_kernel as kernel

# -- pinhole parameter vector --------------------------------------------------------
_P_FX, _P_FY, _P_CX, _P_CY, _P_RMAX, _P_W, _P_H, _P_TILT = range(8)
_P_K = 8  # 14 OpenCV coefficients k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty
_P_T = _P_K + 14  # 3x3 tilt matrix (project) or its inverse (bearing), row-major
PINHOLE_PARAMS = _P_T + 9

# -- fisheye --------------------------------------------------------------------------
_F_FX, _F_S, _F_CX, _F_FY, _F_CY, _F_TMAX, _F_TDMAX, _F_W, _F_H = range(9)
_F_D = 9  # k1..k4
FISHEYE_PARAMS = _F_D + 4

# -- OCam -----------------------------------------------------------------------------
_O_SMAX, _O_INVSTEP, _O_C, _O_D, _O_E, _O_XC, _O_YC, _O_W, _O_H, _O_INVDET, _O_RHOMAX = range(11)
OCAM_PARAMS = 11


@kernel
def _store(pixels, valid, i, u, v, width, height):
    """Store pixel ``i`` and its in-image test (on the stored value, as the caller will index with it)."""
    pixels[i, 0] = u
    pixels[i, 1] = v
    us, vs = pixels[i, 0], pixels[i, 1]
    valid[i] = (us >= -0.5) and (us <= width - 0.5) and (vs >= -0.5) and (vs <= height - 0.5)


@kernel
def _blank(pixels, valid, i):
    pixels[i, 0] = np.nan
    pixels[i, 1] = np.nan
    valid[i] = False


# ------------------------------------------------------------------ pinhole
@register_jitable(inline="always")
def _pinhole_distortion(x, y, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4):
    """OpenCV's radial, tangential and thin-prism distortion of one normalised point (no tilt), and its
    Jacobian: ``xd, yd, d(xd)/dx, d(xd)/dy, d(yd)/dx, d(yd)/dy``.

    The one copy of the polynomial (``project`` and ``bearing`` both call it; compiled inline, so a caller
    that ignores the Jacobian does not compute it).  Coefficients as scalars: a caller keeps them in
    locals, which keeps its loop on SIMD lanes.
    """
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    radial = num / den
    xy2 = 2.0 * x * y
    r4 = r2 * r2
    xd = x * radial + (p1 * xy2 + p2 * (r2 + 2.0 * x * x)) + (s1 * r2 + s2 * r4)
    yd = y * radial + (p1 * (r2 + 2.0 * y * y) + p2 * xy2) + (s3 * r2 + s4 * r4)
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * r2 * k6)
    d_radial = (dnum * den - num * dden) / (den * den)  # d radial / d r2
    gx, gy = 2.0 * x, 2.0 * y
    j_xx = radial + x * d_radial * gx + 2.0 * p1 * y + 6.0 * p2 * x + (s1 + 2.0 * s2 * r2) * gx
    j_xy = x * d_radial * gy + 2.0 * p1 * x + 2.0 * p2 * y + (s1 + 2.0 * s2 * r2) * gy
    j_yx = y * d_radial * gx + 2.0 * p1 * x + 2.0 * p2 * y + (s3 + 2.0 * s4 * r2) * gx
    j_yy = radial + y * d_radial * gy + 6.0 * p1 * y + 2.0 * p2 * x + (s3 + 2.0 * s4 * r2) * gy
    return xd, yd, j_xx, j_xy, j_yx, j_yy


@kernel
def _homography(p, x, y):
    """The 3x3 tilt matrix stored in ``p`` applied to ``(x, y, 1)``, dehomogenised."""
    t = _P_T
    w = p[t + 6] * x + p[t + 7] * y + p[t + 8]
    return (p[t] * x + p[t + 1] * y + p[t + 2]) / w, (p[t + 3] * x + p[t + 4] * y + p[t + 5]) / w


@kernel
def _store_chunk(pixels, valid, start, count, u_buf, v_buf, u_hi, v_hi):
    """Store a chunk's pixels and their in-image test (in float64: as strict as the test on a
    float32 pixel, the bounds being exact in float32)."""
    for k in range(count):
        i = _U(start + k)
        u, v = u_buf[k], v_buf[k]
        pixels[i, 0] = u
        pixels[i, 1] = v
        valid[i] = (u >= -0.5) & (u <= u_hi) & (v >= -0.5) & (v <= v_hi)


#: Points per chunk of the chunked ``project`` kernels: their buffers stay in L1 cache.
_CHUNK = 256
#: Unsigned indices: numba wraps every signed index around (negative = from
#: the end), which costs instructions and keeps loops off SIMD lanes.
_U = np.uintp


@kernel
def pinhole_project(points, p, pixels, valid):
    """Pinhole + OpenCV distortion: ``points (N, 3)`` -> ``pixels (N, 2)``, ``valid (N,)``, in place.

    Not projectable: ``Z <= 0``, a non-finite coordinate, or an undistorted
    radius beyond ``r_max``.  By chunks: a branch-free loop (SIMD lanes)
    into chunk buffers, then the stores.
    """
    fx, fy, cx, cy, r_max = p[_P_FX], p[_P_FY], p[_P_CX], p[_P_CY], p[_P_RMAX]
    u_hi, v_hi = p[_P_W] - 0.5, p[_P_H] - 0.5
    # Coefficients in locals (loads from p inside the loop would keep it off SIMD lanes).
    k1, k2, p1, p2, k3 = p[_P_K], p[_P_K + 1], p[_P_K + 2], p[_P_K + 3], p[_P_K + 4]
    k4, k5, k6 = p[_P_K + 5], p[_P_K + 6], p[_P_K + 7]
    s1, s2, s3, s4 = p[_P_K + 8], p[_P_K + 9], p[_P_K + 10], p[_P_K + 11]
    # The tilt homography is applied always: without tilt it is the identity, exact on finite values.
    t = _P_T
    t00, t01, t02, t10, t11, t12 = p[t], p[t + 1], p[t + 2], p[t + 3], p[t + 4], p[t + 5]
    t20, t21, t22 = p[t + 6], p[t + 7], p[t + 8]
    n_points = points.shape[0]
    m = min(n_points, _CHUNK)
    u_buf = np.empty(m, np.float64)
    v_buf = np.empty(m, np.float64)
    for start in range(0, n_points, _CHUNK):
        count = min(_CHUNK, n_points - start)
        for k in range(count):
            i = _U(start + k)  # unsigned: no wrap-around test, so the loop runs on SIMD lanes
            X, Y, Z = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
            x = X / Z
            y = Y / Z
            ok = (Z > 0.0) & (Z < np.inf) & np.isfinite(X) & np.isfinite(Y) & (math.sqrt(x * x + y * y) <= r_max)
            xd, yd, _, _, _, _ = _pinhole_distortion(x, y, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4)
            w = t20 * xd + t21 * yd + t22
            xt = (t00 * xd + t01 * yd + t02) / w
            yt = (t10 * xd + t11 * yd + t12) / w
            u = fx * xt + cx
            v = fy * yt + cy
            u_buf[k] = u if ok else np.nan
            v_buf[k] = v if ok else np.nan
        _store_chunk(pixels, valid, start, count, u_buf, v_buf, u_hi, v_hi)


@kernel
def pinhole_bearing(uv, p, table_r, table_rd, rays):
    """Pinhole + OpenCV distortion: ``uv (N, 2)`` -> unit ``rays (N, 3)``, in place.

    Newton's method on the distortion, started from the radial-only inverse
    (``table_rd -> table_r``, linear interpolation); steps that would leave
    the monotonic zone ``r <= r_max`` are halved.  NaN where it does not
    converge to a point within ``r_max``.
    """
    tilt = p[_P_TILT] != 0.0
    r_max = p[_P_RMAX]
    k1, k2, p1, p2, k3 = p[_P_K], p[_P_K + 1], p[_P_K + 2], p[_P_K + 3], p[_P_K + 4]
    k4, k5, k6 = p[_P_K + 5], p[_P_K + 6], p[_P_K + 7]
    s1, s2, s3, s4 = p[_P_K + 8], p[_P_K + 9], p[_P_K + 10], p[_P_K + 11]
    last = table_rd.shape[0] - 1
    for i in range(uv.shape[0]):
        xd = (uv[i, 0] - p[_P_CX]) / p[_P_FX]
        yd = (uv[i, 1] - p[_P_CY]) / p[_P_FY]
        if tilt:
            xd, yd = _homography(p, xd, yd)  # p holds the inverse tilt here
        rd = math.sqrt(xd * xd + yd * yd)
        # np.interp: clamped at both ends, NaN stays NaN.
        if rd <= table_rd[0]:
            r0 = table_r[0]
        elif rd >= table_rd[last]:
            r0 = table_r[last]
        elif rd == rd:
            j = np.searchsorted(table_rd, rd, side="right") - 1
            r0 = table_r[j] + (rd - table_rd[j]) * (table_r[j + 1] - table_r[j]) / (table_rd[j + 1] - table_rd[j])
        else:
            r0 = np.nan
        scale = r0 / rd if rd > 0.0 else 1.0
        x, y = xd * scale, yd * scale
        for _ in range(30):
            fx, fy, jxx, jxy, jyx, jyy = _pinhole_distortion(x, y, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4)
            ex, ey = fx - xd, fy - yd
            det = jxx * jyy - jxy * jyx
            dx = (jyy * ex - jxy * ey) / det
            dy = (-jyx * ex + jxx * ey) / det
            step = math.sqrt(dx * dx + dy * dy)
            if not np.isfinite(step):
                break
            xn, yn = x - dx, y - dy
            shrink = 0.5 if math.sqrt(xn * xn + yn * yn) > r_max else 1.0
            x -= shrink * dx
            y -= shrink * dy
            if not step > 1e-15 * (1.0 + math.sqrt(x * x + y * y)):
                break
        fx, fy, _, _, _, _ = _pinhole_distortion(x, y, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4)
        residual = math.sqrt((fx - xd) ** 2 + (fy - yd) ** 2)
        ok = (np.isfinite(x) and np.isfinite(y) and residual <= 1e-10 * (1.0 + rd)
              and math.sqrt(x * x + y * y) <= r_max)
        if ok:
            norm = math.sqrt(x * x + y * y + 1.0)
            rays[i, 0], rays[i, 1], rays[i, 2] = x / norm, y / norm, 1.0 / norm
        else:
            rays[i, 0] = rays[i, 1] = rays[i, 2] = np.nan


# ------------------------------------------------------------------ fisheye
@kernel
def _theta_d(theta, p):
    t2 = theta * theta
    return theta * (1.0 + t2 * (p[_F_D] + t2 * (p[_F_D + 1] + t2 * (p[_F_D + 2] + t2 * p[_F_D + 3]))))


@kernel
def _dtheta_d(theta, p):
    t2 = theta * theta
    return 1.0 + t2 * (3.0 * p[_F_D] + t2 * (5.0 * p[_F_D + 1] + t2 * (7.0 * p[_F_D + 2] + t2 * 9.0 * p[_F_D + 3])))


@kernel
def fisheye_project(points, p, pixels, valid):
    """Kannala-Brandt: ``points (N, 3)`` -> ``pixels (N, 2)``, ``valid (N,)``, in place.

    Not projectable: ``Z <= 0``, a non-finite coordinate, or an angle from
    the axis beyond ``theta_max``.
    """
    width, height = p[_F_W], p[_F_H]
    for i in range(points.shape[0]):
        X, Y, Z = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        r = math.hypot(X, Y)
        theta = math.atan2(r, Z)
        if not (np.isfinite(X) and np.isfinite(Y) and np.isfinite(Z) and Z > 0.0 and theta <= p[_F_TMAX]):
            _blank(pixels, valid, i)
            continue
        scale = _theta_d(theta, p) / r if r > 0.0 else 0.0
        xp, yp = X * scale, Y * scale
        _store(pixels, valid, i, p[_F_FX] * xp + p[_F_S] * yp + p[_F_CX], p[_F_FY] * yp + p[_F_CY], width, height)


@kernel
def fisheye_bearing(uv, p, table_theta_d, table_theta, rays):
    """Kannala-Brandt: ``uv (N, 2)`` -> unit ``rays (N, 3)``, in place.

    Inverts ``theta_d(theta)`` from a lookup table with Newton steps; NaN
    beyond ``theta_d(theta_max)``.
    """
    last = table_theta_d.shape[0] - 1
    t_max = p[_F_TMAX]
    for i in range(uv.shape[0]):
        yp = (uv[i, 1] - p[_F_CY]) / p[_F_FY]
        xp = (uv[i, 0] - p[_F_CX] - p[_F_S] * yp) / p[_F_FX]
        td = math.hypot(xp, yp)
        if not (np.isfinite(td) and td <= p[_F_TDMAX]):
            rays[i, 0] = rays[i, 1] = rays[i, 2] = np.nan
            continue
        if td >= table_theta_d[last]:
            theta = table_theta[last]
        else:
            j = np.searchsorted(table_theta_d, td, side="right") - 1
            theta = table_theta[j] + (td - table_theta_d[j]) * (table_theta[j + 1] - table_theta[j]) / (
                table_theta_d[j + 1] - table_theta_d[j])
        for _ in range(8):
            step = (_theta_d(theta, p) - td) / _dtheta_d(theta, p)
            if not np.isfinite(step):
                step = 0.0
            theta = min(max(theta - step, 0.0), t_max)
            if not abs(step) > 1e-15:
                break
        s = math.sin(theta) / td if td > 0.0 else 0.0
        rays[i, 0], rays[i, 1], rays[i, 2] = xp * s, yp * s, math.cos(theta)


# ------------------------------------------------------------------ OCam
@kernel
def ocam_project(points, p, table, pixels, valid):
    """OCamCalib: ``points (N, 3)`` (OpenCV frame) -> ``pixels (N, 2)``, ``valid (N,)``, in place.

    ``table (K, 2)``: the radius ``rho`` and the slope to the next entry on
    a uniform grid of the half-angle variable ``s`` (``OCamCamera``'s
    ``_half_angle_s``: ``n / (r + |Z|)`` in front, ``2 - n / (r + |Z|)``
    behind; no arctan).  Not projectable: the zero vector, a non-finite
    coordinate, or ``s`` beyond the field of view.

    Arithmetic in the table's type: float64 for the solve, float32 for bulk
    colouring (float32 points and table: 8 points per SIMD instruction
    instead of 4, and square roots and divisions are the cost; pixels within
    about 2e-4 px of float64).

    By chunks, in branch-free loops: the table position of every point
    (SIMD lanes), the table reads alone (random reads into a table larger
    than L1: a loop of nothing else keeps many of them in flight), the
    pixels into chunk buffers (SIMD lanes), then the stores.
    """
    F = table.dtype.type
    one, zero = F(1.0), F(0.0)
    s_max, inv_step = F(p[_O_SMAX]), F(p[_O_INVSTEP])
    c, d, e, xc, yc = F(p[_O_C]), F(p[_O_D]), F(p[_O_E]), F(p[_O_XC]), F(p[_O_YC])
    u_hi, v_hi = p[_O_W] - 0.5, p[_O_H] - 0.5
    last = F(table.shape[0] - 1)
    n_points = points.shape[0]
    m = min(n_points, _CHUNK)
    index = np.empty(m, np.int32)  # int32: converts on SIMD lanes (int64 does not without AVX-512)
    frac = np.empty(m, table.dtype)
    dist = np.empty(m, table.dtype)
    ok = np.empty(m, np.bool_)
    rho = np.empty(m, table.dtype)
    u_buf = np.empty(m, table.dtype)
    v_buf = np.empty(m, table.dtype)
    nan = F(np.nan)
    for start in range(0, n_points, _CHUNK):
        count = min(_CHUNK, n_points - start)
        for k_ in range(count):
            i, k = _U(start + k_), _U(k_)
            X, Y, Z = F(points[i, 0]), F(points[i, 1]), F(points[i, 2])
            n2 = X * X + Y * Y
            n = np.sqrt(n2)  # distance from the optical axis
            r = np.sqrt(Z * Z + n2)
            # tan(alpha / 2) in front (Z >= 0), tan((pi - alpha) / 2) behind: free of cancellation.
            s = one - np.copysign(one - n / (abs(Z) + r), Z)
            good = (s <= s_max) & (r < np.inf)  # NaN (zero vector, NaN input) fails
            pos = s * inv_step
            pos = pos if pos < last else last  # NaN -> the last entry (masked by ok)
            j = np.int32(pos)
            index[k] = j
            frac[k] = pos - F(j)
            dist[k] = n
            ok[k] = good
        for k_ in range(count):
            k = _U(k_)
            j = _U(index[k])
            rho[k] = table[j, 0] + frac[k] * table[j, 1]
        for k_ in range(count):
            i, k = _U(start + k_), _U(k_)
            X, Y = F(points[i, 0]), F(points[i, 1])
            n = dist[k]
            scale = rho[k] / n if n > zero else zero  # on the axis rho = n = 0: the centre
            u = (e * Y + X) * scale + yc
            v = (c * Y + d * X) * scale + xc
            u_buf[k] = u if ok[k] else nan
            v_buf[k] = v if ok[k] else nan
        _store_chunk(pixels, valid, start, count, u_buf, v_buf, u_hi, v_hi)


@kernel
def ocam_bearing(uv, p, pol, rays):
    """OCamCalib: ``uv (N, 2)`` = (column, row) -> unit ``rays (N, 3)`` (OpenCV frame), in place.

    NaN where the radius exceeds ``rho_max`` (outside the monotonic part of ``pol``).
    """
    invdet, c, d, e, xc, yc = p[_O_INVDET], p[_O_C], p[_O_D], p[_O_E], p[_O_XC], p[_O_YC]
    rho_max = p[_O_RHOMAX] * (1.0 + 1e-12)
    for i in range(uv.shape[0]):
        dr, dq = uv[i, 1] - xc, uv[i, 0] - yc
        xp = invdet * (dr - d * dq)
        yp = invdet * (-e * dr + c * dq)
        rho = math.hypot(xp, yp)
        if not rho <= rho_max:
            rays[i, 0] = rays[i, 1] = rays[i, 2] = np.nan
            continue
        zp = pol[pol.shape[0] - 1]
        for k in range(pol.shape[0] - 2, -1, -1):
            zp = zp * rho + pol[k]
        norm = math.sqrt(xp * xp + yp * yp + zp * zp)
        rays[i, 0], rays[i, 1], rays[i, 2] = yp / norm, xp / norm, -zp / norm  # OCam (x, y, z) -> OpenCV

