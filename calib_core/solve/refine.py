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

import math
from typing import Any, Callable, NamedTuple

import numpy as np
from scipy.optimize import least_squares

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
    "refine_angular",
    "angular_at_pose",
    "bearing_frames",
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


def _so3_matrix(phi: np.ndarray, a: float, b: float, d: float) -> np.ndarray:
    """``d I + a [phi]_x + b phi phi^T`` built from Python floats in one array call
    (numpy's per-call overhead dominates for one 3x3 matrix)."""
    x, y, z = float(phi[0]), float(phi[1]), float(phi[2])
    bx, by, bz = b * x, b * y, b * z
    return np.array(
        [
            [d + bx * x, bx * y - a * z, bx * z + a * y],
            [bx * y + a * z, d + by * y, by * z - a * x],
            [bx * z - a * y, by * z + a * x, d + bz * z],
        ]
    )


def _rotation_matrix(phi: np.ndarray) -> np.ndarray:
    """``exp([phi]_x)`` by Rodrigues' formula, ``cos I + (sin/theta) [phi]_x + ((1 - cos)/theta^2) phi phi^T``.

    Plain arithmetic: scipy's ``Rotation.from_rotvec`` costs more than the
    rest of a residual evaluation for a few pairs.
    """
    theta2 = float(phi[0]) ** 2 + float(phi[1]) ** 2 + float(phi[2]) ** 2
    if theta2 < 1e-8:  # theta < 1e-4: Taylor series, exact to float rounding
        cos, a, b = 1.0 - theta2 / 2 + theta2**2 / 24, 1.0 - theta2 / 6, 0.5 - theta2 / 24
    else:
        theta = math.sqrt(theta2)
        cos = math.cos(theta)
        a, b = math.sin(theta) / theta, (1.0 - cos) / theta2
    return _so3_matrix(phi, a, b, cos)


def _left_jacobian_so3(phi: np.ndarray) -> np.ndarray:
    """``J_l(phi)`` with ``exp([phi + dphi]) = exp([J_l dphi]) exp([phi])`` to first order.

    ``I + a K + b K^2`` with ``K = [phi]_x`` and ``K^2 = phi phi^T - theta^2 I``.
    """
    theta2 = float(phi[0]) ** 2 + float(phi[1]) ** 2 + float(phi[2]) ** 2
    if theta2 < 1e-8:
        a, b = 0.5 - theta2 / 24, 1.0 / 6 - theta2 / 120
    else:
        theta = math.sqrt(theta2)
        a = (1 - math.cos(theta)) / theta2
        b = (theta - math.sin(theta)) / (theta2 * theta)
    return _so3_matrix(phi, a, b, 1.0 - b * theta2)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` for (..., 3) arrays (broadcast): np.cross's axis handling costs
    more than the arithmetic for a few vectors."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


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
    e1 = cross3(b, axis)
    e1 /= np.sqrt(np.einsum("ij,ij->i", e1, e1))[:, None]
    e2 = cross3(b, e1)
    return np.stack([e1, e2], axis=1)


def bearing_frames(bearings_camera: np.ndarray, E: np.ndarray | None = None) -> np.ndarray:
    """Per-bearing orthonormal frames, rows ``e1, e2, b``.

    Parameters
    ----------
    bearings_camera : (N, 3) ndarray
        Unit bearings, camera frame.
    E : (N, 2, 3) ndarray, optional
        Their :func:`tangent_basis`, if already computed.

    Returns
    -------
    (N, 3, 3) ndarray
        One product ``frames @ P`` gives a point's two tangent components and
        its component along the bearing (metres, like ``P``).
    """
    b = np.asarray(bearings_camera, dtype=np.float64)
    if E is None:
        E = tangent_basis(b)
    return np.concatenate([E, b[:, None, :]], axis=1)


class _LogMap(NamedTuple):
    """Log map of points (camera frame) against bearings, with what its derivative needs."""

    w: np.ndarray  # (N, 2) tangent components of the unit direction q
    theta: np.ndarray  # (N,) geodesic angle, radians
    g: np.ndarray  # (N,) theta / sin(theta)
    h: np.ndarray  # (N,) (cos sin - theta) / sin^3
    inv_norm: np.ndarray  # (N,) 1 / |P| (1 for P = 0)

    @property
    def residuals(self) -> np.ndarray:
        return self.g[:, None] * self.w


def _log_map(points_camera: np.ndarray, frames: np.ndarray) -> _LogMap:
    y = np.einsum("nij,nj->ni", frames, points_camera)  # (e1.P, e2.P, b.P)
    s_unit = np.hypot(y[:, 0], y[:, 1])
    norm = np.hypot(s_unit, y[:, 2])  # |P|: the frame is orthonormal
    inv_norm = 1.0 / np.where(norm > 0, norm, 1.0)
    theta = np.arctan2(s_unit, y[:, 2])
    s, c = s_unit * inv_norm, y[:, 2] * inv_norm
    small = theta < 1e-3
    if small.any():
        s_safe = np.where(small, 1.0, s)
        # g = theta / sin(theta); h = (cos sin - theta) / sin^3 (series near 0).
        g = np.where(small, 1 + theta**2 / 6 + 7 * theta**4 / 360, theta / s_safe)
        h = np.where(small, -2.0 / 3 - theta**2 / 5, (c * s_safe - theta) / s_safe**3)
    else:
        g = theta / s
        h = (c * s - theta) / s**3
    return _LogMap(y[:, :2] * inv_norm[:, None], theta, g, h, inv_norm)


def _d_residual_d_point(lm: _LogMap, frames: np.ndarray) -> np.ndarray:
    """``d r_i / d P_i`` (N, 2, 3) of the log-map residuals.

    In the frame ``(e1, e2, b)`` of each bearing, with ``q = P / |P|`` in that
    frame ``(w1, w2, c)``: ``dr/dq = [g I + h w w^T | -w]``.  Its component
    along ``q`` is ``w (g + h s^2 - c) = 0`` (``r`` depends on the direction
    only), so ``dr/dP = dr/dq F / |P|`` with no projection needed.
    """
    n = len(lm.w)
    D = np.empty((n, 2, 3))
    hw = lm.h[:, None] * lm.w
    D[:, :, :2] = hw[:, :, None] * lm.w[:, None, :]
    D[:, 0, 0] += lm.g
    D[:, 1, 1] += lm.g
    D[:, :, 2] = -lm.w
    D *= lm.inv_norm[:, None, None]
    return D @ frames


def log_map_residuals(points_camera: np.ndarray, bearings_camera: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Log-map residuals ``(N, 2)`` of points (camera frame) against bearings.

    Each row has norm equal to the geodesic angle (radians) between the
    bearing and the direction of the point.  ``E`` comes from
    :func:`tangent_basis` of the same bearings.
    """
    return _log_map(points_camera, bearing_frames(bearings_camera, E)).residuals


def _pose(x: np.ndarray, R0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return _rotation_matrix(x[:3]) @ R0, x[3:]


class _AngularCost:
    """Residuals and Jacobian of the angular cost as functions of ``x = (delta, t)``.

    MINPACK asks for the Jacobian at the point whose residuals it evaluated
    last, so the pose-dependent quantities are kept for the last ``x``.
    """

    def __init__(self, R0: np.ndarray, points_lidar: np.ndarray, frames: np.ndarray) -> None:
        self.R0 = R0
        self.points = points_lidar
        self.frames = frames
        self._key: bytes | None = None

    def _at(self, x: np.ndarray) -> tuple[np.ndarray, _LogMap]:
        key = x.tobytes()
        if key != self._key:
            R, t = _pose(x, self.R0)
            rotated = self.points @ R.T
            self._rotated, self._lm = rotated, _log_map(rotated + t, self.frames)
            self._key = key
        return self._rotated, self._lm

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """``(2N,)`` log-map residuals, radians."""
        return self._at(x)[1].residuals.ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """``(2N, 6)`` analytic Jacobian w.r.t. ``(delta, t)``."""
        rotated, lm = self._at(x)
        dr_dP = _d_residual_d_point(lm, self.frames)
        n = len(rotated)
        J = np.empty((n, 2, 6))
        J[:, :, 3:] = dr_dP  # dP/dt = I
        # d(exp(delta) R0 p)/d delta = -[R p]_x J_l(delta); a row d times -[a]_x is a x d.
        a, d = rotated[:, None, :], dr_dP
        cross = np.empty((n, 2, 3))
        cross[..., 0] = a[..., 1] * d[..., 2] - a[..., 2] * d[..., 1]
        cross[..., 1] = a[..., 2] * d[..., 0] - a[..., 0] * d[..., 2]
        cross[..., 2] = a[..., 0] * d[..., 1] - a[..., 1] * d[..., 0]
        J[:, :, :3] = cross @ _left_jacobian_so3(x[:3])
        return J.reshape(-1, 6)


def angular_jacobian(
    x: np.ndarray, R0: np.ndarray, points_lidar: np.ndarray, bearings_camera: np.ndarray, E: np.ndarray
) -> np.ndarray:
    """Analytic Jacobian ``(2N, 6)`` of the log-map residuals w.r.t. ``x = (delta, t)``."""
    frames = bearing_frames(bearings_camera, E)
    return _AngularCost(R0, np.asarray(points_lidar, dtype=np.float64), frames).jacobian(np.asarray(x, dtype=np.float64))


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
    if cost == "angular":
        return refine_angular(T_initial, points_lidar, bearing_frames(bearings_camera))
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

        def fun(x: np.ndarray) -> np.ndarray:
            r = pixel_residuals(x, R0, points_lidar, pixels, camera).ravel()
            return np.where(np.isfinite(r), r, _UNPROJECTABLE_PX)

        def jac(x: np.ndarray) -> np.ndarray:
            J = pixel_jacobian(x, R0, points_lidar, pixels, camera)
            return np.where(np.isfinite(J), J, 0.0)

    else:
        raise CalibError(f"unknown cost {cost!r}; use 'angular' or 'pixel'")
    sol = _run_lm(fun, jac, x0, cost)
    return _pose_matrix(sol.x, R0), _iterations(sol)


def _pose_matrix(x: np.ndarray, R0: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = _pose(x, R0)
    return T


def _iterations(sol: Any) -> int:
    return int(sol.njev) if sol.njev is not None else int(sol.nfev)


def refine_angular(T_initial: np.ndarray, points_lidar: np.ndarray, frames: np.ndarray) -> tuple[np.ndarray, int]:
    """:func:`refine_pose` with the angular cost, given the bearing frames.

    ``frames`` (N, 3, 3) has rows ``e1, e2, b`` per bearing (:func:`bearing_frames`),
    so a caller that refines several times computes them once.
    """
    problem = _AngularCost(T_initial[:3, :3], np.asarray(points_lidar, dtype=np.float64), frames)
    sol = _run_lm(problem.residuals, problem.jacobian, np.concatenate([np.zeros(3), T_initial[:3, 3]]), "angular")
    return _pose_matrix(sol.x, problem.R0), _iterations(sol)


def angular_at_pose(
    T_camera_lidar: np.ndarray, points_lidar: np.ndarray, frames: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jacobian, residuals and angles of the angular cost at a pose.

    Returns
    -------
    J : (2N, 6) ndarray
        Jacobian w.r.t. ``(delta, t)`` about ``T_camera_lidar`` (``delta = 0``).
    residuals : (2N,) ndarray
        Log-map residuals, radians.
    angle_rad : (N,) ndarray
        Geodesic angle between each bearing and its transformed point.
    """
    problem = _AngularCost(T_camera_lidar[:3, :3], np.asarray(points_lidar, dtype=np.float64), frames)
    x = np.concatenate([np.zeros(3), T_camera_lidar[:3, 3]])
    J = problem.jacobian(x)
    lm = problem._at(x)[1]
    return J, lm.residuals.ravel(), lm.theta


def rpy_jacobian(R: np.ndarray) -> np.ndarray:
    """``d(roll, pitch, yaw) / d delta`` (3x3, rad/rad) at ``R = Rz Ry Rx``.

    For a left perturbation ``exp([delta]) R`` the angular velocity is
    ``delta_dot = yaw_dot e_z + pitch_dot Rz e_y + roll_dot Rz Ry e_x``, i.e.
    ``delta = M (roll, pitch, yaw)`` with those three columns; the answer is
    ``M^-1``, singular at pitch = +-90 deg (gimbal lock).
    """
    R = np.asarray(R, dtype=np.float64)
    # R e_x = Rz Ry e_x = (cos yaw cos pitch, sin yaw cos pitch, -sin pitch).
    cos_pitch = float(np.hypot(R[0, 0], R[1, 0]))
    if cos_pitch < 1e-9:
        return np.full((3, 3), np.inf)
    cos_yaw, sin_yaw = R[0, 0] / cos_pitch, R[1, 0] / cos_pitch
    M = np.array([[R[0, 0], -sin_yaw, 0.0], [R[1, 0], cos_yaw, 0.0], [R[2, 0], 0.0, 1.0]])
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
