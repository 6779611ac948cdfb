"""Organized point clouds as depth matrices.

Any sensor that already delivers its points on a grid (an organized PCD, a
structured-light camera, a simulator) needs no beam model: each cell's beam
is the ray from the lidar origin through its point.  Lidar frame and units
are those of the cloud (metres).
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix
from .rotating_scanner import _check_wrap_cols, _float_array


def organized_cloud_depth(points, wrap_cols: bool = False) -> DepthMatrix:
    """Depth matrix of an organized point cloud.

    Parameters
    ----------
    points : (H, W, 3) array_like
        One 3-D point per cell in the lidar frame, metres.  A cell with a
        NaN or inf coordinate, or at exactly ``(0, 0, 0)`` (a common
        no-return code), has no return.
    wrap_cols : bool
        True when the columns close a full 360 deg turn, so that column 0's
        left neighbour is column W-1.

    Returns
    -------
    DepthMatrix
        ``range_m = |p|`` and ``directions = p / |p|`` for valid cells; range,
        direction and point are NaN for invalid cells.
        ``meta = {"model": "organized", "points", "wrap_cols"}`` where
        ``meta["points"]`` is the same array as ``DepthMatrix.points``.
    """
    cloud = _float_array(points, "points")
    if cloud.ndim != 3 or cloud.shape[2] != 3 or cloud.shape[0] < 1 or cloud.shape[1] < 1:
        raise CalibError(f"points must be an organized (H, W, 3) array, got shape {cloud.shape}")
    wrap = _check_wrap_cols(wrap_cols)

    with np.errstate(invalid="ignore", over="ignore"):
        range_m = np.linalg.norm(cloud, axis=2)
        valid = np.isfinite(cloud).all(axis=2) & np.isfinite(range_m) & (range_m > 0.0)
    range_clean = np.where(valid, range_m, np.nan)
    points_clean = np.where(valid[..., None], cloud, np.nan)
    directions = points_clean / range_clean[..., None]
    meta = {"model": "organized", "points": points_clean, "wrap_cols": wrap}
    return DepthMatrix(range_m=range_clean, directions=directions, points=points_clean, valid=valid, meta=meta)
