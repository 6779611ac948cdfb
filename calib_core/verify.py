"""Checking a calibration: check pairs, leave-one-out, expected error over the image, a reference.

* **Check pairs** (``Pair.check``) are left out of the fit; their errors under
  the fitted pose are reported apart.  They are the honest test of a result.
* **Leave-one-out**: each fit pair's error under the pose fitted without it.
  Its click was not used by that pose, so the error is distributed like the
  error of a fresh click on the same point: it predicts how well the
  calibration maps points it was not fitted to.
* **Expected reprojection error** over the image: the pose covariance
  ``Sigma`` (6x6 over ``(delta, t)``, see :class:`calib_core.solve.CalibrationResult`)
  propagated to pixels, ``C = J Sigma J^T`` with ``J = d pixel / d (delta, t)``
  at each scene point; the map holds ``sqrt(trace C)`` (the RMS pixel error
  the pose uncertainty alone causes), averaged over the points in each cell.
* **Reference extrinsic**: the rotation angle (deg) and translation
  difference (cm) between two ``T_camera_lidar``, and the pixel distance
  between the scene projected with each.

:func:`verification_to_dict` gives the ``verification:`` block of the
extrinsics YAML; the caller merges it into the document it saves.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .arrays import angle_between_rad
from .errors import CalibError
from .io.extrinsics import finite_or_none
from .solve import MIN_PAIRS, CalibrationResult, solve_extrinsics
from .transforms import rotation_angle_deg, transform_points

__all__ = [
    "VerifyReport",
    "verify_calibration",
    "verify_pairs",
    "leave_one_out",
    "pixel_errors",
    "projects_outside",
    "expected_error_px",
    "expected_error_map",
    "compare_to_reference",
    "error_vs_pair_count",
    "verification_to_dict",
    "extrinsics_document",
]


@dataclass
class VerifyReport:
    """What :func:`verify_calibration` finds.

    Attributes
    ----------
    result : CalibrationResult
        The fit on the fit pairs only (check pairs left out).
    fit_index, check_index : (n_fit,), (n_check,) int arrays
        Positions of the fit pairs and the check pairs in the input.
    ids : list
        The pairs' ids (``Pair.id``, or the position when None), input order.
    check_px, check_deg : (n_check,) arrays
        Error of each check pair under ``result.T_camera_lidar`` (px NaN when
        it does not project into the image or there is no camera).
    check_outside : (n_check,) bool array
        True where the check pair's laser point projects outside the image
        (or behind the camera) under ``result.T_camera_lidar``: it has no pixel
        error, only an angle; a warning names it.
    loo_px, loo_deg : (n_fit,) arrays
        Leave-one-out error of each fit pair.
    pairs_vs_count : dict or None
        :func:`error_vs_pair_count` output.
    reference : dict or None
        :func:`compare_to_reference` output.
    warnings : list of str
    """

    result: CalibrationResult
    fit_index: np.ndarray
    check_index: np.ndarray
    ids: list
    check_px: np.ndarray
    check_deg: np.ndarray
    loo_px: np.ndarray
    loo_deg: np.ndarray
    pairs_vs_count: dict | None = None
    reference: dict | None = None
    warnings: list[str] = field(default_factory=list)
    check_outside: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


# --------------------------------------------------------------------------------------
# errors of pairs under a pose
# --------------------------------------------------------------------------------------


def pixel_errors(T_camera_lidar: np.ndarray, points_lidar: np.ndarray, pixels: np.ndarray, camera) -> np.ndarray:
    """``|project(T X) - pixel|`` in px; NaN where the point does not project into the image."""
    projected, valid = camera.project(transform_points(T_camera_lidar, points_lidar))
    err = np.linalg.norm(np.asarray(projected, dtype=np.float64) - pixels, axis=1)
    return np.where(np.asarray(valid, bool) & np.isfinite(err), err, np.nan)


def projects_outside(T_camera_lidar: np.ndarray, points_lidar: np.ndarray, camera) -> np.ndarray:
    """``(N,)`` bool: True where a laser point (lidar frame, m) does not project into the image under the pose."""
    _, valid = camera.project(transform_points(T_camera_lidar, points_lidar))
    return ~np.asarray(valid, bool).reshape(-1)


def angular_errors_deg(T_camera_lidar: np.ndarray, points_lidar: np.ndarray, bearings: np.ndarray) -> np.ndarray:
    """Angle (deg) between each bearing and the direction of its transformed laser point."""
    return np.degrees(angle_between_rad(transform_points(T_camera_lidar, points_lidar), bearings))


def leave_one_out(
    points_lidar: np.ndarray,
    bearings: np.ndarray,
    pixels: np.ndarray | None = None,
    camera=None,
    T_start: np.ndarray | None = None,
    cost: str = "angular",
) -> tuple[np.ndarray, np.ndarray]:
    """Each pair's error under the pose fitted to all the other pairs.

    Parameters
    ----------
    points_lidar, bearings : (N, 3) arrays
        Laser points (lidar frame, m) and unit bearings (camera frame).
    pixels : (N, 2) array, optional
        Clicked pixels, for the pixel errors (with ``camera``).
    T_start : (4, 4) array, optional
        Starting pose of every refit (the full fit's pose: faster, and the
        same optimum).
    cost : {"angular", "pixel"}

    Returns
    -------
    loo_px, loo_deg : (N,) arrays
        NaN where the refit fails (fewer than 5 pairs, degenerate rest) or,
        for px, where the point does not project into the image.
    """
    n = len(points_lidar)
    loo_px, loo_deg = np.full(n, np.nan), np.full(n, np.nan)
    if n <= MIN_PAIRS:
        return loo_px, loo_deg
    keep = np.ones(n, bool)
    # One refit per pair: n solves, not a loop over pixels.  No outlier search in a refit: the pairs are the fit's
    # inliers already, and a refit that dropped another pair would score pair i against a different set (on the
    # by-eye PJLab pairs it doubled the mean, 27.9 px against a true 12.2 px).
    for i in range(n):
        keep[i] = False
        try:
            fit = solve_extrinsics(
                points_lidar[keep], bearings[keep], camera=camera,
                pixels=None if pixels is None else pixels[keep], cost=cost, initial_T_camera_lidar=T_start,
                robust=False,
            )  # fmt: skip
        except CalibError:
            keep[i] = True
            continue
        keep[i] = True
        T = fit.T_camera_lidar
        loo_deg[i] = angular_errors_deg(T, points_lidar[i : i + 1], bearings[i : i + 1])[0]
        if camera is not None and pixels is not None:
            loo_px[i] = pixel_errors(T, points_lidar[i : i + 1], pixels[i : i + 1], camera)[0]
    return loo_px, loo_deg


# --------------------------------------------------------------------------------------
# pose covariance -> pixels
# --------------------------------------------------------------------------------------


def expected_error_px(
    T_camera_lidar: np.ndarray, covariance_6x6: np.ndarray, camera, points_lidar: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RMS pixel error that the pose uncertainty causes at each scene point.

    ``C = J Sigma J^T`` with ``J = d pixel / d (delta, t)``
    (:func:`calib_core.guide.information.pixel_jacobians`).

    Returns
    -------
    rms_px : (N,) array
        ``sqrt(trace C)``; NaN where the point does not project into the image,
        inf where the covariance is undetermined.
    pixels : (N, 2) array
        The points' pixels under ``T_camera_lidar``.
    pixel_cov : (N, 2, 2) array
        ``C`` per point.
    """
    from .guide.information import pixel_jacobians

    points = np.asarray(points_lidar, dtype=np.float64)
    pixels, J, _ = pixel_jacobians(camera, T_camera_lidar, points)  # J: (N, 2, 6)
    with np.errstate(invalid="ignore", over="ignore"):
        C = J @ np.asarray(covariance_6x6, dtype=np.float64) @ np.transpose(J, (0, 2, 1))
        rms = np.sqrt(np.trace(C, axis1=1, axis2=2))
    _, valid = camera.project(transform_points(T_camera_lidar, points))
    rms = np.where(np.asarray(valid, bool), rms, np.nan)
    return rms, pixels, C


def expected_error_map(
    T_camera_lidar: np.ndarray,
    covariance_6x6: np.ndarray,
    camera,
    points_lidar: np.ndarray,
    cell_px: int = 16,
    max_points: int = 200_000,
) -> np.ndarray:
    """Heat map over the image of the expected reprojection error (px).

    Parameters
    ----------
    points_lidar : (N, 3) array
        Scene points (e.g. the scan's valid points), lidar frame, metres;
        evenly thinned to ``max_points``.
    cell_px : int
        Cell size of the map in image pixels.

    Returns
    -------
    (ceil(H / cell_px), ceil(W / cell_px)) float array
        Mean of :func:`expected_error_px` over the points in each cell; NaN
        where no scene point projects.  Cell ``(r, c)`` covers pixels
        ``u in [c cell_px, (c+1) cell_px)``, ``v`` likewise (centre of the
        top-left pixel at ``(0, 0)``).
    """
    if cell_px < 1:
        raise CalibError(f"cell_px must be at least 1, got {cell_px}")
    pts = np.asarray(points_lidar, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) > max_points:
        pts = pts[:: int(np.ceil(len(pts) / max_points))]
    rms, pix, _ = expected_error_px(T_camera_lidar, covariance_6x6, camera, pts)
    H, W = int(np.ceil(camera.height / cell_px)), int(np.ceil(camera.width / cell_px))
    ok = np.isfinite(rms)
    cells = np.floor((pix[ok] + 0.5) / cell_px).astype(np.int64)
    cells = np.clip(cells, 0, [W - 1, H - 1])
    flat = cells[:, 1] * W + cells[:, 0]
    total = np.bincount(flat, weights=rms[ok], minlength=H * W)
    count = np.bincount(flat, minlength=H * W)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan).reshape(H, W)


# --------------------------------------------------------------------------------------
# reference extrinsic
# --------------------------------------------------------------------------------------


def compare_to_reference(
    T_camera_lidar: np.ndarray,
    T_reference: np.ndarray,
    camera=None,
    points_lidar: np.ndarray | None = None,
    max_points: int = 200_000,
) -> dict[str, Any]:
    """Difference between a calibration and a reference ``T_camera_lidar``.

    Returns
    -------
    dict
        ``rotation_deg`` (angle of ``R_ref^T R``), ``translation_cm`` (norm of
        the translation difference), and with a camera and scene points
        ``px_mean``, ``px_median``, ``px_max``, ``n_points``: the distance
        between each point's pixels under the two poses, over the points that
        project into the image under both.
    """
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    R = np.asarray(T_reference, dtype=np.float64)
    out: dict[str, Any] = {
        "rotation_deg": rotation_angle_deg(R[:3, :3], T[:3, :3]),
        "translation_cm": float(100.0 * np.linalg.norm(T[:3, 3] - R[:3, 3])),
    }
    if camera is not None and points_lidar is not None:
        pts = np.asarray(points_lidar, dtype=np.float64)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts) > max_points:
            pts = pts[:: int(np.ceil(len(pts) / max_points))]
        a, va = camera.project(transform_points(T, pts))
        b, vb = camera.project(transform_points(R, pts))
        both = np.asarray(va, bool) & np.asarray(vb, bool)
        d = np.linalg.norm(np.asarray(a)[both] - np.asarray(b)[both], axis=1)
        out.update(
            px_mean=float(d.mean()) if d.size else float("nan"),
            px_median=float(np.median(d)) if d.size else float("nan"),
            px_max=float(d.max()) if d.size else float("nan"),
            n_points=int(d.size),
        )
    return out


# --------------------------------------------------------------------------------------
# error against the number of pairs
# --------------------------------------------------------------------------------------


def error_vs_pair_count(
    points_lidar: np.ndarray,
    bearings: np.ndarray,
    pixels: np.ndarray | None,
    camera,
    check: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Fit on the first k fit pairs (in their order) for every k from 5 to n.

    Returns
    -------
    dict of arrays, one entry per k
        ``n_pairs``; ``fit_px`` (mean residual of the k pairs); ``check_px``
        (mean error of the check pairs under that fit, NaN without check
        pairs); ``sigma_rotation_deg`` (norm of the roll/pitch/yaw sigmas);
        ``sigma_translation_cm`` (norm of the translation sigmas).  NaN where
        the fit fails.
    """
    check = np.zeros(len(points_lidar), bool) if check is None else np.asarray(check, bool)
    fit_idx = np.flatnonzero(~check)
    chk_idx = np.flatnonzero(check)
    ks = np.arange(MIN_PAIRS + 1, len(fit_idx) + 1)
    out = {name: np.full(len(ks), np.nan) for name in ("fit_px", "check_px", "sigma_rotation_deg", "sigma_translation_cm")}
    out["n_pairs"] = ks
    for j, k in enumerate(ks):  # one solve per count
        sel = fit_idx[:k]
        try:
            r = solve_extrinsics(points_lidar[sel], bearings[sel], camera=camera, pixels=None if pixels is None else pixels[sel])
        except CalibError:
            continue
        out["fit_px"][j] = r.mean_px
        out["sigma_rotation_deg"][j] = float(np.linalg.norm(r.sigma_rpy_deg))
        out["sigma_translation_cm"][j] = float(100.0 * np.linalg.norm(r.sigma_translation_m))
        if chk_idx.size and camera is not None and pixels is not None:
            mean = _mean(pixel_errors(r.T_camera_lidar, points_lidar[chk_idx], pixels[chk_idx], camera))
            out["check_px"][j] = np.nan if mean is None else mean  # NaN: every check pair projects off the image
    return out


# --------------------------------------------------------------------------------------
# everything at once
# --------------------------------------------------------------------------------------


def verify_calibration(
    points_lidar: np.ndarray,
    bearings: np.ndarray,
    pixels: np.ndarray | None = None,
    camera=None,
    check: Sequence[bool] | np.ndarray | None = None,
    ids: Sequence | None = None,
    T_reference: np.ndarray | None = None,
    scene_points_lidar: np.ndarray | None = None,
    cost: str = "angular",
    with_pair_count: bool = True,
    result: CalibrationResult | None = None,
) -> VerifyReport:
    """Fit on the fit pairs, then check pairs, leave-one-out and (optionally) a reference.

    Parameters
    ----------
    points_lidar, bearings, pixels :
        As for :func:`calib_core.solve.solve_extrinsics`, all pairs.
    check : (N,) bool, optional
        True for the check pairs (left out of the fit).
    ids : sequence, optional
        The pairs' ids for reporting (default: their positions).
    T_reference : (4, 4) array, optional
        An imported reference ``T_camera_lidar`` to compare with.
    scene_points_lidar : (M, 3) array, optional
        Scene points for the pixel comparison with the reference.
    result : CalibrationResult, optional
        The fit of the fit pairs already made (e.g. by
        :func:`calib_core.solve.calibrate`, whose rows are the fit pairs in
        order): used instead of fitting again, so the report describes that
        pose.  Pairs it left out as outliers are left out of the other pairs'
        leave-one-out refits; their own leave-one-out error is their error
        under ``result`` (a pose fitted without them).

    Raises
    ------
    CalibError
        Fewer than 4 fit pairs, or the fit fails.
    """
    points = np.asarray(points_lidar, dtype=np.float64)
    bear = np.asarray(bearings, dtype=np.float64)
    pix = None if pixels is None else np.asarray(pixels, dtype=np.float64)
    n = len(points)
    check_mask = np.zeros(n, bool) if check is None else np.asarray(check, bool).reshape(-1)
    if check_mask.shape != (n,):
        raise CalibError(f"check must have one flag per pair ({n}), got {check_mask.size}")
    fit_idx, chk_idx = np.flatnonzero(~check_mask), np.flatnonzero(check_mask)
    if len(fit_idx) < MIN_PAIRS:
        raise CalibError(f"{len(fit_idx)} fit pairs ({len(chk_idx)} are check pairs); the fit needs at least {MIN_PAIRS}")
    if result is None:
        result = solve_extrinsics(
            points[fit_idx], bear[fit_idx], camera=camera, pixels=None if pix is None else pix[fit_idx], cost=cost
        )
    elif len(result.residual_deg) != len(fit_idx):
        raise CalibError(f"the given fit has {len(result.residual_deg)} pairs, but there are {len(fit_idx)} fit pairs")
    T = result.T_camera_lidar
    warnings: list[str] = []
    check_deg = angular_errors_deg(T, points[chk_idx], bear[chk_idx]) if chk_idx.size else np.zeros(0)
    check_outside = np.zeros(chk_idx.size, bool)
    if chk_idx.size and camera is not None and pix is not None:
        check_px = pixel_errors(T, points[chk_idx], pix[chk_idx], camera)
        check_outside = projects_outside(T, points[chk_idx], camera)
    else:
        check_px = np.full(chk_idx.size, np.nan)
    pair_ids = list(ids) if ids is not None else list(range(n))
    # Outliers the fit left out stay out of every refit; their own error is under the fit (made without them).
    inl = np.ones(len(fit_idx), bool)
    inl[[int(i) for i in getattr(result, "outliers", [])]] = False
    loo_px, loo_deg = np.full(len(fit_idx), np.nan), np.full(len(fit_idx), np.nan)
    sel = fit_idx[inl]
    loo_px[inl], loo_deg[inl] = leave_one_out(
        points[sel], bear[sel], None if pix is None else pix[sel], camera, T_start=T, cost=cost
    )
    out_idx = fit_idx[~inl]
    if out_idx.size:
        loo_deg[~inl] = angular_errors_deg(T, points[out_idx], bear[out_idx])
        if camera is not None and pix is not None:
            loo_px[~inl] = pixel_errors(T, points[out_idx], pix[out_idx], camera)
    if len(fit_idx) <= MIN_PAIRS:
        warnings.append(f"leave-one-out needs more than {MIN_PAIRS} fit pairs")
    for i in chk_idx[check_outside]:
        warnings.append(f"check pair {pair_ids[int(i)]}: its laser point projects outside the image under the fit, "
                        "so it has no pixel error (only its angle)")
    if chk_idx.size == 0:
        warnings.append("no check pairs: mark a few pairs as check pairs to test the result on clicks it was not fitted to")
    else:
        mean_check = _mean(check_px)
        if mean_check is not None and np.isfinite(result.mean_px) and mean_check > 3.0 * max(result.mean_px, 0.3):
            warnings.append(
                f"check pairs err {mean_check:.2f} px on average, over 3x the fit residual ({result.mean_px:.2f} px): "
                "the fit does not hold beyond its own pairs"
            )
    reference = None
    if T_reference is not None:
        reference = compare_to_reference(T, T_reference, camera, scene_points_lidar)
    count = error_vs_pair_count(points, bear, pix, camera, check_mask) if with_pair_count else None
    return VerifyReport(
        result=result,
        fit_index=fit_idx,
        check_index=chk_idx,
        ids=pair_ids,
        check_px=check_px,
        check_deg=check_deg,
        loo_px=loo_px,
        loo_deg=loo_deg,
        pairs_vs_count=count,
        reference=reference,
        warnings=warnings,
        check_outside=check_outside,
    )


def verify_pairs(pairs: Sequence, depth, camera, **kwargs) -> VerifyReport:
    """:func:`verify_calibration` on :class:`calib_core.pairs.Pair` objects (their ``check`` flags and ids)."""
    from .pairs import resolve_pairs

    points, bearings, pixels = resolve_pairs(pairs, depth, camera)
    ids = [p.id if p.id is not None else i for i, p in enumerate(pairs)]
    return verify_calibration(points, bearings, pixels, camera, check=[p.check for p in pairs], ids=ids, **kwargs)


def _mean(values: np.ndarray) -> float | None:
    finite = np.asarray(values, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    return float(finite.mean()) if finite.size else None


def verification_to_dict(report: VerifyReport) -> dict[str, Any]:
    """The ``verification:`` block for the extrinsics YAML (plain Python types, None for NaN).

    Layout::

        verification:
          n_fit_pairs: 10
          n_check_pairs: 2
          check_pairs: [{id, px, deg}, ...]        # under the fitted pose
          check_mean_px: ...
          leave_one_out: [{id, px, deg}, ...]      # each fit pair, pose fitted without it
          leave_one_out_mean_px: ...
          sigma: {translation_m: [...], rpy_deg: [...]}
          reference: {rotation_deg, translation_cm, px_mean, px_median, px_max, n_points}
          error_vs_pair_count: {n_pairs: [...], fit_px: [...], check_px: [...], ...}
          warnings: [...]
    """
    r = report.result
    ids = report.ids
    doc: dict[str, Any] = {
        "n_fit_pairs": int(report.fit_index.size),
        "n_check_pairs": int(report.check_index.size),
        "check_pairs": [
            {"id": ids[i], "px": finite_or_none(px), "deg": finite_or_none(deg)}
            for i, px, deg in zip(report.check_index, report.check_px, report.check_deg)
        ],
        "check_mean_px": _mean(report.check_px),
        "check_mean_deg": _mean(report.check_deg),
        "leave_one_out": [
            {"id": ids[i], "px": finite_or_none(px), "deg": finite_or_none(deg)}
            for i, px, deg in zip(report.fit_index, report.loo_px, report.loo_deg)
        ],
        "leave_one_out_mean_px": _mean(report.loo_px),
        "leave_one_out_mean_deg": _mean(report.loo_deg),
        "sigma": {
            "translation_m": [finite_or_none(v) for v in r.sigma_translation_m],
            "rpy_deg": [finite_or_none(v) for v in r.sigma_rpy_deg],
        },
    }
    if report.reference is not None:
        doc["reference"] = {k: (finite_or_none(v) if k != "n_points" else int(v)) for k, v in report.reference.items()}
    if report.pairs_vs_count is not None:
        doc["error_vs_pair_count"] = {
            k: ([int(v) for v in vals] if k == "n_pairs" else [finite_or_none(v) for v in vals]) for k, vals in report.pairs_vs_count.items()
        }
    doc["warnings"] = list(report.warnings)
    return doc


def extrinsics_document(
    result: CalibrationResult,
    pairs: Sequence,
    depth,
    camera,
    base_dir=None,
    report: VerifyReport | None = None,
    **verify_options: Any,
) -> tuple[dict[str, Any], list[str]]:
    """The extrinsics YAML document of a :func:`calib_core.solve.calibrate` result, with its ``verification:`` block.

    Parameters
    ----------
    result : CalibrationResult
        The fit of ``pairs`` (check pairs left out) by ``calibrate``.
    pairs : sequence of Pair
        All pairs, check pairs included.
    base_dir : path-like or None
        Folder the camera's file references are made relative to (None: the
        camera inline, for a download).
    report : VerifyReport, optional
        A report on this same fit, already computed; else :func:`verify_pairs`
        runs (with ``verify_options``, e.g. ``T_reference``).

    Returns
    -------
    doc : dict
        :func:`calib_core.io.extrinsics.extrinsics_to_dict` plus ``verification``.
    notes : list of str
        Why the document has no ``verification`` block, if it has none
        (e.g. too few fit pairs for it).
    """
    from .io.extrinsics import extrinsics_to_dict

    doc = extrinsics_to_dict(result.T_camera_lidar, result, camera, pairs, base_dir=base_dir)
    if report is None:
        try:
            report = verify_pairs(pairs, depth, camera, result=result, **verify_options)
        except CalibError as exc:
            return doc, [f"no verification block: {exc}"]
    doc["verification"] = verification_to_dict(report)
    return doc, []
