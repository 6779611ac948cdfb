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
