"""Cramer-Rao bound of the pose, computed here independently of the solver.

Noise model (stated once, used by the report)
----------------------------------------------
Pair ``i`` is a laser point ``X_i`` (lidar frame, metres) and a clicked pixel
``m_i``.  The click is the true projection plus isotropic Gaussian noise of
``sigma_px`` pixels per axis.  Optionally the laser point carries a zero-mean
error of covariance ``Sigma_L,i`` (3x3, metres^2): the pick rounded to a whole
depth-matrix cell (uniform over the cell, variance ``step^2 / 12`` along the
row and the column direction of the beam) plus the range noise along the beam.
Linearised, the laser error moves the predicted pixel by ``J_X,i dX``, so the
pixel residual of pair ``i`` has covariance

    Sigma_i = sigma_px^2 I_2 + J_X,i Sigma_L,i J_X,i^T.

With ``J_p,i`` the derivative of the predicted pixel with respect to the pose
parameters ``p = (roll, pitch, yaw [rad], tx, ty, tz [m])`` of
``T_camera_lidar``, the Fisher information is ``F = sum_i J_p,i^T Sigma_i^-1 J_p,i``
and any unbiased estimator has ``cov(p_hat) >= F^-1``.  Derivatives are
central finite differences of ``camera.project`` (any camera model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib_core.solve.whiten import cell_pick_covariance
from calib_core.transforms import R_from_rpy_deg, rpy_deg_from_R

_H_ROT_RAD = 1e-6
_H_POS_M = 1e-6


def _project(camera, rpy_rad: np.ndarray, t: np.ndarray, points_lidar: np.ndarray) -> np.ndarray:
    R = R_from_rpy_deg(np.degrees(rpy_rad))
    return camera.project(points_lidar @ R.T + t)[0]


def pose_jacobian_px(camera, T_camera_lidar: np.ndarray, points_lidar: np.ndarray) -> np.ndarray:
    """``d pixel / d p`` at ``T_camera_lidar``: ``(N, 2, 6)``, pixels per radian / metre."""
    p0 = np.concatenate([np.radians(rpy_deg_from_R(T_camera_lidar[:3, :3])), T_camera_lidar[:3, 3]])
    J = np.empty((len(points_lidar), 2, 6))
    for k in range(6):  # six parameters, each a vectorised projection of all points
        h = _H_ROT_RAD if k < 3 else _H_POS_M
        dp = np.zeros(6)
        dp[k] = h
        plus, minus = p0 + dp, p0 - dp
        J[:, :, k] = (_project(camera, plus[:3], plus[3:], points_lidar) - _project(camera, minus[:3], minus[3:], points_lidar)) / (2 * h)
    return J


def point_jacobian_px(camera, T_camera_lidar: np.ndarray, points_lidar: np.ndarray) -> np.ndarray:
    """``d pixel / d X_lidar``: ``(N, 2, 3)``, pixels per metre."""
    J = np.empty((len(points_lidar), 2, 3))
    R, t = T_camera_lidar[:3, :3], T_camera_lidar[:3, 3]
    for k in range(3):
        d = np.zeros(3)
        d[k] = _H_POS_M
        J[:, :, k] = (camera.project((points_lidar + d) @ R.T + t)[0] - camera.project((points_lidar - d) @ R.T + t)[0]) / (2 * _H_POS_M)
    return J


@dataclass(frozen=True)
class Bound:
    """Cramer-Rao bound of ``p = (roll, pitch, yaw, tx, ty, tz)``.

    Attributes
    ----------
    covariance : (6, 6)
        In radians and metres.
    sigma_rpy_deg : (3,)
    sigma_translation_m : (3,)
    """

    covariance: np.ndarray
    sigma_rpy_deg: np.ndarray
    sigma_translation_m: np.ndarray


def cramer_rao(
    camera,
    T_camera_lidar: np.ndarray,
    points_lidar: np.ndarray,
    sigma_px: float,
    laser_covariance: np.ndarray | None = None,
) -> Bound:
    """The bound for one set of pairs at the true pose (see the module docstring)."""
    X = np.asarray(points_lidar, dtype=np.float64).reshape(-1, 3)
    Jp = pose_jacobian_px(camera, T_camera_lidar, X)
    S = np.broadcast_to(sigma_px**2 * np.eye(2), (len(X), 2, 2)).copy()
    if laser_covariance is not None:
        Jx = point_jacobian_px(camera, T_camera_lidar, X)
        S += Jx @ laser_covariance @ np.swapaxes(Jx, 1, 2)
    F = np.einsum("nai,nab,nbj->ij", Jp, np.linalg.inv(S), Jp)
    C = np.linalg.inv(F)
    s = np.sqrt(np.diag(C))
    return Bound(C, np.degrees(s[:3]), s[3:])


def radians_per_pixel(camera, pixels: np.ndarray) -> np.ndarray:
    """Angle between the rays of pixels half a pixel either side, per axis: ``(N, 2)`` rad/px."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    out = np.empty((len(px), 2))
    for k in range(2):
        d = np.zeros(2)
        d[k] = 0.5
        a, b = camera.bearing(px - d), camera.bearing(px + d)
        out[:, k] = np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))
    return out


def mean_error_of_bound(cov6: np.ndarray, rpy_true_deg: np.ndarray, rng: np.random.Generator,
                         draws: int = 4000) -> tuple[float, float]:
    """Mean rotation angle (deg) and translation norm (m) of Gaussian errors with covariance ``cov6``.

    ``cov6`` is over (roll, pitch, yaw [rad], tx, ty, tz [m]); the rotation error of each draw is the
    angle between ``R(rpy_true + d)`` and ``R(rpy_true)`` (R = Rz(yaw) Ry(pitch) Rx(roll)).
    """
    from scipy.spatial.transform import Rotation

    e = rng.multivariate_normal(np.zeros(6), cov6, draws)
    zyx = np.radians(np.asarray(rpy_true_deg, dtype=np.float64)[::-1])
    R0 = Rotation.from_euler("ZYX", zyx)
    R = Rotation.from_euler("ZYX", zyx[None, :] + e[:, 2::-1])
    angle = (R0.inv() * R).magnitude()
    return float(np.degrees(angle).mean()), float(np.linalg.norm(e[:, 3:], axis=1).mean())


def bound_table(ns=(10, 30, 50, 125), starts: int = 20, seed: int = 0) -> list[dict]:
    """Mean errors allowed by the bound on the sample, for n corners spread by farthest-point sampling.

    For each n, ``starts`` sets (farthest-point order from a random first corner, as
    ``simulate_pairs`` picks them); 1 px clicks; three laser models: exact corners, the
    whole-cell pick (the package's pick model,
    :func:`calib_core.solve.whiten.cell_pick_covariance`, at the picked cells' points) and the laser term alone (clicks without noise).
    """
    from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks
    from calib_core.transforms import transform_points

    from .common import load_scenes

    sc = load_scenes(())[0].scene
    corners = np.asarray(sc.corners_lidar, dtype=np.float64).reshape(-1, 3)
    rc_all, err = laser_picks(sc.depth, corners)
    usable = np.flatnonzero(err <= MAX_LASER_PICK_ERROR_M)
    pc = transform_points(sc.T_camera_lidar, corners[usable])
    b = pc / np.linalg.norm(pc, axis=1, keepdims=True)
    rpy = rpy_deg_from_R(sc.T_camera_lidar[:3, :3])
    rng = np.random.default_rng(seed)
    rows = []
    for n in ns:
        n = min(n, len(usable))
        acc = {"exact": [], "cell": [], "laser only": []}
        for _ in range(starts if n < len(usable) else 1):
            chosen = [int(rng.integers(len(usable)))]
            min_cos = b @ b[chosen[0]]
            for _ in range(n - 1):
                nxt = int(np.argmin(min_cos))
                chosen.append(nxt)
                min_cos = np.maximum(min_cos, b @ b[nxt])
            idx = usable[chosen]
            rc = rc_all[idx]
            cell_pts = sc.depth.points[rc[:, 0], rc[:, 1]]
            cov_l = cell_pick_covariance(sc.depth, rc)
            for key, pts, sig, cov in (("exact", corners[idx], 1.0, None), ("cell", cell_pts, 1.0, cov_l),
                                       ("laser only", cell_pts, 1e-3, cov_l)):
                bd = cramer_rao(sc.camera, sc.T_camera_lidar, pts, sig, cov)
                acc[key].append(mean_error_of_bound(bd.covariance, rpy, rng, 4000))
        rows.append({"n": n, **{k: np.mean(v, axis=0) for k, v in acc.items()}})
    return rows


if __name__ == "__main__":
    print("Cramer-Rao mean errors on the sample (1 px clicks): rotation deg / translation cm")
    print("| n | exact laser | whole-cell laser pick (pick model) | laser term alone |")
    print("|---:|---|---|---|")
    for r in bound_table():
        print(f"| {r['n']} | " + " | ".join(f"{r[k][0]:.3f} deg / {100 * r[k][1]:.2f} cm"
                                            for k in ("exact", "cell", "laser only")) + " |")
