"""Several shots, one calibration: pairs from many scenes solved together, checked shot against shot.

A *shot* is a scan and a photo taken together by one rig.  All shots share
the camera model and ``T_camera_lidar`` (``X_camera = T @ X_lidar``,
metres); each pair's laser point is in its own shot's lidar frame.  So the
joint solve is the ordinary solve (:func:`calib_core.solve.solve_extrinsics`:
robust stage, LM, covariance, quality) of all shots' pairs concatenated,
each with its click noise and whole-cell laser pick; a shot with fewer than
4 pairs still contributes.

With two shots or more:

* **Leave-one-shot-out**: each shot's pairs under the pose fitted to the
  other shots alone (px and degrees): the error of the calibration on a
  scene the fit has not seen.
* **A disagreeing shot** (photo and scan not taken at the same instant on a
  turning rig, or the rig moved) is found by a predictive test.  Under the
  pose fitted without shot ``k``, its pixel residuals ``r`` have covariance
  ``V = S + J C J^T`` (``S`` the pairs' click and laser-pick noise, ``J C J^T``
  the held-out pose's uncertainty, :mod:`calib_core.guide.information`).  If
  the shot's scan is turned by a small rotation ``w`` (about the lidar
  origin), ``r = A w + noise`` with ``A = d pixel / d w``; the generalised
  least-squares fit of ``w`` lowers ``r^T V^-1 r`` by
  ``b^T (A^T V^-1 A)^-1 b`` (``b = A^T V^-1 r``), which is chi-square with 3
  degrees of freedom when the shot agrees (in units of the noise variance,
  taken as the larger of the model's and the one the residuals show).  A
  shot is named when that p-value is below ``alpha / (number of shots)``
  (at most ``alpha`` false alarms per calibration); the most significant one
  is named first, left out, and the others are tested again.  Pairs of the
  shot that do not share its common offset (a stray click) are found first
  by hypothesise-and-verify over that offset and left out of its test: a
  shot is named only when most of its pairs agree among themselves.  With
  two shots left the test cannot tell which one is off: both are named and
  the result is ``unreliable``.  The offset modelled is a rotation (what a
  turning rig gives, and most of what a moving one gives for far points); a
  shift that no rotation explains is left to the pair-level robust stage.

The false-alarm rate and the hit rate against the size of the rotation are
measured by ``python -m bench.shots`` (``docs/performance.md``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

from .errors import CalibError
from .solve import MIN_PAIRS, CalibrationResult, Quality, solve_extrinsics
from .solve.calibrate import default_shared_ratio, pair_edge_degrees
from .solve.edges import edge_click_covariance, edge_pixel_errors, slide_along_edges
from .solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M, pairs_pick_covariance

__all__ = [
    "Shot",
    "ShotReport",
    "LeaveOneShotOut",
    "ShotTest",
    "ShotsResult",
    "solve_shots",
    "shot_tests",
    "shots_to_dict",
    "ShotProposal",
    "joint_pose_state",
    "propose_shots",
    "shot_proposals_to_dict",
    "shots_extrinsics_document",
    "verify_shots",
    "format_shots",
    "DEFAULT_ALPHA",
    "UNCHECKED_REASON",
]

#: Chance, per calibration, that a shot which agrees with the others is named (family-wise).
DEFAULT_ALPHA = 0.01
#: The quality reason of a joint fit whose shots were not yet checked against each other (``checks=False``).
UNCHECKED_REASON = ("checking shots…: the shots have not been checked against each other yet "
                    "(leave-one-shot-out and the disagreeing-shot test follow)")
#: Hypotheses of a shot's common offset tried at most (pairs of its pairs, drawn with a fixed seed beyond).
MAX_OFFSET_HYPOTHESES = 300


# --------------------------------------------------------------------------------------
# a shot
# --------------------------------------------------------------------------------------


@dataclass
class Shot:
    """One scan and one photo of the rig, with the pairs picked in them.

    Attributes
    ----------
    points_lidar : (N, 3) ndarray
        Laser point of every pair, this shot's lidar frame, metres.
    bearings : (N, 3) ndarray
        Unit rays of the clicked pixels, OpenCV camera frame.
    pixels : (N, 2) ndarray
        Clicked ``(u, v)``, px (top-left pixel centre = 0).
    laser_cov_m2 : (N, 3, 3) ndarray
        Covariance of each laser point, metres^2, lidar frame (whole-cell pick,
        :func:`calib_core.solve.whiten.cell_pick_covariance`; zero for ``laser_xyz`` pairs).
    has_cell : (N,) bool ndarray
        The pair names a depth-matrix cell (its laser covariance is modelled).
    precision_px : (N,) ndarray
        Each pair's ``precision_px`` (1-sigma of the click, px); NaN where it states none.
    ids : list of int or None
        The pairs' ids (``Pair.id``).
    check : (N,) bool ndarray
        Check pairs: left out of the fit, their errors reported apart.
    pairs : list of Pair
        The pairs as given.
    depth : DepthMatrix or None
        The scan (for proposals).
    name : str
        How reports name the shot's files (e.g. ``"scan.pcd + pairs.yaml"``).
    edge_deg : (N,) ndarray or None
        Each pair's ``edge_deg`` (degrees; NaN for a corner pair), None when no pair is an edge pair
        (:attr:`calib_core.pairs.Pair.edge_deg`): solved as point-on-line pairs, their pixel errors across the edge.
    """

    points_lidar: np.ndarray
    bearings: np.ndarray
    pixels: np.ndarray
    laser_cov_m2: np.ndarray
    has_cell: np.ndarray
    precision_px: np.ndarray
    ids: list
    check: np.ndarray
    pairs: list = field(default_factory=list)
    depth: Any = None
    name: str = ""
    edge_deg: np.ndarray | None = None

    @classmethod
    def from_pairs(cls, pairs: Sequence[Any], depth, camera, *, name: str = "",
                   cell_sigma: float | tuple[float, float] = PICK_CELL_SIGMA,
                   range_sigma_m: float = PICK_RANGE_SIGMA_M) -> "Shot":
        """Resolve :class:`calib_core.pairs.Pair` objects of one shot (as :func:`calib_core.solve.calibrate` does).

        Raises
        ------
        CalibError
            A cell outside the scan or without a return, a pixel outside the image.
        """
        from .pairs import resolve_pairs

        pairs = list(pairs)
        points, bearings, pixels = resolve_pairs(pairs, depth, camera)
        n = len(pairs)
        has_cell = np.array([p.laser_rc is not None for p in pairs], dtype=bool)
        laser_cov = pairs_pick_covariance(pairs, depth, cell_sigma, range_sigma_m)
        laser_cov = np.zeros((n, 3, 3)) if laser_cov is None else laser_cov
        precision = np.array([np.nan if p.precision_px is None else p.precision_px for p in pairs], dtype=np.float64)
        return cls(points, bearings, pixels, laser_cov, has_cell, precision, [p.id for p in pairs],
                   np.array([bool(getattr(p, "check", False)) for p in pairs], dtype=bool), pairs, depth, name,
                   pair_edge_degrees(pairs))

    def edges_at(self, positions: np.ndarray) -> np.ndarray | None:
        """``edge_deg`` of the pairs at ``positions`` (NaN for corner pairs), None when the shot has no edge pair."""
        return None if self.edge_deg is None else np.asarray(self.edge_deg, dtype=np.float64)[positions]

    @property
    def n_pairs(self) -> int:
        return len(self.points_lidar)

    @property
    def fit_positions(self) -> np.ndarray:
        """Positions (in this shot's pairs) of the pairs that enter the fit."""
        return np.flatnonzero(~self.check)


@dataclass
class _Rows:
    """Fit pairs of some shots, concatenated: the solve's input and where each row came from."""

    points: np.ndarray
    bearings: np.ndarray
    pixels: np.ndarray
    sigmas: np.ndarray | None
    laser_cov: np.ndarray | None
    ids: list[int]
    shot: np.ndarray
    position: np.ndarray
    laser_cov_full: np.ndarray  # zeros where unmodelled, for the predictive test
    sigma_full: np.ndarray  # 1 px where unstated
    shared_ratio: float = 0.0  # the by-eye shared error, as calibrate() models it (pairs weighted by count)
    edge_deg: np.ndarray | None = None  # degrees, NaN for corner pairs; None when no row is an edge pair


def _global_ids(shots: Sequence[Shot]) -> list[list[int]]:
    """Each shot's pair ids for the joint solve: the pairs' ids when all are set and distinct across
    shots, else positions in the concatenation of all shots' pairs (check pairs included)."""
    flat = [i for s in shots for i in s.ids]
    if any(i is None for i in flat) or len(set(flat)) != len(flat):
        out, start = [], 0
        for s in shots:
            out.append(list(range(start, start + s.n_pairs)))
            start += s.n_pairs
        return out
    return [list(s.ids) for s in shots]


def _rows(shots: Sequence[Shot], use: Sequence[int], ids: list[list[int]]) -> _Rows:
    """The fit pairs of shots ``use``, in shot order then pair order."""
    parts = [(k, shots[k].fit_positions) for k in use] or [(0, np.zeros(0, dtype=np.int64))]
    cat = lambda get: np.concatenate([get(shots[k])[pos] for k, pos in parts])  # noqa: E731
    points = cat(lambda s: s.points_lidar).reshape(-1, 3)
    precision = cat(lambda s: s.precision_px).reshape(-1)
    has_cell = cat(lambda s: s.has_cell).reshape(-1).astype(bool)
    cov = cat(lambda s: s.laser_cov_m2).reshape(-1, 3, 3)
    sigma_full = np.where(np.isfinite(precision), precision, 1.0)
    edges = np.concatenate([np.full(len(pos), np.nan) if shots[k].edge_deg is None else shots[k].edges_at(pos)
                            for k, pos in parts]).reshape(-1)
    return _Rows(
        points=points,
        bearings=cat(lambda s: s.bearings).reshape(-1, 3),
        pixels=cat(lambda s: s.pixels).reshape(-1, 2),
        # As calibrate(): sigmas only when some pair states one; laser covariances only when some pair names a cell.
        sigmas=None if not np.isfinite(precision).any() else sigma_full,
        laser_cov=cov if has_cell.any() else None,
        ids=[ids[k][int(i)] for k, pos in parts for i in pos],
        shot=np.concatenate([np.full(len(pos), k) for k, pos in parts]).astype(np.int64),
        position=np.concatenate([pos for _, pos in parts]).astype(np.int64),
        laser_cov_full=cov,
        sigma_full=sigma_full,
        shared_ratio=sum(default_shared_ratio([shots[k].pairs[int(i)] for i in pos], shots[k].depth) * len(pos)
                         for k, pos in parts if shots[k].pairs) / max(len(points), 1),
        edge_deg=edges if np.isfinite(edges).any() else None,
    )


def _refuse_shared_points(rows: _Rows) -> None:
    """Two pairs of different shots with the same laser point: the same scan given twice (the solve
    would count that point twice); named by shot and position, which the solve's message cannot do."""
    if len(np.unique(rows.shot)) < 2:
        return
    _, group, counts = np.unique(rows.points, axis=0, return_inverse=True, return_counts=True)
    group = np.ravel(group)
    dup = np.flatnonzero(counts[group] > 1)
    if dup.size:
        i = int(dup[0])
        j = int(np.flatnonzero(group == group[i])[1])
        if rows.shot[i] != rows.shot[j]:
            raise CalibError(
                f"shot {rows.shot[i]} pair {rows.position[i]} and shot {rows.shot[j]} pair {rows.position[j]} use the "
                "same laser point: is one scan given for two shots? Each shot needs its own scan")


def _solve_rows(rows: _Rows, camera, cost: str, options: dict) -> CalibrationResult:
    return solve_extrinsics(rows.points, rows.bearings, camera=camera, pixels=rows.pixels, cost=cost,
                            pair_ids=rows.ids, pixel_sigma=rows.sigmas, laser_cov_m2=rows.laser_cov,
                            shared_ratio=rows.shared_ratio,
                            **({} if rows.edge_deg is None else {"pixel_edge_deg": rows.edge_deg}), **options)


# --------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------


@dataclass
class ShotReport:
    """One shot under the final pose.

    Attributes
    ----------
    index : int
        0-based, in the order the shots were given.
    name : str
    n_pairs, n_fit, n_check : int
        Pairs of the shot, those meant for the fit (not check pairs), check pairs.
    in_fit : bool
        False when the shot was left out as disagreeing.
    outliers : list of int
        Positions (in the shot's pairs) that the robust stage left out.
    mean_px, std_px, mean_deg, std_deg : float
        Errors of the shot's fit pairs (outliers excluded) under the final pose.
    """

    index: int
    name: str
    n_pairs: int
    n_fit: int
    n_check: int
    in_fit: bool
    outliers: list[int]
    mean_px: float
    std_px: float
    mean_deg: float
    std_deg: float


@dataclass
class LeaveOneShotOut:
    """A shot's pairs under the pose fitted without it.

    Attributes
    ----------
    shot : int
    T_camera_lidar : (4, 4) ndarray or None
        The pose fitted to the other shots (None when they cannot be solved).
    error_px, error_deg : (M,) ndarray
        Errors of the shot's pairs used (px NaN where not projectable).
    positions : (M,) int ndarray
        Those pairs' positions in the shot.
    mean_px, rms_px, mean_deg : float
    note : str
        Why nothing could be computed, else empty.
    """

    shot: int
    T_camera_lidar: np.ndarray | None
    error_px: np.ndarray
    error_deg: np.ndarray
    positions: np.ndarray
    mean_px: float
    rms_px: float
    mean_deg: float
    note: str = ""


@dataclass
class ShotTest:
    """The disagreement test of one shot against the others (module docstring).

    Attributes
    ----------
    shot : int
    rotation_deg : float
        Rotation of the shot's scan (about the lidar origin) that best explains its offset, degrees.
    statistic : float
        Drop of the predictive chi-square when that rotation is allowed, in noise variances.
    dof : int
        Its degrees of freedom (3, fewer for a one-pair shot).
    p_value : float
    consistent : (M,) int ndarray
        Positions (in the shot) of the pairs that share the common offset (used by the test).
    noise_factor : float
        The noise variance used, relative to the model (>= 1).
    """

    shot: int
    rotation_deg: float
    statistic: float
    dof: int
    p_value: float
    consistent: np.ndarray
    noise_factor: float


@dataclass
class ShotsResult:
    """Outcome of :func:`solve_shots`.

    Attributes
    ----------
    result : CalibrationResult
        The fit of the shots kept (a disagreeing shot left out), with the shots' findings in
        ``quality.reasons``; its rows are ``row_shot`` / ``row_position``.  With two shots or more its
        ``pair_positions`` / ``check_positions`` count in all shots' pairs concatenated, in shot order.
    row_shot, row_position : (R,) int ndarray
        Shot and position in the shot of each row of ``result``.
    shots : list of ShotReport
    leave_one_shot_out : list of LeaveOneShotOut
        One per shot with two shots or more, else empty.
    tests : list of ShotTest
        One per shot tested: the test that named a disagreeing shot, else the last round's.
    disagreeing : list of int
        Shots named and left out of the fit.
    undecided : list of int
        Two shots that disagree when neither can be told to be the wrong one.
    pair_ids : list of list of int
        Each shot's pair ids as the joint solve names them.
    checked : bool
        False for the joint fit alone (``solve_shots(..., checks=False)`` with two shots or more): no
        leave-one-shot-out nor disagreement test has run, and :data:`UNCHECKED_REASON` keeps the
        status from ``ok``.
    """

    result: CalibrationResult
    row_shot: np.ndarray
    row_position: np.ndarray
    shots: list[ShotReport]
    leave_one_shot_out: list[LeaveOneShotOut]
    tests: list[ShotTest]
    disagreeing: list[int]
    undecided: list[int]
    pair_ids: list[list[int]]
    checked: bool = True


# --------------------------------------------------------------------------------------
# errors under a pose
# --------------------------------------------------------------------------------------


def _errors(camera, T: np.ndarray, points: np.ndarray, pixels: np.ndarray, bearings: np.ndarray,
            edges: np.ndarray | None = None):
    """Pixel (NaN where not projectable; an edge pair's across its edge, ``edges`` degrees or NaN) and angular
    (deg) errors of pairs under ``T``."""
    from .verify import angular_errors_deg, pixel_errors

    if len(points) == 0:
        return np.zeros(0), np.zeros(0)
    if edges is not None:
        projected, valid = camera.project(points @ T[:3, :3].T + T[:3, 3])
        px = np.where(np.asarray(valid, bool), edge_pixel_errors(np.asarray(projected, np.float64), pixels, edges), np.nan)
        return px, angular_errors_deg(T, points, bearings)
    return pixel_errors(T, points, pixels, camera), angular_errors_deg(T, points, bearings)


def _finite_mean(values: np.ndarray) -> float:
    v = values[np.isfinite(values)]
    return float(v.mean()) if v.size else float("nan")


def _finite_std(values: np.ndarray) -> float:
    v = values[np.isfinite(values)]
    return float(v.std()) if v.size else float("nan")


# --------------------------------------------------------------------------------------
# the disagreement test
# --------------------------------------------------------------------------------------


@dataclass
class _HeldOut:
    """The fit of all active shots but one, and what the test of that one needs from it."""

    T: np.ndarray
    covariance: np.ndarray  # (6, 6) pose covariance in units of the noise variance
    ssr: float  # sum of the fit's squared normalised residuals (inliers)
    dof: int
    result: CalibrationResult


def _noise(camera, T, points, laser_cov, sigma, edges=None):
    """Predicted pixels, pose Jacobians (N, 2, 6), scan-rotation Jacobians (N, 2, 3) and noise (N, 2, 2) px^2
    (an edge pair's click noise along its edge :data:`calib_core.solve.edges.EDGE_SLIDE` times wider)."""
    from .guide.information import pair_noise, pixel_jacobians

    pred, J_pose, J_point = pixel_jacobians(camera, T, points)
    S = pair_noise(sigma, J_point, laser_cov)
    if edges is not None:
        S = S + edge_click_covariance(sigma, edges) - np.asarray(sigma, np.float64)[:, None, None] ** 2 * np.eye(2)
    # Scan turned by a small rotation w about the lidar origin: X -> X + w x X, d pixel / d w = J_X (-[X]x);
    # a row d times -[X]x is X x d.
    A = np.cross(points[:, None, :], J_point)
    return pred, J_pose, A, S


def _held_out(rows: _Rows, camera, cost: str, options: dict) -> _HeldOut | None:
    """Fit of ``rows`` and its covariance in noise units (None when it cannot be fitted or determined)."""
    from .guide.information import fisher_information

    try:
        fit = _solve_rows(rows, camera, cost, options)
    except CalibError:
        return None
    if fit.quality.status == "unreliable":
        return None
    T = fit.T_camera_lidar
    keep = np.asarray(fit.inliers, dtype=bool) if fit.inliers is not None else np.ones(len(rows.points), bool)
    edges = None if rows.edge_deg is None else rows.edge_deg[keep]
    pred, J_pose, _, S = _noise(camera, T, rows.points[keep], rows.laser_cov_full[keep], rows.sigma_full[keep], edges)
    r = slide_along_edges(pred, rows.pixels[keep], edges) - pred  # (an edge pair's: across its edge)
    ok = np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(J_pose), axis=(1, 2))
    F = fisher_information(J_pose[ok], S[ok])
    try:
        C = np.linalg.inv(F)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(C)) or np.any(np.diag(C) <= 0):
        return None
    Sinv = np.linalg.inv(S[ok])
    ssr = float(np.einsum("na,nab,nb->", r[ok], Sinv, r[ok]))
    return _HeldOut(T, C, ssr, 2 * int(ok.sum()) - 6, fit)


def _consistent_offset(r, A, Vd, tau2) -> np.ndarray:
    """Pairs sharing one scan rotation: hypothesise (no rotation; from each pair and each two pairs)
    and verify (MSAC, threshold ``tau2`` on the pair's normalised squared residual), then refine."""
    m = len(r)
    Vinv = np.linalg.inv(Vd)
    M1 = np.einsum("nai,nab,nbj->nij", A, Vinv, A)  # (m, 3, 3)
    b1 = np.einsum("nai,nab,nb->ni", A, Vinv, r)  # (m, 3)
    i, j = np.triu_indices(m, 1)
    if len(i) > MAX_OFFSET_HYPOTHESES:
        pick = np.random.default_rng(0).choice(len(i), MAX_OFFSET_HYPOTHESES, replace=False)
        i, j = i[pick], j[pick]
    M = np.concatenate([M1, M1[i] + M1[j]])
    b = np.concatenate([b1, b1[i] + b1[j]])
    w = np.concatenate([np.zeros((1, 3)), np.einsum("nij,nj->ni", np.linalg.pinv(M), b)])  # (H, 3)

    def d2(w_h):  # (H, m) normalised squared residuals
        e = r[None] - np.einsum("naj,hj->hna", A, w_h)
        return np.einsum("hna,nab,hnb->hn", e, Vinv, e)

    cost = np.minimum(d2(w), tau2).sum(axis=1)
    inl = d2(w[[int(np.argmin(cost))]])[0] <= tau2
    for _ in range(3):  # local optimisation: refit on the inliers until stable
        if not inl.any():
            break
        w_ref = np.linalg.pinv(M1[inl].sum(axis=0)) @ b1[inl].sum(axis=0)
        new = d2(w_ref[None])[0] <= tau2
        if np.array_equal(new, inl):
            break
        inl = new
    return np.flatnonzero(inl)


def _test_shot(k: int, shot: Shot, held: _HeldOut, camera) -> ShotTest | None:
    """The predictive rotation test of shot ``k`` against the pose fitted without it."""
    from scipy.special import chdtrc  # chi-square survival function (scipy.stats costs a second to import)

    from .solve.robust import inlier_k

    pos = shot.fit_positions
    if pos.size == 0:
        return None
    sigma = np.where(np.isfinite(shot.precision_px[pos]), shot.precision_px[pos], 1.0)
    edges = shot.edges_at(pos)
    pred, J_pose, A, S = _noise(camera, held.T, shot.points_lidar[pos], shot.laser_cov_m2[pos], sigma, edges)
    r = slide_along_edges(pred, shot.pixels[pos], edges) - pred  # (an edge pair's: across its edge)
    ok = np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(J_pose), axis=(1, 2)) & np.all(np.isfinite(A), axis=(1, 2))
    if not ok.any():
        return None
    pos, r, J_pose, A, S = pos[ok], r[ok], J_pose[ok], A[ok], S[ok]
    m = len(pos)
    factor0 = max(1.0, held.ssr / held.dof) if held.dof > 0 else 1.0
    Vd = S + np.einsum("nai,ij,nbj->nab", J_pose, held.covariance, J_pose)
    sel = _consistent_offset(r, A, Vd, (inlier_k(m) ** 2) * factor0)
    if 2 * sel.size <= m and m >= 2:  # most of the shot's pairs do not share one offset: not a shot-level finding
        return ShotTest(k, float("nan"), 0.0, 0, 1.0, pos[sel], factor0)
    # Full predictive covariance of the consistent pairs (the held-out pose's error is shared).
    Jf = J_pose[sel].reshape(-1, 6)
    Af = A[sel].reshape(-1, 3)
    rf = r[sel].reshape(-1)
    V = Jf @ held.covariance @ Jf.T
    idx = np.arange(sel.size)
    for a in range(2):
        for c in range(2):
            V[2 * idx + a, 2 * idx + c] += S[sel, a, c]
    Vi_A = np.linalg.solve(V, Af)
    Vi_r = np.linalg.solve(V, rf)
    M = Af.T @ Vi_A
    b = Af.T @ Vi_r
    evals, evecs = np.linalg.eigh(M)
    keep = evals > 1e-9 * max(evals[-1], 1e-300)
    dof = int(keep.sum())
    if dof == 0:
        return None
    w = evecs[:, keep] @ ((evecs[:, keep].T @ b) / evals[keep])
    reduction = float(b @ w)
    q1 = float(rf @ Vi_r) - reduction  # what the rotation leaves: the shot's own scatter
    dof1 = 2 * sel.size - dof
    total_dof = max(held.dof, 0) + max(dof1, 0)
    factor = max(1.0, (held.ssr + max(q1, 0.0)) / total_dof) if total_dof > 0 else 1.0
    stat = reduction / factor
    return ShotTest(k, float(np.degrees(np.linalg.norm(w))), stat, dof, float(chdtrc(dof, stat)), pos[sel], factor)


def shot_tests(shots: Sequence[Shot], camera, active: Sequence[int], *, cost: str = "angular",
               initial_T: np.ndarray | None = None, options: dict | None = None,
               ids: list[list[int]] | None = None) -> tuple[dict[int, ShotTest], dict[int, _HeldOut]]:
    """The disagreement test of every shot in ``active`` against the other active shots.

    Returns
    -------
    tests : dict shot -> ShotTest
        Shots whose test could be made (the others need >= 4 determined pairs).
    fits : dict shot -> held-out fit
        The pose fitted without each shot (for leave-one-shot-out).
    """
    ids = _global_ids(shots) if ids is None else ids
    opts = dict(options or {})
    if initial_T is not None:
        opts["initial_T_camera_lidar"] = initial_T
    tests: dict[int, ShotTest] = {}
    fits: dict[int, _HeldOut] = {}
    for k in active:
        others = [j for j in active if j != k]
        rows = _rows(shots, others, ids)
        if len(rows.points) < MIN_PAIRS:
            continue
        held = _held_out(rows, camera, cost, opts)
        if held is None:
            continue
        fits[k] = held
        test = _test_shot(k, shots[k], held, camera)
        if test is not None:
            tests[k] = test
    return tests, fits


# --------------------------------------------------------------------------------------
# the joint solve
# --------------------------------------------------------------------------------------


def _loso_entry(k: int, shot: Shot, T: np.ndarray | None, camera, skip: set[int], note: str = "") -> LeaveOneShotOut:
    pos = np.array([p for p in shot.fit_positions if p not in skip], dtype=np.int64)
    if T is None or pos.size == 0:
        empty = np.zeros(0)
        return LeaveOneShotOut(k, None, empty, empty, pos, float("nan"), float("nan"), float("nan"),
                               note or "no pairs to check")
    px, deg = _errors(camera, T, shot.points_lidar[pos], shot.pixels[pos], shot.bearings[pos], shot.edges_at(pos))
    finite = px[np.isfinite(px)]
    rms = float(np.sqrt(np.mean(finite**2))) if finite.size else float("nan")
    return LeaveOneShotOut(k, T, px, deg, pos, _finite_mean(px), rms, _finite_mean(deg), note)


def _shot_reason_disagree(test: ShotTest) -> str:
    return (f"shot {test.shot} disagrees with the others by {test.rotation_deg:.2f} deg (p = {test.p_value:.1e}): "
            "the photo and scan were probably not taken at the same instant, or the rig moved; "
            "it is left out of the fit; retake it or remove it")


def solve_shots(
    shots: Sequence[Shot],
    camera,
    *,
    cost: str = "angular",
    detect: bool = True,
    alpha: float = DEFAULT_ALPHA,
    checks: bool = True,
    **options: Any,
) -> ShotsResult:
    """Solve ``T_camera_lidar`` from the pairs of all shots together, and check the shots against each other.

    Parameters
    ----------
    shots : sequence of Shot
        At least one; all taken by one rig (one camera, one ``T_camera_lidar``).
    camera : CameraModel
    cost : {"angular", "geodesic", "pixel"}
    detect : bool
        Test every shot against the others and leave a disagreeing one out (two shots or more).
    alpha : float
        Chance per calibration of naming a shot that agrees (module docstring).
    checks : bool
        False: the joint fit alone, without leave-one-shot-out and the disagreement test (a fraction of
        the time, for a live display that shows the checked result a moment later).  With two shots or
        more its status is then never ``ok`` (:data:`UNCHECKED_REASON`) and ``checked`` is False.
    **options
        Passed to :func:`calib_core.solve.solve_extrinsics` (``robust``, ``initial_T_camera_lidar``, ...).

    Returns
    -------
    ShotsResult
        With one shot, ``result`` is exactly :func:`calib_core.solve.calibrate` of its pairs.

    Raises
    ------
    CalibError
        No shot, fewer than 4 fit pairs in all, or input the solve refuses (named).
    """
    shots = list(shots)
    if not shots:
        raise CalibError("no shots: give at least one scan with its pairs")
    if not 0.0 < alpha < 1.0:
        raise CalibError(f"alpha must lie between 0 and 1, got {alpha!r}")
    ids = _global_ids(shots)
    everyone = list(range(len(shots)))
    rows = _rows(shots, everyone, ids)
    if len(rows.points) < MIN_PAIRS:
        counts = ", ".join(str(len(s.fit_positions)) for s in shots)
        raise CalibError(
            f"{len(rows.points)} fit pairs in all ({counts} per shot); the solve needs at least {MIN_PAIRS}")
    _refuse_shared_points(rows)
    joint = _solve_rows(rows, camera, cost, options)
    result, kept = joint, everyone
    tests: dict[int, ShotTest] = {}
    fits: dict[int, _HeldOut] = {}
    named: list[int] = []
    named_tests: dict[int, ShotTest] = {}
    undecided: list[int] = []
    reasons: list[str] = []
    unchecked = len(shots) >= 2 and not checks
    if unchecked:
        reasons.append(UNCHECKED_REASON)
    if len(shots) >= 2 and not unchecked:
        active = [k for k in everyone if len(shots[k].fit_positions)]
        held_options = {k: v for k, v in options.items() if k != "initial_T_camera_lidar"}
        while True:
            tests, fits = shot_tests(shots, camera, active, cost=cost, initial_T=joint.T_camera_lidar,
                                     options=held_options, ids=ids)
            if not detect or len(active) < 2 or not tests:
                break
            worst = min(tests.values(), key=lambda t: t.p_value)
            if worst.p_value >= alpha / len(active):
                break
            if len(active) == 2:
                undecided = list(active)
                reasons.append(
                    f"shots {active[0]} and {active[1]} disagree by {worst.rotation_deg:.2f} deg "
                    f"(p = {worst.p_value:.1e}), and with two shots neither can be told to be the wrong one: "
                    "a photo and scan not taken at the same instant, or a rig that moved; add a third shot")
                break
            named.append(worst.shot)
            named_tests[worst.shot] = worst
            reasons.append(_shot_reason_disagree(worst))
            active = [k for k in active if k != worst.shot]
        if named:
            kept = active
            result = _solve_rows(_rows(shots, kept, ids), camera, cost, options)
    final_rows = _rows(shots, kept, ids)
    result = _with_checks(result, shots, kept, final_rows, camera)
    if len(shots) > 1:  # rows named by their position in all shots' pairs, concatenated (the extrinsics' pairs block)
        start = np.cumsum([0] + [s.n_pairs for s in shots])
        flat_ids = [i for shot_ids in ids for i in shot_ids]
        result.pair_positions = (start[final_rows.shot] + final_rows.position).tolist()
        checks = [int(start[k] + p) for k in range(len(shots)) for p in np.flatnonzero(shots[k].check)]
        result.check_positions, result.check_ids = checks, [flat_ids[i] for i in checks]
    if reasons:
        quality = result.quality
        unreliable = [r for r in quality.reasons] if quality.status == "unreliable" else []
        warn = [] if quality.status == "unreliable" else list(quality.reasons)
        if undecided:
            unreliable = reasons + unreliable
        else:
            warn = reasons + warn
        new_q = Quality.from_reasons(unreliable, warn)
        notes = [w for w in result.warnings if w not in quality.reasons]
        result.quality, result.warnings = new_q, list(new_q.reasons) + notes
    # Per-shot reports under the final pose.
    T = result.T_camera_lidar
    out_rows = set(int(i) for i in result.outliers)
    outliers_by_shot: dict[int, list[int]] = {}
    for i in out_rows:
        outliers_by_shot.setdefault(int(final_rows.shot[i]), []).append(int(final_rows.position[i]))
    reports = []
    for k, s in enumerate(shots):
        skip = set(outliers_by_shot.get(k, []))
        pos = np.array([p for p in s.fit_positions if p not in skip], dtype=np.int64)
        px, deg = _errors(camera, T, s.points_lidar[pos], s.pixels[pos], s.bearings[pos], s.edges_at(pos))
        reports.append(ShotReport(k, s.name, s.n_pairs, len(s.fit_positions), int(s.check.sum()), k in kept,
                                  sorted(skip), _finite_mean(px), _finite_std(px), _finite_mean(deg), _finite_std(deg)))
    loso: list[LeaveOneShotOut] = []
    if len(shots) >= 2 and not unchecked:
        for k, s in enumerate(shots):
            if k in named:  # the final fit was made without it
                consistent = set(named_tests[k].consistent.tolist())
                loso.append(_loso_entry(k, s, T, camera, set(s.fit_positions.tolist()) - consistent))
            elif k in fits:
                skip = set(outliers_by_shot.get(k, []))
                loso.append(_loso_entry(k, s, fits[k].T, camera, skip))
            else:
                others = sum(len(shots[j].fit_positions) for j in kept if j != k)
                loso.append(_loso_entry(k, s, None, camera, set(),
                                        f"the other shots ({others} fit pairs) do not determine a pose alone"))
    tests.update(named_tests)
    return ShotsResult(result, final_rows.shot, final_rows.position, reports, loso,
                       [tests[k] for k in sorted(tests)], named, undecided, ids, checked=not unchecked)


def _with_checks(result: CalibrationResult, shots: Sequence[Shot], kept: list[int], rows: _Rows, camera):
    """Check pairs of every shot (and, for reporting, nothing else) under the fitted pose, as calibrate() does."""
    checks = [(k, int(p)) for k in range(len(shots)) for p in np.flatnonzero(shots[k].check)]
    if not checks:
        return result
    T = result.T_camera_lidar
    pts = np.array([shots[k].points_lidar[p] for k, p in checks])
    pix = np.array([shots[k].pixels[p] for k, p in checks])
    bear = np.array([shots[k].bearings[p] for k, p in checks])
    edges = None
    if any(shots[k].edge_deg is not None for k, _ in checks):
        edges = np.array([np.nan if shots[k].edge_deg is None else shots[k].edge_deg[p] for k, p in checks])
    px, deg = _errors(camera, T, pts, pix, bear, edges)
    result.check_residual_px, result.check_residual_deg = px, deg
    if len(shots) == 1:  # positions in the one shot's pairs, exactly as calibrate() reports them
        ids = _global_ids(shots)[0]
        result.pair_positions = shots[0].fit_positions.tolist()
        result.check_positions = [p for _, p in checks]
        result.check_ids = [ids[p] for _, p in checks]
    return result


def shots_to_dict(shots_result: ShotsResult, shots: Sequence[Shot]) -> list[dict]:
    """The ``shots:`` block of the extrinsics YAML (plain types; None for NaN).

    One entry per shot: ``index``, ``name``, ``n_pairs``, ``n_fit``, ``n_check``, ``in_fit``,
    ``outliers`` (positions in the shot's pairs), ``residuals`` under the final pose
    (``mean_px``, ``std_px``, ``mean_deg``, ``std_deg``), with two shots or more
    ``leave_one_shot_out`` (``mean_px``, ``rms_px``, ``mean_deg``, ``n_pairs``, per pair
    ``{index, px, deg}``, ``note``), and the disagreement ``test`` (``rotation_deg``,
    ``statistic``, ``dof``, ``p_value``, ``disagrees``).
    """
    from .io.extrinsics import finite_or_none as num

    loso = {e.shot: e for e in shots_result.leave_one_shot_out}
    tests = {t.shot: t for t in shots_result.tests}
    out = []
    for rep in shots_result.shots:
        entry: dict[str, Any] = {
            "index": rep.index,
            "name": rep.name,
            "n_pairs": rep.n_pairs,
            "n_fit": rep.n_fit,
            "n_check": rep.n_check,
            "in_fit": bool(rep.in_fit),
            "outliers": [int(p) for p in rep.outliers],
            "residuals": {"mean_px": num(rep.mean_px), "std_px": num(rep.std_px),
                          "mean_deg": num(rep.mean_deg), "std_deg": num(rep.std_deg)},
        }
        if rep.index in loso:
            e = loso[rep.index]
            entry["leave_one_shot_out"] = {
                "mean_px": num(e.mean_px), "rms_px": num(e.rms_px), "mean_deg": num(e.mean_deg),
                "n_pairs": int(e.positions.size) if e.T_camera_lidar is not None else 0,
                "per_pair": [{"index": int(p), "px": num(px), "deg": num(d)}
                             for p, px, d in zip(e.positions, e.error_px, e.error_deg)],
                **({"note": e.note} if e.note else {}),
            }
        if rep.index in tests:
            t = tests[rep.index]
            entry["test"] = {"rotation_deg": num(t.rotation_deg), "statistic": num(t.statistic), "dof": int(t.dof),
                             "p_value": num(t.p_value),
                             "disagrees": rep.index in shots_result.disagreeing or rep.index in shots_result.undecided}
        out.append(entry)
    return out


# --------------------------------------------------------------------------------------
# proposals across shots
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShotProposal:
    """A proposal (:class:`calib_core.guide.Proposal`) in shot ``shot`` (0-based)."""

    shot: int
    proposal: Any

    def to_dict(self) -> dict:
        return {"shot": int(self.shot), **self.proposal.to_dict()}


def joint_pose_state(shots: Sequence[Shot], camera, T_initial: np.ndarray | None = None):
    """The pose of all shots' pairs and its covariance, for proposals (:class:`calib_core.guide.PoseState`).

    As :func:`calib_core.guide.current_pose` does for one shot: the joint solve (>= 4 fit pairs in
    all) or ``T_initial``; the covariance is the inverse Fisher information of the fit pairs (their
    click noise and careful whole-cell pick), inflated by the residuals' variance factor when it
    exceeds 1, plus the prior of ``T_initial`` when fewer than 4 pairs are given.
    """
    from .guide.information import fisher_information, information_inverse, pair_noise, pixel_jacobians
    from .guide.pose_state import DEFAULT_CLICK_SIGMA_PX, DEFAULT_PRIOR_SIGMA, PoseState, pose_state_of_fit

    shots = list(shots)
    ids = _global_ids(shots)
    rows = _rows(shots, list(range(len(shots))), ids)
    n = len(rows.points)
    if n < MIN_PAIRS:
        if T_initial is None:
            raise CalibError(f"proposals need at least {MIN_PAIRS} pairs in all or an initial extrinsic; got {n} pairs")
        T = np.asarray(T_initial, dtype=np.float64)
        s_rot, s_t = np.radians(DEFAULT_PRIOR_SIGMA[0]), DEFAULT_PRIOR_SIGMA[1]
        F = np.diag([s_rot**-2] * 3 + [s_t**-2] * 3)
        if n:
            _, J_pose, J_point = pixel_jacobians(camera, T, rows.points)
            sig = np.where(np.isfinite(rows.sigma_full), rows.sigma_full, DEFAULT_CLICK_SIGMA_PX)
            F = F + fisher_information(J_pose, pair_noise(sig, J_point, rows.laser_cov_full, rows.edge_deg))
        return PoseState(T, information_inverse(F), 1.0, n, "extrinsics")
    opts = {} if T_initial is None else {"initial_T_camera_lidar": T_initial}
    solved = solve_shots(shots, camera, **opts)
    T = solved.result.T_camera_lidar
    # The information of the pairs in the fit: a disagreeing shot and outlier pairs left out.
    rows = _rows(shots, [k for k in range(len(shots)) if k not in solved.disagreeing], ids)
    if solved.result.inliers is not None and len(solved.result.inliers) == len(rows.points):
        keep = np.asarray(solved.result.inliers, dtype=bool)
        rows = dataclasses.replace(rows, points=rows.points[keep], pixels=rows.pixels[keep],
                                   sigma_full=rows.sigma_full[keep], laser_cov_full=rows.laser_cov_full[keep],
                                   edge_deg=None if rows.edge_deg is None else rows.edge_deg[keep])
    source = "pairs of all shots" if T_initial is None else "pairs of all shots (started from the extrinsics)"
    return pose_state_of_fit(camera, T, rows.points, rows.pixels, rows.sigma_full, rows.laser_cov_full, source,
                             edge_deg=rows.edge_deg)


def propose_shots(
    shots: Sequence[Shot],
    camera,
    n: int = 20,
    *,
    T_initial: np.ndarray | None = None,
    images: dict[int, np.ndarray] | None = None,
    click_sigma_px: float | None = None,
    state=None,
    shot_options: dict[int, dict] | None = None,
) -> tuple[list[ShotProposal], Any]:
    """The ``n`` best next pairs over all shots, best first, ranked by one D-optimal gain.

    Each shot's scan is searched by :func:`calib_core.guide.propose` under the joint pose and its
    covariance; the shots' lists are then merged by sequential D-optimal ranking over their union
    (each pick's information is added before the next is chosen, whichever shot it is in), by
    expected gain ``gain x probability`` when a shot has an image.

    Parameters
    ----------
    shots : sequence of Shot
        Each with its ``depth`` (the scan).
    images : dict shot -> (H, W, 3) uint8, optional
        Photos: proposals of those shots need an image corner near their pixel.
    click_sigma_px : float, optional
        Click noise of a guided pair (default :data:`calib_core.guide.GUIDED_CLICK_SIGMA_PX`).
    state : PoseState, optional
        The joint pose and covariance, if already known (:func:`joint_pose_state`).
    shot_options : dict shot -> dict, optional
        More keyword arguments of :func:`calib_core.guide.propose` for that shot, e.g. its scan's precomputed
        ``candidates`` and ``plane_residual`` (a loop over many proposals computes them once per scan),
        or its photo's ``corner_image`` (used instead of one computed from ``images``).

    Returns
    -------
    proposals : list of ShotProposal
    state : PoseState
    """
    from .guide import GUIDED_CLICK_SIGMA_PX, corner_image, propose
    from .guide.information import d_optimal_gain, pair_noise, pixel_jacobians
    from .guide.laser_noise import PICK_CELL_SIGMA as GUIDE_PICK_CELL_SIGMA
    from .guide.laser_noise import cell_covariance
    from .guide.pose_state import DEFAULT_CLICK_SIGMA_PX

    shots = list(shots)
    if n < 1:
        raise CalibError(f"the number of proposals must be at least 1, got {n}")
    sigma = GUIDED_CLICK_SIGMA_PX if click_sigma_px is None else float(click_sigma_px)
    images = dict(images or {})
    bad = [k for k in images if not 0 <= k < len(shots)]
    if bad:
        raise CalibError(f"an image is given for shot {bad[0]}, but there are {len(shots)} shots (0-based)")
    for k, s in enumerate(shots):
        if s.depth is None:
            raise CalibError(f"shot {k} has no scan: proposals need each shot's scan")
    if state is None:
        state = joint_pose_state(shots, camera, T_initial)
    pool: list[ShotProposal] = []
    J_list, S_list, P_list = [], [], []
    for k, s in enumerate(shots):
        used = [tuple(p.laser_rc) for p in s.pairs if p.laser_rc is not None]
        rough = [(i, tuple(p.laser_rc), DEFAULT_CLICK_SIGMA_PX if p.precision_px is None else p.precision_px)
                 for i, p in enumerate(s.pairs) if p.laser_rc is not None and not p.check]
        extra = dict((shot_options or {}).get(k, {}))
        corners = extra.pop("corner_image") if "corner_image" in extra else (
            corner_image(images[k]) if k in images else None)
        props = propose(s.depth, camera, state, n, exclude_rc=used, click_sigma_px=sigma, corner_image=corners,
                        reclick=rough, **extra)
        if not props:
            continue
        rc = np.array([p.laser_rc for p in props], dtype=np.int64)
        pts = np.array([p.laser_xyz for p in props], dtype=np.float64)
        _, J_pose, J_point = pixel_jacobians(camera, state.T_camera_lidar, pts)
        # The pair's own noise as propose() ranks it: the click plus a careful pick of the cell; a re-click
        # adds only what it improves on the rough pair it replaces (S^-1 = S_new^-1 - S_old^-1).
        whole = cell_covariance(s.depth, rc, GUIDE_PICK_CELL_SIGMA)
        S = pair_noise(sigma, J_point, whole)
        re = np.array([p.replaces is not None for p in props], dtype=bool)
        if re.any():
            old = np.array([DEFAULT_CLICK_SIGMA_PX if s.pairs[p.replaces].precision_px is None
                            else s.pairs[p.replaces].precision_px for p in props if p.replaces is not None])
            S_old = pair_noise(old, J_point[re], whole[re])
            S[re] = np.linalg.inv(np.linalg.inv(S[re]) - np.linalg.inv(S_old))
        pool += [ShotProposal(k, p) for p in props]
        J_list.append(J_pose)
        S_list.append(S)
        P_list.append(np.array([p.probability if np.isfinite(p.probability) else 1.0 for p in props]))
    if not pool:
        return [], state
    J, S, P = np.concatenate(J_list), np.concatenate(S_list), np.concatenate(P_list)
    C = np.array(state.covariance, dtype=np.float64)
    alive = np.ones(len(pool), dtype=bool)
    out: list[ShotProposal] = []
    for _ in range(min(n, len(pool))):  # n is a few tens; each step is vectorised over the pool
        g = d_optimal_gain(J, S, C)
        score = np.where(alive & np.isfinite(g), g * P, -np.inf)
        j = int(np.argmax(score))
        if not np.isfinite(score[j]):
            break
        alive[j] = False
        out.append(replace(pool[j], proposal=replace(pool[j].proposal, gain=float(g[j]))))
        G = C @ J[j].T @ np.linalg.inv(S[j] + J[j] @ C @ J[j].T)
        C = C - G @ J[j] @ C
        C = 0.5 * (C + C.T)
    return out, state


def shot_proposals_to_dict(proposals: Sequence[ShotProposal], state=None, shot_names: Sequence[str] = ()) -> dict:
    """The proposals file: ``proposals:`` (best first, each with ``shot``), the ``pose`` and the ``shots``' names."""
    from .guide.propose import proposals_to_dict

    doc = proposals_to_dict(proposals, state)
    if shot_names:
        doc["shots"] = [{"index": i, "name": str(nm)} for i, nm in enumerate(shot_names)]
    return doc


def verify_shots(shots_result: ShotsResult, shots: Sequence[Shot], camera, **verify_options: Any):
    """:func:`calib_core.verify.verify_calibration` of every shot's pairs under the joint fit, a shot left out
    of the fit counted as check pairs (``verify_options``: ``T_reference``, ``scene_points_lidar``, ...)."""
    from .verify import verify_calibration

    left_out = set(shots_result.disagreeing)
    return verify_calibration(
        np.concatenate([s.points_lidar for s in shots]).reshape(-1, 3),
        np.concatenate([s.bearings for s in shots]).reshape(-1, 3),
        np.concatenate([s.pixels for s in shots]).reshape(-1, 2), camera,
        check=np.concatenate([s.check | (k in left_out) for k, s in enumerate(shots)]).astype(bool),
        ids=[i for shot_ids in shots_result.pair_ids for i in shot_ids], result=shots_result.result,
        **verify_options)


def shots_extrinsics_document(shots_result: ShotsResult, shots: Sequence[Shot], camera, base_dir=None,
                              **verify_options: Any) -> tuple[dict, list[str]]:
    """The extrinsics YAML document of a :func:`solve_shots` result.

    :func:`calib_core.io.extrinsics.extrinsics_to_dict` of the fit, its ``pairs`` block holding every
    shot's pairs in shot order (each with ``shot``, 0-based), the ``verification:`` block
    (:func:`calib_core.verify.verify_calibration`; a shot left out counts as check pairs there) and
    the ``shots:`` block (:func:`shots_to_dict`).

    Returns
    -------
    doc : dict
    notes : list of str
        Why the document has no ``verification`` block, if it has none.
    """
    from .io.extrinsics import extrinsics_to_dict
    from .verify import verification_to_dict

    shots = list(shots)
    result = shots_result.result
    pairs_block = [{**p.to_dict(), "shot": k} for k, s in enumerate(shots) for p in s.pairs]
    doc = extrinsics_to_dict(result.T_camera_lidar, result, camera, pairs_block, base_dir=base_dir)
    notes: list[str] = []
    try:
        doc["verification"] = verification_to_dict(verify_shots(shots_result, shots, camera, **verify_options))
    except CalibError as exc:
        notes.append(f"no verification block: {exc}")
    doc["shots"] = shots_to_dict(shots_result, shots)
    return doc, notes


def format_shots(shots_result: ShotsResult) -> str:
    """The per-shot table the CLI prints: residuals under the pose, leave-one-shot-out, the test."""
    loso = {e.shot: e for e in shots_result.leave_one_shot_out}
    tests = {t.shot: t for t in shots_result.tests}

    def f(x, fmt):
        return format(x, fmt) if math.isfinite(x) else "-"

    lines = [f"{'shot':>4}{'pairs':>7}{'fit':>5}{'error [px]':>12}{'LOSO [px]':>11}{'LOSO [deg]':>12}"
             f"{'offset [deg]':>14}{'p':>10}  name"]
    for rep in shots_result.shots:
        e, t = loso.get(rep.index), tests.get(rep.index)
        flag = ("  <- disagrees, left out of the fit" if rep.index in shots_result.disagreeing else
                "  <- disagrees with the other shot" if rep.index in shots_result.undecided else "")
        loso_px = f(e.mean_px, "11.3f") if e else "-"
        loso_deg = f(e.mean_deg, "12.4f") if e else "-"
        offset = f(t.rotation_deg, "14.3f") if t else "-"
        p_value = format(t.p_value, "10.1e") if t else "-"
        n_in_fit = rep.n_fit - len(rep.outliers) if rep.in_fit else 0
        lines.append(f"{rep.index:4d}{rep.n_pairs:7d}{n_in_fit:5d}{f(rep.mean_px, '12.3f'):>12}{loso_px:>11}"
                     f"{loso_deg:>12}{offset:>14}{p_value:>10}  {rep.name}{flag}")
    return "\n".join(lines)
