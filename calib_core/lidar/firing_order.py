"""Rings and columns of a cloud stored laser after laser (scan order).

Many spinning-lidar files have no ring field but keep the sensor's scan
order: all points of one laser as one 360-degree sweep in azimuth, then the
next laser's sweep (KITTI's HDL-64E ``.bin`` files).  Every sweep starts at
a common azimuth, the *cut*, so the ring of a point is the number of times
the azimuth has come round to the cut before it.

Lidar frame: metres, x forward, y left, z up; azimuth ``atan2(y, x)`` and
elevation ``asin(z / |p|)`` in radians.  Elevation is used only to find the
cut and to check the rings: with per-laser origin offsets a beam's elevation
seen from the lidar origin drifts with range, so it cannot label the points.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError

#: What to give when the azimuth step cannot be estimated: the columns, as the command line and Python name them.
AZIMUTH_HINT = "give the azimuth resolution (--h-res-deg DEG on the command line, n_cols=... from Python)"

TWO_PI = 2.0 * np.pi

#: Share of consecutive points that must be azimuth neighbours for a scan order,
#: and the largest azimuth step (degrees) between neighbours (more for coarse sensors).
MIN_NEIGHBOUR_SHARE = 0.9
NEIGHBOUR_STEP_DEG = 3.0
#: A sweep's elevation spread (10-90 %) must stay below this share of the cloud's.
MAX_SWEEP_SPREAD_SHARE = 0.35
#: A scan order needs the points to cover at least this much azimuth (degrees).
MIN_COVERAGE_DEG = 10.0
#: Points on each side of a candidate ring change whose median elevations are compared.
STEP_POINTS = 5
#: Cut search resolution (bins over 360 degrees).
N_CUT_BINS = 3600
#: Elevation change credited to one step when scoring a cut (radians).
ELEVATION_CAP = np.radians(1.0)


class NotFiringOrder(CalibError):
    """The points are not stored laser after laser; the message says why."""


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return np.mod(angle + np.pi, TWO_PI) - np.pi


def find_cut(phase: np.ndarray, elevation: np.ndarray, min_jump: float) -> float:
    """Azimuth (in ``phase`` units, radians) at which every sweep starts.

    Every ring change is a step from the end of one sweep to the start of
    the next; going forward in the scan direction, its arc contains the
    cut, and its two points belong to different lasers, so their elevations
    differ.  So does the arc from the last point of the cloud to its first
    point, which bounds the search.  Each step's forward arc is credited with its elevation change
    (capped, so that range edges inside a sweep weigh little), both as an
    absolute and a signed sum (lasers are usually stored in elevation
    order, so the changes at the cut add up while edges cancel); the cut is
    the centre of the best-scored azimuth interval.

    Parameters
    ----------
    phase : (N,) float
        Azimuth times the scan direction (so that it grows along a sweep), radians.
    elevation : (N,) float
        Elevation of the points, radians.
    min_jump : float
        Backward steps smaller than this (radians) are jitter, not ring changes.
    """
    start = np.mod(phase[:-1], TWO_PI)
    forward = np.mod(np.diff(phase), TWO_PI)
    delta = np.diff(elevation)
    use = forward < TWO_PI - min_jump
    start, forward, delta = start[use], forward[use], delta[use]
    scale = N_CUT_BINS / TWO_PI
    first = np.floor(start * scale).astype(np.int64)
    last = np.floor((start + forward) * scale).astype(np.int64)  # may exceed one turn
    scores = []
    for weight in (np.minimum(np.abs(delta), ELEVATION_CAP), np.clip(delta, -ELEVATION_CAP, ELEVATION_CAP)):
        # Difference array over two turns, folded back onto one.
        diff = np.bincount(first, weights=weight, minlength=2 * N_CUT_BINS + 2)
        diff -= np.bincount(last + 1, weights=weight, minlength=2 * N_CUT_BINS + 2)
        cover = np.cumsum(diff)[: 2 * N_CUT_BINS]
        scores.append(cover[:N_CUT_BINS] + cover[N_CUT_BINS:])
    score = scores[0] + np.abs(scores[1])
    # The first point starts the first sweep and the last ends the last one:
    # the cut lies on the forward arc from the last point to the first.
    arc_start = np.mod(phase[-1], TWO_PI)
    arc_length = np.mod(phase[0] - phase[-1], TWO_PI)
    if arc_length > np.pi:
        # More than half a turn: both points sit at the cut, jittered across
        # each other; search a few degrees around them.
        middle = np.angle(np.exp(1j * phase[0]) + np.exp(1j * phase[-1]))
        arc_start, arc_length = middle - np.radians(2.0), np.radians(4.0)
    bins = np.floor(arc_start * scale).astype(np.int64) + np.arange(-1, int(np.ceil(arc_length * scale)) + 2)
    allowed = np.zeros(N_CUT_BINS, dtype=bool)
    allowed[np.mod(bins, N_CUT_BINS)] = True
    score = np.where(allowed, score, -np.inf)
    best = score >= score.max() - 1e-9 * max(abs(score.max()), 1.0)
    # Centre of the longest run of best bins, circularly.
    doubled = np.r_[best, best].astype(np.int8)
    edges = np.flatnonzero(np.diff(np.r_[0, doubled, 0]))
    runs_start, runs_end = edges[0::2], edges[1::2]
    longest = int(np.argmax(runs_end - runs_start))
    centre = 0.5 * (runs_start[longest] + runs_end[longest])
    return float(np.mod(centre / scale, TWO_PI))


def beam_origin_height(xyz: np.ndarray, max_offset_m: float = 0.5, step_m: float = 0.01, max_points: int = 200_000) -> float:
    """Common height (m) of the beams' origins above the lidar origin.

    A sensor whose lasers sit above (or below) its origin, like the
    HDL-64E (about 0.2 m), sees each beam's elevation from the origin drift
    with range; from the right height ``h`` the elevation
    ``atan2(z - h, sqrt(x^2 + y^2))`` is constant per beam again.  ``h`` is
    the one (on a ``step_m`` grid within ``+-max_offset_m``) whose
    elevation histogram (0.02 deg bins) is the most peaked (largest sum of
    squared counts).  Uses an even subsample of at most ``max_points``.

    Parameters
    ----------
    xyz : (N, 3) float
        Finite, non-zero points in the lidar frame, metres.
    """
    points = np.asarray(xyz, dtype=np.float64)[:: max(1, len(xyz) // max_points)]
    horizontal = np.hypot(points[:, 0], points[:, 1])
    bin_rad = np.radians(0.02)
    best_height, best_score = 0.0, -1.0
    for height in np.arange(-max_offset_m, max_offset_m + 0.5 * step_m, step_m):
        elevation = np.arctan2(points[:, 2] - height, horizontal)
        counts = np.bincount(((elevation - elevation.min()) / bin_rad).astype(np.int64)).astype(np.float64)
        score = float(np.dot(counts, counts))
        if score > best_score * (1.0 + 1e-9):  # ties keep the smaller |h| (grid starts at -max)
            best_height, best_score = float(height), score
    return best_height


def sequence_origin_height(xyz: np.ndarray, max_offset_m: float = 0.5, max_pairs: int = 20_000) -> float:
    """Common height (m) of the beams' origins, for points in scan order.

    Consecutive points are mostly the same laser at neighbouring azimuths;
    seen from the right height their elevations barely change, even across
    range edges.  The height minimises the summed (capped at 1 deg)
    elevation change between consecutive points, in tangent terms
    (``(z - h) / sqrt(x^2 + y^2)``, linear in ``h``): a grid of 5 cm within
    ``+-max_offset_m``, then 1 cm around the best, on at most ``max_pairs``
    evenly spread pairs.
    """
    points = np.asarray(xyz, dtype=np.float64)
    first = np.arange(0, len(points) - 1, max(1, (len(points) - 1) // max_pairs))
    a, b = points[first], points[first + 1]
    ha = np.maximum(np.hypot(a[:, 0], a[:, 1]), 1e-3)
    hb = np.maximum(np.hypot(b[:, 0], b[:, 1]), 1e-3)
    # In tangent terms the change is linear in h: (zb - h)/hb - (za - h)/ha.
    slope_change = b[:, 2] / hb - a[:, 2] / ha
    inverse_change = 1.0 / hb - 1.0 / ha
    cap = np.tan(ELEVATION_CAP)

    def best_of(heights: np.ndarray) -> float:
        change = np.abs(slope_change[None, :] - heights[:, None] * inverse_change[None, :])
        return float(heights[np.argmin(np.minimum(change, cap).sum(axis=1))])

    coarse = best_of(np.arange(-max_offset_m, max_offset_m + 1e-9, 0.05))
    return best_of(coarse + np.arange(-0.05, 0.05 + 1e-9, 0.01))


def azimuth_coverage(azimuth_rad: np.ndarray, bin_deg: float = 1.0) -> float:
    """Azimuth span (radians) the points cover: one turn minus the widest empty arc (in bins of ``bin_deg``)."""
    n_bins = int(round(360.0 / bin_deg))
    occupied = np.bincount((np.mod(azimuth_rad, TWO_PI) * (n_bins / TWO_PI)).astype(np.int64) % n_bins, minlength=n_bins) > 0
    if occupied.all():
        return TWO_PI
    # Widest run of empty bins, circularly: unroll from an occupied bin.
    rolled = np.roll(~occupied, -int(np.argmax(occupied)))
    edges = np.flatnonzero(np.diff(np.r_[0, rolled.astype(np.int8), 0]))
    widest = int((edges[1::2] - edges[0::2]).max())
    return TWO_PI * (n_bins - widest) / n_bins


def _rolling_median_levels(s: np.ndarray, before_end: np.ndarray, after_start: np.ndarray, m: int):
    """Median of ``s`` over the ``m`` points up to ``before_end`` and from ``after_start``."""
    n = len(s)
    offsets = np.arange(m)
    before = np.clip(before_end[:, None] - offsets[None, :], 0, n - 1)
    after = np.clip(after_start[:, None] + offsets[None, :], 0, n - 1)
    return np.median(s[before], axis=1), np.median(s[after], axis=1)


def firing_order_rings(
    xyz: np.ndarray,
    n_beams: int | None = None,
    min_jump_deg: float = 1.0,
    window_deg: float = 10.0,
    level_points: int = 9,
    allow_fewer: bool = False,
) -> np.ndarray:
    """Ring index of every point of a cloud stored laser after laser.

    Steps: the scan direction is the sign of the median azimuth step; the
    cut is found by :func:`find_cut`; measured from the cut in the scan
    direction the azimuth only grows within a sweep, so a ring change shows
    as a step back.  Steps back closer together than ``window_deg`` of
    azimuth are one change: points that motion compensation moved across
    the cut, and lasers whose sweeps start a few degrees off the cut (an
    HDL-64E's per-laser azimuth corrections, when a file cuts sweeps by
    encoder angle) step back twice.  A group counts only when the sweep's
    level drops: the median over ``level_points`` points after it must lie
    well below the median before it (by a quarter of the cloud's azimuth
    extent), so an odd point thrown across the cut and back (a spurious
    wrap) is not a ring.  Within ``window_deg`` around the group, the change
    is placed where the elevation (seen from the beams' common origin
    height, :func:`sequence_origin_height`) steps most between the medians
    of the 5 points before and after.

    Parameters
    ----------
    xyz : (N, 3) float
        Finite, non-zero points in storage order, lidar frame, metres.
    n_beams : int, optional
        Number of beams; when given, the number of sweeps found must equal it.
    min_jump_deg : float
        Smallest backward azimuth step (degrees) that may be a ring change.
    window_deg : float
        Azimuth span (degrees) within which steps back are one change.
    level_points : int
        Points on each side of a change whose median sets the sweep level.
    allow_fewer : bool
        Accept fewer sweeps than ``n_beams`` when the cloud covers less than
        300 degrees of azimuth (cropped: some beams may see nothing in it).

    Returns
    -------
    (N,) int64
        Sweep index in storage order (0 = first stored sweep).

    Raises
    ------
    NotFiringOrder
        If consecutive points are not azimuth neighbours, if fewer than two
        sweeps (or not ``n_beams``) are found; the message says which.
    """
    points = np.asarray(xyz, dtype=np.float64)
    if n_beams is not None and int(n_beams) < 1:
        raise CalibError(f"beams must be a positive integer, got {n_beams}")
    if len(points) < 16:
        raise NotFiringOrder(f"too few points ({len(points)}) to find sweeps")
    azimuth = np.arctan2(points[:, 1], points[:, 0])
    steps = _wrap(np.diff(azimuth))
    typical = float(np.median(np.abs(steps)))
    # Neighbours: within 3 deg, or 3 typical steps for a coarse sensor, but a
    # typical step over 10 deg is no sensor's resolution (shuffled: ~90 deg).
    limit = np.radians(NEIGHBOUR_STEP_DEG) if typical > np.radians(10.0) else max(np.radians(NEIGHBOUR_STEP_DEG), 3.0 * typical)
    neighbour = np.abs(steps) <= limit
    share = float(neighbour.mean())
    if share < MIN_NEIGHBOUR_SHARE:
        raise NotFiringOrder(
            f"the cloud does not look like beams stored in firing order: only {100 * share:.0f} % of "
            f"consecutive points are azimuth neighbours"
        )
    coverage = azimuth_coverage(azimuth)
    if coverage < np.radians(MIN_COVERAGE_DEG):
        raise NotFiringOrder(
            f"the cloud does not look like a spinning lidar's scan: seen from the origin it covers only "
            f"{np.degrees(coverage):.1f} deg of azimuth"
        )
    # Elevation seen from the beams' common origin height: a laser's points
    # then keep one elevation across range edges, so that the elevation
    # changes left are mostly laser changes.
    height = sequence_origin_height(points)
    elevation = np.arctan2(points[:, 2] - height, np.hypot(points[:, 0], points[:, 1]))
    direction = 1.0 if np.median(steps) >= 0.0 else -1.0
    phase = direction * azimuth
    min_jump = np.radians(min_jump_deg)
    cut = find_cut(phase, elevation, min_jump)
    swept = np.mod(phase - cut, TWO_PI)
    drops = np.flatnonzero(np.diff(swept) < -min_jump)  # change between drops[k] and drops[k] + 1
    changes = np.zeros(0, dtype=np.int64)
    if drops.size:
        window = max(int(np.ceil(np.radians(window_deg) / max(typical, 1e-9))), 1)
        opens = np.r_[True, np.diff(drops) > window]
        first = drops[opens]
        last = drops[np.r_[opens[1:], True]]
        level_before, level_after = _rolling_median_levels(swept, first, last + 1, max(int(level_points), 1))
        extent = coverage
        real = level_before - level_after > max(min_jump, 0.25 * extent)
        # The first sweep may start, and the last end, a little across the cut.
        margin = max(window, int(level_points))
        real &= (first >= margin) & (last < len(points) - 1 - margin)
        # The change: where the elevation level steps most, within a window
        # around the group (medians of STEP_POINTS on each side, so that one
        # odd point does not decide).
        first, last = first[real], last[real]
        if first.size:
            n = len(points)
            lo = np.maximum(first - window, 1)
            hi = np.minimum(last + window + 1, n - 1)
            starts = lo[:, None] + np.arange(int((hi - lo).max()) + 1)[None, :]  # first point of the new sweep
            offsets = np.arange(STEP_POINTS)
            after = np.median(elevation[np.minimum(starts[..., None] + offsets, n - 1)], axis=-1)
            before = np.median(elevation[np.maximum(starts[..., None] - 1 - offsets, 0)], axis=-1)
            # Two lasers may look alike in elevation for a while; then the
            # firing rhythm tells: a change breaks the regular azimuth step.
            # Elevation in units of 0.1 deg (beams of multi-beam lidars are
            # 0.3 deg or more apart; seen from the beams' origin a laser's
            # elevation varies less), azimuth in typical steps, capped at 1:
            # a dropped return also breaks the rhythm.
            level = np.abs(after - before)
            el_scale = np.radians(0.1)
            az_irregular = np.abs(np.abs(steps) - typical) / max(typical, 1e-9)

            def discontinuity(elevation_step, index):
                return elevation_step / el_scale + 0.5 * np.minimum(az_irregular[index - 1], 2.0)

            scores = np.where(starts <= hi[:, None], discontinuity(level, starts), -np.inf)
            coarse = starts[np.arange(len(first)), np.argmax(scores, axis=1)]
            # Medians blur the step over a few points: settle on the largest
            # single discontinuity next to it.
            near = np.clip(coarse[:, None] + np.arange(-STEP_POINTS + 1, STEP_POINTS)[None, :], 1, n - 1)
            jump = discontinuity(np.abs(elevation[near] - elevation[near - 1]), near)
            changes = np.unique(near[np.arange(len(first)), np.argmax(jump, axis=1)])
    n_found = len(changes) + 1
    cropped = coverage < np.radians(300.0)
    fewer_ok = allow_fewer and cropped and n_beams is not None and n_found < int(n_beams)
    if n_found < 2 or (n_beams is not None and n_found != int(n_beams) and not fewer_ok):
        expected = f"{int(n_beams)} beams" if n_beams is not None else "several beams"
        raise NotFiringOrder(f"the cloud does not look like {expected} stored in firing order: found {n_found} azimuth sweeps")
    starts = np.zeros(len(points), dtype=np.int64)
    starts[changes] = 1
    sweeps = np.cumsum(starts)
    _check_sweep_elevations(elevation, sweeps, n_found)
    return sweeps


def _check_sweep_elevations(elevation: np.ndarray, sweeps: np.ndarray, n_sweeps: int) -> None:
    """Refuse sweeps that are not single lasers: a laser's points span a narrow elevation band.

    The band is wider than one beam spacing when the beams start off the
    origin, but stays a small part of the sensor's field of view; a sweep
    holding many lasers (points stored column after column, or sorted by
    azimuth) spans most of it.
    """
    low, span = float(elevation.min()), float(np.ptp(elevation)) or 1.0
    order = np.argsort(sweeps + 0.5 * (elevation - low) / span)  # one float sort, by sweep then elevation
    sorted_el = elevation[order]
    starts = np.searchsorted(sweeps[order], np.arange(n_sweeps), side="left")
    counts = np.diff(np.r_[starts, len(order)])
    low = sorted_el[starts + (0.1 * (counts - 1)).astype(np.int64)]
    high = sorted_el[starts + (0.9 * (counts - 1)).astype(np.int64)]
    spread = np.percentile(elevation, 90) - np.percentile(elevation, 10)
    typical = float(np.median(high - low))
    if spread > 0 and typical > MAX_SWEEP_SPREAD_SHARE * spread:
        raise NotFiringOrder(
            f"the cloud does not look like beams stored in firing order: a typical azimuth sweep spans "
            f"{np.degrees(typical):.1f} deg of elevation, {100 * typical / spread:.0f} % of the cloud's"
        )


def sequence_columns(col_coord: np.ndarray, rows: np.ndarray, n_cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Columns of points stored in firing order, one cell per firing.

    Binning each point's azimuth alone puts two firings into one cell
    wherever the firing times are uneven (an HDL-64E alternates steps of
    0.18 and 0.09 deg).  Along a sweep the firings are in order, so each
    point gets a column of its own: strictly increasing integers near the
    points' column coordinates (the mean of a forward and a backward
    running push, which spreads a crowd of firings to both sides).

    Parameters
    ----------
    col_coord : (N,) float
        Column coordinate of every point in storage order (cell centres at
        integers), any turn.
    rows : (N,) int
        Row of every point; the points of a row must be contiguous.
    n_cols : int
        Columns per turn.

    Returns
    -------
    cols : (N,) int64
        Column in ``[0, n_cols)``.
    displacement : (N,) float
        Column minus coordinate, in columns (how far a point was moved).
    """
    n = len(col_coord)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    new_row = np.r_[True, rows[1:] != rows[:-1]]
    step = np.mod(np.diff(col_coord) + 0.5 * n_cols, n_cols) - 0.5 * n_cols
    step = np.r_[0.0, step]
    step[new_row] = 0.0
    unwrapped = np.cumsum(step)
    row_start = np.flatnonzero(new_row)
    row_id = np.cumsum(new_row) - 1
    unwrapped += (col_coord[row_start] - unwrapped[row_start])[row_id]
    inner = step[~new_row]
    sign = -1.0 if inner.size and np.median(inner) < 0.0 else 1.0
    value = sign * unwrapped
    index = np.arange(n, dtype=np.float64)
    # Strictly increasing integers near the coordinates: pushed forward where
    # firings crowd (running max of round(value) - index), pushed backward
    # (running min from the end), and the two averaged, so that a crowd
    # spreads to both sides as a least-squares (isotonic) fit would.  Their
    # sum grows by at least 2 per point, so the floored mean still grows by
    # at least 1: no two points of a row share a column.
    separation = 4.0 * (n + n_cols + np.ptp(value) + 1.0)  # rows never interact
    shifted = np.floor(value + 0.5) - index + row_id * separation
    forward = np.maximum.accumulate(shifted)
    backward = np.minimum.accumulate(shifted[::-1])[::-1]
    integer = np.floor(0.5 * (forward + backward)) - row_id * separation + index
    cols = np.mod(sign * integer, n_cols).astype(np.int64)
    return cols, sign * integer - unwrapped


def estimate_step(azimuth_rad: np.ndarray, rows: np.ndarray) -> float:
    """Mean azimuth step (radians) between consecutive firings of a row.

    Steps between consecutive points of the same row in storage order,
    keeping those between a quarter and 1.5 times the median (no dropped
    returns, no jitter); their mean, not their median, because firing
    steps can alternate (an HDL-64E's 0.18 and 0.09 deg average 0.167).
    """
    steps = np.abs(_wrap(np.diff(azimuth_rad)))[rows[1:] == rows[:-1]]
    steps = steps[steps > 1e-7]
    if steps.size < 8:
        raise CalibError(f"cannot estimate the azimuth resolution from {steps.size} azimuth steps; {AZIMUTH_HINT}")
    median = float(np.median(steps))
    regular = steps[(steps >= 0.25 * median) & (steps <= 1.5 * median)]
    return float(regular.mean())
