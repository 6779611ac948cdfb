"""Hypothesise and verify: find the pairs that agree on one pose, leave the rest out.

Scheme (LO-MSAC with a least-median start, on bearings):

1. **Hypotheses**: Grunert P3P (:func:`~calib_core.solve.bearing_pnp.p3p_grunert`)
   on minimal sets of three pairs -- every triple for up to
   :data:`ALL_TRIPLES_MAX_N` pairs, otherwise well-spread plus random triples --
   plus any poses passed in (the least-squares fit on all pairs).
2. **Scale**: the noise scale of the whitened residuals is known a priori
   (``prior_scale``, e.g. 1 px clicks) or, without a prior, estimated by least
   median of squares: the pose whose ``h``-th smallest residual
   (``h = floor(n/2) + 1``, a majority) is smallest, with Rousseeuw's
   consistency factor.
3. **Verify** (MSAC, Torr & Zisserman 2000): every hypothesis is scored by
   ``sum_i min(|z_i|^2, tau^2)`` with ``tau = k * scale``; the best one gives
   the first inliers.
4. **Local optimisation** (LO-RANSAC, Chum, Matas & Kittler 2003): LM on the
   inliers, new residuals for every pair, a new scale from the inliers
   (never below the prior), new inliers; repeated until the set is stable.

A pair is an outlier when its whitened residual exceeds ``tau``
(:data:`INLIER_K` sigmas; for a 2-D Gaussian residual a good pair exceeds
3.5 sigma with probability exp(-3.5^2 / 2) = 0.2 %).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .bearing_pnp import _triples, p3p_grunert
from .kernels import lm_refine, score_poses, whitened_residuals

__all__ = ["RobustFit", "INLIER_K", "robust_fit", "robust_scale", "inlier_scale"]

#: Inlier threshold in sigmas of the whitened residual.
INLIER_K = 3.5
#: Up to this many pairs every triple is a hypothesis (C(12, 3) = 220).
ALL_TRIPLES_MAX_N = 12
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


def _hypotheses(points, bearings, extra_R, extra_t, rng):
    n = len(points)
    if n <= ALL_TRIPLES_MAX_N:
        tri = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)])
    else:
        tri = _triples(bearings, rng)
    T, _ = p3p_grunert(points[tri], bearings[tri])
    Rs = np.concatenate([np.asarray(extra_R).reshape(-1, 3, 3), T[:, :3, :3]])
    ts = np.concatenate([np.asarray(extra_t).reshape(-1, 3), T[:, :3, 3]])
    return np.ascontiguousarray(Rs), np.ascontiguousarray(ts)


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
    """Largest set of pairs consistent with one pose, and that pose refined on it.

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
    Rs, ts = _hypotheses(points, bearings, start_R, start_t, np.random.default_rng(seed))
    sq = score_poses(Rs, ts, points, frames, W)  # (K, N)
    sq = np.where(np.isfinite(sq), sq, np.inf)
    floor = max(min_scale, prior_scale or 0.0)
    if prior_scale is None:
        h = n // 2 + 1
        kth = np.partition(sq, h - 1, axis=1)[:, h - 1]
        best = int(np.argmin(kth))
        scale = max(robust_scale(sq[best]), floor)
    else:
        scale = floor
    tau2 = (INLIER_K * scale) ** 2
    msac = np.minimum(sq, tau2).sum(axis=1)
    best = int(np.argmin(msac))
    R, t = Rs[best], ts[best]
    inliers = sq[best] < tau2
    iterations = 0
    for _ in range(10):  # LO: usually stable after 1-3 rounds
        if inliers.sum() < 3:
            break
        idx = np.flatnonzero(inliers)
        R, t, it, _status = lm_refine(R, t, points[idx], frames[idx], W[idx], LM_MAX_ITER)
        iterations += it
        z, _ = whitened_residuals(R, t, points, frames, W)
        r2 = np.einsum("ij,ij->i", z, z)
        s_in = inlier_scale(r2[inliers])
        scale = max(s_in, floor) if np.isfinite(s_in) else scale
        new = r2 < (INLIER_K * scale) ** 2
        if np.array_equal(new, inliers):
            break
        inliers = new
    return RobustFit(R, t, inliers, scale, iterations, len(Rs))
