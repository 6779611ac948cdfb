"""How sharp a painted marking's edges are in the laser intensity: :func:`edge_width_cells`.

A lidar's beam footprint smears a painted stripe's intensity over about a
cell along each ring, so the cell that *looks* like the stripe's corner in
the scan's intensity (the ``marking`` candidates of :mod:`.candidates`) can
sit one or two cells outside the paint's corner (PJLab manual_calib's
crosswalk at 18-25 m: 10-15 photo px off, with 7.6 px per column).  The
proposal screen leaves out markings whose edges are smeared over more than a
cell (``docs/perf/guide_clean_corners.md``).  Rebuilding the corner from the
rings' crossings of its edges was measured and did not come closer to the
photo's corner than the cell (``bench/ring_crossing.py``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cell_windows", "edge_width_cells", "MIN_CONTRAST"]

#: Paint against asphalt: the window's 90th intensity percentile over its 20th must be at least this.
MIN_CONTRAST = 2.5


def cell_windows(values: np.ndarray, rc: np.ndarray, half_rows: int, half_cols: int) -> np.ndarray:
    """(N, 2 half_rows + 1, 2 half_cols + 1) windows of ``values`` around ``rc`` (NaN outside the matrix)."""
    H, W = values.shape
    rows = rc[:, 0, None, None] + np.arange(-half_rows, half_rows + 1)[None, :, None]
    cols = rc[:, 1, None, None] + np.arange(-half_cols, half_cols + 1)[None, None, :]
    inside = (rows >= 0) & (rows < H) & (cols >= 0) & (cols < W)
    return np.where(inside, values[np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)], np.nan)


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
    win = cell_windows(values, rc, half_rows, half_cols)
    wide = cell_windows(values, rc, half_rows + 2, half_cols + 2)
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
