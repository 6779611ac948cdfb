"""KITTI 000002's published calibration, parsed here independently of calib_core (a reference for the tests)."""

from __future__ import annotations

import numpy as np

from repo_paths import REPO

KITTI = REPO.parent / "shared" / "data" / "kitti_object_000002"
KITTI_CALIB = KITTI / "calib" / "000002.txt"


def kitti_K_T() -> tuple[np.ndarray, np.ndarray]:
    """K = P2[:, :3] and T_camera_lidar = [I | K^-1 P2[:, 3]] @ R0 @ Tr (rectified camera 2, metres)."""
    rows = {}
    for line in KITTI_CALIB.read_text().splitlines():
        if ":" in line:
            key, values = line.split(":", 1)
            rows[key.strip()] = np.array(values.split(), float)
    P2 = rows["P2"].reshape(3, 4)
    K = P2[:, :3]
    shift = np.eye(4)
    shift[:3, 3] = np.linalg.solve(K, P2[:, 3])
    R0 = np.eye(4)
    R0[:3, :3] = rows["R0_rect"].reshape(3, 3)
    Tr = np.eye(4)
    Tr[:3, :] = rows["Tr_velo_to_cam"].reshape(3, 4)
    return K, shift @ R0 @ Tr
