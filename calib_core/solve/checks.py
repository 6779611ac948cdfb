"""Degeneracy checks for the pose solver.

Input checks raise :class:`calib_core.errors.CalibError` with a one-line
message naming the problem (and the pair indices, 0-based); weak but usable
geometry gives warning strings that the solver passes on in its result.
"""

from __future__ import annotations

import math

import numpy as np

from ..arrays import angle_between_rad, as_rows, as_transform
from ..errors import CalibError
from .kernels import pair_checks, pair_checks_frames
from .refine import PARAMETER_NAMES

__all__ = [
    "MIN_PAIRS",
    "validate_pairs",
    "validate_pixels",
    "validate_initial_T",
    "conditioning_warning",
]

MIN_PAIRS = 4
#: |norm - 1| above this is an error (not float rounding): the array is not bearings.
UNIT_TOLERANCE = 1e-3
#: Two laser points closer than this (metres) are the same point.
SAME_POINT_M = 1e-6
#: Two bearings closer than this (radians) are the same click.
SAME_BEARING_RAD = 1e-6
#: Second / first singular value of the centred laser points below this: collinear.
COLLINEAR_RATIO = 1e-3
#: Largest angle between two bearings: error below, warning below the second.
CONE_ERROR_DEG = 2.0
CONE_WARNING_DEG = 15.0
#: Condition number of the Jacobi-scaled J^T J above which we warn (well-spread
#: pairs give 10-1e3; laser points 1 % off a line give ~1e5).
CONDITION_WARNING = 1e4


def median(values: np.ndarray) -> float:
    """``np.median`` of a 1-D array (same value), without its overhead for a few elements."""
    v = np.sort(values)
    k = v.size // 2
    return float(v[k]) if v.size % 2 else float((v[k - 1] + v[k]) / 2)


def _largest_angle_deg(bearings: np.ndarray, cos_min_to_mean: float) -> float:
    """Largest angle between two unit bearings, degrees: exact below :data:`CONE_WARNING_DEG`,
    otherwise only known to be at least that.

    The angle ``alpha`` from the mean direction to the farthest bearing
    (``arccos(cos_min_to_mean)``) is a cheap bound: for that bearing ``b``,
    the mean of ``b . b_j`` over all ``j`` is ``|mean| cos(alpha) <=
    cos(alpha)`` when ``alpha <= 90`` deg, so some ``b_j`` is at least
    ``alpha`` away from ``b``; when ``alpha > 90`` deg that mean is negative,
    so some ``b_j`` is over 90 deg away.  Only a narrow cone, the case the
    checks are about, needs all pairs.
    """
    if math.isfinite(cos_min_to_mean):
        alpha_deg = math.degrees(math.acos(min(max(cos_min_to_mean, -1.0), 1.0)))
        if alpha_deg >= CONE_WARNING_DEG:
            return alpha_deg
    cos = bearings @ bearings.T
    i, j = np.unravel_index(np.argmin(cos), cos.shape)
    return float(np.degrees(angle_between_rad(bearings[i], bearings[j])))


def validate_pairs(points_lidar: object, bearings_camera: object, probe_step_rad: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray | None, np.ndarray | None]:
    """Check laser points and bearings; return clean float64 copies, warnings and, from the same compiled
    call, the bearings' frames and tangent probes.

    Parameters
    ----------
    points_lidar : (N, 3) array_like
        Laser points, lidar frame, metres.
    bearings_camera : (N, 3) array_like
        Unit bearings, camera frame.  Norms within 1e-3 of 1 are renormalised.
    probe_step_rad : float, optional
        Step (radians) of the tangent probes; None for the plain checks (no frames, no probes).

    Returns
    -------
    points_lidar : (N, 3) ndarray
    bearings_camera : (N, 3) ndarray
        Exactly unit.
    warnings : list of str
    frames : (N, 3, 3) ndarray or None
        Rows ``e1, e2, b`` of each unit bearing (:func:`.kernels.bearing_frames`).
    probes : (4N, 3) ndarray or None
        Directions ``b +- h e1``, ``b +- h e2`` (:func:`.kernels.tangent_probes`, ``h = probe_step_rad``).

    Raises
    ------
    CalibError
        Wrong shapes; fewer than 4 pairs; NaN or inf (names the pair); a zero
        or non-unit bearing; the same laser point or the same bearing in two
        pairs (names them); coincident or (nearly) collinear laser points; all
        bearings within 2 deg of each other.
    """
    points = np.ascontiguousarray(as_rows(points_lidar, "points_lidar", 3, single_row=False))
    bearings = np.ascontiguousarray(as_rows(bearings_camera, "bearings_camera", 3, single_row=False))
    if len(points) != len(bearings):
        raise CalibError(f"got {len(points)} laser points but {len(bearings)} bearings")
    n = len(points)
    if n < MIN_PAIRS:
        raise CalibError(f"need at least {MIN_PAIRS} pairs to solve the pose, got {n}")
    # One compiled pass computes every figure; the messages are chosen here, in order.
    frames = probes = None
    if probe_step_rad is None:
        bad_p, bad_b, zero_b, off_b, off_norm, bearings, sp0, sp1, sb0, sb1, sv0, sv1, cos_min = pair_checks(
            points, bearings, SAME_POINT_M, SAME_BEARING_RAD, UNIT_TOLERANCE)
    else:
        (bad_p, bad_b, zero_b, off_b, off_norm, bearings, sp0, sp1, sb0, sb1, sv0, sv1, cos_min, frames,
         probes) = pair_checks_frames(points, bearings, SAME_POINT_M, SAME_BEARING_RAD, UNIT_TOLERANCE,
                                      float(probe_step_rad))
    if bad_p >= 0:
        raise CalibError(f"pair {bad_p}: laser point is not finite (NaN or inf)")
    if bad_b >= 0:
        raise CalibError(f"pair {bad_b}: bearing is not finite (NaN or inf)")
    if zero_b >= 0:
        raise CalibError(f"pair {zero_b}: bearing has zero length")
    if off_b >= 0:
        raise CalibError(f"pair {off_b}: bearing is not a unit vector (norm {off_norm:.6g})")
    if sp0 >= 0:
        raise CalibError(f"pairs {sp0} and {sp1} use the same laser point")
    if sb0 >= 0:
        raise CalibError(f"pairs {sb0} and {sb1} use the same bearing (the same pixel clicked twice)")
    if sv1 < COLLINEAR_RATIO * sv0:
        raise CalibError(
            "the laser points are (nearly) collinear, so the rotation about their line is undetermined; "
            "pick points off that line"
        )

    warnings: list[str] = []
    max_angle_deg = _largest_angle_deg(bearings, cos_min)
    if max_angle_deg < CONE_ERROR_DEG:
        raise CalibError(
            f"all pairs lie within {max_angle_deg:.2g} deg of each other in the view; "
            "spread them over the whole image"
        )
    if max_angle_deg < CONE_WARNING_DEG:
        warnings.append(
            f"all pairs lie in a small part of the view (within {max_angle_deg:.1f} deg); spread them out"
        )
    return points, bearings, warnings, frames, probes


def validate_pixels(pixels: object, n: int) -> np.ndarray:
    """Check clicked pixels ``(N, 2)``; return a float64 copy."""
    px = as_rows(pixels, "pixels", 2, single_row=False)
    if len(px) != n:
        raise CalibError(f"got {len(px)} pixels for {n} pairs")
    if not np.isfinite(px).all():
        bad = np.nonzero(~np.all(np.isfinite(px), axis=1))[0]
        raise CalibError(f"pair {bad[0]}: pixel is not finite (NaN or inf)")
    return px


def validate_initial_T(T: object) -> np.ndarray:
    """Check a user-supplied initial ``T_camera_lidar`` and re-orthonormalise its rotation."""
    a = as_transform(T, "initial_T_camera_lidar")
    R = a[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-3 or np.linalg.det(R) <= 0:
        raise CalibError("initial_T_camera_lidar does not hold a rotation matrix")
    U, _, Vt = np.linalg.svd(R)
    out = np.eye(4)
    out[:3, :3] = U @ Vt
    out[:3, 3] = a[:3, 3]
    return out


def conditioning_warning(JtJ: np.ndarray) -> str | None:
    """A warning naming poorly constrained pose parameters, or None.

    ``J^T J`` is scaled to unit diagonal first (rotations in radians and
    translations in metres are not comparable); if its condition number
    exceeds :data:`CONDITION_WARNING`, the parameters with a large share in
    the weakest eigenvector are named.
    """
    d = np.sqrt(np.diag(JtJ))
    if not (np.all(np.isfinite(JtJ)) and np.all(d > 0)):
        weak = [PARAMETER_NAMES[k] for k in np.nonzero(~(d > 0))[0]] or list(PARAMETER_NAMES)
        return f"the pairs do not constrain {', '.join(weak)}"
    eigval, eigvec = np.linalg.eigh(JtJ / d[:, None] / d[None, :])
    cond = eigval[-1] / max(eigval[0], 1e-300)
    if cond <= CONDITION_WARNING:
        return None
    v = np.abs(eigvec[:, 0])
    weak = [PARAMETER_NAMES[k] for k in np.argsort(-v) if v[k] >= 0.3]
    return (
        f"the pairs barely constrain {' + '.join(weak)} (condition number {cond:.1e}); "
        "add pairs at other depths and directions"
    )
