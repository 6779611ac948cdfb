"""Where a painted marking's corner lies between the laser cells: rings crossing its two edges.

A lidar's beam footprint smears a painted stripe's intensity over about a
cell along each ring, so the cell that *looks* like the stripe's corner in
the scan's intensity (the ``marking`` candidates of :mod:`.candidates`) can
sit one or two cells outside the paint's corner (PJLab manual_calib's
crosswalk at 18-25 m: 10-15 photo px off, with 7.6 px per column).  A
symmetric smear leaves the *half-way* level where the paint is: along a ring
the intensity passes half-way between asphalt and paint where the ring
crosses the stripe's side.

:func:`ring_crossing_corner` locates, in each cell's window, every crossing
of that half-way level between neighbouring cells (linear interpolation,
sub-cell): crossings between columns of one ring sample the edge the rings
cross (the stripe's side), crossings between rings of one column sample the
edge along the rings (the stripe's end).  A straight line is fitted to each
set (in cell coordinates; on flat ground over a few cells the edges stay
straight) and the lines are intersected: the corner, in fractional
``(row, col)``.  :func:`point_at` turns it into a lidar point (bilinear
interpolation of the four cells' points).  The proposal code uses it to
choose the cell nearest the corner and to leave out markings whose nearest
cell is still far from it in the photo.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ring_crossing_corner", "point_at", "edge_width_cells", "MIN_CONTRAST"]

#: Paint against asphalt: the window's 90th intensity percentile over its 20th must be at least this.
MIN_CONTRAST = 2.5


def _windows(values: np.ndarray, rc: np.ndarray, half_rows: int, half_cols: int) -> np.ndarray:
    """(N, 2 half_rows + 1, 2 half_cols + 1) windows of ``values`` around ``rc`` (NaN outside the matrix)."""
    H, W = values.shape
    rows = rc[:, 0, None, None] + np.arange(-half_rows, half_rows + 1)[None, :, None]
    cols = rc[:, 1, None, None] + np.arange(-half_cols, half_cols + 1)[None, None, :]
    inside = (rows >= 0) & (rows < H) & (cols >= 0) & (cols < W)
    return np.where(inside, values[np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)], np.nan)


def _nearest_crossing(a: np.ndarray, b: np.ndarray, mid: np.ndarray, offset: np.ndarray, centre: float):
    """Per line of cells (axis 1), the half-way crossing between neighbours ``a`` and ``b`` (along axis 2)
    nearest ``centre``: its fractional position along the line (NaN where the line has none)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        cross = ((a - mid) * (b - mid) < 0) & np.isfinite(a) & np.isfinite(b)
        t = np.where(cross, (mid - a) / (b - a), np.nan)
    pos = offset[None, None, :] + t
    dist = np.where(cross, np.abs(pos - centre), np.inf)
    k = np.argmin(dist, axis=2)
    found = np.take_along_axis(pos, k[..., None], axis=2)[..., 0]
    return np.where(np.isfinite(np.take_along_axis(dist, k[..., None], axis=2)[..., 0]), found, np.nan)


def _line_fit(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ``y = a + b x`` per row of (N, k) samples (NaN = missing): a, b and the number of samples."""
    ok = np.isfinite(x) & np.isfinite(y)
    n = ok.sum(axis=1)
    xs, ys = np.where(ok, x, 0.0), np.where(ok, y, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my = xs.sum(axis=1) / n, ys.sum(axis=1) / n
        dx = np.where(ok, x - mx[:, None], 0.0)
        sxx = (dx * dx).sum(axis=1)
        b = np.where(sxx > 1e-9, (dx * np.where(ok, y - my[:, None], 0.0)).sum(axis=1) / sxx, np.nan)
    return my - b * mx, b, n


def ring_crossing_corner(depth, rows_cols: np.ndarray, half_rows: int = 2, half_cols: int = 3) -> np.ndarray:
    """A painted corner's fractional ``(row, col)`` near each cell, from the rings' crossings of its edges.

    Parameters
    ----------
    depth : DepthMatrix
        With an intensity field (``depth.meta["field_images"]``).
    rows_cols : (N, 2) int
        Cells near a marking's corner (``marking`` candidates).
    half_rows, half_cols : int
        Half-size of the window searched, rings and columns.

    Returns
    -------
    (N, 2) float64
        Fractional ``(row, col)`` of the corner, cell units (the cell ``(r, c)`` is at ``(r, c)``); NaN where
        the window has no intensity contrast (:data:`MIN_CONTRAST`), fewer than two crossings on either edge,
        or the corner falls outside the window.
    """
    from ..display_images import find_intensity

    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    out = np.full((len(rc), 2), np.nan)
    found = find_intensity(depth.meta.get("field_images"))
    if found is None or not len(rc):
        return out
    values = np.asarray(found[1], dtype=np.float64)
    if values.shape != tuple(depth.shape):
        return out
    values = np.where(np.asarray(depth.valid, dtype=bool) & np.isfinite(values), values, np.nan)
    win = _windows(values, rc, half_rows, half_cols)
    wide = _windows(values, rc, half_rows + 1, half_cols + 2)
    with np.errstate(invalid="ignore"):
        lo, hi = np.nanpercentile(wide, 20, axis=(1, 2)), np.nanpercentile(wide, 90, axis=(1, 2))
    mid = (0.5 * (lo + hi))[:, None, None]
    # Side edge: on each ring, the crossing between neighbouring columns nearest the cell (col offsets).
    col_off = np.arange(-half_cols, half_cols, dtype=np.float64)
    side_col = _nearest_crossing(win[:, :, :-1], win[:, :, 1:], mid, col_off, 0.0)  # (N, rows)
    side_row = np.broadcast_to(np.arange(-half_rows, half_rows + 1, dtype=np.float64), side_col.shape)
    # End edge: in each column, the crossing between neighbouring rings nearest the cell (row offsets).
    row_off = np.arange(-half_rows, half_rows, dtype=np.float64)
    wt = np.swapaxes(win, 1, 2)
    end_row = _nearest_crossing(wt[:, :, :-1], wt[:, :, 1:], mid, row_off, 0.0)  # (N, cols)
    end_col = np.broadcast_to(np.arange(-half_cols, half_cols + 1, dtype=np.float64), end_row.shape)
    a1, b1, n1 = _line_fit(side_row, side_col)  # col = a1 + b1 row
    a2, b2, n2 = _line_fit(end_col, end_row)  # row = a2 + b2 col
    with np.errstate(invalid="ignore", divide="ignore"):
        row = (a2 + b2 * a1) / (1.0 - b2 * b1)
        col = a1 + b1 * row
    good = ((hi >= MIN_CONTRAST * np.maximum(lo, 1e-6)) & (n1 >= 2) & (n2 >= 2) & np.isfinite(row)
            & np.isfinite(col) & (np.abs(row) <= half_rows) & (np.abs(col) <= half_cols))
    out[good, 0] = rc[good, 0] + row[good]
    out[good, 1] = rc[good, 1] + col[good]
    return out


def point_at(depth, rows_cols_f: np.ndarray) -> np.ndarray:
    """Lidar points (N, 3), metres, at fractional cells: bilinear interpolation of the four cells' points
    (NaN where one of them has no return or the position is NaN)."""
    f = np.asarray(rows_cols_f, dtype=np.float64).reshape(-1, 2)
    out = np.full((len(f), 3), np.nan)
    ok = np.isfinite(f).all(axis=1)
    if not ok.any():
        return out
    H, W = depth.shape
    r0 = np.clip(np.floor(f[ok, 0]).astype(np.int64), 0, H - 2)
    c0 = np.clip(np.floor(f[ok, 1]).astype(np.int64), 0, W - 2)
    tr, tc = (f[ok, 0] - r0)[:, None], (f[ok, 1] - c0)[:, None]
    P, V = depth.points, np.asarray(depth.valid, dtype=bool)
    p = ((1 - tr) * (1 - tc) * P[r0, c0] + (1 - tr) * tc * P[r0, c0 + 1] + tr * (1 - tc) * P[r0 + 1, c0]
         + tr * tc * P[r0 + 1, c0 + 1])
    valid = V[r0, c0] & V[r0, c0 + 1] & V[r0 + 1, c0] & V[r0 + 1, c0 + 1]
    out[np.flatnonzero(ok)[valid]] = p[valid]
    return out


def edge_width_cells(depth, rows_cols: np.ndarray, half_rows: int = 1, half_cols: int = 3) -> np.ndarray:
    """How many cells each intensity edge near a cell is smeared over along the rings, (N,).

    On each ring of the ``(2 half_rows + 1) x (2 half_cols + 1)`` window, the cells between 20 % and 80 % of
    the way from the asphalt level (the wider window's 20th intensity percentile) to the paint level (its
    90th) are counted, and divided by the number of half-way crossings on that ring (one per edge); the
    mean over the rings that have a crossing.  A sharp edge seen by a beam one cell wide leaves about one
    such cell per edge (the cell straddling it); a stripe smeared by a wider beam footprint leaves two or
    more.  NaN without intensity, contrast (:data:`MIN_CONTRAST`) or a crossing.
    """
    from ..display_images import find_intensity

    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    found = find_intensity(depth.meta.get("field_images"))
    if found is None or not len(rc):
        return np.full(len(rc), np.nan)
    values = np.asarray(found[1], dtype=np.float64)
    if values.shape != tuple(depth.shape):
        return np.full(len(rc), np.nan)
    values = np.where(np.asarray(depth.valid, dtype=bool) & np.isfinite(values), values, np.nan)
    win = _windows(values, rc, half_rows, half_cols)
    wide = _windows(values, rc, half_rows + 2, half_cols + 2)
    with np.errstate(invalid="ignore"):
        lo, hi = np.nanpercentile(wide, 20, axis=(1, 2)), np.nanpercentile(wide, 90, axis=(1, 2))
        level = (win - lo[:, None, None]) / (hi - lo)[:, None, None]
        between = ((level > 0.2) & (level < 0.8)).sum(axis=2)
        a, b = level[:, :, :-1] - 0.5, level[:, :, 1:] - 0.5
        crossings = ((a * b < 0) & np.isfinite(a) & np.isfinite(b)).sum(axis=2)
        per_ring = np.where(crossings > 0, between / np.maximum(crossings, 1), 0.0)
        rings = (crossings > 0).sum(axis=1)
        width = np.where(rings > 0, per_ring.sum(axis=1) / np.maximum(rings, 1), np.nan)
    return np.where(hi >= MIN_CONTRAST * np.maximum(lo, 1e-6), width, np.nan)
