"""Rigid transforms, rotations and their parametrisations (pure functions).

Conventions (see :mod:`calib_core`):

* ``T_a_b`` is a 4x4 homogeneous matrix with ``X_a = T_a_b @ X_b``; translations
  in metres.
* Roll, pitch, yaw in degrees with ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``
  (extrinsic x-y-z; SciPy's ``Rotation.from_euler("xyz", [roll, pitch, yaw])``).
* Quaternions are ``(x, y, z, w)``, scalar last, as in ROS and SciPy; returned
  with ``w >= 0``.

All rotation arithmetic goes through :class:`scipy.spatial.transform.Rotation`.
Bad input (wrong shape, NaN, zero quaternion) raises
:class:`calib_core.errors.CalibError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .arrays import as_rows, finite_array
from .errors import CalibError

__all__ = [
    "make_T",
    "invert_T",
    "transform_points",
    "rpy_deg_from_R",
    "R_from_rpy_deg",
    "quat_xyzw_from_R",
    "R_from_quat_xyzw",
    "rotation_angle_deg",
    "ViewingDirection",
    "viewing_direction",
    "R_from_viewing_deg",
]


def _Rotation():
    """``scipy.spatial.transform.Rotation``, imported on first use: importing ``scipy.spatial`` takes
    0.3-0.8 s, on the app's start-up path otherwise."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _rotation(R: ArrayLike, name: str = "R"):
    return _Rotation().from_matrix(finite_array(R, (3, 3), name))


def make_T(R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Homogeneous transform from a rotation and a translation.

    Parameters
    ----------
    R : (3, 3) array_like
        Rotation matrix (used as given, not re-orthonormalised).
    t : (3,) array_like
        Translation, metres.

    Returns
    -------
    (4, 4) ndarray
        ``[[R, t], [0, 0, 0, 1]]``.
    """
    T = np.eye(4)
    T[:3, :3] = finite_array(R, (3, 3), "R")
    T[:3, 3] = finite_array(np.ravel(t), (3,), "t")
    return T


def invert_T(T: ArrayLike) -> np.ndarray:
    """Inverse of a rigid transform: ``T_b_a`` from ``T_a_b``.

    Uses ``R^T`` and ``-R^T t`` (no general matrix inverse).
    """
    T = finite_array(T, (4, 4), "T")
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def transform_points(T: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Apply ``T_a_b`` to points expressed in frame b.

    Parameters
    ----------
    T : (4, 4) array_like
        ``T_a_b``.
    points : (N, 3) array_like
        Points in frame b, metres.  NaN rows stay NaN.

    Returns
    -------
    (N, 3) ndarray
        The points in frame a, metres.
    """
    T = finite_array(T, (4, 4), "T")
    p = as_rows(points, "points", 3, single_row=False)
    # R @ p.T is a wide product; p @ R.T (tall and thin) was up to 10x slower
    # in OpenBLAS here.  The result is written C-contiguous for OpenCV.
    out = np.empty_like(p)
    np.add((T[:3, :3] @ p.T).T, T[:3, 3], out=out)
    return out


def rpy_deg_from_R(R: ArrayLike) -> np.ndarray:
    """Roll, pitch, yaw in degrees with ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Pitch lies in [-90, 90]; roll and yaw in (-180, 180].  At pitch = +-90 deg
    (gimbal lock) only roll - yaw (or roll + yaw) is defined; SciPy then sets
    yaw to zero and warns.
    """
    return _rotation(R).as_euler("xyz", degrees=True)


def R_from_rpy_deg(rpy_deg: ArrayLike) -> np.ndarray:
    """Rotation matrix ``Rz(yaw) Ry(pitch) Rx(roll)`` from ``(roll, pitch, yaw)`` in degrees."""
    rpy = finite_array(np.ravel(rpy_deg), (3,), "rpy_deg")
    return _Rotation().from_euler("xyz", rpy, degrees=True).as_matrix()


def quat_xyzw_from_R(R: ArrayLike) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, with ``w >= 0``."""
    return _rotation(R).as_quat(canonical=True)


def R_from_quat_xyzw(q: ArrayLike) -> np.ndarray:
    """Rotation matrix of a quaternion ``(x, y, z, w)``; it is normalised first."""
    q = finite_array(np.ravel(q), (4,), "quaternion")
    if np.linalg.norm(q) < 1e-12:
        raise CalibError("quaternion has zero length")
    return _Rotation().from_quat(q).as_matrix()


def rotation_angle_deg(R_a: ArrayLike, R_b: ArrayLike) -> float:
    """Angle in degrees, in [0, 180], of the relative rotation ``R_a^T R_b``."""
    Ra = finite_array(R_a, (3, 3), "R_a")
    Rb = finite_array(R_b, (3, 3), "R_b")
    return float(np.degrees(_Rotation().from_matrix(Ra.T @ Rb).magnitude()))


@dataclass(frozen=True)
class ViewingDirection:
    """Where a camera looks in the lidar frame, and how it is turned about that direction.

    Attributes
    ----------
    direction_lidar : (3,) ndarray
        Unit vector of the optical axis (camera +z, OpenCV frame) in the lidar frame.
    azimuth_deg : float
        ``atan2(d_y, d_x)`` of that direction, degrees in (-180, 180]: 0 along lidar +x,
        90 along lidar +y.  NaN when the camera looks exactly along lidar +-z.
    elevation_deg : float
        ``asin(d_z)``, degrees in [-90, 90]: above (positive) or below the lidar's x-y plane.
    roll_deg : float
        Rotation of the camera about its optical axis, degrees in (-180, 180]: 0 when the
        image's up (camera -y) leans towards lidar +z and the camera x axis is horizontal
        (perpendicular to lidar z); ``+phi`` when the camera is turned by ``phi`` about its own
        +z (right-hand rule, i.e. clockwise seen from behind the camera).  It is
        ``atan2(-u_x, -u_y)`` of ``u``, lidar +z in camera coordinates.  NaN when the camera
        looks exactly along lidar +-z (no "up" in the image plane).
    sigma_deg : (3,) ndarray
        1-sigma of azimuth, elevation and roll, degrees, propagated to first order from the
        rotation covariance; NaN when none was given.  Azimuth and roll grow as
        ``1 / cos(elevation)`` towards lidar +-z, where they are undefined (inf).
    """

    direction_lidar: np.ndarray
    azimuth_deg: float
    elevation_deg: float
    roll_deg: float
    sigma_deg: np.ndarray


def viewing_direction(R_camera_lidar: ArrayLike, rotation_cov_rad2: ArrayLike | None = None) -> ViewingDirection:
    """The camera's viewing direction in the lidar frame (azimuth, elevation) and its roll about it.

    Unlike roll/pitch/yaw of ``R_camera_lidar`` -- in gimbal lock (pitch = -90 deg) for a camera
    looking horizontally along lidar +x, the usual rig -- these angles are singular only for a
    camera looking straight along lidar +-z.  No three angles are regular everywhere (a rotation
    is not a direction times an angle), so the two charts complement each other.

    Parameters
    ----------
    R_camera_lidar : (3, 3) array_like
        Rotation of ``T_camera_lidar`` (``X_camera = R X_lidar + t``), OpenCV camera frame
        (x right, y down, z forward).
    rotation_cov_rad2 : (3, 3) array_like, optional
        Covariance of the rotation, radians^2, of ``delta`` with ``R_true = exp([delta]_x) R``
        (camera axes): the top-left block of
        :attr:`calib_core.solve.CalibrationResult.covariance_6x6`.

    Returns
    -------
    ViewingDirection
    """
    R = finite_array(R_camera_lidar, (3, 3), "R_camera_lidar")
    d = R[2].copy()  # camera +z in lidar coordinates: R^T e_z
    u = R[:, 2].copy()  # lidar +z in camera coordinates: R e_z
    rho = math.hypot(d[0], d[1])  # = cos(elevation) = hypot(u_x, u_y)
    elevation = math.degrees(math.atan2(d[2], rho))
    if rho > 1e-12:
        azimuth = _half_open_deg(math.atan2(d[1], d[0]))
        roll = _half_open_deg(math.atan2(-u[0], -u[1]))
    else:
        azimuth = roll = float("nan")
    sigma = np.full(3, np.nan)
    if rotation_cov_rad2 is not None:
        cov = np.asarray(rotation_cov_rad2, dtype=np.float64)
        if cov.shape != (3, 3):
            raise CalibError(f"rotation_cov_rad2 must be 3x3, got shape {cov.shape}")
        sigma = _viewing_sigma_deg(R, d, u, rho, cov)
    return ViewingDirection(d, azimuth, elevation, roll, sigma)


def _half_open_deg(angle_rad: float) -> float:
    """Degrees in (-180, 180], without a negative zero."""
    deg = math.degrees(angle_rad) + 0.0
    return 180.0 if deg <= -180.0 else deg


def _viewing_sigma_deg(R: np.ndarray, d: np.ndarray, u: np.ndarray, rho: float, cov: np.ndarray) -> np.ndarray:
    """1-sigma (deg) of azimuth, elevation, roll: ``sqrt(diag(J cov J^T))`` with ``J = d(az, el, roll) / d delta``.

    A left perturbation ``exp([delta]) R`` moves ``d = R^T e_z`` by ``R^T [e_z]_x delta`` and
    ``u = R e_z`` by ``-[u]_x delta``; the angles' gradients follow from their ``atan2`` forms.
    """
    if not np.all(np.isfinite(cov)):
        return np.full(3, np.inf)
    ez_cross = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dd = R.T @ ez_cross  # (3, 3): d(d) / d delta
    du = -np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])  # d(u) / d delta
    g_el = np.array([-d[2] * d[0] / rho, -d[2] * d[1] / rho, rho]) if rho > 0 else np.array([0.0, 0.0, 0.0])
    J = np.zeros((3, 3))
    J[1] = g_el @ dd
    if rho > 1e-12:
        J[0] = np.array([-d[1], d[0], 0.0]) / rho**2 @ dd
        J[2] = np.array([u[1], -u[0], 0.0]) / rho**2 @ du
    var = np.einsum("ij,jk,ik->i", J, cov, J)
    sigma = np.degrees(np.sqrt(np.maximum(var, 0.0)))
    if rho <= 1e-12:
        sigma[[0, 2]] = np.inf
    return sigma


def R_from_viewing_deg(azimuth_deg: float, elevation_deg: float, roll_deg: float) -> np.ndarray:
    """``R_camera_lidar`` of a camera looking along (azimuth, elevation) in the lidar frame, turned by
    ``roll`` about its optical axis: the inverse of :func:`viewing_direction` (same conventions)."""
    az, el, roll = np.radians(finite_array(np.array([azimuth_deg, elevation_deg, roll_deg], dtype=np.float64),
                                           (3,), "viewing angles"))
    d = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    x0 = np.array([np.sin(az), -np.cos(az), 0.0])  # horizontal, to the right: d x e_z / cos(el)
    y0 = np.cross(d, x0)  # down in the image, its lidar z is -cos(el)
    c, s = np.cos(roll), np.sin(roll)
    # Camera axes in lidar coordinates, turned by roll about d: C = [x0 y0 d] Rz(roll); R = C^T.
    x, y = c * x0 + s * y0, -s * x0 + c * y0
    return np.stack([x, y, d])
