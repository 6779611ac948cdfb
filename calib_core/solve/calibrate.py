"""From pairs (as a user makes them) to a calibration: the one call the CLI and the app share.

:func:`calibrate` resolves the pairs (laser cells or points, clicked pixels),
takes each pair's id and ``precision_px``, models the laser pick of a whole
depth-matrix cell (:func:`calib_core.solve.whiten.cell_pick_covariance`) and
calls :func:`calib_core.solve.solve_extrinsics`.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = ["calibrate", "pair_ids_and_sigmas", "RANGE_SIGMA_M"]

#: Range noise assumed for laser cells, metres (1-sigma); a cell pick's angular error dominates.
RANGE_SIGMA_M = 0.02


def pair_ids_and_sigmas(pairs: Sequence[Any]) -> tuple[list[int], np.ndarray | None]:
    """Pair ids and per-pair pixel sigmas for :func:`calib_core.solve.solve_extrinsics`.

    Ids: the pairs' ``id`` when every pair has a distinct one, else their
    0-based positions.  Sigmas: ``precision_px`` (1 px where a pair has
    none), or None when no pair states one.
    """
    ids = [p.id for p in pairs]
    if any(i is None for i in ids) or len(set(ids)) != len(ids):
        ids = list(range(len(pairs)))
    if all(p.precision_px is None for p in pairs):
        return ids, None
    return ids, np.array([p.precision_px if p.precision_px is not None else 1.0 for p in pairs], dtype=np.float64)


def calibrate(pairs: Sequence[Any], depth: Any, camera: Any, *, cost: str = "angular", **options: Any):
    """Solve ``T_camera_lidar`` from :class:`calib_core.pairs.Pair` objects.

    Parameters
    ----------
    pairs : sequence of Pair
        ``laser_rc`` (a cell of ``depth``) or ``laser_xyz`` (lidar frame, metres), and ``pixel``.
    depth : DepthMatrix or None
        Needed when a pair names a cell.
    camera : CameraModel
    cost : {"angular", "geodesic", "pixel"}
    **options
        Passed to :func:`calib_core.solve.solve_extrinsics` (e.g. ``robust``).

    Returns
    -------
    CalibrationResult
        ``outliers`` are positions in ``pairs``; ``outlier_ids`` their ids.
    """
    from ..pairs import resolve_pairs
    from . import solve_extrinsics
    from .whiten import cell_pick_covariance

    points, bearings, pixels = resolve_pairs(pairs, depth, camera)
    ids, sigmas = pair_ids_and_sigmas(pairs)
    laser_cov = None
    cells = [i for i, p in enumerate(pairs) if p.laser_rc is not None]
    if cells and depth is not None:
        laser_cov = np.zeros((len(pairs), 3, 3))
        rc = np.array([pairs[i].laser_rc for i in cells], dtype=np.int64)
        laser_cov[cells] = cell_pick_covariance(depth, rc, RANGE_SIGMA_M)
    return solve_extrinsics(
        points, bearings, camera=camera, pixels=pixels, cost=cost, pair_ids=ids, pixel_sigma=sigmas,
        laser_cov_m2=laser_cov, **options,
    )
