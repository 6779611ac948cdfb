"""How far a calibration can be trusted: ``ok``, ``warning`` or ``unreliable``, with one line per reason.

``unreliable`` means the pose must not be used: too few pairs agree on it,
at most half of them do, or its uncertainty is undefined or huge.
``warning`` means it is usable but something deserves a look (pairs left out
as outliers, weak geometry, residuals above the expected click noise, too few
pairs for the residuals to estimate the error: :func:`error_estimate_reason`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .edges import EDGE_SLIDE, edge_frames
from .kernels import so3_exp

__all__ = [
    "Quality",
    "STATUSES",
    "geometry_reasons",
    "UNRELIABLE_ROTATION_DEG",
    "WARNING_ROTATION_DEG",
    "UNRELIABLE_TRANSLATION_FRACTION",
    "WARNING_TRANSLATION_FRACTION",
    "COPLANAR_RATIO",
    "FEW_INLIERS",
    "MIN_PAIRS_FOR_ERROR",
    "NO_ERROR_ESTIMATE",
    "error_estimate_reason",
    "pairs_in_fit",
    "NEAR_SINGULAR_DEG",
    "orientation_notes",
    "LeaveOneOut",
    "leave_one_out_estimate",
    "leave_one_out_reasons",
    "with_leave_one_out",
    "LOO_FACTOR",
    "LOO_FLOOR_PX",
    "LOO_NOISY_PX",
    "HIGH_LEVERAGE",
    "off_plane_advice",
    "GOAL_ROTATION_DEG",
    "GOAL_TRANSLATION_M",
    "GOAL_SIGMAS",
    "goal_reason",
]

STATUSES = ("ok", "warning", "unreliable")
#: 1-sigma of the rotation along its worst axis (deg) above which the pose is unreliable / gets a warning.
UNRELIABLE_ROTATION_DEG = 3.0
WARNING_ROTATION_DEG = 1.0
#: 1-sigma of the translation as a fraction of the median laser range: unreliable / warning.
UNRELIABLE_TRANSLATION_FRACTION = 0.10
WARNING_TRANSLATION_FRACTION = 0.02
#: Smallest / largest singular value of the centred laser points below this: near-coplanar.
COPLANAR_RATIO = 0.05
#: Fewer inliers than this cannot check one another (a wrong pair would go unseen).
FEW_INLIERS = 6
#: The accuracy a calibration is for (the by-eye walkthrough's target, docs/by_eye.md): within this rotation
#: (deg) and translation (m) at :data:`GOAL_SIGMAS` sigma; a pose whose uncertainty does not promise it is not "ok".
GOAL_ROTATION_DEG = 0.5
GOAL_TRANSLATION_M = 0.10
GOAL_SIGMAS = 2.0
#: :func:`goal_reason` names no nearer range than this (m) to add pairs at (it asks for more, and the nearest the
#: scene has, instead): few scenes have corners nearer.
NEAR_ADVICE_MIN_M = 3.0
#: Fewest pairs in the fit whose residuals estimate the error (:func:`error_estimate_reason`).
MIN_PAIRS_FOR_ERROR = 5
#: What the error display says instead of a mean error below :data:`MIN_PAIRS_FOR_ERROR` pairs.
NO_ERROR_ESTIMATE = "no error estimate yet"


def error_estimate_reason(n_inliers: int) -> str | None:
    """Why the residuals of ``n_inliers`` pairs in the fit say nothing of the error, or None when they do.

    The pose has 6 unknowns and each pair gives 2 residuals, so the fit leaves
    ``dof = 2 n - 6`` degrees of freedom and the sum of squared residuals is
    ``sigma^2 chi^2(dof)``.  The residuals estimate the error from ``dof >= 4``,
    i.e. :data:`MIN_PAIRS_FOR_ERROR` = 5 pairs:

    * ``dof <= 2`` (4 pairs or fewer): the density of ``chi^2(dof)`` is largest
      at 0, so a near-exact fit is the likeliest outcome whatever the click
      error (3 pairs fit exactly: "0.000 px").  The root-mean-square residual
      is ``sqrt(dof / 2n)`` = half the clicks' error at 4 pairs, and the 95 %
      interval of sigma given the residuals spans a factor 12 (0.52 to 6.3
      times the estimate).
    * ``dof = 4`` (5 pairs): the mode ``dof - 2`` is positive, and the interval
      narrows to a factor 4.8 (0.60 to 2.87); 2.2 at 10 pairs.

    Returns
    -------
    str or None
        E.g. ``"4 pairs fit any pose closely; add pairs"``; the quality reason
        is ``f"{NO_ERROR_ESTIMATE}: {reason}"``.
    """
    m = int(n_inliers)
    if m >= MIN_PAIRS_FOR_ERROR:
        return None
    return f"{m} pairs fit any pose closely; add pairs"


def goal_reason(rotation_sigma_deg: float, translation_sigma_m: float, median_range_m: float) -> str | None:
    """One line when the pose's uncertainty does not promise the goal, else None.

    The goal: :data:`GOAL_ROTATION_DEG` and :data:`GOAL_TRANSLATION_M` at :data:`GOAL_SIGMAS` sigma.  The
    advice: a translation error is an angle error times the pairs' distance, so pairs nearer than
    ``median_range_m * goal / (GOAL_SIGMAS * sigma)`` would bring it within the goal; a rotation error
    shrinks with the pairs' spread over the image.

    Parameters
    ----------
    rotation_sigma_deg : float
        1-sigma of the rotation along its worst axis, degrees.
    translation_sigma_m : float
        1-sigma of the translation along its worst direction, metres.
    median_range_m : float
        Median distance of the pairs in the fit from the camera, metres.
    """
    rot, trans = GOAL_SIGMAS * float(rotation_sigma_deg), GOAL_SIGMAS * float(translation_sigma_m)
    parts, advice = [], []
    if not math.isfinite(rot) or not math.isfinite(trans):
        return None  # (undefined: geometry_reasons says so)
    if trans > GOAL_TRANSLATION_M:
        parts.append(f"translation uncertain to +/- {100 * trans:.0f} cm")
        near = median_range_m * GOAL_TRANSLATION_M / trans if median_range_m > 0 else 0.0
        # Under a few metres there is seldom anything to pair (run 13: "nearer than 3 m" on PJLab, where nothing is).
        advice.append(f"nearer than {near:.0f} m" if near >= NEAR_ADVICE_MIN_M
                      else "as near as the scene has, and more of them")
        advice.append("at several depths")
    if rot > GOAL_ROTATION_DEG:
        parts.append(f"rotation uncertain to +/- {rot:.1f} deg")
        advice.append("spread over the whole image")
    if not parts:
        return None
    return (f"{' and '.join(parts)} ({GOAL_SIGMAS:g} sigma; not within {GOAL_ROTATION_DEG:g} deg / "
            f"{100 * GOAL_TRANSLATION_M:.0f} cm): add pairs {', '.join(advice)}")


def pairs_in_fit(result) -> int:
    """Pairs in the fit of a :class:`~calib_core.solve.CalibrationResult` (outliers and check pairs not counted)."""
    inliers = getattr(result, "inliers", None)
    if inliers is not None:
        return int(np.count_nonzero(inliers))
    return int(result.n_pairs) - len(getattr(result, "outliers", []))


@dataclass(frozen=True)
class Quality:
    """Verdict on a calibration.

    Attributes
    ----------
    status : {"ok", "warning", "unreliable"}
    reasons : list of str
        One line each, the most serious first; empty when ``status == "ok"``.
    """

    status: str = "ok"
    reasons: list[str] = field(default_factory=list)
    #: The pairs' leave-one-out errors and leverages (:func:`with_leave_one_out`), None when not computed.
    leave_one_out: "LeaveOneOut | None" = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")

    @staticmethod
    def from_reasons(unreliable: list[str], warnings: list[str]) -> "Quality":
        status = "unreliable" if unreliable else ("warning" if warnings else "ok")
        return Quality(status, list(unreliable) + list(warnings))

    def to_dict(self) -> dict:
        return {"status": self.status, "reasons": [str(r) for r in self.reasons]}


def geometry_reasons(
    singular_values: np.ndarray,
    n_inliers: int,
    rotation_sigma_deg: float,
    sigma_translation_m: np.ndarray,
    median_range_m: float,
    translation_sigma_worst_m: float | None = None,
    goal: bool = False,
) -> tuple[list[str], list[str]]:
    """``(unreliable, warnings)`` about the inliers' geometry and the pose's uncertainty.

    Parameters
    ----------
    singular_values : (3,) ndarray
        Singular values of the centred laser points of the pairs in the fit, descending.
    n_inliers : int
        Pairs in the fit.
    rotation_sigma_deg : float
        1-sigma of the rotation along its worst axis, degrees (not roll/pitch/yaw: those
        blow up near gimbal lock although the rotation is fine).
    sigma_translation_m : (3,) ndarray
        1-sigma of the translation, metres.
    median_range_m : float
        Median distance of the inlier points from the camera, metres.
    translation_sigma_worst_m : float, optional
        1-sigma of the translation along its worst direction, metres (the covariance's largest
        eigenvalue, square-rooted), for :func:`goal_reason`; default the largest of ``sigma_translation_m``.
    goal : bool
        Check the goal (:func:`goal_reason`, a warning): the solve asks for it where the uncertainty includes
        the error by-eye pairs share (``shared_ratio > 0``: cells of a measured scan).  Not for the ideal
        synthetic scenes, whose exact sigmas keep the thresholds above (the sample's 10 simulated clicks on a
        0.52 deg/px fisheye give 0.36 deg, 0.7 deg at 2 sigma, and are "ok" by those).
    """
    bad: list[str] = []
    weak: list[str] = []
    m = int(n_inliers)
    s_rot = float(rotation_sigma_deg)
    # Plain floats: this runs once per solve, where numpy's per-call overhead would dominate.
    s_ts = np.asarray(sigma_translation_m, dtype=np.float64).tolist()
    s_t = max(s_ts) if all(math.isfinite(v) for v in s_ts) else math.inf
    if not (math.isfinite(s_rot) and math.isfinite(s_t)):
        bad.append("the uncertainty of the pose is undefined (the pairs in the fit do not determine it)")
    else:
        if s_rot > UNRELIABLE_ROTATION_DEG:
            bad.append(f"the rotation is uncertain by {s_rot:.1f} deg (1 sigma, above {UNRELIABLE_ROTATION_DEG:g} deg)")
        elif s_rot > WARNING_ROTATION_DEG:
            weak.append(f"the rotation is uncertain by {s_rot:.2f} deg (1 sigma); add well-spread pairs")
        frac = s_t / median_range_m if median_range_m > 0 else math.inf
        if frac > UNRELIABLE_TRANSLATION_FRACTION:
            bad.append(
                f"the translation is uncertain by {100 * s_t:.1f} cm (1 sigma, {100 * frac:.0f} % of the "
                f"{median_range_m:.2f} m median range)"
            )
        elif frac > WARNING_TRANSLATION_FRACTION:
            weak.append(f"the translation is uncertain by {100 * s_t:.1f} cm (1 sigma); add pairs at other depths")
        if goal and not bad:
            line = goal_reason(s_rot, s_t if translation_sigma_worst_m is None else translation_sigma_worst_m,
                               median_range_m)
            if line:  # (it says what the two lines above said, and more: it replaces them)
                weak = [w for w in weak if not w.startswith(("the rotation is uncertain", "the translation is unc"))]
                weak.insert(0, line)
    sv0, _, sv2 = np.asarray(singular_values, dtype=np.float64).tolist()[:3]
    if m >= 4 and sv2 < COPLANAR_RATIO * sv0 and m < 2 * FEW_INLIERS:
        weak.append(
            f"the {m} laser points in the fit lie near one plane: few coplanar pairs can fit a wrong pose; "
            "add pairs off that plane"
        )
    no_error = error_estimate_reason(m)
    if no_error is not None:
        weak.append(f"{NO_ERROR_ESTIMATE}: {no_error}")
    if m < FEW_INLIERS:
        weak.append(f"only {m} pairs in the fit: too few to find a wrong pair among them; add pairs")
    return bad, weak


#: Within this many degrees of its singularity an angle chart gets a note: its angles' sigmas are
#: then inflated up to ``1 / cos(90 - 10 deg)`` = 5.8x beyond the rotation's own uncertainty.
NEAR_SINGULAR_DEG = 10.0


def _inflation(cos_angle: float) -> str:
    return "without bound" if cos_angle < 1e-6 else f"up to {1.0 / cos_angle:.0f}x"


def orientation_notes(R_camera_lidar: np.ndarray) -> list[str]:
    """Notes on how to read the orientation (not on the calibration's quality), one line each.

    Roll/pitch/yaw (``R = Rz(yaw) Ry(pitch) Rx(roll)``) are in gimbal lock at pitch = +-90 deg, which
    for ``R_camera_lidar`` is a camera looking along lidar +-x: the usual forward camera.  Azimuth,
    elevation and roll about the optical axis (:func:`calib_core.transforms.viewing_direction`) are
    singular for a camera looking along lidar +-z (an upward omnidirectional camera).  A note is
    given when the pose is within :data:`NEAR_SINGULAR_DEG` of either; at most one of the two
    applies, so the other chart is always readable.
    """
    # Python floats (one list, then plain indexing): numpy's per-element indexing would cost more than the maths.
    R = np.asarray(R_camera_lidar, dtype=np.float64).tolist()
    notes: list[str] = []
    cos_pitch = math.hypot(R[0][0], R[1][0])
    pitch = math.degrees(math.atan2(-R[2][0], cos_pitch))
    if 90.0 - abs(pitch) < NEAR_SINGULAR_DEG:
        notes.append(
            f"pitch is {pitch:.1f} deg, within {NEAR_SINGULAR_DEG:g} deg of +-90 (near gimbal lock): roll, yaw and "
            f"their sigmas are ill-conditioned ({_inflation(cos_pitch)} the rotation's own uncertainty); read the "
            "viewing direction (azimuth, elevation, roll about the optical axis), the matrix or the quaternion"
        )
    # The optical axis in lidar coordinates is R's last row (as in viewing_direction); plain floats, once per solve.
    cos_el = math.hypot(R[2][0], R[2][1])
    elevation = math.degrees(math.atan2(R[2][2], cos_el))
    if 90.0 - abs(elevation) < NEAR_SINGULAR_DEG:
        notes.append(
            f"the camera looks {90.0 - abs(elevation):.1f} deg from lidar {'+' if elevation > 0 else '-'}z:"
            f" its azimuth, roll about the optical axis and their sigmas are ill-conditioned ({_inflation(cos_el)} the "
            "rotation's own uncertainty); read roll/pitch/yaw, the matrix or the quaternion"
        )
    return notes


# --------------------------------------------------------------------------------------
# leave-one-out: does the fit error flatter a few pairs?
# --------------------------------------------------------------------------------------

#: The pairs' leave-one-out error (RMS) above this many times what the fit's own residuals predict: a warning.
LOO_FACTOR = 2.0
#: ... but only when the mean leave-one-out error is above this (px): below it the pairs are fine anyway.
LOO_FLOOR_PX = 2.0
#: Mean leave-one-out error (px) above which the clicks are too far off for "ok": 3x the 1.5 px per axis expected
#: of a click and a laser pick is 4.5 px per axis, a mean 2-D error of 1.25 x 4.5 = 5.6 px; rounded up.
LOO_NOISY_PX = 6.0
#: A pair whose 2x2 hat-matrix block has an eigenvalue above this carries the pose: a mistake in it shows in
#: its own residual at most ``1 - HIGH_LEVERAGE`` (10 %) of its size along that direction.
HIGH_LEVERAGE = 0.9
#: A pose whose translation moves more than this (metres) when one pair is left out hangs on that pair.  Measured
#: on the 18 kept by-eye sessions of runs 1-9 (docs/by_eye.md), solved as the app solves them: of the four "ok"
#: results 22-65 cm from the published pose it warns on the worst (PJLab run 9, 64.6 cm off, 18.2 cm without one
#: pair) and misses three (5.0-8.4 cm); it also warns on the one "ok" result 10.1 cm off (10.5 cm without one pair).
LOO_SHIFT_M = 0.10


@dataclass(frozen=True)
class LeaveOneOut:
    """Each fit pair's error under the pose fitted without it, from the hat matrix of the fit (no refit).

    For a least-squares fit with Jacobian ``J`` (pixels per pose parameter, rows weighted by ``1 / sigma``) the
    hat matrix ``H = J (J^T J)^-1 J^T`` maps the clicks to the fitted pixels; pair ``i``'s 2x2 block ``H_ii`` says
    how much of its own error the pose absorbs.  Its residual under the pose fitted *without* it is then
    ``(I - H_ii)^-1 e_i`` (exact for a linear model; the pose is near-linear over pixel-sized errors, which
    ``tests/test_leave_one_out.py`` checks against refits).

    Attributes
    ----------
    loo_px : (n,) ndarray
        Leave-one-out error of each pair in the fit, px (NaN where it has no pixel or the pose needs it whole).
    fit_px : (n,) ndarray
        Its residual under the fit, px.
    leverage : (n,) ndarray
        Largest eigenvalue of ``H_ii``, in [0, 1]: 1 means the pose follows that pair's click whatever it is.
    ids : list of int
        The pairs' ids (for the messages).
    expected_loo_rms_px : float
        The RMS leave-one-out error the fit's own residuals predict (``s^2 trace((I - H_ii)^-1)``, with ``s`` the
        residual scale over ``2 n - 6`` degrees of freedom), px; NaN when unknown.
    shift_m : (n,) ndarray
        How far the translation of ``T_camera_lidar`` moves when the pose is fitted without each pair, metres
        (the same case-deletion step, ``N^-1 J_i^T (I - H_ii)^-1 r_i``; NaN where ``loo_px`` is).
    turn_deg : (n,) ndarray
        How far the rotation turns then, degrees.
    """

    loo_px: np.ndarray
    fit_px: np.ndarray
    leverage: np.ndarray
    ids: list
    expected_loo_rms_px: float
    shift_m: np.ndarray | None = None
    turn_deg: np.ndarray | None = None

    @property
    def mean_px(self) -> float:
        """Mean leave-one-out error over the pairs that have one, px (NaN if none)."""
        finite = self.loo_px[np.isfinite(self.loo_px)]
        return float(finite.mean()) if finite.size else float("nan")

    @property
    def rms_px(self) -> float:
        finite = self.loo_px[np.isfinite(self.loo_px)]
        return float(np.sqrt(np.mean(finite**2))) if finite.size else float("nan")


#: Gauss-Newton steps from the solve's pose to the optimum of the weighted pixel cost (2 are within 0.01 px on
#: the by-eye sessions; each costs one projection of the pairs).
GAUSS_NEWTON_STEPS = 3


def _pixel_jacobian(camera, points_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``d pixel / d (delta, t)`` (n, 2, 6) for ``X_c = exp(delta) X_c + t`` by central differences of the
    projection, the pixels (n, 2) and whether each point projects (n,)."""
    n = len(points_camera)
    h = 1e-6 * np.maximum(np.linalg.norm(points_camera, axis=1), 1e-3)
    steps = np.concatenate([np.eye(3), -np.eye(3)])
    shifted = points_camera[None, :, :] + steps[:, None, :] * h[None, :, None]
    proj, ok = camera.project(np.concatenate([points_camera, shifted.reshape(-1, 3)]))
    proj = np.asarray(proj, np.float64)
    ok = np.asarray(ok, bool).reshape(7, n).all(axis=0)
    moved = proj[n:].reshape(6, n, 2)
    dp_dx = np.transpose((moved[:3] - moved[3:]) / (2.0 * h[None, :, None]), (1, 2, 0))  # (n, 2, 3)
    X = points_camera
    skew = np.zeros((n, 3, 3))  # [X]_x; d(exp(delta) X)/d delta = -[X]_x
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -X[:, 2], X[:, 1], -X[:, 0]
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = X[:, 2], -X[:, 1], X[:, 0]
    dX = np.concatenate([-skew, np.broadcast_to(np.eye(3), skew.shape)], axis=2)  # (n, 3, 6)
    return dp_dx @ dX, proj[:n], ok & np.isfinite(dp_dx).all(axis=(1, 2))


def leave_one_out_estimate(
    T_camera_lidar: np.ndarray,
    points_lidar: np.ndarray,
    pixels: np.ndarray,
    camera,
    pixel_sigma: np.ndarray | None = None,
    ids=None,
    pixel_edge_deg: np.ndarray | None = None,
) -> LeaveOneOut | None:
    """Leave-one-out errors and leverages of the pairs of a fit, from its hat matrix (:class:`LeaveOneOut`).

    Parameters
    ----------
    T_camera_lidar : (4, 4) array
        The fitted pose (maps lidar points, metres, into the camera frame).
    points_lidar, pixels : (n, 3), (n, 2) arrays
        The pairs in the fit: laser points (lidar frame, m) and clicked pixels (px).
    camera : CameraModel
    pixel_sigma : (n,) array, optional
        1-sigma of each click (px), as the fit weighed them; None: all alike.
    ids : sequence, optional
        The pairs' ids, for messages (default positions).
    pixel_edge_deg : (n,) array, optional
        Edge pairs' edge angles, degrees (NaN for a corner pair; :mod:`calib_core.solve.edges`): weighed with
        their anisotropic click covariance, and their fit and leave-one-out errors (and expected error) are the
        distance ACROSS the edge.

    Returns
    -------
    LeaveOneOut or None
        None with fewer than :data:`MIN_PAIRS_FOR_ERROR` pairs with a pixel (the residuals then say nothing of the
        error: :func:`error_estimate_reason`) or when the pose is undetermined by them.
    """
    T = np.array(T_camera_lidar, np.float64)
    pts = np.asarray(points_lidar, np.float64).reshape(-1, 3)
    pix = np.asarray(pixels, np.float64).reshape(-1, 2)
    n = len(pts)
    ids = list(range(n)) if ids is None else list(ids)
    w = np.ones(n) if pixel_sigma is None else 1.0 / np.asarray(pixel_sigma, np.float64).reshape(n)
    edges = None if pixel_edge_deg is None else np.asarray(pixel_edge_deg, np.float64).reshape(n)
    # Per-pair pixel whitening Wp = M^-1 / sigma (M = I for a corner pair, n n^T + k t t^T for an edge pair), its
    # inverse, and the part of an error that is reported (I, or n n^T: across the edge).
    M_inv, M, report = (np.broadcast_to(np.eye(2), (n, 2, 2)),) * 3
    if edges is not None and np.isfinite(edges).any():
        M_inv, M, report = (np.array(M_inv), np.array(M), np.array(report))
        edge = np.isfinite(edges)
        t, nrm = edge_frames(edges[edge])
        nn, tt = nrm[:, :, None] * nrm[:, None, :], t[:, :, None] * t[:, None, :]
        M_inv[edge], M[edge], report[edge] = nn + tt / EDGE_SLIDE, nn + EDGE_SLIDE * tt, nn
    Wp = M_inv * w[:, None, None]
    loo, fit, lev = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    # The hat matrix holds at the optimum of the weighted pixel cost: a few Gauss-Newton steps take the given
    # pose there (the solve's own cost weighs pairs a little differently: angles, the laser pick).
    for _ in range(GAUSS_NEWTON_STEPS + 1):
        J, proj, ok = _pixel_jacobian(camera, pts @ T[:3, :3].T + T[:3, 3])
        e = proj - pix
        ok &= np.isfinite(e).all(axis=1) & np.isfinite(w) & (w > 0)
        m = int(ok.sum())
        if m < MIN_PAIRS_FOR_ERROR:
            return None
        Jw = Wp[ok] @ J[ok]  # (m, 2, 6)
        rw = np.einsum("kab,kb->ka", Wp[ok], e[ok])  # (m, 2)
        N = np.einsum("kai,kaj->ij", Jw, Jw)
        if not np.isfinite(N).all() or np.linalg.cond(N) > 1e12:
            return None
        Ninv = np.linalg.inv(N)
        step = -Ninv @ np.einsum("kai,ka->i", Jw, rw)  # (delta, t): X_c -> exp(delta) X_c + t
        if not np.isfinite(step).all():
            return None
        if _ == GAUSS_NEWTON_STEPS or np.linalg.norm(step[:3]) < 1e-9 and np.linalg.norm(step[3:]) < 1e-9:
            break
        R_step = so3_exp(np.ascontiguousarray(step[:3]))
        T[:3, :3], T[:3, 3] = R_step @ T[:3, :3], R_step @ T[:3, 3] + step[3:]
    e_shown = np.einsum("kab,kb->ka", report[ok], e[ok])  # (across an edge pair's edge)
    fit[ok] = np.hypot(e_shown[:, 0], e_shown[:, 1])
    H = Jw @ Ninv @ np.transpose(Jw, (0, 2, 1))  # (m, 2, 2) diagonal blocks of the hat matrix
    H = 0.5 * (H + np.transpose(H, (0, 2, 1)))
    tr, det = H[:, 0, 0] + H[:, 1, 1], H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0]
    lev[ok] = np.clip(0.5 * tr + np.sqrt(np.maximum(0.25 * tr**2 - det, 0.0)), 0.0, 1.0)
    A = np.eye(2) - H
    detA = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    carried = detA <= 1e-9  # the pose follows this click wholly: no prediction without it
    adj = np.stack([np.stack([A[:, 1, 1], -A[:, 0, 1]], -1), np.stack([-A[:, 1, 0], A[:, 0, 0]], -1)], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        Ainv = adj / detA[:, None, None]
        z = np.einsum("kab,kb->ka", Ainv, rw)  # weighted leave-one-out residuals
        B = report[ok] @ M[ok] / w[ok, None, None]  # whitened -> shown px: Wp^-1, then across an edge pair's edge
        z_px = np.einsum("kab,kb->ka", B, z)
        loo[ok] = np.where(carried, np.nan, np.hypot(z_px[:, 0], z_px[:, 1]))
        s2 = float(np.sum(rw**2)) / (2 * m - 6)
        # Each pair's expected squared error, px^2: s^2 trace(B (I - H_ii)^-1 B^T) (s^2 trace((I - H_ii)^-1) / w_i^2
        # for a corner pair).
        BAB = np.einsum("kab,kbc,kdc->kad", B, Ainv, B)
        expected = s2 * np.where(carried, np.nan, BAB[:, 0, 0] + BAB[:, 1, 1])
        expected_rms = float(np.sqrt(np.nanmean(expected))) if np.isfinite(expected).any() else float("nan")
        # The pose fitted without pair i differs by N^-1 J_i^T z_i in (delta, t); the translation of T then
        # moves by delta x t + dt.
        d = np.einsum("ij,kaj,ka->ki", Ninv, Jw, z)
        moved = np.cross(d[:, :3], T[:3, 3]) + d[:, 3:]
        shift, turn = np.full(n, np.nan), np.full(n, np.nan)
        shift[ok] = np.where(carried, np.nan, np.linalg.norm(moved, axis=1))
        turn[ok] = np.where(carried, np.nan, np.degrees(np.linalg.norm(d[:, :3], axis=1)))
    return LeaveOneOut(loo_px=loo, fit_px=fit, leverage=lev, ids=ids, expected_loo_rms_px=expected_rms,
                       shift_m=shift, turn_deg=turn)


def leave_one_out_reasons(loo: LeaveOneOut | None, fit_mean_px: float | None = None) -> list[str]:
    """Warnings when the fit error flatters a few pairs (one line each; empty when it does not).

    ``fit_mean_px`` is the fit error as shown (the solve's mean residual, px); default the mean of ``loo.fit_px``.

    * The pairs' mean leave-one-out error is over :data:`LOO_NOISY_PX`: clicks the pose was not fitted to land
      that far off, whatever the fit error says (the residuals of few pairs understate it: at 6 pairs the pose
      absorbs half of every click's error).
    * Their RMS is over :data:`LOO_FACTOR` times what the fit's own residuals predict for it (and the mean over
      :data:`LOO_FLOOR_PX`): the pose bends towards pairs whose errors it hides.
    * A pair has a leverage over :data:`HIGH_LEVERAGE`: the pose rests on it, and an error in it would hardly
      show in its residual.
    * Leaving one pair out moves the translation more than :data:`LOO_SHIFT_M`: the result hangs on that pair,
      whatever the residuals say.
    """
    if loo is None:
        return []
    reasons: list[str] = []
    rms, expected, mean = loo.rms_px, loo.expected_loo_rms_px, loo.mean_px
    fit_mean = float(np.nanmean(loo.fit_px)) if fit_mean_px is None else float(fit_mean_px)
    if math.isfinite(mean) and mean > LOO_NOISY_PX:
        reasons.append(
            f"pairs left out of the fit err {mean:.1f} px on average (above {LOO_NOISY_PX:g} px; the fit error is "
            f"{fit_mean:.2f} px): the clicks are off by several pixels; check the pairs with the largest error "
            "left out, add well-spread pairs"
        )
    elif math.isfinite(rms) and math.isfinite(expected) and rms > LOO_FACTOR * expected and mean > LOO_FLOOR_PX:
        reasons.append(
            f"pairs left out of the fit err {mean:.1f} px on average against a fit error of {fit_mean:.2f} px "
            f"({rms / expected:.1f}x what the residuals predict): the pose bends to fit a few pairs; "
            "check the pairs with the largest error left out, add well-spread pairs"
        )
    carried = [i for i in range(len(loo.ids)) if np.isfinite(loo.leverage[i]) and loo.leverage[i] > HIGH_LEVERAGE]
    if carried:
        worst = max(carried, key=lambda i: loo.leverage[i])
        names = ", ".join(str(loo.ids[i]) for i in carried[:5]) + (" ..." if len(carried) > 5 else "")
        reasons.append(
            f"the pose rests on pair{'s' if len(carried) > 1 else ''} {names} (leverage up to "
            f"{loo.leverage[worst]:.2f}: an error there shows only {100 * (1 - loo.leverage[worst]):.0f} % in its "
            "residual); add pairs near it and elsewhere"
        )
    shift = np.full(len(loo.ids), np.nan) if loo.shift_m is None else np.asarray(loo.shift_m, np.float64)
    if np.isfinite(shift).any() and np.nanmax(shift) > LOO_SHIFT_M:
        i = int(np.nanargmax(shift))
        reasons.append(
            f"without pair {loo.ids[i]} the translation moves {100 * shift[i]:.1f} cm (above "
            f"{100 * LOO_SHIFT_M:.0f} cm): the result hangs on that pair; check it, and add pairs near it and at "
            "other depths"
        )
    return reasons


#: How a near-coplanar reason starts (:func:`geometry_reasons`); :func:`with_leave_one_out` says where to add pairs.
PLANE_REASON_END = "lie near one plane: few coplanar pairs can fit a wrong pose; add pairs off that plane"


def off_plane_advice(T_camera_lidar: np.ndarray | None, points_lidar: np.ndarray, pixels: np.ndarray, width: int,
                     height: int) -> str:
    """Where pairs off the plane of ``points_lidar`` (``(n, 3)``, lidar frame, metres) would go, in words, from
    their ``pixels`` (``(n, 2)``, original image, ``width`` x ``height``) and ranges (from the lidar, metres).

    With a pose ``T_camera_lidar`` to trust (None: none), the plane is named by its normal in the camera frame
    (x right, y down, z forward): level (like the ground), across the view (like a wall ahead) or along it (like a
    wall beside the road), else tilted.  Then the pairs' range band, the image's thirds that hold no pair, and
    where off-plane pairs would lie: above the pairs' rows for a level plane, nearer or farther for a plane across
    the view, on the image's other side for a plane along it, else in the empty thirds (by-eye run 6: "add pairs
    off that plane" did not say where).
    """
    P = np.asarray(points_lidar, np.float64).reshape(-1, 3)
    uv = np.asarray(pixels, np.float64).reshape(-1, 2)
    rng = np.linalg.norm(P, axis=1)
    lo, hi = float(rng.min()), float(rng.max())
    normal = np.zeros(3)
    if T_camera_lidar is not None:
        normal = np.linalg.svd(P - P.mean(axis=0))[2][2] @ np.asarray(T_camera_lidar, np.float64)[:3, :3].T
    axis = int(np.argmax(np.abs(normal)))
    upright = abs(normal[axis]) >= 0.8
    if T_camera_lidar is None:
        kind, where = "", "in the image's empty thirds, at other ranges"
    elif upright and axis == 1:
        kind, where = "level (like the ground)", (f"above image row {uv[:, 1].min():.0f}, where the scan reaches "
                                                  "(poles, signs, walls' upper edges)")
    elif upright and axis == 2:
        kind, where = "across the view (like a wall ahead)", f"nearer than {lo:.1f} m or farther than {hi:.1f} m"
    elif upright:
        left = float(np.mean(uv[:, 0])) < width / 2.0
        kind = "along the view (like a wall beside the road)"
        where = (f"right of image column {uv[:, 0].max():.0f}" if left else
                 f"left of image column {uv[:, 0].min():.0f}") + " (the other side of the view)"
    else:
        kind, where = "tilted", "in the empty parts of the image"
    empty = [f"{name} third" for name, lo_v in (("top", 0.0), ("middle", height / 3.0), ("bottom", 2 * height / 3.0))
             if not ((uv[:, 1] >= lo_v - 0.5) & (uv[:, 1] < lo_v + height / 3.0 - 0.5)).any()]
    empty += [f"{name} third" for name, lo_u in (("left", 0.0), ("centre", width / 3.0), ("right", 2 * width / 3.0))
              if not ((uv[:, 0] >= lo_u - 0.5) & (uv[:, 0] < lo_u + width / 3.0 - 0.5)).any()]
    none_in = f"; no pair in the image's {', '.join(empty)}" if empty else ""
    named = f"the plane is {kind}, " if kind else ""
    return f"{named}the pairs {lo:.1f}-{hi:.1f} m from the lidar{none_in}: add pairs {where}"


def _with_plane_advice(reasons: list, result, points_lidar, pixels, camera) -> list:
    """``reasons`` with the near-coplanar one saying where to add pairs (:func:`off_plane_advice`)."""
    out = []
    for r in reasons:
        if str(r).endswith(PLANE_REASON_END) and len(points_lidar) >= 3:
            trusted = result.quality.status != "unreliable"  # an unreliable pose could name the plane wrong
            r = str(r)[:-len("add pairs off that plane")] + off_plane_advice(
                result.T_camera_lidar if trusted else None, points_lidar, pixels, camera.width, camera.height)
        out.append(r)
    return out


def with_leave_one_out(result, points_lidar, pixels, camera, pixel_sigma=None, pair_ids=None, *, pixel_edge_deg=None):
    """Add the leave-one-out check to a solve's result in place: ``result.quality`` (with its
    :attr:`Quality.leave_one_out`) and ``result.warnings`` get :func:`leave_one_out_reasons`.

    Parameters
    ----------
    result : CalibrationResult
        The fit of these pairs (its ``inliers`` select the pairs in the fit).
    points_lidar, pixels : (n, 3), (n, 2) arrays
        All the pairs the solve was given (lidar frame, m; px), in its order.
    pixel_sigma : (n,) array, optional
        As given to the solve.
    pair_ids : sequence, optional
        As given to the solve (default positions).
    pixel_edge_deg : (n,) array, optional
        As given to the solve (NaN for a corner pair): edge pairs' errors are across their edge.

    Returns
    -------
    CalibrationResult
        ``result`` itself.
    """
    if camera is None or pixels is None:
        return result
    inliers = getattr(result, "inliers", None)
    keep = np.ones(len(points_lidar), bool) if inliers is None else np.asarray(inliers, bool)
    all_ids = list(range(len(keep))) if pair_ids is None else list(pair_ids)
    ids = [all_ids[i] for i in np.flatnonzero(keep)]
    sig = None if pixel_sigma is None else np.asarray(pixel_sigma, np.float64)[keep]
    edges = None if pixel_edge_deg is None else np.asarray(pixel_edge_deg, np.float64)[keep]
    loo = leave_one_out_estimate(result.T_camera_lidar, np.asarray(points_lidar)[keep],
                                 np.asarray(pixels)[keep], camera, sig, ids, pixel_edge_deg=edges)
    old = result.quality
    new_reasons = [r for r in leave_one_out_reasons(loo, getattr(result, "mean_px", None)) if r not in old.reasons]
    status = old.status if (old.status == "unreliable" or not new_reasons) else "warning"
    reasons = _with_plane_advice(list(old.reasons), result, np.asarray(points_lidar)[keep], np.asarray(pixels)[keep],
                                 camera) + new_reasons
    result.quality = Quality(status, reasons, leave_one_out=loo)
    notes = [w for w in result.warnings if w not in old.reasons]
    result.warnings = reasons + notes
    return result
