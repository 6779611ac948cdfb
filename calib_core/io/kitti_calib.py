"""KITTI object-detection calibration files (``calib/NNNNNN.txt``): camera 2 and the Velodyne.

Each line is ``KEY: numbers``.  Camera 2's rectified projection is
``x = P2 @ R0_rect @ Tr_velo_to_cam @ X``; with ``P2 = K @ [I | K^-1 P2[:, 3]]`` that is a
pinhole ``K`` and the rigid ``T_camera_lidar = [I | K^-1 P2[:, 3]] @ R0_rect @ Tr_velo_to_cam``
(metres), mapping Velodyne points into the rectified camera-2 frame.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import CalibError


def read_kitti_camera2(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """``K`` (3x3, px) of rectified camera 2 and ``T_camera_lidar`` (4x4, metres) from a KITTI calib file.

    Raises
    ------
    CalibError
        A key (``P2``, ``R0_rect``, ``Tr_velo_to_cam``) is missing or has the wrong number of values.
    """
    rows = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            if ":" in line:
                key, values = line.split(":", 1)
                rows[key.strip()] = np.array(values.split(), dtype=float)
    shapes = {"P2": (3, 4), "R0_rect": (3, 3), "Tr_velo_to_cam": (3, 4)}
    for key, shape in shapes.items():
        if key not in rows or rows[key].size != shape[0] * shape[1]:
            raise CalibError(f"{path}: KITTI calib needs '{key}:' with {shape[0] * shape[1]} numbers")
    P2 = rows["P2"].reshape(3, 4)
    R0 = np.eye(4)
    R0[:3, :3] = rows["R0_rect"].reshape(3, 3)
    Tr = np.eye(4)
    Tr[:3, :] = rows["Tr_velo_to_cam"].reshape(3, 4)
    K = P2[:, :3]
    offset = np.eye(4)
    offset[:3, 3] = np.linalg.solve(K, P2[:, 3])
    return K, offset @ R0 @ Tr
