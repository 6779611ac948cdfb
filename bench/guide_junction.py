"""A laser cell replaced by the corner where three fitted planes meet, only where they fit well.

A whole-cell pick is off the corner by up to a cell plus the range noise.
Where the cell sits at a junction of three planes (a room or box corner), the
planes fitted to the surrounding points intersect at the corner itself.
Elsewhere a fit is worse than the cell, so the cell is replaced only when:
three planes each hold at least ``min_inliers`` points of the window with an
RMS under ``max_rms_m``, their normals are far from coplanar
(``|det| >= min_det``), and the intersection lies within ``max_shift_cells``
cell extents of the cell's point.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["JunctionFit", "fit_junctions"]


class JunctionFit(NamedTuple):
    """Result of :func:`fit_junctions`.

    Attributes
    ----------
    points_lidar : (N, 3) ndarray
        The junction where the test passed, else the cell's own point (lidar frame, m).
    fitted : (N,) bool
        The junction replaced the cell.
    """

    points_lidar: np.ndarray
    fitted: np.ndarray


def _window_points(depth, rc: tuple[int, int], half_rows: int, half_cols: int) -> np.ndarray:
    H, W = depth.shape
    r0, r1 = max(rc[0] - half_rows, 0), min(rc[0] + half_rows + 1, H)
    cols = np.arange(rc[1] - half_cols, rc[1] + half_cols + 1)
    cols = np.mod(cols, W) if depth.meta.get("wrap_cols", False) else cols[(cols >= 0) & (cols < W)]
    block = depth.points[r0:r1][:, cols].reshape(-1, 3)
    return block[np.all(np.isfinite(block), axis=1)]


def _best_plane(P: np.ndarray, rng: np.random.Generator, tol_m: float, hypotheses: int) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC plane (unit normal n, offset d with n.x = d) and its inlier mask; hypotheses vectorised."""
    idx = rng.integers(0, len(P), size=(hypotheses, 3))
    a, b, c = P[idx[:, 0]], P[idx[:, 1]], P[idx[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    good = norm > 1e-9
    n = n[good] / norm[good, None]
    d = np.einsum("ij,ij->i", n, a[good])
    if len(n) == 0:
        return np.zeros(3), np.zeros(len(P), dtype=bool)
    counts = (np.abs(P @ n.T - d) <= tol_m).sum(axis=0)
    k = int(np.argmax(counts))
    inl = np.abs(P @ n[k] - d[k]) <= tol_m
    # Least-squares refit on the inliers.
    Q = P[inl]
    centroid = Q.mean(axis=0)
    nn = np.linalg.svd(Q - centroid, full_matrices=False)[2][-1]
    inl = np.abs((P - centroid) @ nn) <= tol_m
    return np.append(nn, nn @ centroid), inl


def fit_junctions(
    depth,
    rows_cols: np.ndarray,
    *,
    half_rows: int = 4,
    half_cols: int = 6,
    tol_m: float = 0.02,
    min_inliers: int = 12,
    max_rms_m: float = 0.008,
    min_det: float = 0.5,
    max_shift_cells: float = 1.5,
    seed: int = 0,
) -> JunctionFit:
    """Fit three planes around each cell and keep their junction where they fit well (module docstring).

    The window is ``2 half_rows + 1`` rows by ``2 half_cols + 1`` columns
    (9 x 13 by default).  A loop over the cells (a few tens, each vectorised).
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    out = depth.points[rc[:, 0], rc[:, 1]].astype(np.float64).copy()
    fitted = np.zeros(len(rc), dtype=bool)
    rng = np.random.default_rng(seed)
    from calib_core.guide.laser_noise import cell_covariance  # local: the cell extent from the same model

    extent = np.sqrt(np.linalg.eigvalsh(cell_covariance(depth, rc, 1.0, 0.0))[:, -1])
    for i, (r, c) in enumerate(rc):  # a few tens of cells
        P = _window_points(depth, (int(r), int(c)), half_rows, half_cols)
        planes = []
        left = np.ones(len(P), dtype=bool)
        for _ in range(3):
            if left.sum() < min_inliers:
                break
            plane, inl_sub = _best_plane(P[left], rng, tol_m, 200)
            if inl_sub.sum() < min_inliers:
                break
            Q = P[left][inl_sub]
            rms = float(np.sqrt(np.mean((Q @ plane[:3] - plane[3]) ** 2)))
            if rms > max_rms_m:
                break
            planes.append(plane)
            idx = np.flatnonzero(left)
            left[idx[inl_sub]] = False
        if len(planes) < 3:
            continue
        N = np.array([p[:3] for p in planes])
        if abs(np.linalg.det(N)) < min_det:
            continue
        x = np.linalg.solve(N, np.array([p[3] for p in planes]))
        if np.linalg.norm(x - out[i]) <= max_shift_cells * max(extent[i], 1e-6):
            out[i], fitted[i] = x, True
    return JunctionFit(out, fitted)
