"""Lay out an unorganized spinning-lidar cloud as a depth matrix.

A spinning lidar measures one column of ``n_beams`` ranges per firing and
turns about its z axis, so its natural image has one row per beam (ring) and
one column per azimuth step.  Most drivers store the cloud as a flat list
with the no-return points dropped; this module puts the points back on that
grid, as array code.

Grid conventions (shared by every function here)
------------------------------------------------
* Lidar frame: metres, x forward, y left, z up.  Elevation
  ``asin(z / |p|)`` and azimuth ``atan2(y, x)`` in radians.
* Row 0 is the HIGHEST beam, so the image reads top-down.
* Columns cover 360 degrees (``wrap_cols=True``).  Column ``c`` is centred on
  azimuth ``pi - (c + 0.5) * 2 pi / W``: column 0 looks backwards, the image
  centre looks forward (+x), a quarter of the width looks left (+y), so the
  panorama is seen from inside, not mirrored.
* A cell keeps the NEARER point when several points fall into it.
* Valid cells hold the real measured point (never re-projected) with
  ``range_m = |point|`` and ``direction = point / |point|``.  Empty cells are
  invalid (range and point NaN) but still get a direction, from the row's
  elevation and the column's azimuth, so overlays and the UI can reason about
  them.
* Points that are not finite or sit at the origin (a common no-return code)
  are dropped and counted in ``meta["n_points_dropped"]``, as are points
  whose range over- or underflows (beyond 1e150 or below 1e-150 m).

``DepthMatrix.meta`` records ``organize`` (the method), ``model =
"organized"`` with ``points`` (so the native file stores the exact points),
``wrap_cols``, ``point_index`` ((H, W) index of each cell's point in the
input, -1 where empty), ``row_elevation_rad`` (H,), ``col_azimuth_rad`` (W,)
and the counts ``n_points_in``, ``n_points_dropped``, ``n_points_kept``,
``n_points_collided`` (points lost to a nearer one in the same cell),
``n_cells_with_collision`` and ``n_points_behind`` (collided points more
than :data:`BEHIND_SHARE` farther than their cell's nearest point: hidden,
seen from the origin).
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix
from .firing_order import AZIMUTH_HINT, azimuth_coverage, beam_origin_height, estimate_step, firing_order_rings, sequence_columns
from .organized import organized_cloud_depth
from .spherical import spherical_directions

TWO_PI = 2.0 * np.pi

#: Upper bound of the spherical fallback's default grid, in cells per point.
MAX_SPHERICAL_CELLS_PER_POINT = 4.0

#: A spherical grid whose columns leave at least this share of the turn empty in one arc is cut to the rest
#: (:func:`crop_to_field_of_view`); a cloud covering less azimuth than the rest is seen over a narrow field.
NARROW_FIELD_EMPTY_SHARE = 0.5

#: Field names that carry a spinning lidar's beam index.
RING_FIELD_NAMES = ("ring", "laser_id", "channel")


# --------------------------------------------------------------------------
# Small array helpers
# --------------------------------------------------------------------------


def _clean_points(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(N, 3)`` as float64 and the mask of usable ones (finite, not at the origin)."""
    points = np.asarray(xyz, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise CalibError(f"expected points of shape (N, 3), got {points.shape}")
    # Squared range in one pass; NaN/inf coordinates, the origin and ranges
    # that over- or underflow (beyond 1e150 or below 1e-150 m) are no measurement.
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        squared = np.einsum("ij,ij->i", points, points)
        keep = (squared > 1e-300) & (squared < 1e300)
    if not keep.any():
        raise CalibError(f"no usable points: all {len(points)} points are NaN/inf, at the origin or of absurd size")
    return points, keep


def _spherical_angles(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range (m), elevation and azimuth (rad) of points ``(N, 3)`` in the lidar frame."""
    range_m = np.linalg.norm(points, axis=1)
    elevation = np.arcsin(np.clip(points[:, 2] / range_m, -1.0, 1.0))
    azimuth = np.arctan2(points[:, 1], points[:, 0])
    return range_m, elevation, azimuth


def _group_median(values: np.ndarray, labels: np.ndarray, n_groups: int) -> np.ndarray:
    """Median of ``values`` per integer label ``0..n_groups-1`` (NaN for empty groups)."""
    # One float sort on label + value scaled into [0, 0.5): faster than lexsort.
    low, span = float(values.min()), float(np.ptp(values)) or 1.0
    order = np.argsort(labels + 0.5 * (values - low) / span)
    sorted_labels = labels[order]
    sorted_values = values[order]
    ids = np.arange(n_groups)
    starts = np.searchsorted(sorted_labels, ids, side="left")
    counts = np.searchsorted(sorted_labels, ids, side="right") - starts
    medians = np.full(n_groups, np.nan)
    has = counts > 0
    lo = starts[has] + (counts[has] - 1) // 2
    hi = starts[has] + counts[has] // 2
    medians[has] = 0.5 * (sorted_values[lo] + sorted_values[hi])
    return medians


def column_azimuths(n_cols: int) -> np.ndarray:
    """Azimuth (rad) of the centre of each of ``n_cols`` columns over 360 degrees.

    Column ``c`` looks at ``pi - (c + 0.5) * 2 pi / n_cols`` (column 0 looks
    backwards, the centre column forwards along +x, azimuth decreasing to the
    right so the panorama is not mirrored).
    """
    return np.pi - (np.arange(n_cols) + 0.5) * (TWO_PI / n_cols)


# --------------------------------------------------------------------------
# Estimating the grid
# --------------------------------------------------------------------------


def estimate_n_cols(azimuth_rad: np.ndarray, beam: np.ndarray) -> int:
    """Number of azimuth columns over 360 degrees, from the points of each beam.

    The typical azimuth step is the median gap between azimuth-sorted points
    of the same beam (gaps from dropped returns are rarer than regular steps,
    so they do not move the median).

    Parameters
    ----------
    azimuth_rad : (N,) float
        Point azimuths in radians.
    beam : (N,) int
        Beam (ring) label of every point.

    Returns
    -------
    int
        ``round(2 pi / step)``.
    """
    # One float sort by beam, then azimuth (in [-pi, pi], so beam * 8 separates beams).
    order = np.argsort(beam * 8.0 + (azimuth_rad + np.pi))
    az = azimuth_rad[order]
    same_beam = beam[order][1:] == beam[order][:-1]
    steps = np.diff(az)[same_beam]
    # Ignore exact duplicates (e.g. the start/end overlap of a sweep).
    steps = steps[steps > 1e-7]
    if steps.size < 8:
        raise CalibError(f"cannot estimate the azimuth resolution from {steps.size} azimuth steps; {AZIMUTH_HINT}")
    step = float(np.median(steps))
    return max(int(round(TWO_PI / step)), 1)


def cluster_elevations(elevation_rad: np.ndarray, n_beams: int, max_iter: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Cluster point elevations into ``n_beams`` beams (1-D k-means).

    Initialisation splits the sorted elevations at the ``n_beams - 1``
    widest gaps between *populated* elevation bins (bins holding at least a
    small share of a beam's points, so that isolated outliers cannot claim a
    gap); Lloyd iterations then refine the centres.  In one dimension the
    nearest-centre assignment is a ``searchsorted`` against the midpoints.

    Parameters
    ----------
    elevation_rad : (N,) float
        Point elevations in radians.
    n_beams : int
        Number of beams of the sensor.

    Returns
    -------
    labels : (N,) int64
        Beam index of every point, 0 = lowest beam.
    centres_rad : (n_beams,) float64
        Median elevation of every beam, ascending.
    """
    el = np.asarray(elevation_rad, dtype=np.float64)
    n_beams = int(n_beams)
    if n_beams < 1:
        raise CalibError(f"beams must be a positive integer, got {n_beams}")
    if el.size < n_beams:
        raise CalibError(f"cannot find {n_beams} beams in {el.size} points")
    if n_beams == 1:
        return np.zeros(el.size, dtype=np.int64), np.array([np.median(el)])

    lo, hi = float(el.min()), float(el.max())
    span = hi - lo
    if span <= 0.0:
        raise CalibError(f"cannot find {n_beams} beams: all points have the same elevation")
    # Bins much finer than any beam spacing (0.005 deg, or finer if the span is tiny).
    bin_width = min(np.radians(0.005), span / (50.0 * n_beams))
    n_bins = int(np.ceil(span / bin_width)) + 1
    bin_index = np.minimum(((el - lo) / bin_width).astype(np.int64), n_bins - 1)
    counts = np.bincount(bin_index, minlength=n_bins)
    min_support = max(2, int(0.002 * el.size / n_beams))
    populated = np.flatnonzero(counts >= min_support)
    if populated.size < n_beams:
        populated = np.flatnonzero(counts > 0)
    if populated.size < n_beams:
        raise CalibError(f"cannot find {n_beams} beams: the elevations take only {populated.size} distinct values")
    gaps = np.diff(populated)
    cut_after = np.sort(np.argpartition(gaps, -(n_beams - 1))[-(n_beams - 1):])
    # Bin boundaries halfway across each chosen gap -> initial labels.
    boundary_bins = 0.5 * (populated[cut_after] + populated[cut_after + 1])
    boundaries = lo + (boundary_bins + 0.5) * bin_width
    labels = np.searchsorted(boundaries, el)

    centres = np.full(n_beams, np.nan)
    for _ in range(max_iter):
        sums = np.bincount(labels, weights=el, minlength=n_beams)
        sizes = np.bincount(labels, minlength=n_beams)
        new_centres = np.where(sizes > 0, sums / np.maximum(sizes, 1), centres)
        new_centres = np.sort(np.where(np.isnan(new_centres), np.nanmean(new_centres), new_centres))
        new_labels = np.searchsorted(0.5 * (new_centres[1:] + new_centres[:-1]), el)
        converged = np.array_equal(new_labels, labels)
        labels, centres = new_labels, new_centres
        if converged:
            break
    return labels.astype(np.int64), _group_median(el, labels, n_beams)


# --------------------------------------------------------------------------
# Building the depth matrix
# --------------------------------------------------------------------------


#: A point farther than the nearest point of its cell by this share of that range lies behind it.
BEHIND_SHARE = 0.1


def _nearest_per_cell(cell: np.ndarray, range_m: np.ndarray, n_cells: int) -> tuple[np.ndarray, int, int]:
    """Indices of the nearest point of every occupied cell, the number of cells holding several points and
    the number of points lying behind a nearer one of their cell (more than :data:`BEHIND_SHARE` farther).

    Only the points of shared cells are sorted (usually few).
    """
    counts = np.bincount(cell, minlength=n_cells)
    shared = counts[cell] > 1
    alone = np.flatnonzero(~shared)
    if alone.size == len(cell):
        return alone, 0, 0
    contested = np.flatnonzero(shared)
    order = contested[np.lexsort((range_m[contested], cell[contested]))]
    first = np.r_[True, cell[order][1:] != cell[order][:-1]]
    winners = np.sort(np.r_[alone, order[first]])
    # Seen from the origin, a point behind a nearer one in the same direction would be hidden.
    nearest = range_m[order][np.maximum.accumulate(np.where(first, np.arange(order.size), 0))]
    behind = int(np.count_nonzero(range_m[order] > (1.0 + BEHIND_SHARE) * nearest))
    return winners, int(first.sum()), behind


def _assemble(
    points: np.ndarray,
    keep: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    row_elevation: np.ndarray,
    cell_azimuth: np.ndarray,
    meta: dict,
    kept_points: np.ndarray | None = None,
    kept_range: np.ndarray | None = None,
) -> DepthMatrix:
    """Scatter kept points into cells, nearer point wins.

    ``rows``/``cols`` are given for the kept points only; ``cell_azimuth`` is
    ``(W,)`` or ``(H, W)`` and, with ``row_elevation (H,)``, gives the
    direction of empty cells.  ``kept_points``/``kept_range``: ``points[keep]``
    and its ranges when the caller has them already.
    """
    n_rows, n_cols = len(row_elevation), cell_azimuth.shape[-1]
    kept_points = points[keep] if kept_points is None else kept_points
    kept_range = np.linalg.norm(kept_points, axis=1) if kept_range is None else kept_range
    cell = rows * n_cols + cols
    winners, cells_with_collision, n_behind = _nearest_per_cell(cell, kept_range, n_rows * n_cols)
    n_occupied = len(winners)

    target = cell[winners]
    winner_points, winner_range = kept_points[winners], kept_range[winners]
    range_m = np.full(n_rows * n_cols, np.nan)
    cell_points = np.full((n_rows * n_cols, 3), np.nan)
    range_m[target] = winner_range
    cell_points[target] = winner_points
    valid = np.zeros(n_rows * n_cols, dtype=bool)
    valid[target] = True
    # Directions: the measured one where a point is, the grid's elsewhere.
    directions = np.empty((n_rows * n_cols, 3))
    directions[target] = winner_points / winner_range[:, None]
    empty = np.flatnonzero(~valid)
    empty_row, empty_col = np.divmod(empty, n_cols)
    empty_azimuth = cell_azimuth[empty_row, empty_col] if cell_azimuth.ndim == 2 else cell_azimuth[empty_col]
    directions[empty] = spherical_directions(row_elevation[empty_row], empty_azimuth)
    point_index = np.full(n_rows * n_cols, -1, dtype=np.int64)
    point_index[target] = np.flatnonzero(keep)[winners]

    meta = dict(meta)
    meta.update(
        wrap_cols=True,
        n_points_in=int(len(points)),
        n_points_dropped=int(len(points) - keep.sum()),
        n_points_kept=n_occupied,
        n_points_collided=int(keep.sum() - n_occupied),
        n_cells_with_collision=cells_with_collision,
        n_points_behind=n_behind,
        row_elevation_rad=np.asarray(row_elevation, dtype=np.float64),
        col_azimuth_rad=column_azimuths(n_cols),
        point_index=point_index.reshape(n_rows, n_cols),
    )
    # model "organized": the native file stores these exact points (see npz_format).
    meta["model"] = "organized"
    meta["points"] = cell_points.reshape(n_rows, n_cols, 3)
    return DepthMatrix(
        range_m=range_m.reshape(n_rows, n_cols),
        directions=directions.reshape(n_rows, n_cols, 3),
        points=meta["points"],
        valid=valid.reshape(n_rows, n_cols),
        meta=meta,
    )


def _dense_labels(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(labels, return_inverse=True)``, without a sort for small non-negative integers."""
    labels = np.asarray(labels)
    if labels.size and labels.dtype.kind in "iu" and labels.min() >= 0 and labels.max() < 1_000_000:
        present = np.bincount(labels) > 0
        ids = np.flatnonzero(present)
        lookup = np.cumsum(present) - 1
        return ids.astype(labels.dtype), lookup[labels]
    ids, inverse = np.unique(labels, return_inverse=True)
    return ids, inverse.reshape(-1)


def _beam_elevation_at_infinity(
    points: np.ndarray, beam: np.ndarray, n_beams: int, fallback: np.ndarray, range_m: np.ndarray | None = None
) -> np.ndarray:
    """Each beam's elevation (rad) free of its origin's height above the lidar origin.

    A beam leaving from height ``h`` at elevation ``v`` measures
    ``z / |p| = sin v + h / |p|`` (to first order): a straight line in
    ``1 / |p|`` whose intercept is ``sin v``.  Least squares per beam; beams
    whose ranges hardly vary (no line to fit) keep ``fallback``.  ``range_m``:
    the points' ranges, when the caller has them.
    """
    range_m = np.linalg.norm(points, axis=1) if range_m is None else range_m
    x = 1.0 / np.maximum(range_m, 1.0)
    y = points[:, 2] / range_m
    n = np.bincount(beam, minlength=n_beams).astype(np.float64)
    sx, sy = np.bincount(beam, x, n_beams), np.bincount(beam, y, n_beams)
    sxx, sxy = np.bincount(beam, x * x, n_beams), np.bincount(beam, x * y, n_beams)
    det = n * sxx - sx * sx
    ok = (n >= 10) & (det > 1e-6 * np.maximum(n * n, 1.0) * np.maximum(sxx / np.maximum(n, 1.0), 1e-12))
    slope = np.where(ok, (n * sxy - sx * sy) / np.where(ok, det, 1.0), 0.0)
    intercept = (sy - slope * sx) / np.maximum(n, 1.0)
    return np.where(ok, np.arcsin(np.clip(intercept, -1.0, 1.0)), fallback)


def _organize_labelled(
    xyz: np.ndarray, beam: np.ndarray, n_cols: int | None, meta: dict, in_sequence: bool = False
) -> DepthMatrix:
    """Shared core: one row per distinct beam label, columns by azimuth.

    ``in_sequence``: the points of each beam are stored in firing order, so
    columns come from :func:`sequence_columns` (one cell per firing) and the
    resolution from the mean firing step.
    """
    points, keep = _clean_points(xyz)
    beam = np.asarray(beam)
    if beam.shape != (len(points),):
        raise CalibError(f"beam labels have shape {beam.shape}, expected ({len(points)},)")
    kept_points = points[keep]
    kept_range, elevation, azimuth = _spherical_angles(kept_points)
    beam_ids, beam_index = _dense_labels(beam[keep])
    n_rows = len(beam_ids)
    median_elevation = _group_median(elevation, beam_index, n_rows)
    if in_sequence:
        # Beams may start off the origin (an HDL-64E's lasers sit 0.1-0.25 m
        # above it): order them by their elevation far away, not as seen here.
        median_elevation = _beam_elevation_at_infinity(kept_points, beam_index, n_rows, median_elevation, kept_range)
    # Row 0 = highest beam.
    beam_order = np.argsort(-median_elevation, kind="stable")
    row_of_beam = np.empty(n_rows, dtype=np.int64)
    row_of_beam[beam_order] = np.arange(n_rows)
    rows = row_of_beam[beam_index]

    if n_cols is None:
        n_cols = round(TWO_PI / estimate_step(azimuth, rows)) if in_sequence else estimate_n_cols(azimuth, beam_index)
    n_cols = int(n_cols)
    if n_cols < 1:
        raise CalibError(f"n_cols must be positive, got {n_cols}")
    step = TWO_PI / n_cols
    col_coord = (np.pi - azimuth) / step  # column centres at c + 0.5
    # Each beam may fire at its own azimuth offset: centre its points in their
    # cells (circular mean of the fractional column) so that jitter does not
    # push neighbours into one cell.
    frac_angle = TWO_PI * (col_coord - np.floor(col_coord))
    mean_cos = np.bincount(rows, weights=np.cos(frac_angle), minlength=n_rows)
    mean_sin = np.bincount(rows, weights=np.sin(frac_angle), minlength=n_rows)
    row_shift = np.angle(mean_cos + 1j * mean_sin) / TWO_PI - 0.5
    row_shift = row_shift - np.round(row_shift)  # in [-0.5, 0.5] columns
    if in_sequence:
        cols, displacement = sequence_columns(col_coord - row_shift[rows] - 0.5, rows, n_cols)
        meta = {**meta, "column_displacement_p99": float(np.percentile(np.abs(displacement), 99)) if len(cols) else 0.0}
    else:
        cols = np.mod(np.floor(col_coord - row_shift[rows]).astype(np.int64), n_cols)
    cell_azimuth = np.pi - (np.arange(n_cols)[None, :] + 0.5 + row_shift[:, None]) * step

    meta = dict(meta)
    meta.update(
        beam_ids=beam_ids[beam_order],
        column_shift=row_shift,
        n_cols_estimated=bool(meta.pop("_n_cols_estimated", False)),
    )
    return _assemble(points, keep, rows, cols, median_elevation[beam_order], cell_azimuth, meta, kept_points, kept_range)


# --------------------------------------------------------------------------
# Public organisers
# --------------------------------------------------------------------------


def organize_by_ring(xyz: np.ndarray, ring: np.ndarray, n_cols: int | None = None) -> DepthMatrix:
    """Depth matrix of a spinning-lidar cloud with a per-point ring (beam) index.

    Parameters
    ----------
    xyz : (N, 3) float
        Points in the lidar frame, metres.
    ring : (N,) int
        Beam index of every point (any numbering; rows are ordered by the
        rings' median elevation, highest first).  Ring ids without points
        get no row.
    n_cols : int, optional
        Azimuth columns over 360 degrees; default: estimated from the
        azimuth step between points of the same ring.

    Returns
    -------
    DepthMatrix
        ``(n_rings, n_cols)``, ``wrap_cols=True``.  ``meta`` records
        ``organize="ring"``, the ring id of each row (``beam_ids``), the row
        elevations and column azimuths (radians), and the counts of points
        kept, dropped and lost to collisions.
    """
    ring = np.asarray(ring)
    if ring.dtype.kind == "f":
        if not np.all(np.isfinite(ring)) or not np.all(ring == np.round(ring)):
            raise CalibError("ring field must hold whole numbers")
        ring = ring.astype(np.int64)
    elif ring.dtype.kind not in "iu":
        raise CalibError(f"ring field must be integer, got dtype {ring.dtype}")
    return _organize_labelled(xyz, ring, n_cols, {"organize": "ring", "_n_cols_estimated": n_cols is None})


def organize_by_elevation(xyz: np.ndarray, n_beams: int, n_cols: int | None = None, range_aware: bool = False) -> DepthMatrix:
    """Depth matrix of a cloud without ring field, beams found by elevation clustering.

    Works for sensors whose beams leave from (nearly) the lidar origin, so
    that every beam has one elevation, and, with ``range_aware``, for
    sensors whose beams leave from a common height above it (see
    :func:`beam_origin_height`).  See :func:`cluster_elevations`.

    Parameters
    ----------
    xyz : (N, 3) float
        Points in the lidar frame, metres.
    n_beams : int
        Number of beams of the sensor.
    n_cols : int, optional
        Azimuth columns over 360 degrees (default: estimated).
    range_aware : bool
        Cluster the elevation seen from the beams' estimated common origin
        height instead of from the lidar origin.

    Returns
    -------
    DepthMatrix
        ``(n_beams, n_cols)``; ``meta["organize"] = "elevation"`` and
        ``meta["beam_spread_rad"]`` (largest 1-99 percentile elevation spread
        of a beam, a check that ``n_beams`` was right); with ``range_aware``,
        ``meta["beam_origin_height_m"]``.
    """
    points, keep = _clean_points(xyz)
    _, elevation, _ = _spherical_angles(points[keep])
    meta = {"organize": "elevation", "n_beams": int(n_beams), "_n_cols_estimated": n_cols is None}
    if range_aware:
        height = beam_origin_height(points[keep])
        kept = points[keep]
        elevation = np.arctan2(kept[:, 2] - height, np.hypot(kept[:, 0], kept[:, 1]))
        meta["beam_origin_height_m"] = height
    labels_kept, centres = cluster_elevations(elevation, n_beams)
    labels = np.zeros(len(points), dtype=np.int64)
    labels[keep] = labels_kept
    residual = np.abs(elevation - centres[labels_kept])
    meta["beam_spread_rad"] = float(np.percentile(residual, 99)) * 2.0
    return _organize_labelled(points, labels, n_cols, meta)


#: Beam counts of common spinning lidars; a cropped cloud is padded to the next one.
STANDARD_BEAM_COUNTS = (16, 32, 64, 128)


def organize_by_firing_order(
    xyz: np.ndarray, n_beams: int | None = None, n_cols: int | None = None, pad_cropped: bool = False
) -> DepthMatrix:
    """Depth matrix of a cloud stored laser after laser (sensor scan order).

    Rings are the azimuth sweeps of :func:`firing_order_rings`; rows are
    ordered by the rings' median elevation (highest first); columns follow
    the firings along each sweep (:func:`sequence_columns`) at the mean
    firing step, so that uneven firing times do not put two points in one
    cell.

    Parameters
    ----------
    xyz : (N, 3) float
        Points in storage order, lidar frame, metres.
    n_beams : int, optional
        Number of beams; when given, must match the number of sweeps found,
        except in a cloud cropped in azimuth (e.g. to a camera's view,
        KITTI's ``velodyne_reduced``), where beams that saw nothing in the
        crop get empty rows (``meta["n_empty_beams_added"]``).
    n_cols : int, optional
        Azimuth columns over 360 degrees (default: 360 deg / mean firing step).
    pad_cropped : bool
        Without ``n_beams``, pad a cloud cropped in azimuth (under 300 deg)
        to the next of :data:`STANDARD_BEAM_COUNTS` beams (KITTI's
        ``velodyne_reduced``: 46 of the HDL-64E's lasers see into the
        camera, 64 rows).  The padded rows hold no point, so they change the
        layout only.

    Returns
    -------
    DepthMatrix
        ``(n_sweeps, n_cols)``; ``meta["organize"] = "firing_order"``,
        ``meta["column_displacement_p99"]`` (99th percentile of how far, in
        columns, a point sits from its azimuth's cell).

    Raises
    ------
    NotFiringOrder
        When the points are not stored laser after laser (the message says why).
    """
    points, keep = _clean_points(xyz)
    labels = np.zeros(len(points), dtype=np.int64)
    labels[keep] = firing_order_rings(points[keep], n_beams, allow_fewer=True)
    n_sweeps = int(labels[keep].max() + 1)
    meta = {"organize": "firing_order", "n_sweeps": n_sweeps, "_n_cols_estimated": n_cols is None}
    depth = _organize_labelled(points, labels, n_cols, meta, in_sequence=True)
    target = n_beams
    if target is None and pad_cropped and azimuth_coverage(np.arctan2(points[keep, 1], points[keep, 0])) < np.radians(300.0):
        target = next((count for count in STANDARD_BEAM_COUNTS if count >= n_sweeps), None)
    if target is not None and n_sweeps < int(target):
        depth = _pad_missing_beams(depth, int(target) - n_sweeps)
    return depth


def _pad_missing_beams(depth: DepthMatrix, n_missing: int) -> DepthMatrix:
    """Add empty rows for beams without points (a cloud cropped to a camera's view).

    The rows go on the side whose edge row holds fewer points (the crop cut
    through it), spaced by the median gap of the five nearest rows'
    elevations.
    """
    counts = depth.valid.sum(axis=1)
    at_bottom = counts[-1] <= counts[0]
    elevation = depth.meta["row_elevation_rad"]
    edge = elevation[-6:] if at_bottom else elevation[:6]
    gap = float(np.median(np.abs(np.diff(edge)))) if len(edge) > 1 else np.radians(0.4)
    extra = (elevation[-1] - gap * np.arange(1, n_missing + 1)) if at_bottom else (elevation[0] + gap * np.arange(n_missing, 0, -1))
    n_cols = depth.shape[1]
    cell_azimuth = np.arctan2(depth.directions[..., 1], depth.directions[..., 0])
    col_azimuth = np.angle(np.nanmean(np.exp(1j * cell_azimuth), axis=0))
    new_dirs = spherical_directions(extra[:, None], col_azimuth[None, :])

    def stack(block, new):
        return np.concatenate([block, new] if at_bottom else [new, block], axis=0)

    meta = dict(depth.meta)
    points = stack(depth.points, np.full((n_missing, n_cols, 3), np.nan))
    meta.update(
        points=points,
        row_elevation_rad=stack(elevation, extra),
        point_index=stack(meta["point_index"], np.full((n_missing, n_cols), -1, dtype=np.int64)),
        n_empty_beams_added=n_missing,
        empty_beams_at="bottom" if at_bottom else "top",
    )
    return DepthMatrix(
        range_m=stack(depth.range_m, np.full((n_missing, n_cols), np.nan)),
        directions=stack(depth.directions, new_dirs),
        points=points,
        valid=stack(depth.valid, np.zeros((n_missing, n_cols), dtype=bool)),
        meta=meta,
    )


def count_beam_elevations(xyz: np.ndarray, gap_deg: float = 0.01, min_share: float = 0.99, max_beams: int = 256) -> int | None:
    """Number of beams when the points' elevations fall into clearly separate values.

    A sensor whose beams all leave from the origin (or a simulator) gives
    every beam one elevation: the sorted elevations form runs separated by
    gaps wider than ``gap_deg``.  Runs holding at least 0.05 % of the
    points count as beams; they must hold ``min_share`` of the points,
    number 2..``max_beams`` and be narrow (median width under a quarter of
    their median spacing), else None (e.g. an HDL-64E, whose beams'
    elevations drift with range and overlap).
    """
    points, keep = _clean_points(xyz)
    _, elevation, _ = _spherical_angles(points[keep])
    ordered = np.sort(elevation)
    breaks = np.flatnonzero(np.diff(ordered) > np.radians(gap_deg))
    starts, ends = np.r_[0, breaks + 1], np.r_[breaks, len(ordered) - 1]
    sizes = ends - starts + 1
    beams = sizes >= max(10, 0.0005 * len(ordered))
    n_beams = int(beams.sum())
    if not (2 <= n_beams <= max_beams and sizes[beams].sum() >= min_share * len(ordered)):
        return None
    # Beams are lines, not bands: a run much narrower than the spacing of runs.
    width = np.median(ordered[ends[beams]] - ordered[starts[beams]])
    spacing = np.median(np.diff(ordered[starts[beams]]))
    return n_beams if width < 0.25 * spacing else None


def azimuth_span_rad(azimuth_rad: np.ndarray) -> tuple[float, float]:
    """The smallest arc of azimuths holding every point: ``(start, width)`` in radians.

    ``start`` is the arc's first azimuth (counter-clockwise from it the arc
    runs ``width``); a full turn when the points leave no gap wider than the
    others.  The complement of the widest gap between sorted azimuths.
    """
    az = np.sort(np.mod(np.asarray(azimuth_rad, dtype=np.float64), TWO_PI))
    if az.size < 2:
        return (float(az[0]) if az.size else 0.0), 0.0
    gaps = np.diff(np.r_[az, az[0] + TWO_PI])
    widest = int(np.argmax(gaps))
    start = az[(widest + 1) % az.size]
    return float(start), float(TWO_PI - gaps[widest])


def default_spherical_resolution_deg(xyz: np.ndarray) -> float:
    """Square cell size (degrees) for the spherical fallback.

    The typical azimuth step between points of (almost) the same elevation,
    so that consecutive points of a beam get their own columns: points are
    grouped into runs of sorted elevations without a gap wider than 0.01
    degree (for a multi-beam lidar, its beams).  Without such structure (one
    run, or too few steps), about two cells per point over the cloud's field
    of view, ``sqrt(360 * elevation_span / N / 2)``.  Never finer than
    ``sqrt(360 * elevation_span / N) / 2``, so that the grid has at most about
    :data:`MAX_SPHERICAL_CELLS_PER_POINT` cells per point (a finer grid is
    mostly empty and costs memory: 36 M cells for a 2 M-point cloud).
    Rounded up to 0.01 degree, at least 0.01.
    """
    points, keep = _clean_points(xyz)
    _, elevation, azimuth = _spherical_angles(points[keep])
    span_deg = max(float(np.degrees(elevation.max() - elevation.min())), 0.01)
    equal_area = float(np.sqrt(360.0 * span_deg / keep.sum()))
    ordered = np.sort(elevation)
    gap = np.flatnonzero(np.diff(ordered) > np.radians(0.01))
    # Run label of every point: how many gaps lie below its elevation.
    runs = np.searchsorted(ordered[gap], elevation, side="left")
    resolution = equal_area / np.sqrt(2.0)  # unstructured: two cells per point keep ~80 % of the points
    if gap.size:
        try:
            resolution = 360.0 / estimate_n_cols(azimuth, runs)
        except CalibError:
            pass
    resolution = max(resolution, equal_area / np.sqrt(MAX_SPHERICAL_CELLS_PER_POINT))
    return max(float(np.ceil(resolution * 100.0 - 1e-6) / 100.0), 0.01)


#: A cloud seen over a narrow field covers at least this many degrees of azimuth and of elevation (a camera's
#: field); less is not one sensor's view from the origin (an aerial tile seen from far away).
MIN_FIELD_DEG = 5.0


def narrow_field_of_view(xyz: np.ndarray) -> tuple[float, float] | None:
    """``(azimuth, elevation)`` extent in degrees when the points fill a narrow field seen from the origin.

    Narrow: the points cover at most half a turn of azimuth
    (:data:`NARROW_FIELD_EMPTY_SHARE`) and at least :data:`MIN_FIELD_DEG`
    of azimuth and of elevation, like an RGB-D camera's frame stored in its
    own frame (SUN RGB-D as mmdetection3d keeps it).  None otherwise.
    """
    points, keep = _clean_points(xyz)
    _, elevation, azimuth = _spherical_angles(points[keep])
    azimuth_deg = float(np.degrees(azimuth_span_rad(azimuth)[1]))
    elevation_deg = float(np.degrees(elevation.max() - elevation.min()))
    if MIN_FIELD_DEG <= azimuth_deg <= 360.0 * (1.0 - NARROW_FIELD_EMPTY_SHARE) and elevation_deg >= MIN_FIELD_DEG:
        return azimuth_deg, elevation_deg
    return None


def narrow_field_resolution_deg(xyz: np.ndarray) -> float:
    """Square cell size (degrees) for a cloud seen over a narrow field: one cell per point of the area it fills.

    An RGB-D frame is a random subsample of a depth image: it has no beams
    and no scan order.  Cells holding one point on average keep about 63 %
    of the points and fill about as many cells, which the BA images need (a
    BA pixel needs its neighbour's return too); two cells per point would
    keep 80 % but leave most BA pixels without a neighbour.  The area is the
    part of the azimuth-elevation plane the points fill, counted on coarse
    cells of about ten points (a frustum fills less than its bounding box).
    Rounded up to 0.01 degree, at least 0.01.
    """
    points, keep = _clean_points(xyz)
    _, elevation, azimuth = _spherical_angles(points[keep])
    start, width = azimuth_span_rad(azimuth)
    azimuth_deg = max(float(np.degrees(width)), 0.01)
    span_deg = max(float(np.degrees(elevation.max() - elevation.min())), 0.01)
    n_points = int(keep.sum())
    coarse = np.sqrt(azimuth_deg * span_deg * 10.0 / n_points)
    rows = np.floor((np.degrees(elevation) - np.degrees(elevation.min())) / coarse).astype(np.int64)
    cols = np.floor(np.degrees(np.mod(azimuth - start, TWO_PI)) / coarse).astype(np.int64)
    filled = np.unique(rows * (int(azimuth_deg / coarse) + 2) + cols).size * coarse * coarse
    area_deg2 = min(azimuth_deg * span_deg, filled)
    return max(float(np.ceil(np.sqrt(area_deg2 / n_points) * 100.0 - 1e-6) / 100.0), 0.01)


def crop_to_field_of_view(depth: DepthMatrix, min_empty_share: float = NARROW_FIELD_EMPTY_SHARE) -> DepthMatrix:
    """A 360-degree grid cut to the columns its points cover, when they leave a wide arc empty.

    An RGB-D frame or a forward-looking sensor seen over a narrow field
    fills a small part of a full turn's columns; the others would only be
    black in the BA images.  When the widest run of empty columns (around
    the turn) is at least ``min_empty_share`` of the columns, the grid keeps
    the other columns, in order, and ``wrap_cols`` becomes False; otherwise
    ``depth`` is returned unchanged.  Cells keep their points, directions and
    ``point_index``; ``meta["col_azimuth_rad"]`` the kept columns' azimuths
    and ``meta["cropped_cols"]`` ``(first column, columns kept, columns of
    the full turn)``.
    """
    n_cols = depth.shape[1]
    occupied = depth.valid.any(axis=0)
    if occupied.all() or not occupied.any() or not depth.meta.get("wrap_cols", False):
        return depth
    # Widest circular run of empty columns: runs in the doubled sequence, capped at one turn.
    empty = np.r_[~occupied, ~occupied].astype(np.int64)
    edges = np.flatnonzero(np.diff(np.r_[0, empty, 0]))
    starts, stops = edges[::2], edges[1::2]
    lengths = np.minimum(stops - starts, n_cols)
    widest = int(np.argmax(lengths))
    if lengths[widest] < min_empty_share * n_cols:
        return depth
    first = int(stops[widest]) % n_cols
    keep = (first + np.arange(n_cols - int(lengths[widest]))) % n_cols
    meta = dict(depth.meta)
    meta.update(
        wrap_cols=False,
        col_azimuth_rad=np.asarray(meta["col_azimuth_rad"])[keep],
        point_index=meta["point_index"][:, keep],
        points=depth.points[:, keep],
        cropped_cols=(first, int(keep.size), n_cols),
    )
    return DepthMatrix(
        range_m=depth.range_m[:, keep],
        directions=depth.directions[:, keep],
        points=meta["points"],
        valid=depth.valid[:, keep],
        meta=meta,
    )


def organize_spherical(
    xyz: np.ndarray,
    v_res_deg: float,
    h_res_deg: float,
    v_range_deg: tuple[float, float] | None = None,
) -> DepthMatrix:
    """Plain spherical projection grid: fixed elevation and azimuth bins.

    The fallback for clouds whose beams are unknown.  Rows are elevation bins
    from the top of ``v_range_deg`` down; columns follow the module's azimuth
    convention over 360 degrees.  Points outside ``v_range_deg`` are dropped.

    Parameters
    ----------
    xyz : (N, 3) float
        Points in the lidar frame, metres.
    v_res_deg, h_res_deg : float
        Elevation and azimuth bin sizes in degrees.
    v_range_deg : (low, high), optional
        Elevation interval in degrees; default: the cloud's elevation span.

    Returns
    -------
    DepthMatrix
        ``meta["organize"] = "spherical"`` with the resolutions and range.
        Valid cells hold the measured points; empty cells the bin-centre
        direction.
    """
    v_res, h_res = float(v_res_deg), float(h_res_deg)
    if not (np.isfinite(v_res) and v_res > 0 and np.isfinite(h_res) and h_res > 0):
        raise CalibError(f"spherical resolution must be positive, got v={v_res_deg} h={h_res_deg} deg")
    points, keep = _clean_points(xyz)
    _, elevation, azimuth = _spherical_angles(points)
    if v_range_deg is None:
        low, high = np.degrees(elevation[keep].min()), np.degrees(elevation[keep].max())
    else:
        low, high = (float(v) for v in v_range_deg)
        if not high > low:
            raise CalibError(f"v_range_deg must be (low, high) with low < high, got {v_range_deg}")
    n_rows = max(int(np.ceil((high - low) / v_res - 1e-9)), 1)
    n_cols = max(int(round(360.0 / h_res)), 1)
    if n_rows * n_cols > 50_000_000:
        raise CalibError(f"spherical grid of {n_rows} x {n_cols} cells is too large; use a coarser resolution")
    # Bins of v_res centred on the interval, row 0 at the top.
    top = 0.5 * (low + high) + 0.5 * n_rows * v_res
    row_coord = (top - np.degrees(elevation)) / v_res
    keep &= (np.degrees(elevation) >= low) & (np.degrees(elevation) <= high)
    if not keep.any():
        raise CalibError(f"no points inside the elevation range {low:.3f}..{high:.3f} deg")
    rows = np.clip(np.floor(row_coord[keep]).astype(np.int64), 0, n_rows - 1)
    cols = np.mod(np.floor((np.pi - azimuth[keep]) / (TWO_PI / n_cols)).astype(np.int64), n_cols)
    row_elevation = np.radians(top - (np.arange(n_rows) + 0.5) * v_res)
    meta = {
        "organize": "spherical",
        "v_res_deg": v_res,
        "h_res_deg": 360.0 / n_cols,
        "v_range_deg": (float(low), float(high)),
    }
    return _assemble(points, keep, rows, cols, row_elevation, column_azimuths(n_cols), meta)


def organize_grid(points: np.ndarray, wrap_cols: bool | None = None) -> DepthMatrix:
    """Depth matrix of an already organized cloud, turned to this module's orientation.

    Drivers differ in how they lay out organized clouds (e.g. ring 0 = lowest
    beam in the first row).  The grid is flipped upside down when the rows'
    median elevation grows downwards, and left-right when the columns'
    azimuth grows to the right (a mirrored panorama); the cells themselves
    are kept.  Empty cells get the direction of their row's median elevation
    and column's mean azimuth.

    Parameters
    ----------
    points : (H, W, 3) float
        Organized points in the lidar frame, metres; NaN/inf or (0, 0, 0)
        marks a missing return.
    wrap_cols : bool, optional
        Whether the columns close 360 degrees; default: detected (the
        columns' azimuth step times W is one turn).

    Returns
    -------
    DepthMatrix
        ``meta["organize"] = "organized"`` with ``flipped_rows``,
        ``flipped_cols``, ``wrap_cols`` (and ``wrap_cols_detected``) and
        ``point_index`` (index of each cell in the input's row-major order).
    """
    cloud = organized_cloud_depth(points, wrap_cols=False)  # validates the shape
    if not cloud.valid.any():
        raise CalibError(f"the organized cloud of {cloud.shape[0]} x {cloud.shape[1]} cells has no valid point")
    n_rows, n_cols = cloud.shape
    index = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    valid = cloud.valid
    direction = np.where(valid[..., None], cloud.directions, 0.0)
    elevation = np.arcsin(np.clip(direction[..., 2], -1.0, 1.0))
    azimuth = np.arctan2(direction[..., 1], direction[..., 0])

    counts_row = valid.sum(axis=1)
    row_elevation = np.where(counts_row > 0, (elevation * valid).sum(axis=1) / np.maximum(counts_row, 1), np.nan)
    col_azimuth = np.angle((np.exp(1j * azimuth) * valid).sum(axis=0))
    col_has = valid.any(axis=0)
    col_azimuth[~col_has] = np.nan

    def slope(values: np.ndarray) -> float:
        has = np.isfinite(values)
        if has.sum() < 2:
            return 0.0
        return float(np.polyfit(np.flatnonzero(has), values[has], 1)[0])

    flip_rows = slope(row_elevation) > 0.0
    col_step = 0.0
    if col_has.sum() > 1:
        unwrapped = np.full(n_cols, np.nan)
        unwrapped[col_has] = np.unwrap(col_azimuth[col_has])
        col_step = slope(unwrapped)
    flip_cols = col_step > 0.0
    detected_wrap = bool(col_step != 0.0 and abs(abs(col_step) * n_cols - TWO_PI) <= max(2.0 * abs(col_step), 0.02 * TWO_PI))
    wrap = detected_wrap if wrap_cols is None else bool(wrap_cols)

    rows = slice(None, None, -1) if flip_rows else slice(None)
    cols = slice(None, None, -1) if flip_cols else slice(None)
    oriented = organized_cloud_depth(np.asarray(points, dtype=np.float64)[rows, cols], wrap_cols=wrap)
    fill = spherical_directions(row_elevation[rows][:, None], col_azimuth[cols][None, :])
    directions = np.where(oriented.valid[..., None], oriented.directions, fill)
    point_index = np.where(oriented.valid, index[rows, cols], -1)
    meta = dict(oriented.meta)
    meta.update(
        organize="organized",
        flipped_rows=bool(flip_rows),
        flipped_cols=bool(flip_cols),
        wrap_cols_detected=detected_wrap,
        n_points_in=int(n_rows * n_cols),
        n_points_dropped=int(n_rows * n_cols - valid.sum()),
        n_points_kept=int(valid.sum()),
        point_index=point_index,
    )
    return DepthMatrix(
        range_m=oriented.range_m, directions=directions, points=oriented.points, valid=oriented.valid, meta=meta
    )
