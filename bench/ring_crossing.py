"""Painted corners rebuilt from the rings' crossings of their edges (measured in ``bench.guide_by_eye
--ring-crossing``; not used by the product: the rebuilt corner was no closer to the photo's corner than the cell).

Along a ring the intensity passes half-way between asphalt and paint where the ring crosses the stripe's side
(a symmetric smear keeps that level where the paint is).  :func:`ring_crossing_corner` locates, in each cell's
window, every crossing of that level between neighbouring cells (linear interpolation, sub-cell): crossings
between columns of one ring sample the edge the rings cross, crossings between rings of one column the edge
along the rings.  A straight line is fitted to each set and the lines are intersected: the corner, in fractional
``(row, col)``.  :func:`point_at` turns it into a lidar point (bilinear interpolation of the four cells' points).
"""

from __future__ import annotations

import numpy as np

from calib_core.guide.marking_corner import MIN_CONTRAST, cell_windows


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
    from calib_core.display_images import find_intensity

    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    out = np.full((len(rc), 2), np.nan)
    found = find_intensity(depth.meta.get("field_images"))
    if found is None or not len(rc):
        return out
    values = np.asarray(found[1], dtype=np.float64)
    if values.shape != tuple(depth.shape):
        return out
    values = np.where(np.asarray(depth.valid, dtype=bool) & np.isfinite(values), values, np.nan)
    win = cell_windows(values, rc, half_rows, half_cols)
    wide = cell_windows(values, rc, half_rows + 1, half_cols + 2)
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
