"""Levenberg-Marquardt refinement of ``T_camera_lidar`` and its covariance.

Angular cost (paper eq. 7): ``0.5 * sum_i angle(b_i, R p_i + t)^2``.  The
residual of pair i is the 2-vector log map of the reprojected bearing
``q_i = normalize(R p_i + t)`` into the tangent plane of the clicked bearing
``b_i``,

    r_i = theta_i / sin(theta_i) * E_i q_i,   theta_i = atan2(|b_i x q_i|, b_i . q_i),

where the rows of ``E_i`` (2x3) are an orthonormal basis of that tangent plane.
``|r_i| = theta_i`` exactly, so ``sum |r_i|^2`` is the paper's cost, each pair
gives two equations, and, unlike ``arccos``, ``r_i`` is smooth at
``theta = 0``.

Pixel cost (paper eq. 6): ``r_i = project(R p_i + t) - m_i``.

Pose parameters: ``x = (delta, t)`` with ``R = exp([delta]_x) R0`` (rotation
vector ``delta`` in radians, a perturbation about the camera axes of a fixed
reference rotation ``R0``) and translation ``t`` in metres.  The covariance is
reported in these coordinates at the optimum (``R0 = R_hat``, ``delta = 0``).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from ..errors import CalibError

__all__ = [
    "PARAMETER_NAMES",
    "PoseUncertainty",
    "tangent_basis",
    "log_map_residuals",
    "angular_jacobian",
    "pixel_residuals",
    "pixel_jacobian",
    "refine_pose",
    "rpy_jacobian",
    "pose_covariance",
    "covariance_from_jacobian",
]

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


def _skew(v: np.ndarray) -> np.ndarray:
    """``[v]_x`` for (..., 3) vectors."""
    z = np.zeros(v.shape[:-1])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            np.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            np.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


def _left_jacobian_so3(phi: np.ndarray) -> np.ndarray:
    """``J_l(phi)`` with ``exp([phi + dphi]) = exp([J_l dphi]) exp([phi])`` to first order."""
    theta = float(np.linalg.norm(phi))
    K = _skew(phi)
    if theta < 1e-4:
        a, b = 0.5 - theta**2 / 24, 1.0 / 6 - theta**2 / 120
    else:
        a = (1 - np.cos(theta)) / theta**2
        b = (theta - np.sin(theta)) / theta**3
    return np.eye(3) + a * K + b * (K @ K)


def tangent_basis(bearings_camera: np.ndarray) -> np.ndarray:
    """Orthonormal tangent-plane bases of unit bearings.

    Parameters
    ----------
    bearings_camera : (N, 3) ndarray
        Unit vectors.

    Returns
    -------
    (N, 2, 3) ndarray
        Rows ``e1, e2`` with ``(e1, e2, b)`` a right-handed orthonormal frame.
    """
    b = np.asarray(bearings_camera, dtype=np.float64)
    # Cross with the coordinate axis least aligned with b (never parallel).
    axis = np.eye(3)[np.argmin(np.abs(b), axis=1)]
    e1 = np.cross(b, axis)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(b, e1)
    return np.stack([e1, e2], axis=1)


def _log_map_parts(points_camera: np.ndarray, bearings_camera: np.ndarray, E: np.ndarray):
    norm = np.linalg.norm(points_camera, axis=1, keepdims=True)
    q = points_camera / np.where(norm > 0, norm, 1.0)
    w = np.einsum("nij,nj->ni", E, q)  # components of q in the tangent plane
    s = np.linalg.norm(w, axis=1)
    c = np.sum(bearings_camera * q, axis=1)
    theta = np.arctan2(s, c)
    small = theta < 1e-3
    s_safe = np.where(small, 1.0, s)
    # g = theta / sin(theta); h = (cos sin - theta) / sin^3 (series near 0).
    g = np.where(small, 1 + theta**2 / 6 + 7 * theta**4 / 360, theta / s_safe)
    h = np.where(small, -2.0 / 3 - theta**2 / 5, (c * s_safe - theta) / s_safe**3)
    return q, norm[:, 0], w, g, h


def log_map_residuals(points_camera: np.ndarray, bearings_camera: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Log-map residuals ``(N, 2)`` of points (camera frame) against bearings.

    Each row has norm equal to the geodesic angle (radians) between the
    bearing and the direction of the point.  ``E`` comes from
    :func:`tangent_basis` of the same bearings.
    """
    _, _, w, g, _ = _log_map_parts(points_camera, bearings_camera, E)
    return g[:, None] * w


def _d_residual_d_point(points_camera: np.ndarray, bearings_camera: np.ndarray, E: np.ndarray) -> np.ndarray:
    """``d r_i / d P_i`` (N, 2, 3) of :func:`log_map_residuals`."""
    q, norm, w, g, h = _log_map_parts(points_camera, bearings_camera, E)
    # dr/dq = g E + w (h w^T E - b^T); only its part orthogonal to q matters.
    wE = np.einsum("ni,nij->nj", w, E)
    dr_dq = g[:, None, None] * E + w[:, :, None] * (h[:, None] * wE - bearings_camera)[:, None, :]
    dq_dP = (np.eye(3) - q[:, :, None] * q[:, None, :]) / norm[:, None, None]
    return dr_dq @ dq_dP


def _pose(x: np.ndarray, R0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return Rotation.from_rotvec(x[:3]).as_matrix() @ R0, x[3:]


def angular_jacobian(
    x: np.ndarray, R0: np.ndarray, points_lidar: np.ndarray, bearings_camera: np.ndarray, E: np.ndarray
) -> np.ndarray:
    """Analytic Jacobian ``(2N, 6)`` of the log-map residuals w.r.t. ``x = (delta, t)``."""
    R, t = _pose(x, R0)
    rotated = points_lidar @ R.T
    dr_dP = _d_residual_d_point(rotated + t, bearings_camera, E)
    # d(exp(delta) R0 p) / d delta = -[R p]_x J_l(delta);  dP/dt = I.
    dP_ddelta = -_skew(rotated) @ _left_jacobian_so3(x[:3])
    J = np.concatenate([dr_dP @ dP_ddelta, dr_dP], axis=2)
    return J.reshape(-1, 6)


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
    R0 = T_initial[:3, :3]
    x0 = np.concatenate([np.zeros(3), T_initial[:3, 3]])
    if cost == "angular":
        E = tangent_basis(bearings_camera)

        def fun(x: np.ndarray) -> np.ndarray:
            R, t = _pose(x, R0)
            return log_map_residuals(points_lidar @ R.T + t, bearings_camera, E).ravel()

        def jac(x: np.ndarray) -> np.ndarray:
            return angular_jacobian(x, R0, points_lidar, bearings_camera, E)

    elif cost == "pixel":
        start = pixel_residuals(x0, R0, points_lidar, pixels, camera)
        bad = np.nonzero(~np.all(np.isfinite(start), axis=1))[0]
        if bad.size:
            raise CalibError(
                f"pixel cost: the camera cannot project the laser points of pairs {bad.tolist()} "
                "at the initial pose"
            )

        def fun(x: np.ndarray) -> np.ndarray:
            r = pixel_residuals(x, R0, points_lidar, pixels, camera).ravel()
            return np.where(np.isfinite(r), r, _UNPROJECTABLE_PX)

        def jac(x: np.ndarray) -> np.ndarray:
            J = pixel_jacobian(x, R0, points_lidar, pixels, camera)
            return np.where(np.isfinite(J), J, 0.0)

    else:
        raise CalibError(f"unknown cost {cost!r}; use 'angular' or 'pixel'")
    sol = _run_lm(fun, jac, x0, cost)
    R, t = _pose(sol.x, R0)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    iterations = int(sol.njev) if sol.njev is not None else int(sol.nfev)
    return T, iterations


def rpy_jacobian(R: np.ndarray) -> np.ndarray:
    """``d(roll, pitch, yaw) / d delta`` (3x3, rad/rad) at ``R = Rz Ry Rx``.

    For a left perturbation ``exp([delta]) R`` the angular velocity is
    ``delta_dot = yaw_dot e_z + pitch_dot Rz e_y + roll_dot Rz Ry e_x``, i.e.
    ``delta = M (roll, pitch, yaw)`` with those three columns; the answer is
    ``M^-1``, singular at pitch = +-90 deg (gimbal lock).
    """
    roll, pitch, yaw = Rotation.from_matrix(R).as_euler("xyz")
    Rz = Rotation.from_euler("z", yaw).as_matrix()
    Ry = Rotation.from_euler("y", pitch).as_matrix()
    M = np.stack([Rz @ Ry @ np.array([1.0, 0, 0]), Rz @ np.array([0, 1.0, 0]), np.array([0, 0, 1.0])], axis=1)
    if abs(np.cos(pitch)) < 1e-9:
        return np.full((3, 3), np.inf)
    return np.linalg.inv(M)


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
        propagation through :func:`rpy_jacobian`.
    JtJ : (6, 6) ndarray
        ``J^T J`` at the estimate (unit noise).
    """

    covariance_6x6: np.ndarray
    sigma_translation_m: np.ndarray
    sigma_rpy_deg: np.ndarray
    JtJ: np.ndarray


def covariance_from_jacobian(J: np.ndarray, sigma: float, R: np.ndarray) -> PoseUncertainty:
    """``sigma^2 (J^T J)^-1`` and the sigmas of ``t`` and of roll/pitch/yaw.

    Parameters
    ----------
    J : (2N, 6) ndarray
        Jacobian of the residuals w.r.t. ``(delta, t)`` at the estimate.
    sigma : float
        Standard deviation of one residual component (radians for the angular
        cost, pixels for the pixel cost).
    R : (3, 3) ndarray
        Estimated rotation (for the roll/pitch/yaw Jacobian).
    """
    JtJ = J.T @ J
    # Inverse of the Jacobi-scaled matrix: rotations (rad) and translations (m)
    # differ in scale by orders of magnitude.
    d = np.sqrt(np.diag(JtJ))
    if np.all(d > 0) and np.all(np.isfinite(JtJ)):
        scaled = JtJ / d[:, None] / d[None, :]
        eigval, eigvec = np.linalg.eigh(scaled)
        if eigval[0] > 1e-14 * eigval[-1]:
            inv_scaled = (eigvec / eigval) @ eigvec.T
            cov = sigma**2 * inv_scaled / d[:, None] / d[None, :]
        else:
            cov = np.full((6, 6), np.inf)
    else:
        cov = np.full((6, 6), np.inf)
    sigma_t = np.sqrt(np.diag(cov)[3:])
    G = rpy_jacobian(R)
    finite = np.all(np.isfinite(cov)) and np.all(np.isfinite(G))
    cov_rpy = G @ cov[:3, :3] @ G.T if finite else np.full((3, 3), np.inf)
    sigma_rpy = np.degrees(np.sqrt(np.abs(np.diag(cov_rpy))))
    return PoseUncertainty(cov, sigma_t, sigma_rpy, JtJ)


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
    points = np.asarray(points_lidar, dtype=np.float64)
    points_camera = points @ T[:3, :3].T + T[:3, 3]
    bearings = points_camera / np.linalg.norm(points_camera, axis=1, keepdims=True)
    E = tangent_basis(bearings)
    J = angular_jacobian(np.concatenate([np.zeros(3), T[:3, 3]]), T[:3, :3], points, bearings, E)
    return covariance_from_jacobian(J, float(noise_rad), T[:3, :3])
