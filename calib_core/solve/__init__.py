"""Extrinsic pose from laser-point / camera-bearing pairs (paper Sec. IV).

Pipeline of :func:`solve_extrinsics`:

1. :mod:`.checks` rejects degenerate input (CalibError) and flags weak
   geometry (warnings).
2. :mod:`.bearing_pnp` finds an initial pose: Quan & Lan's linear N-point
   depths + a rigid fit (:mod:`.rigid`), as in the paper, and Grunert P3P on
   many triples as a robust fallback; the one with the smaller angular cost
   wins.
3. :mod:`.refine` runs Levenberg-Marquardt on the geodesic angle (eq. 7) or,
   for comparisons, on the pixel error (eq. 6), and computes the covariance
   ``sigma^2 (J^T J)^-1`` at the optimum.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import CalibError
from .bearing_pnp import angular_errors_rad, initial_pose
from .checks import (
    MIN_PAIRS,
    conditioning_warning,
    outlier_indices,
    validate_initial_T,
    validate_pairs,
    validate_pixels,
)
from .refine import (
    PARAMETER_NAMES,
    PoseUncertainty,
    angular_at_pose,
    bearing_frames,
    covariance_from_jacobian,
    pixel_jacobian,
    pixel_residuals,
    pose_covariance,
    refine_angular,
    refine_pose,
)

__all__ = [
    "CalibrationResult",
    "solve_extrinsics",
    "pose_covariance",
    "PoseUncertainty",
    "PARAMETER_NAMES",
    "MIN_PAIRS",
]


@dataclass
class CalibrationResult:
    """Outcome of :func:`solve_extrinsics`.

    Attributes
    ----------
    T_camera_lidar : (4, 4) ndarray
        Estimated pose, ``X_camera = T_camera_lidar @ X_lidar`` (metres).
    initial_T_camera_lidar : (4, 4) ndarray
        The starting pose of the refinement.
    covariance_6x6 : (6, 6) ndarray
        Covariance of ``(delta, t)``: ``delta`` (rad) is the rotation vector of
        ``R_true @ R_hat^T`` (about the camera axes), ``t`` (m) the
        translation; order :data:`PARAMETER_NAMES`.  inf where undetermined.
    sigma_translation_m : (3,) ndarray
        1-sigma of the translation, metres.
    sigma_rpy_deg : (3,) ndarray
        1-sigma of roll, pitch, yaw, degrees (as in the paper's Table I).
    residual_deg : (N,) ndarray
        Angle between each clicked bearing and its reprojected laser point.
    residual_px : (N,) ndarray
        Pixel distance between each clicked pixel and the projected laser
        point; NaN where the point does not project into the image or there is
        no camera.
    mean_px, std_px, mean_deg, std_deg : float
        Mean and standard deviation of the finite residuals (NaN if none).
    n_pairs : int
    warnings : list of str
        Weak geometry, outliers, poorly constrained parameters.
    outliers : list of int
        Indices of pairs with outlying angular residuals (rule of
        :func:`calib_core.solve.checks.outlier_indices`, applied after
        refitting without the worst pairs so that one bad click does not
        implicate its neighbours).  They are reported, not removed:
        ``T_camera_lidar`` uses all pairs.
    iterations : int
        Levenberg-Marquardt iterations (Jacobian evaluations).
    cost_name : str
        ``"angular"`` (eq. 7) or ``"pixel"`` (eq. 6).
    initial_method : str
        ``"quan_lan"``, ``"p3p"`` or ``"given"``.
    """

    T_camera_lidar: np.ndarray
    initial_T_camera_lidar: np.ndarray
    covariance_6x6: np.ndarray
    sigma_translation_m: np.ndarray
    sigma_rpy_deg: np.ndarray
    residual_deg: np.ndarray
    residual_px: np.ndarray
    mean_px: float
    std_px: float
    mean_deg: float
    std_deg: float
    n_pairs: int
    warnings: list[str] = field(default_factory=list)
    outliers: list[int] = field(default_factory=list)
    iterations: int = 0
    cost_name: str = "angular"
    initial_method: str = ""


def _mean_std(values: np.ndarray) -> tuple[float, float]:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return float("nan"), float("nan")
    return float(finite.mean()), float(finite.std())


def _pixel_errors(camera: Any, T: np.ndarray, points_lidar: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    projected, valid = camera.project(points_lidar @ T[:3, :3].T + T[:3, 3])
    err = np.linalg.norm(np.asarray(projected, dtype=np.float64) - pixels, axis=1)
    return np.where(np.asarray(valid, dtype=bool) & np.isfinite(err), err, np.nan)


def _find_outliers(
    T: np.ndarray, points: np.ndarray, bearings: np.ndarray, residual_deg: np.ndarray, frames: np.ndarray
) -> list[int]:
    """Outlying pairs, robust to the pull a bad pair has on the least-squares fit.

    A bad click drags the fit, so good pairs near it get large residuals too.
    Greedy backward elimination: while the rule of
    :func:`~calib_core.solve.checks.outlier_indices` flags a pair, drop the
    worst one and refit on the rest; finally judge every pair against the fit
    and the residual statistics of the pairs kept.  Keeps at least 5 pairs.
    """
    if not outlier_indices(residual_deg):
        return []
    keep = np.ones(len(points), dtype=bool)
    r = residual_deg
    while keep.sum() > MIN_PAIRS + 1:
        flagged = [i for i in outlier_indices(r, reference_deg=r[keep]) if keep[i]]
        if not flagged:
            break
        keep[max(flagged, key=lambda i: r[i])] = False
        try:
            T, _ = refine_angular(T, points[keep], frames[keep])
        except CalibError:
            break
        r = np.degrees(angular_errors_rad(T, points, bearings))
    return outlier_indices(r, reference_deg=r[keep])


def solve_extrinsics(
    points_lidar: np.ndarray,
    bearings_camera: np.ndarray,
    *,
    camera: Any = None,
    pixels: np.ndarray | None = None,
    cost: str = "angular",
    initial_T_camera_lidar: np.ndarray | None = None,
    noise_rad: float | None = None,
) -> CalibrationResult:
    """Estimate ``T_camera_lidar`` from n >= 4 laser-point / bearing pairs.

    Parameters
    ----------
    points_lidar : (N, 3) array_like
        Laser points in the lidar frame, metres.
    bearings_camera : (N, 3) array_like
        Unit bearings of the clicked pixels in the OpenCV camera frame; any
        direction on the sphere (also more than 90 deg off axis).
    camera : CameraModel, optional
        Needed for pixel residuals and for ``cost="pixel"``.
    pixels : (N, 2) array_like, optional
        Clicked ``(u, v)`` pixels.  With a camera but without pixels, the
        pixels of the bearings (``camera.project(bearings)``) are used.
    cost : {"angular", "pixel"}
        ``"angular"``: geodesic angle, paper eq. 7 (the method).  ``"pixel"``:
        reprojection error, eq. 6, for benchmarks; it starts from the angular
        optimum.
    initial_T_camera_lidar : (4, 4) array_like, optional
        Start the refinement here instead of the closed-form initial pose.
    noise_rad : float, optional
        Known click noise (std of the bearing error along each tangent
        direction, radians).  The covariance is then ``noise_rad^2 (J^T J)^-1``
        (the Cramer-Rao bound); otherwise ``sigma^2`` is the residual variance
        ``SSR / (2N - 6)``.  Used with the angular cost only.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    CalibError
        Degenerate or malformed input (see
        :func:`calib_core.solve.checks.validate_pairs`), a missing camera or
        pixels for ``cost="pixel"``, or a failed refinement (with the reason).
    """
    if cost not in ("angular", "pixel"):
        raise CalibError(f"unknown cost {cost!r}; use 'angular' or 'pixel'")
    points, bearings, warnings = validate_pairs(points_lidar, bearings_camera)
    n = len(points)
    if noise_rad is not None and not (np.isfinite(noise_rad) and noise_rad > 0):
        raise CalibError(f"noise_rad must be a positive number, got {noise_rad!r}")
    if pixels is not None:
        pixels = validate_pixels(pixels, n)
    elif camera is not None:
        projected, valid = camera.project(bearings)
        pixels = np.where(np.asarray(valid, dtype=bool)[:, None], np.asarray(projected, dtype=np.float64), np.nan)
    if cost == "pixel" and (camera is None or pixels is None):
        raise CalibError("cost='pixel' needs a camera and the clicked pixels")
    if cost == "pixel" and not np.all(np.isfinite(pixels)):
        bad = np.nonzero(~np.all(np.isfinite(pixels), axis=1))[0]
        raise CalibError(f"cost='pixel': the bearings of pairs {bad.tolist()} do not map to pixels of this camera")

    # 1. Initial pose.
    if initial_T_camera_lidar is not None:
        T_init = validate_initial_T(initial_T_camera_lidar)
        method = "given"
    else:
        T_init, method, init_cost = initial_pose(points, bearings)
        if not np.isfinite(init_cost):
            raise CalibError("no initial pose found from these pairs (all closed-form solutions failed)")

    # 2. Refinement: always on the angle; the pixel cost continues from there.
    frames = bearing_frames(bearings)  # tangent bases, computed once per solve
    T, iterations = refine_angular(T_init, points, frames)
    if cost == "pixel":
        T, more = refine_pose(T, points, bearings, cost="pixel", camera=camera, pixels=pixels)
        iterations += more

    # 3. Covariance at the optimum (parameters: delta about R_hat, t).
    dof = 2 * n - 6
    J, r, angle_rad = angular_at_pose(T, points, frames)
    if cost == "angular":
        if noise_rad is not None:
            sigma = float(noise_rad)
        else:
            sigma = float(np.sqrt(np.sum(r**2) / dof))
    else:
        x_opt = np.concatenate([np.zeros(3), T[:3, 3]])
        J = pixel_jacobian(x_opt, T[:3, :3], points, pixels, camera)
        r = pixel_residuals(x_opt, T[:3, :3], points, pixels, camera)
        sigma = float(np.sqrt(np.nansum(r**2) / dof))
        if noise_rad is not None:
            warnings.append("noise_rad is ignored with cost='pixel'; sigma comes from the pixel residuals")
    uncertainty = covariance_from_jacobian(np.where(np.isfinite(J), J, 0.0), sigma, T[:3, :3])
    weak = conditioning_warning(uncertainty.JtJ)
    if weak:
        warnings.append(weak)

    # 4. Report.  The log map's norm is the geodesic angle (atan2 form, as angular_errors_rad).
    residual_deg = np.degrees(angle_rad)
    if camera is not None and pixels is not None:
        residual_px = _pixel_errors(camera, T, points, pixels)
        off = np.nonzero(~np.isfinite(residual_px))[0]
        if off.size:
            warnings.append(
                f"pairs {off.tolist()} do not reproject into the image; their pixel error is NaN"
            )
    else:
        residual_px = np.full(n, np.nan)
    mean_deg, std_deg = _mean_std(residual_deg)
    mean_px, std_px = _mean_std(residual_px)
    outliers = _find_outliers(T, points, bearings, residual_deg, frames)
    if outliers:
        worst = ", ".join(f"{residual_deg[i]:.2f}" for i in outliers[:5])
        warnings.append(f"pairs {outliers} have large residuals ({worst} deg); check these clicks")
    pitch_deg = np.degrees(np.arcsin(np.clip(-T[2, 0], -1.0, 1.0)))
    if abs(pitch_deg) > 89.0:
        warnings.append(
            "pitch is within 1 deg of +-90 deg (gimbal lock): roll, yaw and their sigmas are ill-defined; "
            "use the matrix or quaternion"
        )
    return CalibrationResult(
        T_camera_lidar=T,
        initial_T_camera_lidar=T_init,
        covariance_6x6=uncertainty.covariance_6x6,
        sigma_translation_m=uncertainty.sigma_translation_m,
        sigma_rpy_deg=uncertainty.sigma_rpy_deg,
        residual_deg=residual_deg,
        residual_px=residual_px,
        mean_px=mean_px,
        std_px=std_px,
        mean_deg=mean_deg,
        std_deg=std_deg,
        n_pairs=n,
        warnings=warnings,
        outliers=outliers,
        iterations=iterations,
        cost_name=cost,
        initial_method=method,
    )
