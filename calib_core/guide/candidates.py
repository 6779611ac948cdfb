"""Laser cells that make good features to pair: corners of the scan.

Two kinds, found with the Shi-Tomasi measure (smaller eigenvalue of the
structure tensor) on images of the depth matrix after a 3x3 / 5x5 median of
the ranges (range noise of a centimetre is tens of degrees of BA or normal on
neighbouring cells):

* ``depth_jump``: corners of depth discontinuities, on the log-range image;
* ``junction``: corners of the surface-normal image (the 3-channel image whose
  Bearing Angle images are projections), where planes meet: box and shelf
  corners, room corners.

A depth-jump peak is kept only where the near side of the step covers
clearly less or more than half of the 7x7 window around it
(:func:`near_fraction`): a corner of the near region, not a straight stretch
of a depth edge, where range noise alone makes structure-tensor peaks.
The peak may sit a cell or two off the corner itself; a depth-jump peak is
moved to the near-side cell at the corner's tip (:func:`snap_to_corner_cell`,
the cell a person picks), and where that still misses the person moves the
cell in the BA loupe (:mod:`.laser_noise` models the offset).

A third kind, ``marking``, is a corner of the scan's intensity image (a
painted road marking, a sign's border) where the scan has an intensity
field (:func:`intensity_log_image`): on a flat road it is the only corner
the laser and the photo share.

Gradients are clipped to a fixed magnitude before the structure tensor, so a
small step corners as well as a large one and the thresholds are absolute
(fractions of the clipped magnitude), the same on any scan.  Cells next to a
no-return cell are skipped: the border of a hole is not a scene feature.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Candidates", "KINDS", "find_candidates", "intensity_log_image", "corner_response", "depth_discontinuity", "near_region_width",
           "plane_residual_m", "snap_to_corner_cell"]

#: Feature kinds; duplicates within ``min_distance`` keep the first kind.
KINDS = ("depth_jump", "junction", "marking")

#: Clipped gradient magnitude per cell and kind: log range (1.5 % of the range), unit normal (about 11 deg).
_GRADIENT_CLIP = {"depth_jump": 0.015, "junction": 0.2, "marking": 0.5}
#: Near-side share of a 7x7 window below / above which a depth-jump peak is a corner (1/2 = straight edge).
_MAX_CONVEX_SHARE, _MIN_CONCAVE_SHARE = 0.4, 0.7
#: Structure-tensor window per kind, cells.
_WINDOW = {"depth_jump": 3, "junction": 5, "marking": 3}


@dataclass(frozen=True)
class Candidates:
    """Candidate laser cells.

    Attributes
    ----------
    rows_cols : (N, 2) int64
        Depth-matrix cells (row, col).
    points_lidar : (N, 3) float64
        Their measured points, lidar frame, metres.
    kind : (N,) int8
        Index into :data:`KINDS`.
    strength : (N,) float64
        Shi-Tomasi measure in units of the kind's squared gradient clip
        (:func:`find_candidates`; at least its ``threshold``).
    """

    rows_cols: np.ndarray
    points_lidar: np.ndarray
    kind: np.ndarray
    strength: np.ndarray

    def __len__(self) -> int:
        return len(self.rows_cols)

    def subset(self, keep: np.ndarray) -> "Candidates":
        return Candidates(self.rows_cols[keep], self.points_lidar[keep], self.kind[keep], self.strength[keep])


def corner_response(channels: np.ndarray, valid: np.ndarray, window: int, gradient_clip: float | None = None) -> np.ndarray:
    """Shi-Tomasi measure of a (multi-channel) image: (H, W) float32, 0 where not valid.

    Sobel gradients (scaled to units per cell) of every channel, clipped to
    ``gradient_clip`` in magnitude, with no gradient where a 3x3 neighbour is
    not ``valid``; the structure tensor is summed over the channels and a
    ``window`` x ``window`` box.
    """
    ch = np.nan_to_num(np.asarray(channels, dtype=np.float32))
    if ch.ndim == 2:
        ch = ch[:, :, None]
    gx = cv2.Sobel(ch, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(ch, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    if gx.ndim == 2:
        gx, gy = gx[:, :, None], gy[:, :, None]
    inner = cv2.erode(np.asarray(valid, np.uint8), np.ones((3, 3), np.uint8), borderValue=0) > 0
    scale = inner.astype(np.float32)
    if gradient_clip is not None:
        mag = np.sqrt((gx * gx + gy * gy).sum(axis=2))
        scale *= np.minimum(1.0, gradient_clip / np.maximum(mag, 1e-12))
    gx *= scale[:, :, None]
    gy *= scale[:, :, None]
    box = lambda a: cv2.boxFilter(a, -1, (window, window), normalize=False)  # noqa: E731
    a, b, c = box((gx * gx).sum(2)), box((gx * gy).sum(2)), box((gy * gy).sum(2))
    lam_min = 0.5 * (a + c) - np.sqrt(np.maximum(0.25 * (a - c) ** 2 + b * b, 0.0))
    return np.where(inner, lam_min, 0.0).astype(np.float32)


def _peaks(response: np.ndarray, threshold: float, min_distance: int) -> np.ndarray:
    """Local maxima above ``threshold``, at least ``min_distance`` apart: (M, 2) rows, cols."""
    k = 2 * min_distance + 1
    local_max = response >= cv2.dilate(response, np.ones((k, k), np.uint8))
    rows, cols = np.nonzero(local_max & (response >= threshold))
    return np.stack([rows, cols], axis=1).astype(np.int64)


def _median_ranges(depth, ksize: int) -> np.ndarray:
    """Ranges after a ``ksize`` median (invalid cells keep 0 and do not spread)."""
    r = np.where(depth.valid, depth.range_m, 0.0).astype(np.float32)
    m = cv2.medianBlur(r, ksize)
    return np.where(depth.valid & (m > 0), m, r)


def surface_normals(depth, ksize: int = 5) -> np.ndarray:
    """Unit normals (H, W, 3) of the median-filtered, Gaussian-smoothed points, facing the sensor."""
    r = np.where(depth.valid, depth.range_m, 0.0)
    dirs = np.nan_to_num(depth.directions)
    P = np.nan_to_num(depth.points + ((_median_ranges(depth, ksize) - r)[:, :, None] * dirs)).astype(np.float32)
    P = cv2.GaussianBlur(P, (5, 5), 1.0)
    du = np.roll(P, -1, axis=1) - np.roll(P, 1, axis=1)
    dv = np.roll(P, -1, axis=0) - np.roll(P, 1, axis=0)
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=2, keepdims=True) + 1e-12
    flip = np.einsum("ijk,ijk->ij", n, dirs) > 0
    return np.where(flip[:, :, None], -n, n)


def cell_spacing_m(depth) -> np.ndarray:
    """Smaller of the distances (m) from each cell's point to its row and column neighbours' beams.

    ``range * |d direction|`` per axis (central differences; wrapping columns of a 360 deg scan).
    Where it is below the range noise the normals are noise (near the poles
    of a rotating scanner).
    """
    d = np.nan_to_num(depth.directions)
    wrap = bool(depth.meta.get("wrap_cols", False))
    d_col = np.roll(d, -1, axis=1) - np.roll(d, 1, axis=1)
    if not wrap:
        d_col[:, 0] = d_col[:, -1] = np.inf
    d_row = np.roll(d, -1, axis=0) - np.roll(d, 1, axis=0)
    d_row[0] = d_row[-1] = np.inf
    step = 0.5 * np.minimum(np.linalg.norm(d_row, axis=2), np.linalg.norm(d_col, axis=2))
    return np.where(depth.valid, depth.range_m, 0.0) * step


def window_cells(shape, rows_cols: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns (N, k, k), ``k = 2 half + 1``, of the window around each cell, clipped to the matrix."""
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    off = np.arange(-half, half + 1)
    rows = np.clip(rc[:, 0, None, None] + off[None, :, None], 0, shape[0] - 1)
    cols = np.clip(rc[:, 1, None, None] + off[None, None, :], 0, shape[1] - 1)
    return tuple(np.broadcast_arrays(rows, cols))


def near_fraction(depth, rows_cols: np.ndarray, half: int = 3) -> np.ndarray:
    """Share of the window's cells on the near side of the depth step through each cell (no return = far).

    About 1/4 at a convex corner of the near region, 3/4 at a concave one and
    1/2 on a straight depth edge; NaN where the window has no depth step.
    """
    rows, cols = window_cells(depth.shape, rows_cols, half)
    ok_cell = depth.valid[rows, cols]
    lr = np.where(ok_cell, np.log(np.where(ok_cell, depth.range_m[rows, cols], 1.0)), np.inf)
    lo = lr.min(axis=(1, 2))
    hi = np.where(np.isfinite(lr), lr, -np.inf).max(axis=(1, 2))
    hi = np.where(~ok_cell.all(axis=(1, 2)), np.maximum(hi, lo + 1.0), hi)
    near = lr < (0.5 * (lo + hi))[:, None, None]
    frac = near.mean(axis=(1, 2))
    return np.where(hi - lo >= 0.005, frac, np.nan)


def intensity_log_image(depth) -> tuple[np.ndarray, np.ndarray] | None:
    """The scan's per-cell intensity as a log image and where it is defined, or None (no intensity field).

    ``log(I - I_1 + 0.05 max(|I_1|, 1))`` with ``I_1`` the 1st percentile:
    a step of 0.5 is a contrast of about 65 %, whatever the sensor's
    intensity scale.  No-return cells with at least 4
    returning neighbours get their median (twice: holes of two cells): a
    painted marking's outline, not dropout speckle.
    """
    from ..display_images import find_intensity

    found = find_intensity(depth.meta.get("field_images"))
    if found is None:
        return None
    values = np.asarray(found[1], dtype=np.float64)
    if values.shape != tuple(depth.shape):
        return None
    ok = np.asarray(depth.valid, dtype=bool) & np.isfinite(values)
    if not ok.any():
        return None
    lo = float(np.percentile(values[ok], 1))
    log_i = np.log(np.maximum(np.where(ok, values, lo) - lo, 0.0) + 0.05 * max(abs(lo), 1.0)).astype(np.float32)
    # Dropouts on dark asphalt (a quarter of the road's cells at 20 m on a 64-beam scan) cut every gradient
    # window next to them: fill holes of one or two cells from their neighbours.
    for _ in range(2):
        log_i, ok = _fill_from_neighbours(log_i, ok, 4)
    return log_i.astype(np.float32), ok


def _fill_from_neighbours(values: np.ndarray, ok: np.ndarray, min_valid: int) -> tuple[np.ndarray, np.ndarray]:
    """Cells not ``ok`` with at least ``min_valid`` of their 8 neighbours ``ok`` get those neighbours' median."""
    H, W = values.shape
    pad_v = np.pad(np.where(ok, values, np.nan).astype(np.float32), 1, constant_values=np.nan)
    shifts = np.stack([pad_v[1 + dr:H + 1 + dr, 1 + dc:W + 1 + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                       if dr or dc], axis=2)
    n = np.isfinite(shifts).sum(axis=2)
    hole = ~ok & (n >= min_valid)
    if not hole.any():
        return values, ok
    out = values.copy()
    out[hole] = np.nanmedian(shifts[hole], axis=1)
    return out, ok | hole


def find_candidates(depth, threshold: float = 0.5, min_distance: int = 1, min_spacing_m: float = 0.01) -> Candidates:
    """Corner cells of a depth matrix (module docstring).

    Parameters
    ----------
    depth : DepthMatrix
    threshold : float
        Minimum Shi-Tomasi measure, in units of the squared gradient clip:
        1 is about a full-strength edge along one side of the window and
        another along the other side.
    min_distance : int
        Non-maximum suppression radius, cells (also between kinds).
    min_spacing_m : float
        Cells closer than this to their neighbours (:func:`cell_spacing_m`) are skipped.

    Returns
    -------
    Candidates
    """
    valid = np.asarray(depth.valid, dtype=bool)
    sound = valid & (cell_spacing_m(depth) >= min_spacing_m)
    # No return reads as far away (sky, glass, beyond range): its border is a depth jump.
    log_range = np.log(np.maximum(_median_ranges(depth, 3), 1e-3))
    far = float(log_range[valid].max()) + 1.0 if valid.any() else 0.0
    images = {
        "depth_jump": np.where(valid, log_range, far),
        "junction": surface_normals(depth),
    }
    masks = {"depth_jump": np.ones_like(valid), "junction": valid}
    intensity = intensity_log_image(depth)
    if intensity is not None:
        images["marking"], masks["marking"] = intensity
    taken = np.zeros(depth.shape, dtype=bool)
    k = 2 * min_distance + 1
    rcs, kinds, strengths = [], [], []
    for i, name in enumerate(KINDS):
        if name not in images:
            continue
        g = _GRADIENT_CLIP[name]
        resp = corner_response(images[name], masks[name], _WINDOW[name], g)
        unit = g * g * (2.0 if name == "junction" else 1.0)
        rc = _peaks(resp, threshold * unit, min_distance + (name == "junction"))
        s = resp[rc[:, 0], rc[:, 1]] / unit
        if name == "depth_jump":
            # A corner of the near region, not a straight stretch of a depth edge.
            f = near_fraction(depth, rc)
            corner = (f <= _MAX_CONVEX_SHARE) | (f >= _MIN_CONCAVE_SHARE)
            rc, s = snap_to_corner_cell(depth, rc[corner]), s[corner]
        keep = ~taken[rc[:, 0], rc[:, 1]] & sound[rc[:, 0], rc[:, 1]]
        rc, s = rc[keep], s[keep]
        mark = np.zeros(depth.shape, np.uint8)
        mark[rc[:, 0], rc[:, 1]] = 1
        taken |= cv2.dilate(mark, np.ones((k, k), np.uint8)) > 0
        rcs.append(rc)
        kinds.append(np.full(len(rc), i, np.int8))
        strengths.append(s)
    rc = np.concatenate(rcs).astype(np.int64)
    _, first = np.unique(rc, axis=0, return_index=True)  # localisation can land two corners on one cell
    first = np.sort(first)
    rc = rc[first]
    return Candidates(rc, depth.points[rc[:, 0], rc[:, 1]], np.concatenate(kinds)[first],
                      np.concatenate(strengths).astype(np.float64)[first])


def _log_range_windows(depth, rows_cols: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """Log ranges (N, k, k) of the windows around cells (no return = far: the window's max + 1) and validity."""
    rows, cols = window_cells(depth.shape, rows_cols, half)
    ok = depth.valid[rows, cols]
    lr = np.log(np.where(ok, depth.range_m[rows, cols], 1.0))
    top = np.where(ok, lr, -np.inf).max(axis=(1, 2))
    return np.where(ok, lr, np.where(np.isfinite(top), top, 0.0)[:, None, None] + 1.0), ok


def depth_discontinuity(depth, rows_cols: np.ndarray, half: int = 2) -> np.ndarray:
    """Largest step of log range between neighbouring cells in excess of its neighbouring steps, (N,).

    A depth jump is a spike of the first difference along a row or column
    (``|d_k| - max(|d_k-1|, |d_k+1|)``); a plane seen at a grazing angle has
    large but smooth differences, and where two such planes meet (a wall
    against the floor) the difference changes without a spike.
    """
    lr, _ = _log_range_windows(depth, rows_cols, half + 1)
    best = np.zeros(len(lr))
    for axis in (1, 2):
        d = np.abs(np.diff(lr, axis=axis))
        mid = np.take(d, np.arange(1, d.shape[axis] - 1), axis=axis)
        before = np.take(d, np.arange(0, d.shape[axis] - 2), axis=axis)
        after = np.take(d, np.arange(2, d.shape[axis]), axis=axis)
        spike = mid - np.maximum(before, after)
        best = np.maximum(best, spike.reshape(len(lr), -1).max(axis=1))
    return best


def near_region_width(depth, rows_cols: np.ndarray, half: int = 3) -> np.ndarray:
    """Whether the near side of the depth step at each cell is at least 3 cells wide somewhere in the window, (N,) bool.

    A near region thinner than that (a table leg, a cable) has no cell that
    lies clearly on it, so its corner cannot be picked within a cell.
    """
    lr, _ = _log_range_windows(depth, rows_cols, half)
    lo, hi = lr.min(axis=(1, 2)), lr.max(axis=(1, 2))
    near = (lr < (0.5 * (lo + hi))[:, None, None]).astype(np.uint8)
    core = np.stack([cv2.erode(m, np.ones((3, 3), np.uint8), borderValue=0) for m in near]) if len(near) else near
    return core.reshape(len(lr), -1).any(axis=1)


def plane_residual_m(depth, rows_cols: np.ndarray, half: int = 3) -> np.ndarray:
    """RMS distance (m) of the window's points from their best-fitting plane, (N,); NaN with < 6 points.

    About the range noise where the window is one plane (a floor seen at a
    grazing angle, whose normals are noisy enough to look like a junction);
    well above it where planes meet or a depth step crosses the window.
    """
    rows, cols = window_cells(depth.shape, rows_cols, half)
    ok = depth.valid[rows, cols].reshape(len(rows), -1)
    P = np.nan_to_num(depth.points[rows, cols].reshape(len(rows), -1, 3))
    n = ok.sum(axis=1)
    w = ok[:, :, None].astype(np.float64)
    mean = (P * w).sum(axis=1) / np.maximum(n, 1)[:, None]
    D = (P - mean[:, None, :]) * w
    cov = np.einsum("nki,nkj->nij", D, D) / np.maximum(n, 1)[:, None, None]
    smallest = np.linalg.eigvalsh(cov)[:, 0]
    return np.where(n >= 6, np.sqrt(np.maximum(smallest, 0.0)), np.nan)


def snap_to_corner_cell(depth, rows_cols: np.ndarray, half: int = 2) -> np.ndarray:
    """Move each depth-jump peak to the near-side cell at the tip of the corner, (N, 2).

    The structure-tensor peak sits a cell or two off the corner; the cell a
    person picks is the near-side cell with the most far-side neighbours
    (5 of 8 at a convex corner), nearest the peak on ties.  A cell with no
    near-side neighbour of that kind stays.
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    if len(rc) == 0:
        return rc
    lr, _ = _log_range_windows(depth, rc, half + 1)
    new = _snap_in_windows(rc, lr, half, depth.shape)
    return np.where(depth.valid[new[:, 0], new[:, 1]][:, None], new, rc)


def _snap_in_windows(rc: np.ndarray, values: np.ndarray, half: int, shape, min_step: float = 0.005) -> np.ndarray:
    """The cell below the windows' midpoint (the near side) with the most neighbours above it, nearest the centre
    on ties, (N, 2); the cell itself where none has 4 or where the window's span is below ``min_step``."""
    lo, hi = values.min(axis=(1, 2)), values.max(axis=(1, 2))
    near = values < (0.5 * (lo + hi))[:, None, None]
    far = ~near
    k = 2 * half + 3
    counts = np.zeros((len(rc), k - 2, k - 2))
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                counts += far[:, 1 + dr:k - 1 + dr, 1 + dc:k - 1 + dc]
    inner_near = near[:, 1:-1, 1:-1]
    off = np.arange(-half, half + 1)
    dist = np.maximum(np.abs(off)[:, None], np.abs(off)[None, :])
    score = np.where(inner_near & (counts >= 4), counts * 10 - dist[None], -np.inf).reshape(len(rc), -1)
    best = np.argmax(score, axis=1)
    ok = np.isfinite(score[np.arange(len(rc)), best]) & (hi - lo >= min_step)
    H, W = shape
    new = rc + np.stack([off[best // len(off)], off[best % len(off)]], axis=1)
    new[:, 0] = np.clip(new[:, 0], 0, H - 1)
    new[:, 1] = np.clip(new[:, 1], 0, W - 1)
    return np.where(ok[:, None], new, rc)
