"""How far a calibration can be trusted: ``ok``, ``warning`` or ``unreliable``, with one line per reason.

``unreliable`` means the pose must not be used: too few pairs agree on it,
at most half of them do, or its uncertainty is undefined or huge.
``warning`` means it is usable but something deserves a look (pairs left out
as outliers, weak geometry, residuals above the expected click noise).
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
    if m < FEW_INLIERS:
        weak.append(f"only {m} pairs in the fit: too few to find a wrong pair among them; add pairs")
    return bad, weak
