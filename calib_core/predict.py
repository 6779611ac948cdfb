"""Predictions under a given pose: the camera pixel of a laser cell, the laser cell seen at a camera pixel.

Used by the app's loupes to frame the other end of a pair before it is clicked.
Frames: ``T_camera_lidar`` maps lidar points (metres) into the camera frame;
pixels are ``(u, v)`` of the original camera image, top-left pixel centre 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .overlays import project_lidar_points
from .transforms import transform_points


def predict_pixel(T_camera_lidar: np.ndarray, camera, depth, row: int, col: int) -> tuple[float, float] | None:
    """Camera pixel where the pose expects laser cell ``(row, col)``; None if the camera does not see it.

    Parameters
    ----------
    T_camera_lidar : (4, 4) float
    camera : CameraModel
    depth : DepthMatrix
    row, col : int
        Depth-matrix cell (must be a valid return).
    """
    if not depth.valid[int(row), int(col)]:
        return None
    uv, ok = project_lidar_points(T_camera_lidar, camera, depth.cell_points(np.array([[int(row), int(col)]])))
    return (float(uv[0, 0]), float(uv[0, 1])) if ok[0] else None


@dataclass(frozen=True)
class ProjectedScan:
    """Every valid scan point projected under one pose (computed once per pose, queried per click).

    Attributes
    ----------
    pixels : (N, 2) float
        Camera pixels of the points the camera sees.
    z : (N,) float
        Their distance from the camera centre (metres).
    rows_cols : (N, 2) int
        Their depth-matrix cells.
    """

    pixels: np.ndarray
    z: np.ndarray
    rows_cols: np.ndarray

    @classmethod
    def build(cls, T_camera_lidar: np.ndarray, camera, points_lidar: np.ndarray, rows_cols: np.ndarray) -> "ProjectedScan":
        pts = transform_points(np.asarray(T_camera_lidar, dtype=np.float64), np.asarray(points_lidar, np.float64))
        uv, ok = camera.project(pts)
        return cls(np.asarray(uv[ok], np.float64), np.linalg.norm(pts[ok], axis=1),
                   np.asarray(rows_cols, np.int64)[ok])

    def cell_at(self, u: float, v: float, radius_px: float = 3.0, depth_slack: float = 0.05) -> tuple[int, int] | None:
        """The laser cell the camera sees at pixel ``(u, v)``: the nearest surface among points projecting close by.

        Among the points within ``radius_px`` of the pixel, those within
        ``depth_slack`` (relative) of the nearest distance are the visible
        surface; of them the one projecting closest to the pixel is returned.
        Without a point within the radius, the point projecting nearest is
        returned if it is within 4 radii; else None.
        """
        if len(self.pixels) == 0:
            return None
        d2 = (self.pixels[:, 0] - u) ** 2 + (self.pixels[:, 1] - v) ** 2
        near = np.flatnonzero(d2 <= radius_px * radius_px)
        if len(near) == 0:
            k = int(np.argmin(d2))
            return tuple(int(x) for x in self.rows_cols[k]) if d2[k] <= (4 * radius_px) ** 2 else None
        z = self.z[near]
        front = near[z <= z.min() * (1.0 + depth_slack)]
        k = int(front[np.argmin(d2[front])])
        return int(self.rows_cols[k, 0]), int(self.rows_cols[k, 1])


def ellipse_outline(center, cov: np.ndarray, n_sigma: float = 3.0, n: int = 48) -> np.ndarray:
    """Points ``(n + 1, 2)`` of the ``n_sigma`` ellipse of a 2-D Gaussian (closed: first point repeated).

    Parameters
    ----------
    center : (2,) float
        Mean, pixels.
    cov : (2, 2) float
        Covariance, pixels squared (symmetric positive semi-definite).
    """
    c = np.asarray(cov, dtype=np.float64).reshape(2, 2)
    w, V = np.linalg.eigh(0.5 * (c + c.T))
    axes = V * (n_sigma * np.sqrt(np.clip(w, 0.0, None)))[None, :]
    t = np.linspace(0.0, 2.0 * np.pi, n + 1)
    return np.asarray(center, np.float64).reshape(1, 2) + np.stack([np.cos(t), np.sin(t)], axis=1) @ axes.T
