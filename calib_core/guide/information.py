"""Fisher information of the 6-DoF pose from laser-point / pixel pairs.

Pose parameters ``x = (delta, t)`` as in :mod:`calib_core.solve.refine`:
``R = exp([delta]_x) R_hat`` (rotation vector ``delta`` about the camera axes,
radians) and the translation ``t`` of ``T_camera_lidar`` (metres).

Noise model of pair ``i``: the clicked pixel is the projection of the true
feature plus isotropic noise of ``sigma_px`` per axis; the laser point is the
true feature plus an error of covariance ``Sigma_L,i`` (metres^2, e.g. the
pick rounded to a whole cell).  To first order the pixel residual has
covariance

    S_i = sigma_px,i^2 I_2 + J_X,i Sigma_L,i J_X,i^T

and the information is ``F = sum_i J_i^T S_i^-1 J_i`` with ``J_i`` the
derivative of the projected pixel with respect to ``x``.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError

__all__ = [
    "pixel_jacobians",
    "pair_noise",
    "fisher_information",
    "pose_pixel_covariance",
    "d_optimal_gain",
    "information_inverse",
]

#: Relative step of the central differences of ``camera.project`` (of the point's distance).
_REL_STEP = 1e-6


def pixel_jacobians(camera, T_camera_lidar: np.ndarray, points_lidar: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted pixels and their derivatives with respect to the pose and the laser point.

    Parameters
    ----------
    camera : CameraModel
    T_camera_lidar : (4, 4) ndarray
        Pose at which to linearise (``X_camera = T @ X_lidar``, metres).
    points_lidar : (N, 3) ndarray
        Laser points, lidar frame, metres.

    Returns
    -------
    pixels : (N, 2) ndarray
        Projected ``(u, v)``; NaN where the camera cannot project the point.
    J_pose : (N, 2, 6) ndarray
        ``d pixel / d (delta, t)``, px/rad and px/m.
    J_point : (N, 2, 3) ndarray
        ``d pixel / d X_lidar``, px/m.
    """
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    X = np.asarray(points_lidar, dtype=np.float64).reshape(-1, 3)
    R, t = T[:3, :3], T[:3, 3]
    Xr = X @ R.T
    P = Xr + t
    n = len(P)
    pixels, _ = camera.project(P)
    pixels = np.asarray(pixels, dtype=np.float64)
    h = _REL_STEP * np.maximum(np.linalg.norm(P, axis=1), 1e-3)
    # d pixel / d P_camera by central differences: all 6 offsets in one projection call.
    offsets = np.concatenate([np.eye(3), -np.eye(3)])  # (6, 3)
    stacked = (P[None, :, :] + offsets[:, None, :] * h[None, :, None]).reshape(-1, 3)
    proj, _ = camera.project(stacked)
    proj = np.asarray(proj, dtype=np.float64).reshape(6, n, 2)
    dpi_dP = np.transpose((proj[:3] - proj[3:]) / (2.0 * h[None, :, None]), (1, 2, 0))  # (N, 2, 3)
    # dP/d delta = -[R X]_x, dP/dt = I;  a row d times -[a]_x is a x d.
    J_pose = np.empty((n, 2, 6))
    J_pose[:, :, 3:] = dpi_dP
    J_pose[:, :, :3] = np.cross(Xr[:, None, :], dpi_dP)
    J_point = dpi_dP @ R
    return pixels, J_pose, J_point


def pair_noise(sigma_px, J_point: np.ndarray, laser_cov: np.ndarray | None = None,
               edge_deg: np.ndarray | None = None) -> np.ndarray:
    """Pixel-residual covariances ``S_i`` (N, 2, 2), px^2 (module docstring).

    Parameters
    ----------
    sigma_px : float or (N,) array_like
        Click noise per image axis, pixels.
    J_point : (N, 2, 3) ndarray
        From :func:`pixel_jacobians`.
    laser_cov : (N, 3, 3) ndarray, optional
        Laser-point error covariance, metres^2; None for exact points.
    edge_deg : (N,) ndarray, optional
        Edge pairs' edge angles, degrees (NaN for a corner): their click noise is
        :func:`calib_core.solve.edges.edge_click_covariance`, next to nothing along the edge.
    """
    from ..solve.edges import edge_click_covariance

    n = len(J_point)
    s = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (n,))
    S = edge_click_covariance(s, edge_deg)
    if laser_cov is not None:
        S = S + J_point @ laser_cov @ np.swapaxes(J_point, 1, 2)
    return S


def fisher_information(J_pose: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``F = sum_i J_i^T S_i^-1 J_i`` (6, 6) of pairs whose Jacobian is finite."""
    ok = np.all(np.isfinite(J_pose), axis=(1, 2)) & np.all(np.isfinite(S), axis=(1, 2))
    if not ok.any():
        return np.zeros((6, 6))
    W = np.linalg.inv(S[ok])
    return np.einsum("nai,nab,nbj->ij", J_pose[ok], W, J_pose[ok])


def pose_pixel_covariance(J_pose: np.ndarray, pose_cov: np.ndarray) -> np.ndarray:
    """Pixel covariance (N, 2, 2), px^2, of predicted pixels from a pose covariance (6, 6)."""
    return J_pose @ pose_cov @ np.swapaxes(J_pose, 1, 2)


def d_optimal_gain(J_pose: np.ndarray, S: np.ndarray, pose_cov: np.ndarray) -> np.ndarray:
    """Increase of ``log det F`` if each candidate pair were added: (N,), nats.

    By the matrix determinant lemma, adding ``J^T S^-1 J`` to ``F = C^-1``
    raises ``log det F`` by ``log det(I_2 + S^-1 J C J^T)``; NaN where the
    candidate cannot be projected.
    """
    A = np.linalg.solve(S, pose_pixel_covariance(J_pose, pose_cov))
    det = (1.0 + A[:, 0, 0]) * (1.0 + A[:, 1, 1]) - A[:, 0, 1] * A[:, 1, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(det > 0, np.log(det), np.nan)


def information_inverse(F: np.ndarray) -> np.ndarray:
    """Pose covariance ``F^-1`` (6, 6), Jacobi-scaled (rad and m differ in scale); :class:`CalibError` when F
    is singular."""
    F = np.asarray(F, dtype=np.float64)
    d = np.sqrt(np.diag(F))
    if not (np.all(d > 0) and np.all(np.isfinite(F))):
        raise CalibError("the pose is not determined by these pairs (singular information matrix)")
    scaled = F / d[:, None] / d[None, :]
    w, V = np.linalg.eigh(scaled)
    if w[0] <= 1e-12 * w[-1]:
        raise CalibError("the pose is not determined by these pairs (singular information matrix)")
    return (V / w) @ V.T / d[:, None] / d[None, :]
