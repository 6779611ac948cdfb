"""From pairs (as a user makes them) to a calibration: the one call the CLI and the app share.

:func:`calibrate` resolves the pairs (laser cells or points, clicked pixels),
takes each pair's id and ``precision_px``, models the laser pick of a whole
depth-matrix cell (:func:`calib_core.solve.whiten.cell_pick_covariance`) and
the error by-eye pairs share (:data:`calib_core.solve.whiten.BY_EYE_SHARED_RATIO`),
and calls :func:`calib_core.solve.solve_extrinsics`.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from .whiten import BY_EYE_SHARED_RATIO, PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M

__all__ = ["calibrate", "default_shared_ratio", "pair_edge_degrees", "pair_ids_and_sigmas"]


def default_shared_ratio(pairs: Sequence[Any], depth: Any) -> float:
    """The shared part of the pairs' error (:data:`calib_core.solve.whiten.BY_EYE_SHARED_RATIO`) where it applies.

    It was measured on cells of measured scans (organised from a sensor's points: ``depth.meta["model"] ==
    "organized"``) picked by eye and scored against published calibrations, so it holds what such pairs
    share: a person's reading of where an object's corner is, and the sensor's own part (edge returns,
    motion during the sweep, the reference's error).  An ideal synthetic scan (the sample, the simulated
    scenes: its points exact by construction, its clicks simulated in the tests) has no such measurement:
    0 there, and for pairs that name a lidar point instead of a cell.  With some pairs of each kind, the
    ratio times the share of the pairs that name a cell of a measured scan.
    """
    if not pairs or depth is None or getattr(depth, "meta", {}).get("model") != "organized":
        return 0.0
    return BY_EYE_SHARED_RATIO * sum(p.laser_rc is not None for p in pairs) / len(pairs)


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


def pair_edge_degrees(pairs: Sequence[Any]) -> np.ndarray | None:
    """Each pair's ``edge_deg`` (degrees, :attr:`calib_core.pairs.Pair.edge_deg`) for
    :func:`calib_core.solve.solve_extrinsics`' ``pixel_edge_deg``: NaN for a corner pair, None when no pair
    is an edge pair.

    Raises
    ------
    CalibError
        An ``edge_deg`` that is not a finite number (one line naming the pair by its id, else its position).
    """
    from ..errors import CalibError

    edges = [getattr(p, "edge_deg", None) for p in pairs]
    if all(e is None for e in edges):
        return None
    out = np.full(len(pairs), np.nan)
    for k, e in enumerate(edges):  # (a Python list of pairs: one check per pair, no array yet)
        if e is None:
            continue
        try:
            value = float(e)
        except (TypeError, ValueError):
            value = float("nan")
        if isinstance(e, bool) or not np.isfinite(value):
            name = f"pair {pairs[k].id}" if getattr(pairs[k], "id", None) is not None else f"pair {k}"
            raise CalibError(f"{name}: edge_deg must be a finite angle in degrees, got {e!r}"[:300])
        out[k] = value % 180.0
    return out


def calibrate(pairs: Sequence[Any], depth: Any, camera: Any, *, cost: str = "angular",
              cell_sigma: float | tuple[float, float] = PICK_CELL_SIGMA, range_sigma_m: float = PICK_RANGE_SIGMA_M,
              shared_ratio: float | None = None, **options: Any):
    """Solve ``T_camera_lidar`` from :class:`calib_core.pairs.Pair` objects.

    Parameters
    ----------
    pairs : sequence of Pair
        ``laser_rc`` (a cell of ``depth``) or ``laser_xyz`` (lidar frame, metres), and ``pixel``.
    depth : DepthMatrix or None
        Needed when a pair names a cell.
    camera : CameraModel
    cost : {"angular", "geodesic", "pixel"}
    cell_sigma, range_sigma_m : optional
        The laser pick model of the pairs that name a cell (cells across the beam, rows then
        columns; metres along it): :func:`calib_core.solve.whiten.cell_pick_covariance`'s
        defaults unless a study of the model asks for others.
    shared_ratio : float, optional
        The part of the pairs' error they share, as a variance ratio to the independent part: the
        covariance and sigmas are ``1 + shared_ratio`` times wider in variance than the residuals
        alone say.  None (default): :func:`default_shared_ratio` (by-eye picks on a measured scan);
        0 for errors known to be independent (simulated clicks).
    **options
        Passed to :func:`calib_core.solve.solve_extrinsics` (e.g. ``robust``).

    Returns
    -------
    CalibrationResult
        Pairs marked ``check`` are left out of the fit; their errors at the pose are in
        ``check_residual_px`` / ``check_residual_deg``.  Edge pairs (``edge_deg`` set) are solved as
        point-on-line pairs (``pixel_edge_deg`` of :func:`calib_core.solve.solve_extrinsics`), and their
        pixel errors (``residual_px``, the mean, ``check_residual_px``, the leave-one-out errors) are
        distances ACROSS the edge; and ``pair_positions`` maps the
        result's rows (and ``outliers``) to positions in ``pairs``.  ``outlier_ids`` are ids.
    """
    from ..pairs import resolve_pairs
    from .extrinsics import solve_extrinsics
    from .bearing_pnp import angular_errors_rad
    from .edges import edge_pixel_errors
    from .whiten import pairs_pick_covariance

    all_ids, _ = pair_ids_and_sigmas(pairs)
    if shared_ratio is None:
        shared_ratio = default_shared_ratio([p for p in pairs if not getattr(p, "check", False)], depth)
    fit = [i for i, p in enumerate(pairs) if not getattr(p, "check", False)]
    checks = [i for i, p in enumerate(pairs) if getattr(p, "check", False)]
    fit_pairs = [pairs[i] for i in fit]
    points, bearings, pixels = resolve_pairs(fit_pairs, depth, camera)
    _, sigmas = pair_ids_and_sigmas(fit_pairs)
    edges = pair_edge_degrees(fit_pairs)
    check_edges = pair_edge_degrees([pairs[i] for i in checks])
    laser_cov = pairs_pick_covariance(fit_pairs, depth, cell_sigma, range_sigma_m)
    result = solve_extrinsics(
        points, bearings, camera=camera, pixels=pixels, cost=cost, pair_ids=[all_ids[i] for i in fit],
        pixel_sigma=sigmas, laser_cov_m2=laser_cov, shared_ratio=shared_ratio,
        **({} if edges is None else {"pixel_edge_deg": edges}), **options,
    )
    from .quality import with_leave_one_out  # leave-one-out errors and leverages: does the fit flatter few pairs?

    with_leave_one_out(result, points, pixels, camera, sigmas, [all_ids[i] for i in fit], pixel_edge_deg=edges)
    if checks:
        T = result.T_camera_lidar
        cp, cb, cpx = resolve_pairs([pairs[i] for i in checks], depth, camera)
        uv, ok = camera.project(cp @ T[:3, :3].T + T[:3, 3])
        err = edge_pixel_errors(np.asarray(uv, dtype=np.float64), cpx, check_edges)  # (across an edge pair's edge)
        result.check_residual_px = np.where(np.asarray(ok, dtype=bool) & np.isfinite(err), err, np.nan)
        result.check_residual_deg = np.degrees(angular_errors_rad(T, cp, cb))
        result.pair_positions = fit
        result.check_positions = checks
        result.check_ids = [all_ids[i] for i in checks]
    return result
