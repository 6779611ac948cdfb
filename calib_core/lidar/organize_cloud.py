"""Choose how a point cloud becomes a depth matrix, and say what it kept.

:func:`organize_cloud` is the dispatch behind ``load_scan(organize=...)``:
it picks the method (``auto``) or runs the one asked for, records an
:class:`~calib_core.lidar.report.OrganizeReport` in
``meta["organize_report"]`` and refuses clouds that do not look like one
sensor's view.  Lidar frame: metres; with ``sensor_origin`` the cloud's
frame shifted to that point (axes unchanged).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix
from .firing_order import NotFiringOrder
from .organize import (
    count_beam_elevations,
    crop_to_field_of_view,
    default_spherical_resolution_deg,
    narrow_field_of_view,
    narrow_field_resolution_deg,
    organize_by_elevation,
    organize_by_firing_order,
    organize_by_ring,
    organize_grid,
    organize_spherical,
)
from .report import check_points_kept, organize_report

#: ``organize=`` choices; "firing" is a short alias of "firing_order".
ORGANIZE_METHODS = ("auto", "organized", "ring", "elevation", "firing_order", "firing", "spherical")


def parse_sensor_origin(value) -> np.ndarray | None:
    """``(3,)`` float64 scanner position in the cloud's frame (metres), or None."""
    if value is None:
        return None
    try:
        origin = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise CalibError(f"sensor origin must be three numbers X Y Z (metres), got {value!r}") from None
    if origin.shape != (3,) or not np.isfinite(origin).all() or np.abs(origin).max() > 1e7:
        raise CalibError(f"sensor origin must be three finite numbers X Y Z (metres), got {value!r}")
    return origin


def _resolution(v_res_deg, h_res_deg, default_deg, why: str) -> tuple[float, float, str]:
    """The cell size (degrees) given, or ``default_deg()`` where not given, and the note that says so."""
    if v_res_deg is not None and h_res_deg is not None:
        return v_res_deg, h_res_deg, ""
    default = default_deg()
    note = f"spherical cells of {default} deg ({why}; --h-res-deg/--v-res-deg to change)"
    return (default if v_res_deg is None else v_res_deg), (default if h_res_deg is None else h_res_deg), note


def _spherical(xyz, v_res_deg, h_res_deg, v_range_deg) -> tuple[DepthMatrix, str]:
    v_res_deg, h_res_deg, note = _resolution(v_res_deg, h_res_deg, lambda: default_spherical_resolution_deg(xyz),
                                             "default")
    depth = organize_spherical(xyz, v_res_deg, h_res_deg, v_range_deg)
    if note:
        depth = dataclasses.replace(depth, meta={**depth.meta, "spherical_resolution": note})
    return depth, note


#: Seen from the origin, at most this share of a narrow field's points may lie behind nearer ones.
MAX_BEHIND_SHARE = 0.05


def _narrow_field(xyz, field, v_res_deg, h_res_deg, v_range_deg) -> tuple[DepthMatrix, str]:
    """A cloud seen over a narrow field (an RGB-D frame): one cell per point, columns cut to the field.

    Refused when too many points lie behind nearer points of their cell: not
    one view from the origin (an object scanned from around it).
    """
    v_res_deg, h_res_deg, note = _resolution(v_res_deg, h_res_deg, lambda: narrow_field_resolution_deg(xyz),
                                             "one per point")
    depth = crop_to_field_of_view(organize_spherical(xyz, v_res_deg, h_res_deg, v_range_deg))
    behind = depth.meta["n_points_behind"] / max(int(depth.meta["n_points_in"] - depth.meta["n_points_dropped"]), 1)
    if behind > MAX_BEHIND_SHARE:
        raise CalibError(
            f"the cloud does not look like a scan seen from the lidar origin: {100 * behind:.0f} % of its points lie "
            f"behind nearer points in the same direction (an object scanned from around it?; give the scanner "
            f"position with --sensor-origin X Y Z if the points are in a world frame)"
        )
    where = f"a narrow field of {field[0]:.0f} x {field[1]:.0f} deg seen from the origin (an RGB-D frame?)"
    if "cropped_cols" in depth.meta:
        where += ", columns cut to it"
    note = f"{where}; {note}" if note else where
    return dataclasses.replace(depth, meta={**depth.meta, "spherical_resolution": note}), note


#: A firing order that loses more points than this to shared cells is not one.
MAX_FIRING_ORDER_LOSS = 0.05


def _check_firing_layout(depth: DepthMatrix) -> None:
    """Refuse sweeps that are not a sensor's lasers: too many points share cells."""
    report = organize_report(depth)
    if 1.0 - report.kept_share > MAX_FIRING_ORDER_LOSS:
        raise NotFiringOrder(
            f"the cloud does not look like beams stored in firing order: the {report.rows} azimuth sweeps "
            f"found would lose {100 * (1.0 - report.kept_share):.0f} % of the points to shared cells"
        )


def organize_cloud(
    xyz: np.ndarray,
    *,
    ring: np.ndarray | None = None,
    ring_name: str = "ring",
    organized_shape: tuple[int, int] | None = None,
    organize: str = "auto",
    beams: int | None = None,
    n_cols: int | None = None,
    v_res_deg: float | None = None,
    h_res_deg: float | None = None,
    v_range_deg: tuple[float, float] | None = None,
    wrap_cols: bool | None = None,
    sensor_origin=None,
    min_kept_share: float | None = None,
) -> DepthMatrix:
    """Organise a cloud into a depth matrix.

    ``auto`` takes, in this order: the file's own grid (``organized_shape``);
    the ring field; the scan order (points stored laser after laser, see
    :func:`~calib_core.lidar.firing_order.firing_order_rings`); and when the
    order is not a firing order, elevation clustering into ``beams`` beams
    if given (seen from the beams' common origin height), else into the
    beams found as separate elevations (:func:`count_beam_elevations`),
    else spherical binning: over a narrow field seen from the origin (an
    RGB-D frame, :func:`narrow_field_of_view`) one cell per point with the
    columns cut to that field, else :func:`default_spherical_resolution_deg`.
    The reason for the choice is in the report.

    Parameters
    ----------
    xyz : (N, 3) float
        Points in storage order, metres.
    ring : (N,) int, optional
        Per-point beam index (a ring field), named ``ring_name``.
    organized_shape : (H, W), optional
        The file's own grid, when the cloud is organized.
    organize : str
        One of :data:`ORGANIZE_METHODS`: ``"auto"`` as above, ``"organized"`` the file's grid (an error without
        one); the others force that method (``"firing"`` is ``"firing_order"``).
    beams, n_cols, v_res_deg, h_res_deg, v_range_deg, wrap_cols :
        See :mod:`calib_core.lidar.organize`.  Without ``n_cols``, a given
        ``h_res_deg`` (degrees) also sets the columns of the ring, firing
        and elevation layouts (``round(360 / h_res_deg)``).
    sensor_origin : (3,) float, optional
        Scanner position in the cloud's frame (metres), for scans stored in
        a world frame; the points are shifted so that it is the origin.
    min_kept_share : float, optional
        Refuse when fewer usable points are kept (default
        :data:`~calib_core.lidar.report.MIN_POINTS_KEPT_SHARE`); not applied
        to organized grids.

    Returns
    -------
    DepthMatrix
        ``meta["organize_report"]`` holds the :class:`OrganizeReport`;
        ``meta["sensor_origin"]`` the shift applied, if any.

    Raises
    ------
    CalibError
        Bad options, or a cloud that does not look like a scan seen from
        the lidar origin.
    """
    if organize not in ORGANIZE_METHODS:
        raise CalibError(f"unknown organize method '{organize}' (one of {', '.join(ORGANIZE_METHODS)})")
    if beams is not None and (isinstance(beams, bool) or not isinstance(beams, (int, np.integer)) or beams < 1):
        raise CalibError(f"beams must be a positive integer, got {beams!r}")
    method = "firing_order" if organize == "firing" else organize
    origin = parse_sensor_origin(sensor_origin)
    # The azimuth resolution, when given, also sets the columns of the beam-based layouts.
    beam_cols = n_cols if n_cols is not None or h_res_deg is None else max(int(round(360.0 / float(h_res_deg))), 1)
    points = np.asarray(xyz, dtype=np.float64)
    if origin is not None:
        points = points - origin

    reason = ""
    if method == "auto" and organized_shape is not None and min(organized_shape) < 2:
        organized_shape = None  # an N x 1 "grid" (PCD WIDTH 1) is a list of points
    if method == "organized" or (method == "auto" and organized_shape is not None):
        if organized_shape is None:
            raise CalibError("the cloud is not organized (it has no WIDTH x HEIGHT grid)")
        depth = organize_grid(points.reshape(*organized_shape, 3), wrap_cols=wrap_cols)
        reason = f"the file's own {organized_shape[0]} x {organized_shape[1]} grid" if method == "auto" else ""
    elif method == "ring" or (method == "auto" and ring is not None):
        if ring is None:
            raise CalibError("the cloud has no ring field: organise it another way (--organize elevation --beams N)")
        depth = organize_by_ring(points, ring, n_cols=beam_cols)
        reason = f"ring field '{ring_name}'" if method == "auto" else ""
    elif method == "auto":
        try:
            depth = organize_by_firing_order(points, beams, n_cols=beam_cols, pad_cropped=True)
            _check_firing_layout(depth)
            reason = f"no ring field; points stored laser after laser ({depth.meta['n_sweeps']} azimuth sweeps)"
            if depth.meta.get("n_empty_beams_added"):
                why_rows = f"beams={beams}" if beams is not None else (
                    f"a cloud cropped in azimuth, taken as a {depth.shape[0]}-beam sensor; pass --beams N to change"
                )
                reason += f", {depth.meta['n_empty_beams_added']} empty rows added at the {depth.meta['empty_beams_at']} ({why_rows})"
        except NotFiringOrder as err:
            why = str(err).replace("the cloud does not look like", "not").rstrip(".")
            if beams is not None:
                depth = organize_by_elevation(points, beams, n_cols=beam_cols, range_aware=True)
                height = depth.meta["beam_origin_height_m"]
                reason = f"fallback to elevation clustering into {beams} beams (seen from {height:+.2f} m): {why}"
            elif (found := count_beam_elevations(points)) is not None:
                depth = organize_by_elevation(points, found, n_cols=beam_cols)
                reason = f"fallback to elevation clustering: {why}; the elevations fall into {found} separate beams"
            elif (field := narrow_field_of_view(points)) is not None:
                depth, note = _narrow_field(points, field, v_res_deg, h_res_deg, v_range_deg)
                reason = f"fallback to spherical binning: {why}; {note}"
            else:
                depth, note = _spherical(points, v_res_deg, h_res_deg, v_range_deg)
                reason = f"fallback to spherical binning: {why}; {note or 'resolution as given'}; pass --beams N for one row per beam"
    elif method in ("elevation", "firing_order"):
        if beams is None and method == "elevation":
            raise CalibError(f"organize='{method}' needs the number of beams (--beams N; beams=... from Python)")
        depth = organize_by_elevation(points, beams, n_cols=beam_cols) if method == "elevation" else organize_by_firing_order(points, beams, n_cols=beam_cols)
    else:
        depth, reason = _spherical(points, v_res_deg, h_res_deg, v_range_deg)

    report = organize_report(depth, reason)
    if report.method != "organized":
        check_points_kept(report, *(() if min_kept_share is None else (min_kept_share,)))
    meta = {**depth.meta, "organize_report": report}
    if origin is not None:
        meta["sensor_origin"] = origin
    return dataclasses.replace(depth, meta=meta)
