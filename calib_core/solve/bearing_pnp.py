"""Initial pose from laser points and camera bearing vectors (PnP on the sphere).

Two closed-form routes, both on unit bearings that may point anywhere on the
sphere (catadioptric cameras see more than 90 deg off axis; nothing here
assumes ``z > 0``).  A bearing fixes the *signed* direction of its point: the
point lies at depth ``d > 0`` along it.

1. The paper's route (Sec. IV-B): Quan & Lan's linear N-point method
   (L. Quan and Z. Lan, "Linear N-point camera pose determination", IEEE PAMI
   21(7), 1999) gives the depth of every point; the camera-frame points
   ``d_i * b_i`` are then registered to the laser points in closed form
   (:func:`calib_core.solve.rigid.rigid_fit`).
2. A robust fallback, because the linear method is noise-sensitive (the paper
   says so): Grunert's P3P in the form reviewed by R. M. Haralick, C. Lee,
   K. Ottenberg and M. Noelle, "Review and analysis of solutions of the three
   point perspective pose estimation problem", IJCV 13(3), 1994, solved on many
   well-spread triples; every candidate pose is scored on all pairs.

:func:`initial_pose` returns whichever candidate has the smaller angular cost
(paper eq. 7).
"""

from __future__ import annotations

import functools

import numpy as np

from ..arrays import angle_between_rad
from .kernels import p3p_grunert
from .checks import median
from .rigid import rigid_fit

__all__ = [
    "angular_errors_rad",
    "quan_lan_quartic",
    "quan_lan_depths",
    "quan_lan_pose",
    "p3p_grunert",
    "initial_pose",
]


def angular_errors_rad(
    T_camera_lidar: np.ndarray, points_lidar: np.ndarray, bearings_camera: np.ndarray
) -> np.ndarray:
    """Geodesic angle between each bearing and its transformed laser point.

    Parameters
    ----------
    T_camera_lidar : (..., 4, 4) ndarray
        One or a stack of candidate poses.
    points_lidar : (N, 3) ndarray
        Laser points, lidar frame, metres.
    bearings_camera : (N, 3) ndarray
        Unit bearings, camera frame.

    Returns
    -------
    (..., N) ndarray
        ``atan2(|b x p|, b . p)`` in radians, in [0, pi] (smooth and exact
        everywhere, unlike ``arccos``).
    """
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    P = np.einsum("...ij,nj->...ni", T[..., :3, :3], points_lidar) + T[..., None, :3, 3]
    return angle_between_rad(bearings_camera, P)


# --------------------------------------------------------------------------
# Quan & Lan (PAMI 1999)
# --------------------------------------------------------------------------


def quan_lan_quartic(
    c12: np.ndarray,
    c13: np.ndarray,
    c23: np.ndarray,
    d12: np.ndarray,
    d13: np.ndarray,
    d23: np.ndarray,
) -> np.ndarray:
    """Quan & Lan's quartic ``g(x) = a0 + a1 x + a2 x^2 + a3 x^3 + a4 x^4``.

    For three points with depths ``x1, x2, x3`` along unit bearings, the law of
    cosines gives ``f_ij = x_i^2 + x_j^2 - 2 c_ij x_i x_j - d_ij = 0`` with
    ``c_ij = b_i . b_j`` and ``d_ij = |p_i - p_j|^2`` (squared distance).
    Eliminating ``x2`` and ``x3`` (Quan & Lan 1999, Sec. 2) leaves a degree-8
    polynomial in ``x1`` with only even powers, i.e. a quartic in
    ``x = x1^2``.  The coefficients below are the resultant
    ``Res_x3(Res_x2(f12, f23), f13)`` expanded with sympy and regrouped in
    ``m = d12 + d13 - d23`` (derivation script not shipped; the formula is
    checked in the tests by evaluating ``g`` at true depths).  ``a_k`` is
    homogeneous of degree ``4 - k`` in the squared distances.

    Parameters
    ----------
    c12, c13, c23 : ndarray
        Cosines between the bearings (broadcast together).
    d12, d13, d23 : ndarray
        Squared distances between the points.

    Returns
    -------
    (..., 5) ndarray
        ``(a0, a1, a2, a3, a4)``, ascending powers of ``x = x1^2``.
    """
    # Short names and shared products: the expansion has ~250 array operations otherwise.
    A, B, C = c12, c13, c23
    s = d12 + d13
    m = s - d23
    A2, B2, C2 = A * A, B * B, C * C
    ABC = A * B * C
    A2B2 = A2 * B2
    p = d12 * d13
    m2 = m * m
    D = A2 + B2 + C2 - 2 * ABC - 1
    u = m2 - 4 * C2 * p
    a0 = u * u
    # Terms shared by a1, a2 and a3.
    A2d12, B2d13 = A2 * d12, B2 * d13
    ABCs, C2s = ABC * s, C2 * s
    a1 = 8 * (
        (A2 - ABC + B2 - 1) * m2 * m
        - (2 * C2 * (A2 * d13 + B2 * d12) + A2d12 - 2 * ABCs + B2d13 - C2s) * m2
        + 4 * C * p * ((A2 + B2 + 1 - ABC) * C - 2 * A * B) * m
        - 4 * C2 * p * (A2d12 - 2 * ABCs + B2d13 + C2s)
    )
    A4, B4 = A2 * A2, B2 * B2
    d12_2, d13_2 = d12 * d12, d13 * d13
    q3 = d12_2 + 3 * p + d13_2
    dd = d12 - d13
    a2 = (
        8 * (2 * A4 - 4 * A2 * ABC + 6 * A2B2 + 2 * A2 * C2 - 5 * A2 - 4 * B2 * ABC + 2 * ABC + 2 * B4 + 2 * B2 * C2 - 5 * B2 - C2 + 3) * m2
        - 32
        * (
            A4 * d12
            - 3 * A2 * ABC * d12
            + 2 * ABC * ABC * s
            + A2B2 * s
            + (A2 - B2) * C2 * dd
            - A2d12
            - 3 * B2 * ABC * d13
            - C2 * ABCs
            + B4 * d13
            - B2d13
            + C2s
        )
        * m
        + 16
        * (
            A4 * d12_2
            - 4 * A2 * ABCs * d12
            + 4 * ABC * ABC * q3
            - 2 * A2B2 * p
            + 2 * A2 * C2 * d12_2
            - 4 * B2 * ABCs * d13
            - 4 * C2 * ABC * q3
            + 8 * ABC * p
            + B4 * d13_2
            + 2 * B2 * C2 * d13_2
            + C2 * C2 * (q3 + p)
            - 2 * C2 * p
        )
    )
    a3 = 32 * D * ((2 * A2B2 - A2 - ABC - B2 + 1) * m - (2 * A2B2 * s - A2d12 - 2 * ABCs - B2d13 + C2s))
    a4 = 16 * D * D
    return np.stack(np.broadcast_arrays(a0, a1, a2, a3, a4), axis=-1)


# Index pairs (a, b, c, e) with a + b = c + e: for t = (1, x, ..., x^4),
# t_a t_b = t_c t_e.  Quan & Lan use them to pin down t when n = 4.
_QL_PRODUCT_CONSTRAINTS = np.array(
    [(0, 2, 1, 1), (0, 3, 1, 2), (0, 4, 1, 3), (0, 4, 2, 2), (1, 3, 2, 2), (1, 4, 2, 3), (2, 4, 3, 3)]
)

_QL_MAX_ROWS = 300  # quartics per reference point (subsampled beyond this)


def _x_from_t(t: np.ndarray) -> np.ndarray:
    """Least-squares ``x`` with ``t_{k+1} = x t_k`` for ``t ~ (1, x, ..., x^4)``."""
    return np.sum(t[..., :-1] * t[..., 1:], axis=-1) / np.sum(t[..., :-1] ** 2, axis=-1)


@functools.lru_cache(maxsize=64)
def _ql_all_triples(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every reference i, all pairs (j, k), j < k, that do not contain i: ``(n, m)`` each."""
    ref = np.arange(n)[:, None]
    J, K = np.triu_indices(n, 1)
    keep = (J[None, :] != ref) & (K[None, :] != ref)
    cols = np.nonzero(keep)[1].reshape(n, -1)
    out = np.broadcast_to(ref, cols.shape), J[cols], K[cols]
    for a in out[1:]:
        a.flags.writeable = False  # cached: shared between calls
    return out


def _ql_triples(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Index triples ``(i, j, k)`` of the quartics, ``(n, rows)`` each."""
    if (n - 1) * (n - 2) // 2 <= _QL_MAX_ROWS:
        return _ql_all_triples(n)
    # Random pairs (with repetition) of distinct j, k, both != i.
    ref = np.arange(n)[:, None]
    j = (ref + 1 + rng.integers(0, n - 1, (n, _QL_MAX_ROWS))) % n
    k0 = (ref + 1 + rng.integers(0, n - 2, (n, _QL_MAX_ROWS))) % n  # never i or i - 1
    k = np.where(k0 == j, (ref - 1) % n, k0)
    return np.broadcast_to(ref, j.shape), j, k


def _ql_rows(cos: np.ndarray, sq: np.ndarray, triples: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Quartic coefficients ``(n, rows, 5)`` for bearing cosines and squared distances."""
    i, j, k = triples
    return quan_lan_quartic(cos[i, j], cos[i, k], cos[j, k], sq[i, j], sq[i, k], sq[j, k])


def _quan_lan_x(A: np.ndarray) -> np.ndarray:
    """Squared depths ``x_i`` from the quartics ``A`` (n, rows, 5) of every reference point; NaN where unsolved."""
    n = A.shape[0]
    # Each quartic is defined up to scale: give every row the same weight.
    norms = np.sqrt(np.einsum("nrk,nrk->nr", A, A))[..., None]
    A = A / np.where(norms > 0, norms, 1.0)
    _, _, Vt = np.linalg.svd(A, full_matrices=n < 5)  # A: (n, rows, 5); Vt: (n, 5, 5)
    if n >= 5:
        # Over-determined: t is the right singular vector of the smallest
        # singular value (Quan & Lan, Sec. 3).
        t = Vt[:, -1, :]
    else:
        # n = 4: three equations, five unknowns -> t = lam v4 + rho v5 (Quan &
        # Lan, Sec. 4).  The products t_a t_b = t_c t_e are linear in
        # (lam^2, lam rho, rho^2); their null vector gives lam : rho.
        v4, v5 = Vt[:, 3, :], Vt[:, 4, :]
        a, b, c, e = _QL_PRODUCT_CONSTRAINTS.T
        B = np.stack(
            [
                v4[:, a] * v4[:, b] - v4[:, c] * v4[:, e],
                v4[:, a] * v5[:, b] + v5[:, a] * v4[:, b] - v4[:, c] * v5[:, e] - v5[:, c] * v4[:, e],
                v5[:, a] * v5[:, b] - v5[:, c] * v5[:, e],
            ],
            axis=-1,
        )  # (n, 7, 3)
        y = np.linalg.svd(B)[2][:, -1, :]  # ~ (lam^2, lam rho, rho^2)
        # lam : rho = y0 : y1 = y1 : y2; use the better-conditioned ratio.
        use_first = np.abs(y[:, 0]) >= np.abs(y[:, 2])
        lam = np.where(use_first, y[:, 0], y[:, 1])
        rho = np.where(use_first, y[:, 1], y[:, 2])
        t = lam[:, None] * v4 + rho[:, None] * v5
    with np.errstate(invalid="ignore", divide="ignore"):
        x = _x_from_t(t)
    return np.where(np.isfinite(x) & (x > 0), x, np.nan)


def quan_lan_depths(points_lidar: np.ndarray, bearings_camera: np.ndarray, seed: int = 0) -> np.ndarray:
    """Depth of every point along its bearing by Quan & Lan's linear method.

    Parameters
    ----------
    points_lidar : (N, 3) ndarray
        Laser points (any rigid frame; only their distances matter), metres,
        ``N >= 4``.
    bearings_camera : (N, 3) ndarray
        Unit bearings, camera frame.
    seed : int
        Seed for subsampling the quartics when N is large (N > 25).

    Returns
    -------
    (N,) ndarray
        Depths in metres (> 0); NaN where the method gives no positive root.

    Notes
    -----
    The problem is scale-covariant, so it is solved in normalised units (two
    passes: first scaled by the spread of the points, then by the median
    depth) to keep ``t = (1, x, ..., x^4)`` well balanced.
    """
    P = np.asarray(points_lidar, dtype=np.float64)
    Bm = np.asarray(bearings_camera, dtype=np.float64)
    rng = None  # created only if the quartics are subsampled (n > 25)
    scale = np.sqrt(np.mean(np.sum((P - P.mean(axis=0)) ** 2, axis=1)))
    if not scale > 0:
        return np.full(len(P), np.nan)
    cos = np.clip(Bm @ Bm.T, -1.0, 1.0)
    sq = np.sum((P[:, None, :] - P[None, :, :]) ** 2, axis=-1)
    n = len(P)
    sampled = (n - 1) * (n - 2) // 2 > _QL_MAX_ROWS
    A = None
    for _ in range(2):
        if A is None or sampled:  # (sampled: new random quartics for each pass)
            if sampled and rng is None:
                rng = np.random.default_rng(seed)
            A = _ql_rows(cos, sq / scale**2, _ql_triples(n, rng))
        else:
            # The same quartics in the new units: a_k scales as (squared distance)^(4 - k).
            A = A * ((A_scale / scale) ** 2) ** np.arange(4, -1, -1)
        A_scale = scale
        x = _quan_lan_x(A)
        depths = np.sqrt(x) * scale
        finite = depths[np.isfinite(depths)]
        mid = median(finite) if finite.size else np.nan
        if not np.isfinite(mid) or mid <= 0:
            break
        scale = mid
    return depths


def quan_lan_pose(points_lidar: np.ndarray, bearings_camera: np.ndarray, seed: int = 0) -> np.ndarray | None:
    """``T_camera_lidar`` from Quan & Lan depths and a rigid 3-D/3-D fit.

    Returns None when fewer than three depths are recovered.
    """
    depths = quan_lan_depths(points_lidar, bearings_camera, seed=seed)
    ok = np.isfinite(depths)
    if ok.sum() < 3:
        return None
    points_camera = depths[ok, None] * bearings_camera[ok]
    T = rigid_fit(points_lidar[ok], points_camera)
    return T if np.all(np.isfinite(T)) else None


# --------------------------------------------------------------------------
# Grunert's P3P (Haralick et al. 1994)
# --------------------------------------------------------------------------


def _spread_order(bearings: np.ndarray, count: int) -> np.ndarray:
    """First ``count`` indices in farthest-point order on the sphere (greedy max-min angle)."""
    n = len(bearings)
    order = [int(np.argmin(bearings @ bearings.mean(axis=0)))]
    max_cos = bearings @ bearings[order[0]]  # cosine to the nearest chosen bearing
    for _ in range(min(count, n) - 1):  # a handful of picks
        max_cos[order] = np.inf
        nxt = int(np.argmin(max_cos))
        order.append(nxt)
        max_cos = np.maximum(max_cos, bearings @ bearings[nxt])
    return np.array(order)


@functools.lru_cache(maxsize=32)
def _all_triples(n: int) -> np.ndarray:
    """All index triples ``i < j < k`` of ``n`` pairs, (m, 3), in lexicographic order (cached, read-only)."""
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    keep = (i < j) & (j < k)
    out = np.stack([i[keep], j[keep], k[keep]], axis=1)
    out.flags.writeable = False
    return out


def _triples(bearings: np.ndarray, rng: np.random.Generator, max_random: int = 200) -> np.ndarray:
    """Triples for P3P: all of them for small N, else well-spread plus random ones."""
    n = len(bearings)
    if n <= 12:
        return _all_triples(n)
    spread = np.sort(_spread_order(bearings, 8)[_all_triples(8)], axis=1)
    rand = np.sort(np.argsort(rng.random((max_random, n)), axis=1)[:, :3], axis=1)
    return np.unique(np.concatenate([spread, rand]), axis=0)


#: Quan & Lan's pose is kept without a P3P search when its RMS angular error is below this.
QUAN_LAN_ACCEPT_RMS_RAD = np.radians(2.0)
#: With more pairs, Quan & Lan runs on this many well-spread ones (farthest-point order of the bearings).
QUAN_LAN_MAX_PAIRS = 20


def initial_pose(
    points_lidar: np.ndarray, bearings_camera: np.ndarray, seed: int = 0
) -> tuple[np.ndarray, str, float]:
    """Best closed-form pose among Quan & Lan and P3P candidates.

    Parameters
    ----------
    points_lidar : (N, 3) ndarray
        Laser points, lidar frame, metres, ``N >= 4``.
    bearings_camera : (N, 3) ndarray
        Unit bearings, camera frame.
    seed : int
        Seed of the random triples/quartic subsampling (deterministic output).

    Notes
    -----
    With more than :data:`QUAN_LAN_MAX_PAIRS` pairs, Quan & Lan's depths come
    from that many well-spread pairs; every candidate is scored on all pairs.

    Returns
    -------
    T_camera_lidar : (4, 4) ndarray
        The candidate with the smallest sum of squared angles over all pairs.
    method : str
        ``"quan_lan"`` or ``"p3p"``.
    cost : float
        Its angular cost ``0.5 * sum(angle^2)``, rad^2.
    """
    candidates: list[np.ndarray] = []
    methods: list[str] = []
    # Quan-Lan costs O(n^3) (n quartic systems of (n-1)(n-2)/2 rows): run it on
    # well-spread pairs only; the candidate is still scored on all of them.
    n = len(points_lidar)
    sub = np.sort(_spread_order(bearings_camera, QUAN_LAN_MAX_PAIRS)) if n > QUAN_LAN_MAX_PAIRS else slice(None)
    T_ql = quan_lan_pose(points_lidar[sub], bearings_camera[sub], seed=seed)
    if T_ql is not None:
        errors = angular_errors_rad(T_ql[None], points_lidar, bearings_camera)[0]
        # Clicks are good to a fraction of a degree: an initial pose that fits every
        # pair to within a few degrees is in LM's basin, and the P3P search (the
        # larger share of the solve time) adds nothing.
        if np.sqrt(np.mean(errors**2)) < QUAN_LAN_ACCEPT_RMS_RAD:
            return T_ql, "quan_lan", float(0.5 * np.sum(errors**2))
        candidates.append(T_ql[None])
        methods.append("quan_lan")
    tri = _triples(bearings_camera, np.random.default_rng(seed))
    T_p3p, _ = p3p_grunert(points_lidar[tri], bearings_camera[tri])
    if len(T_p3p):
        candidates.append(T_p3p)
        methods.extend(["p3p"] * len(T_p3p))
    if not candidates:
        return np.eye(4), "none", float("inf")
    T_all = np.concatenate(candidates, axis=0)
    cost = 0.5 * np.sum(angular_errors_rad(T_all, points_lidar, bearings_camera) ** 2, axis=-1)
    best = int(np.argmin(cost))
    return T_all[best], methods[best], float(cost[best])
