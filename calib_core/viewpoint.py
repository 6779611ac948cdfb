"""Where to stand to look at a scan the way a calibrated camera sees it (the 3-D check view, paper Fig. 9)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .transforms import invert_T

__all__ = ["viewpoint_behind_camera"]


def viewpoint_behind_camera(T_camera_lidar: ArrayLike | None, up_lidar: ArrayLike, back_m: float = 1.5,
                            above_m: float = 0.7, ahead_m: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """An eye a little behind and above the camera, and the point it looks at, levelled to ``up_lidar``.

    Parameters
    ----------
    T_camera_lidar : (4, 4) array_like or None
        Maps lidar points into the camera frame (OpenCV: z forward).  None: a
        viewer at the lidar origin looking along the lidar's +x.
    up_lidar : (3,) array_like
        Unit up direction of the scene, lidar frame.
    back_m, above_m, ahead_m : float
        Metres behind the camera (along its levelled viewing direction),
        above it, and from the camera to the looked-at point.

    Returns
    -------
    eye, look_at : (3,) ndarray
        Lidar frame, metres.  When the camera looks almost straight up or
        down, a horizontal direction perpendicular to ``up_lidar`` stands in
        for its viewing direction.
    """
    up = np.asarray(up_lidar, dtype=np.float64).reshape(3)
    if T_camera_lidar is None:
        centre, forward = np.zeros(3), np.array([1.0, 0.0, 0.0])
    else:
        T_lidar_camera = invert_T(T_camera_lidar)
        centre, forward = T_lidar_camera[:3, 3], T_lidar_camera[:3, 2]  # the camera's z axis, lidar frame
    level = forward - float(forward @ up) * up
    if np.linalg.norm(level) < 0.1:
        level = np.cross(up, [0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.cross(up, [1.0, 0.0, 0.0])
    level = level / np.linalg.norm(level)
    return centre - back_m * level + above_m * up, centre + ahead_m * level
