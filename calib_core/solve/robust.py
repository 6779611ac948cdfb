"""Hypothesise and verify: find the pairs that agree on one pose, leave the rest out.

Scheme (LO-RANSAC with a least-median start, on bearings, with spread-weighted votes):

1. **Hypotheses**: Grunert P3P (:func:`~calib_core.solve.bearing_pnp.p3p_grunert`)
   on minimal sets of three pairs -- every triple for up to
   :data:`ALL_TRIPLES_MAX_N` pairs, otherwise well-spread plus random triples --
   plus any poses passed in (the least-squares fit on all pairs).
2. **Scale**: the noise scale of the whitened residuals is known a priori
   (``prior_scale``, e.g. 1 px clicks) or, without a prior, estimated by least
   median of squares: the pose whose ``h``-th smallest residual
   (``h = floor(n/2) + 1``, a majority) is smallest, with Rousseeuw's
   consistency factor.
3. **Verify**: every hypothesis is scored by its support
   ``sum_i v_i (1 - |z_i|^2 / tau^2)`` over its inliers (``|z_i| < tau = k * scale``).
   With every vote ``v_i = 1`` this is MSAC (Torr & Zisserman 2000).  Here pairs at one
   place in the view share one vote (:func:`spread_votes`): a tight cluster of pairs fits
   a whole family of poses, so a wrong pose pivoting on it can collect as many inliers
   (the cluster plus a gross outlier far away) as the true pose collects among
   well-spread pairs.  Counted by places, the cluster is one vote and the spread pairs
   one each.  Well-separated pairs vote as in MSAC.
4. **Local optimisation** (LO-RANSAC, Chum, Matas & Kittler 2003): LM on the
   inliers, new residuals for every pair, a new scale from the inliers
   (never below the prior), new inliers; repeated until the set is stable.
   Then left-out pairs a few tau away are tried back one at a time (:func:`_grow`):
   a fit on 4 or 5 pairs bends to them and can leave a good pair just outside.

A pair is an outlier when its whitened residual exceeds ``tau = k(n) * scale``,
with ``k(n)`` (:func:`inlier_k`) chosen so that n good pairs with Gaussian
noise have a :data:`FAMILY_ALPHA` chance that *any* of them exceeds it (a 2-D
Gaussian residual exceeds ``k`` sigma with probability ``exp(-k^2 / 2)``):
3.7 sigma for 10 pairs, 4.8 for 1000, never below :data:`INLIER_K`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .bearing_pnp import _all_triples, _spread_order, p3p_grunert
from .kernels import lm_refine, score_poses, whitened_residuals

__all__ = [
    "RobustFit", "INLIER_K", "inlier_k", "robust_fit", "robust_scale", "inlier_scale", "cluster_width_rad",
    "pair_kernel", "spread_votes", "support",
]

#: Smallest inlier threshold, in sigmas of the whitened residual.
INLIER_K = 3.5
#: Chance that a set of good pairs loses one of them to the outlier test.
FAMILY_ALPHA = 0.01
#: Triples per batch of hypotheses (the search stops once enough were tried).
BATCH = 32
#: Well-spread pairs (farthest-point order of the bearings) whose triples are tried first.
SPREAD = 6
#: Hypotheses are first scored on this many pairs; only the best :data:`SHORTLIST` on all of them.
PREVIEW = 24
SHORTLIST = 6
#: Confidence of having drawn at least one all-inlier triple (adaptive RANSAC stopping).
CONFIDENCE = 0.999
#: Up to this many pairs every triple is a hypothesis (C(12, 3) = 220).
ALL_TRIPLES_MAX_N = 12
#: Most triples tried (the bound of the adaptive stopping rule at about 20 % inliers).
MAX_TRIPLES = 1024
#: Pairs within about this fraction of the bearings' angular radius share one vote (a tight cluster
#: votes about once): :func:`spread_votes`.
CLUSTER_FRACTION = 1.0 / 12.0
#: Above this many pairs every inlier votes 1 (:func:`pair_kernel`).
SPREAD_MAX_N = 256
#: Left-out pairs within this many tau of the final fit are tried back into it (:func:`_grow`), at most MAX_GROW.
GROW_FACTOR = 3.0
MAX_GROW = 16
#: LM iterations per local optimisation.
LM_MAX_ITER = 100
#: median(|z|^2) = 2 ln 2 sigma^2 for a 2-D Gaussian of sigma per axis.
_MEDIAN_CHI2_2 = 2.0 * math.log(2.0)


class RobustFit(NamedTuple):
    """Outcome of :func:`robust_fit`.

    Attributes
    ----------
    R, t : (3, 3), (3,) ndarray
        Pose refined on the inliers.
    inliers : (N,) bool ndarray
    scale : float
        Noise scale of the whitened residuals used for the final threshold.
    iterations : int
        LM iterations, all local optimisations together.
    hypotheses : int
        Candidate poses scored.
    """

    R: np.ndarray
    t: np.ndarray
    inliers: np.ndarray
    scale: float
    iterations: int
    hypotheses: int


def inlier_k(n: int) -> float:
    """Inlier threshold in sigmas for n pairs: ``sqrt(-2 ln(alpha / n))``, at least :data:`INLIER_K`."""
    return max(INLIER_K, math.sqrt(-2.0 * math.log(FAMILY_ALPHA / max(n, 1))))


def robust_scale(sq: np.ndarray, n_params: int = 6) -> float:
    """Noise sigma per axis from squared 2-D residual norms ``sq``, by their median (LMedS).

    ``sigma = sqrt(median / (2 ln 2)) * (1 + 5 / (n - p))`` with ``p = n_params / 2``
    pairs' worth of parameters: Rousseeuw & Leroy's small-sample factor.
    """
    n = sq.size
    med = float(np.median(sq))
    return math.sqrt(med / _MEDIAN_CHI2_2) * (1.0 + 5.0 / max(n - n_params / 2.0, 1.0))


def inlier_scale(sq_inliers: np.ndarray) -> float:
    """Sigma per axis from the inliers' squared residual norms: ``sqrt(SSR / (2 n - 6))`` (nan if 2n <= 6)."""
    dof = 2 * sq_inliers.size - 6
    return math.sqrt(float(sq_inliers.sum()) / dof) if dof > 0 else float("nan")


def _triple_batches(bearings: np.ndarray, rng: np.random.Generator):
    """Triples of pair indices in batches: every triple for few pairs, else well-spread then random ones."""
    n = len(bearings)
    if n <= ALL_TRIPLES_MAX_N:
        yield _all_triples(n)
        return
    yield _spread_order(bearings, SPREAD)[_all_triples(SPREAD)]  # the well-spread ones first
    while True:
        # Three distinct indices per row: draw, then redraw the few rows with a repeat.
        t = rng.integers(0, n, (BATCH, 3))
        rep = (t[:, 0] == t[:, 1]) | (t[:, 0] == t[:, 2]) | (t[:, 1] == t[:, 2])
        yield t[~rep]


def cluster_width_rad(bearings: np.ndarray) -> float:
    """Angular width (radians) within which pairs share one vote: :data:`CLUSTER_FRACTION` of the
    bearings' angular radius (largest angle from their mean direction, at most 90 deg)."""
    mean = bearings.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < 1e-9:
        radius = math.pi / 2
    else:
        radius = min(math.acos(min(max(float(np.min(bearings @ (mean / norm))), -1.0), 1.0)), math.pi / 2)
    return max(CLUSTER_FRACTION * radius, 1e-6)


def pair_kernel(bearings: np.ndarray, width_rad: float) -> np.ndarray | None:
    """``k(theta_ij) = exp(-chord_ij^2 / (2 w^2))`` between every two pairs (N, N), or None above
    :data:`SPREAD_MAX_N` pairs.

    ``chord = 2 sin(theta / 2)`` of the angle between the bearings, ``w`` the chord of
    ``width_rad``; 1 on the diagonal.  With hundreds of pairs a cluster of a few cannot outvote the
    rest, and the N x N kernel would cost more than the search: plain MSAC votes then.
    """
    if len(bearings) > SPREAD_MAX_N:
        return None
    inv_2w2 = 1.0 / (2.0 * (2.0 * math.sin(width_rad / 2.0)) ** 2)
    chord2 = np.maximum(2.0 - 2.0 * (bearings @ bearings.T), 0.0)
    return np.exp(-chord2 * inv_2w2)


def spread_votes(kernel: np.ndarray | None, inliers: np.ndarray) -> np.ndarray:
    """Each inlier's share of one vote: ``1 / sum_j k(theta_ij)`` over the hypothesis' inliers ``j``.

    Pairs far apart (``theta >> width``) keep a whole vote each; ``m`` pairs at one place share
    one vote, so a tight cluster counts about once.

    Parameters
    ----------
    kernel : (N, N) ndarray or None
        :func:`pair_kernel`; None: every inlier votes 1 (MSAC).
    inliers : (K, N) bool ndarray
        Each hypothesis' inliers.

    Returns
    -------
    (K, N) ndarray
        Votes in (0, 1] for inliers, 0 elsewhere.
    """
    inl = inliers.astype(np.float64)
    if kernel is None:
        return inl
    return np.where(inliers, 1.0 / np.maximum(inl @ kernel, 1.0), 0.0)


def support(sq: np.ndarray, tau2: float, votes: np.ndarray) -> np.ndarray:
    """Spread-weighted MSAC support of each hypothesis: ``sum_i v_i (1 - |z_i|^2 / tau^2)`` over its inliers.

    With every vote 1 this is MSAC (Torr & Zisserman 2000): ``n tau^2 - sum_i min(|z_i|^2, tau^2)``
    divided by ``tau^2``, so ranking by it is ranking by the MSAC cost.
    """
    return np.sum(votes * np.clip(1.0 - sq / tau2, 0.0, 1.0), axis=1)


def robust_fit(
    points: np.ndarray,
    bearings: np.ndarray,
    frames: np.ndarray,
    W: np.ndarray,
    prior_scale: float | None,
    start_R: np.ndarray,
    start_t: np.ndarray,
    *,
    min_scale: float = 0.0,
    seed: int = 0,
) -> RobustFit:
    """The set of pairs that agree on one pose and determine it best, and that pose refined on it.

    Parameters
    ----------
    points : (N, 3) ndarray
        Laser points, lidar frame, metres.
    bearings : (N, 3) ndarray
        Unit bearings, camera frame.
    frames : (N, 3, 3) ndarray
        Bearing frames (rows e1, e2, b).
    W : (N, 2, 2) ndarray
        Whitening matrices (:func:`calib_core.solve.whiten.whitening`).
    prior_scale : float or None
        Expected sigma of the whitened residuals (1.0 when they are in units
        of the expected click noise); None: estimated from the data only.
    start_R, start_t : ndarray
        A pose to include among the hypotheses (e.g. the least-squares fit).
    min_scale : float
        Floor of the scale (noise-free data would otherwise give a zero threshold).
    seed : int
        Seed of the random triples (deterministic output).
    """
    n = len(points)
    k = inlier_k(n)
    floor = max(min_scale, prior_scale or 0.0)
    rng = np.random.default_rng(seed)
    Rs = np.ascontiguousarray(np.asarray(start_R, dtype=np.float64).reshape(1, 3, 3))
    ts = np.ascontiguousarray(np.asarray(start_t, dtype=np.float64).reshape(1, 3))
    best_R, best_t, best_sq, best_score = Rs[0], ts[0], None, -np.inf
    scale = floor
    tried = 0
    hypotheses = 0
    preview = np.sort(rng.choice(n, min(n, PREVIEW), replace=False))
    kernel = pair_kernel(bearings, cluster_width_rad(bearings))
    for tri in _triple_batches(bearings, rng):
        T_new, _ = p3p_grunert(points[tri], bearings[tri])
        R_new, t_new = np.ascontiguousarray(T_new[:, :3, :3]), np.ascontiguousarray(T_new[:, :3, 3])
        Rs = np.concatenate([Rs, R_new]) if hypotheses == 0 else R_new
        ts = np.concatenate([ts, t_new]) if hypotheses == 0 else t_new
        hypotheses += len(Rs)
        if n > PREVIEW and len(Rs) > SHORTLIST:
            # Preview on a few pairs (Matas & Chum's pre-test idea), full score for the best few.
            sub = preview if best_sq is not None or prior_scale is not None else None
            if sub is not None:
                sq_sub = score_poses(Rs, ts, points[sub], frames[sub], W[sub])
                tau2_sub = (k * scale) ** 2
                keep = np.argsort(np.minimum(np.where(np.isfinite(sq_sub), sq_sub, np.inf), tau2_sub).sum(axis=1))
                keep = keep[:SHORTLIST]
                Rs, ts = np.ascontiguousarray(Rs[keep]), np.ascontiguousarray(ts[keep])
        sq = score_poses(Rs, ts, points, frames, W)  # (K, N)
        sq = np.where(np.isfinite(sq), sq, np.inf)
        tried += len(tri)
        if best_sq is None and prior_scale is None:
            # No prior: least median of squares over the first batch sets the scale.
            h = n // 2 + 1
            kth = np.partition(sq, h - 1, axis=1)[:, h - 1]
            scale = max(robust_scale(sq[int(np.argmin(kth))]), floor)
        tau2 = (k * scale) ** 2
        score = support(sq, tau2, spread_votes(kernel, sq < tau2))
        j = int(np.argmax(score))
        if score[j] > best_score:
            best_score, best_R, best_t, best_sq = float(score[j]), Rs[j], ts[j], sq[j]
        w = float(np.mean(best_sq < tau2))
        needed = math.log(1 - CONFIDENCE) / math.log(max(1 - w**3, 1e-12)) if w < 1 else 1
        if n <= ALL_TRIPLES_MAX_N or tried >= needed or tried >= MAX_TRIPLES:
            break
    R, t = best_R, best_t
    inliers = best_sq < (k * scale) ** 2
    iterations = 0
    for _ in range(10):  # LO: usually stable after 1-3 rounds
        if inliers.sum() < 3:
            break
        idx = np.flatnonzero(inliers)
        R, t, it, _status, _ = lm_refine(R, t, points[idx], frames[idx], W[idx], LM_MAX_ITER)
        iterations += it
        z, _ = whitened_residuals(R, t, points, frames, W)
        r2 = np.einsum("ij,ij->i", z, z)
        s_in = inlier_scale(r2[inliers])
        scale = max(s_in, floor) if np.isfinite(s_in) else scale
        new = r2 < (k * scale) ** 2
        if np.array_equal(new, inliers):
            break
        inliers = new
    if inliers.sum() >= 3:
        R, t, inliers, scale, more = _grow(R, t, inliers, points, frames, W, k, scale, floor)
        iterations += more
    return RobustFit(R, t, inliers, scale, iterations, hypotheses)


def _grow(R, t, inliers, points, frames, W, k, scale, floor):
    """Add back left-out pairs that fit once they are in the fit; ``(R, t, inliers, scale, iterations)``.

    A fit on few pairs bends to them (4 pairs leave 2 degrees of freedom) and can put a good pair
    a few tau away, where the local optimisation never recruits it.  Each left-out pair within
    :data:`GROW_FACTOR` tau, nearest first, is tried: the pose is refitted with it, and it stays
    when every pair of the grown set is then within tau (tau itself is not changed).
    """
    iterations = 0
    tau = k * scale
    tau2 = tau * tau
    z, _ = whitened_residuals(R, t, points, frames, W)
    r2 = np.einsum("ij,ij->i", z, z)
    near = np.flatnonzero(~inliers & (r2 < (GROW_FACTOR * tau) ** 2))
    for j in near[np.argsort(r2[near])][:MAX_GROW]:  # a few pairs at most
        if inliers[j]:
            continue
        idx = np.flatnonzero(inliers | (np.arange(len(inliers)) == j))
        R2, t2, it, _status, _ = lm_refine(R, t, points[idx], frames[idx], W[idx], LM_MAX_ITER)
        iterations += it
        z2, _ = whitened_residuals(R2, t2, points, frames, W)
        r2_new = np.einsum("ij,ij->i", z2, z2)
        if np.all(r2_new[idx] < tau2):
            R, t, r2 = R2, t2, r2_new
            inliers = r2 < tau2
    s_in = inlier_scale(r2[inliers])
    return R, t, inliers, max(s_in, floor) if np.isfinite(s_in) else scale, iterations
