"""Refinement of ``T_camera_lidar`` and its covariance.

Angular cost (paper eq. 7): ``0.5 * sum_i |W_i r_i|^2`` where ``r_i`` is the
2-vector log map of the reprojected bearing ``q_i = normalize(R p_i + t)``
into the tangent plane of the clicked bearing ``b_i``,

    r_i = theta_i / sin(theta_i) * E_i q_i,   theta_i = atan2(|b_i x q_i|, b_i . q_i),

where the rows of ``E_i`` (2x3) are an orthonormal basis of that tangent plane.
``|r_i| = theta_i`` exactly, so with ``W_i = I`` the sum is the paper's cost;
each pair gives two equations, and, unlike ``arccos``, ``r_i`` is smooth at
``theta = 0``.  ``W_i`` whitens the residual (:mod:`calib_core.solve.whiten`).
The residual, its Jacobian and the Levenberg-Marquardt loop are compiled
(:mod:`calib_core.solve.kernels`); this module wraps them.

Pixel cost (paper eq. 6, for comparisons): ``r_i = project(R p_i + t) - m_i``,
minimised with scipy's MINPACK LM (the camera models are Python).

Pose parameters: ``x = (delta, t)`` with ``R = exp([delta]_x) R0`` (rotation
vector ``delta`` in radians, a perturbation about the camera axes of a fixed
reference rotation ``R0``) and translation ``t`` in metres.  The covariance is
reported in these coordinates at the optimum (``R0 = R_hat``, ``delta = 0``).
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import numpy as np

from ..errors import CalibError
from .kernels import (
    bearing_frames,
    covariance,
    lm_refine,
    normal_equations,
    rpy_sigmas,
    so3_exp,
)

__all__ = [
    "PARAMETER_NAMES",
    "PoseUncertainty",
    "pixel_residuals",
    "pixel_jacobian",
    "refine_pose",
    "refine_angular",
    "lm_failure",
    "pose_covariance",
    "LM_MAX_ITER",
]

#: Levenberg-Marquardt iterations before the solve gives up.
LM_MAX_ITER = 200

#: Names of the 6 pose parameters, in the order of the Jacobian columns and of
#: ``covariance_6x6``.
PARAMETER_NAMES = (
    "rotation about camera x",
    "rotation about camera y",
    "rotation about camera z",
    "translation x",
    "translation y",
    "translation z",
)

# Residual used where the camera cannot project a point during the pixel LM
# (pixels); large enough that LM rejects the step.
_UNPROJECTABLE_PX = 1e4


def _identity_W(n: int) -> np.ndarray:
    return np.broadcast_to(np.eye(2), (n, 2, 2)).copy()


def _pose(x: np.ndarray, R0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return so3_exp(np.ascontiguousarray(x[:3], dtype=np.float64)) @ R0, x[3:]


def pixel_residuals(
    x: np.ndarray, R0: np.ndarray, points_lidar: np.ndarray, pixels: np.ndarray, camera: Any
) -> np.ndarray:
    """Pixel residuals ``(N, 2)`` ``project(R p + t) - pixels``; NaN where not projectable."""
    R, t = _pose(x, R0)
    projected, _ = camera.project(points_lidar @ R.T + t)
    return np.asarray(projected, dtype=np.float64) - pixels


def pixel_jacobian(
    x: np.ndarray, R0: np.ndarray, points_lidar: np.ndarray, pixels: np.ndarray, camera: Any, step: float = 1e-6
) -> np.ndarray:
    """Central-difference Jacobian ``(2N, 6)`` of :func:`pixel_residuals`.

    ``step`` is in radians for ``delta`` and metres for ``t``; the truncation
    error is O(step^2), far below pixel precision.
    """
    cols = []
    for k in range(6):  # six parameters
        dx = np.zeros(6)
        dx[k] = step
        plus = pixel_residuals(x + dx, R0, points_lidar, pixels, camera)
        minus = pixel_residuals(x - dx, R0, points_lidar, pixels, camera)
        cols.append(((plus - minus) / (2 * step)).ravel())
    return np.stack(cols, axis=1)


def least_squares(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.least_squares``, imported on first use (only the pixel cost needs it; importing
    ``scipy.optimize`` would cost the app's start-up 0.2-0.4 s)."""
    from scipy.optimize import least_squares as scipy_least_squares

    return scipy_least_squares(*args, **kwargs)


def _run_lm(fun: Callable, jac: Callable, x0: np.ndarray, what: str) -> Any:
    try:
        sol = least_squares(
            fun, x0, jac=jac, method="lm", x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=2000
        )
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise CalibError(f"Levenberg-Marquardt ({what}) failed: {exc}") from exc
    if sol.status <= 0:
        raise CalibError(f"Levenberg-Marquardt ({what}) failed: {sol.message}")
    if not np.all(np.isfinite(sol.x)) or not np.isfinite(sol.cost):
        raise CalibError(f"Levenberg-Marquardt ({what}) failed: the estimate is not finite")
    return sol


def refine_pose(
    T_initial: np.ndarray,
    points_lidar: np.ndarray,
    bearings_camera: np.ndarray,
    *,
    cost: str = "angular",
    camera: Any = None,
    pixels: np.ndarray | None = None,
    pixel_sigma: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Minimise the angular (eq. 7) or pixel (eq. 6) cost from ``T_initial``.

    Parameters
    ----------
    T_initial : (4, 4) ndarray
        Starting ``T_camera_lidar``.
    points_lidar : (N, 3) ndarray
        Laser points, lidar frame, metres.
    bearings_camera : (N, 3) ndarray
        Unit bearings, camera frame.
    cost : {"angular", "pixel"}
        ``"pixel"`` needs ``camera`` and ``pixels`` ``(N, 2)``.
    camera : CameraModel, optional
    pixels : (N, 2) ndarray, optional
        Clicked ``(u, v)`` pixels.
    pixel_sigma : (N,) ndarray, optional
        1-sigma of each click, px: the pixel residuals are divided by it.
        (The angular cost here is unwhitened; :func:`calib_core.solve.solve_extrinsics`
        whitens it.)

    Returns
    -------
    T_camera_lidar : (4, 4) ndarray
    iterations : int
        Jacobian evaluations (LM iterations).

    Raises
    ------
    CalibError
        If LM fails (the message carries the reason) or, for the pixel cost, a
        point cannot be projected at the start.
    """
    if cost == "angular":
        frames = bearing_frames(np.ascontiguousarray(bearings_camera, dtype=np.float64))
        return refine_angular(T_initial, points_lidar, frames)
    R0 = T_initial[:3, :3]
    x0 = np.concatenate([np.zeros(3), T_initial[:3, 3]])
    if cost == "pixel":
        start = pixel_residuals(x0, R0, points_lidar, pixels, camera)
        bad = np.nonzero(~np.all(np.isfinite(start), axis=1))[0]
        if bad.size:
            raise CalibError(
                f"pixel cost: the camera cannot project the laser points of pairs {bad.tolist()} "
                "at the initial pose"
            )

        inv_s = 1.0 if pixel_sigma is None else np.repeat(1.0 / np.asarray(pixel_sigma, dtype=np.float64), 2)

        def fun(x: np.ndarray) -> np.ndarray:
            r = pixel_residuals(x, R0, points_lidar, pixels, camera).ravel() * inv_s
            return np.where(np.isfinite(r), r, _UNPROJECTABLE_PX)

        def jac(x: np.ndarray) -> np.ndarray:
            J = pixel_jacobian(x, R0, points_lidar, pixels, camera) * (inv_s if np.ndim(inv_s) == 0 else inv_s[:, None])
            return np.where(np.isfinite(J), J, 0.0)

    else:
        raise CalibError(f"unknown cost {cost!r}; use 'angular' or 'pixel'")
    sol = _run_lm(fun, jac, x0, cost)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = _pose(sol.x, R0)
    return T, int(sol.njev) if sol.njev is not None else int(sol.nfev)


def refine_angular(
    T_initial: np.ndarray, points_lidar: np.ndarray, frames: np.ndarray, W: np.ndarray | None = None
) -> tuple[np.ndarray, int]:
    """:func:`refine_pose` with the (whitened) angular cost, given the bearing frames.

    Parameters
    ----------
    T_initial : (4, 4) ndarray
        Starting ``T_camera_lidar``.
    points_lidar : (N, 3) ndarray
        Laser points, lidar frame, metres.
    frames : (N, 3, 3) ndarray
        Rows ``e1, e2, b`` per bearing (:func:`.kernels.bearing_frames`), so a caller
        that refines several times computes them once.
    W : (N, 2, 2) ndarray, optional
        Whitening matrices; identity (paper eq. 7 as printed) when omitted.

    Raises
    ------
    CalibError
        The normal equations are singular or the cost is not finite.
    """
    P = np.ascontiguousarray(points_lidar, dtype=np.float64)
    W = _identity_W(len(P)) if W is None else np.ascontiguousarray(W, dtype=np.float64)
    T0 = np.asarray(T_initial, dtype=np.float64)
    R, t, iterations, status, _ = lm_refine(
        np.ascontiguousarray(T0[:3, :3]), np.ascontiguousarray(T0[:3, 3]), P, frames, W, LM_MAX_ITER
    )
    failure = lm_failure(status, R, t)
    if failure:
        raise CalibError(failure)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T, int(iterations)


def lm_failure(status: int, R: np.ndarray, t: np.ndarray) -> str | None:
    """Why the angular LM (:func:`.kernels.lm_refine`, status as there) gave no pose, or None."""
    if status == -2 or not math.isfinite(float(R.sum()) + float(t.sum())):
        return "Levenberg-Marquardt (angular) failed: the cost is not finite at the initial pose"
    if status == -1:
        return "Levenberg-Marquardt (angular) failed: the normal equations are singular (degenerate pairs)"
    return None


class PoseUncertainty(NamedTuple):
    """Covariance of a pose estimate and the derived 1-sigma values.

    Attributes
    ----------
    covariance_6x6 : (6, 6) ndarray
        Covariance of ``(delta, t)`` (rad, m; order :data:`PARAMETER_NAMES`),
        ``delta`` being the rotation vector of ``R_true R_hat^T`` (camera axes).
        Entries are inf where ``J^T J`` is singular.
    sigma_translation_m : (3,) ndarray
        Standard deviation of ``t`` (metres).
    sigma_rpy_deg : (3,) ndarray
        Standard deviation of roll, pitch, yaw (degrees), first-order
        propagation through ``d(roll, pitch, yaw) / d delta`` (:func:`.kernels.rpy_sigmas`).
    JtJ : (6, 6) ndarray
        ``J^T J`` at the estimate (unit noise).
    """

    covariance_6x6: np.ndarray
    sigma_translation_m: np.ndarray
    sigma_rpy_deg: np.ndarray
    JtJ: np.ndarray


def pose_covariance(T_camera_lidar: np.ndarray, points_lidar: np.ndarray, noise_rad: float) -> PoseUncertainty:
    """Covariance of the angular-cost estimate for isotropic bearing noise.

    The Jacobian is taken at zero residual (the bearings are the exact
    directions of the transformed laser points), so with the true pose and the
    true click noise this is the first-order Cramer-Rao bound.

    Parameters
    ----------
    T_camera_lidar : (4, 4) ndarray
        Pose at which to linearise.
    points_lidar : (N, 3) ndarray
        Laser points, lidar frame, metres.
    noise_rad : float
        Standard deviation of the bearing error along each of the two
        tangent directions, radians.
    """
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    points = np.ascontiguousarray(points_lidar, dtype=np.float64)
    points_camera = points @ T[:3, :3].T + T[:3, 3]
    bearings = points_camera / np.linalg.norm(points_camera, axis=1, keepdims=True)
    frames = bearing_frames(bearings)
    R, t = np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])
    H, _, _ = normal_equations(R, t, points, frames, _identity_W(len(points)))
    cov, _ = covariance(H, float(noise_rad))
    sigma_t, sigma_rpy = rpy_sigmas(R, cov)
    return PoseUncertainty(cov, sigma_t, sigma_rpy, H)
