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
    """
    bad: list[str] = []
    weak: list[str] = []
    m = int(n_inliers)
    s_rot = float(rotation_sigma_deg)
    # Plain floats: this runs once per solve, where numpy's per-call overhead would dominate.
    s_ts = [float(v) for v in sigma_translation_m]
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
    sv0, sv2 = float(singular_values[0]), float(singular_values[2])
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
    R = np.asarray(R_camera_lidar, dtype=np.float64)
    notes: list[str] = []
    cos_pitch = math.hypot(R[0, 0], R[1, 0])
    pitch = math.degrees(math.atan2(-R[2, 0], cos_pitch))
    if 90.0 - abs(pitch) < NEAR_SINGULAR_DEG:
        notes.append(
            f"pitch is {pitch:.1f} deg, within {NEAR_SINGULAR_DEG:g} deg of +-90 (near gimbal lock): roll, yaw and "
            f"their sigmas are ill-conditioned ({_inflation(cos_pitch)} the rotation's own uncertainty); read the "
            "viewing direction (azimuth, elevation, roll about the optical axis), the matrix or the quaternion"
        )
    # The optical axis in lidar coordinates is R's last row (as in viewing_direction); plain floats, once per solve.
    cos_el = math.hypot(R[2, 0], R[2, 1])
    elevation = math.degrees(math.atan2(R[2, 2], cos_el))
    if 90.0 - abs(elevation) < NEAR_SINGULAR_DEG:
        notes.append(
            f"the camera looks {90.0 - abs(elevation):.1f} deg from lidar {'+' if elevation > 0 else '-'}z:"
            f" its azimuth, roll about the optical axis and their sigmas are ill-conditioned ({_inflation(cos_el)} the "
            "rotation's own uncertainty); read roll/pitch/yaw, the matrix or the quaternion"
        )
    return notes
