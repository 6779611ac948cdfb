"""Which laser points the camera sees: a z-buffer of the scan seen from the camera.

Camera and lidar look from different places, so a laser point that projects
into the image may be hidden behind something nearer to the camera.
"""

from __future__ import annotations

import numpy as np

__all__ = ["visible_in_camera"]


def visible_in_camera(
    camera,
    T_camera_lidar: np.ndarray,
    scan_points_lidar: np.ndarray,
    query_points_lidar: np.ndarray,
    cell_px: int = 4,
    tolerance: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of query points and whether the camera sees them.

    A query point is visible when it projects into the image and is no
    farther from the camera than ``(1 + tolerance)`` times (plus 5 cm) the
    nearest scan point projected into its z-buffer cell of ``cell_px``
    pixels.

    Parameters
    ----------
    camera : CameraModel
    T_camera_lidar : (4, 4) ndarray
    scan_points_lidar : (M, 3) ndarray
        All valid scan points (the occluders), lidar frame, metres.
    query_points_lidar : (N, 3) ndarray

    Returns
    -------
    pixels : (N, 2) ndarray
        Projected ``(u, v)``, NaN where not projectable.
    visible : (N,) bool
    """
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    gw, gh = -(-camera.width // cell_px), -(-camera.height // cell_px)
    zbuf = np.full(gh * gw, np.inf)
    P = np.asarray(scan_points_lidar, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    pix, ok = camera.project(P)
    if ok.any():
        cell = _cell(pix[ok], cell_px, gw, gh)
        np.minimum.at(zbuf, cell, np.linalg.norm(P[ok], axis=1))
    zmin = zbuf
    Q = np.asarray(query_points_lidar, dtype=np.float64).reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
    qpix, qok = camera.project(Q)
    qpix = np.asarray(qpix, dtype=np.float64)
    visible = np.asarray(qok, dtype=bool).copy()
    if visible.any():
        d = np.linalg.norm(Q[visible], axis=1)
        visible[visible] = d <= zmin[_cell(qpix[visible], cell_px, gw, gh)] * (1 + tolerance) + 0.05
    return qpix, visible


def _cell(pix: np.ndarray, cell_px: int, gw: int, gh: int) -> np.ndarray:
    col = np.clip(((pix[:, 0] + 0.5) // cell_px).astype(np.int64), 0, gw - 1)
    row = np.clip(((pix[:, 1] + 0.5) // cell_px).astype(np.int64), 0, gh - 1)
    return row * gw + col
