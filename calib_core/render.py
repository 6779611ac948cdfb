"""The scan seen from the camera: a z-buffered render of the depth matrix in the camera image's geometry.

A 64-beam scan is hard to read as a 64-row image; rendered from the camera's
own viewpoint, beside the photo, its corners are recognisable.  Every image
pixel shows the nearest laser return projecting there, each return filling
a small rectangle of pixels (its *footprint*) so that the rings close into a
surface.

Frames and units: ``T_camera_lidar`` maps lidar points (metres) into the
OpenCV camera frame (x right, y down, z forward).  Pixels are ``(u, v)`` =
(column, row), the top-left pixel's centre at ``(0, 0)``; pixel ``(u, v)``
belongs to image cell ``(floor(v + 0.5), floor(u + 0.5))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ._jit import kernel
from .arrays import as_transform
from .errors import CalibError
from .overlays import _to_camera

#: Two neighbouring pixels whose returns differ in camera distance by more than this share of the nearer one
#: form a depth edge.
EDGE_RELATIVE_JUMP = 0.1
#: The automatic footprint's half-width is capped per axis at this many times its median over the returns
#: near the image (at least 2 px) and at FOOTPRINT_MAX_HALF_PX: where a neighbour's projection is stretched
#: (image borders of a wide-angle lens, a lidar's sparse outer beams) the footprint may not bleed.
FOOTPRINT_CAP_FACTOR = 3.0
FOOTPRINT_MAX_HALF_PX = 64
#: A range step between neighbouring cells is part of a smooth surface when it is at most this many times
#: the smaller of the steps just before and after it along the same direction (see ``_is_ramp``).
RAMP_STEP_RATIO = 2.5


@dataclass(frozen=True)
class CameraRender:
    """The scan rendered in the camera's own geometry under one pose.

    Attributes
    ----------
    range_m : (H, W) float32
        Lidar range of the return shown at each pixel: its distance from the lidar origin, metres.  NaN where
        no return is shown.
    cell_rc : (H, W, 2) int32
        Depth-matrix ``(row, col)`` of the return shown; -1 where none.
    camera_depth_m : (H, W) float32
        Distance of that return from the camera centre, metres (the z-buffer key); NaN where none.
    edge : (H, W) bool
        Depth edges: a pixel with a return whose 4-neighbour has no return, or a return more than
        :data:`EDGE_RELATIVE_JUMP` nearer or farther (relative to the nearer of the two) -- unless the two
        show neighbouring cells on one smooth surface (consecutive range steps alike, as between the rings
        on the ground far away).
    """

    range_m: np.ndarray
    cell_rc: np.ndarray
    camera_depth_m: np.ndarray
    edge: np.ndarray

    @property
    def has_return(self) -> np.ndarray:
        """(H, W) bool: the pixel shows a return."""
        return self.cell_rc[..., 0] >= 0


# ------------------------------------------------------------------ z-buffer
@kernel
def _splat_nearest(col, row, half_u, half_v, key, width, height, best_key, best_index):
    """Nearest-wins z-buffer with footprints, in place.

    Point ``i`` covers the pixels ``|c - col[i]| <= half_u[i]``, ``|r - row[i]| <= half_v[i]`` inside the
    image; each pixel keeps the smallest ``key`` (ties: the lower index) in ``best_key`` (H, W) float32
    and that point's index in ``best_index`` (H, W) int32.

    (``overlays._zbuffer`` keeps only the minimum per coarse cell for the colouring's depth test; here every
    pixel needs the index of its winner, over a per-point rectangle.)
    """
    for i in range(col.shape[0]):
        k = key[i]
        r0, r1 = max(row[i] - half_v[i], 0), min(row[i] + half_v[i] + 1, height)
        c0, c1 = max(col[i] - half_u[i], 0), min(col[i] + half_u[i] + 1, width)
        for r in range(r0, r1):
            for c in range(c0, c1):
                if k < best_key[r, c]:
                    best_key[r, c] = k
                    best_index[r, c] = i


# ------------------------------------------------------------------ geometry
def _project_cells(camera, T: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(N, 2)`` of lidar points (NaN where not projectable, finite outside the image too) and their
    distances from the camera centre ``(N,)``, metres.

    The transform runs in the colouring's compiled kernel (float64 maths, float32 results: pixels within
    about 1e-3 px of float64, and no BLAS call, whose threads stall on a busy machine).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    xyz, dist = np.empty((3, pts.shape[0]), np.float32), np.empty(pts.shape[0], np.float32)
    _to_camera(pts, np.ascontiguousarray(T[:3], dtype=np.float64), xyz, dist)
    pixels, _ = camera.project(xyz.T)
    return np.asarray(pixels, np.float64), dist.astype(np.float64)


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of ``v`` (N, 3)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _footprint_half_px(depth, camera, T, pixels, rows, cols, cap_half):
    """Automatic half-widths ``(half_u, half_v)`` (N,) int32 of the footprints of the valid cells.

    Each cell's footprint spans half the way to the projections of its four grid neighbours, where each
    neighbour is taken along its own beam direction but at *this* cell's range, from this cell's beam
    origin: ``p + rho * (d_neighbour - d)``.  That is the angular spacing of the scan at this cell, in
    pixels, independent of what the neighbour hit (a neighbour across a depth edge gives no larger
    footprint) and of the scanner's axis offsets.  Where the neighbour has no return but the cell beyond it
    has, that one is taken: two returns around a single missing cell meet in its middle.  Half-width
    ``ceil(spacing / 2)`` closes the gap between two rounded centres.  Capped per axis at
    ``FOOTPRINT_CAP_FACTOR`` times the axis's median (at least 2 px) and at ``cap_half``.
    """
    wrap = bool(depth.meta.get("wrap_cols", False))
    h, w = depth.shape
    valid = np.asarray(depth.valid, bool).ravel()
    # Unit beam direction and range of every cell: the depth matrix's own, else from the point.
    unit = np.array(depth.directions, dtype=np.float64).reshape(-1, 3)
    pts = np.asarray(depth.points, np.float64).reshape(-1, 3)
    rho = np.array(depth.range_m, dtype=np.float64).ravel()
    lost = ~np.isfinite(unit).all(axis=1)
    if lost.any():
        norm = _norm(pts[lost])
        with np.errstate(invalid="ignore", divide="ignore"):
            unit[lost] = pts[lost] / norm[:, None]
        rho[lost] = norm
    bad_rho = ~np.isfinite(rho) & valid
    rho[bad_rho] = _norm(pts[bad_rho])

    def cell_of(step_row, step_col):
        """Flat index of the cell ``step`` away from every valid cell, whether it exists, and has a return."""
        r, c = rows + step_row, cols + step_col
        if wrap:
            c = c % w
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        flat = np.clip(r, 0, h - 1) * w + np.clip(c, 0, w - 1)
        return flat, inside, inside & valid[flat]

    own = rows * w + cols
    own_rho = rho[own][:, None]
    origin = pts[own] - own_rho * unit[own]  # the beam's origin (0 without axis offsets)
    spread = np.full((rows.size, 2), np.nan)
    for d_row, d_col in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        flat1, inside1, has1 = cell_of(d_row, d_col)
        flat2, _, has2 = cell_of(2 * d_row, 2 * d_col)
        skip = ~has1 & has2
        nb_dir = unit[np.where(skip, flat2, flat1)]
        nb_dir[~inside1 & ~skip] = np.nan
        nb_pixels, _ = _project_cells(camera, T, origin + own_rho * nb_dir)
        spread = np.fmax(spread, np.abs(nb_pixels - pixels))
    half = spread / 2.0
    finite = np.isfinite(half)
    median = np.array([np.median(half[finite[:, k], k]) if finite[:, k].any() else 0.0 for k in (0, 1)])
    cap = np.minimum(cap_half, np.maximum(2.0, FOOTPRINT_CAP_FACTOR * median))
    half = np.where(finite, half, median)
    half = np.clip(np.ceil(half - 1e-6), 0, np.floor(cap)).astype(np.int32)
    return np.ascontiguousarray(half[:, 0]), np.ascontiguousarray(half[:, 1])


@kernel
def _cell_range_at(cell_range, row, col, wrap):
    """Range of cell ``(row, col)``; columns wrap when ``wrap``; NaN off the grid."""
    h, w = cell_range.shape
    if wrap:
        col = col % w
    if row < 0 or row >= h or col < 0 or col >= w:
        return np.nan
    return cell_range[row, col]


@kernel
def _is_ramp(cell_range, wrap, ra, ca, rb, cb, ratio):
    """Cells ``a = (ra, ca)`` and ``b = (rb, cb)`` are grid neighbours on one smooth surface.

    The step ``s1 = r(b) - r(a)`` is compared with the steps one cell before and after along the same
    direction ``d = b - a``: ``s0 = r(a) - r(a - d)``, ``s2 = r(b + d) - r(b)``.  On a surface seen at a
    grazing angle (the ground far away) consecutive steps are alike, however large; at an occlusion edge
    the step stands alone.  A ramp: ``|s1| <= ratio * min(|s0|, |s2|)``; a missing cell makes no ramp.
    """
    w = cell_range.shape[1]
    dr, dc = rb - ra, cb - ca
    if wrap:
        dc = (dc + w // 2) % w - w // 2
    if abs(dr) > 1 or abs(dc) > 1:
        return False
    r_a = _cell_range_at(cell_range, ra, ca, wrap)
    r_b = _cell_range_at(cell_range, rb, cb, wrap)
    s0 = r_a - _cell_range_at(cell_range, ra - dr, ca - dc, wrap)
    s2 = _cell_range_at(cell_range, rb + dr, cb + dc, wrap) - r_b
    return abs(r_b - r_a) <= ratio * min(abs(s0), abs(s2))  # NaN compares False


@kernel
def _depth_edges(cam_depth, cell_rc, cell_range, wrap, jump_ratio, ramp_ratio):
    """Depth-edge pixels (H, W) bool: a return whose 4-neighbour pixel has no return, or one more than
    ``jump_ratio`` nearer or farther from the camera (relative to the nearer) -- unless the two pixels show
    neighbouring cells of the scan on one smooth surface (:func:`_is_ramp`), as between the rings on the
    ground far away."""
    h, w = cam_depth.shape
    edge = np.zeros((h, w), np.bool_)
    for r in range(h):
        for c in range(w):
            a = cam_depth[r, c]
            for k in range(2):
                r2, c2 = (r + 1, c) if k == 0 else (r, c + 1)
                if r2 >= h or c2 >= w:
                    continue
                b = cam_depth[r2, c2]
                ha, hb = a == a, b == b
                if ha != hb:
                    cut = True
                elif ha and abs(a - b) > jump_ratio * min(a, b):
                    cut = not _is_ramp(cell_range, wrap, cell_rc[r, c, 0], cell_rc[r, c, 1],
                                       cell_rc[r2, c2, 0], cell_rc[r2, c2, 1], ramp_ratio)
                else:
                    cut = False
                if cut:
                    edge[r, c] |= ha
                    edge[r2, c2] |= hb
    return edge


@kernel
def _fill_render(best_index, rows, cols, norm, cam_dist, range_img, cam_img, cell_rc):
    """Write the winner ``best_index`` (H, W) of every pixel (-1: none) into the render's arrays."""
    h, w = best_index.shape
    for r in range(h):
        for c in range(w):
            i = best_index[r, c]
            if i >= 0:
                range_img[r, c] = norm[i]
                cam_img[r, c] = cam_dist[i]
                cell_rc[r, c, 0] = rows[i]
                cell_rc[r, c, 1] = cols[i]
            else:
                range_img[r, c] = np.nan
                cam_img[r, c] = np.nan
                cell_rc[r, c, 0] = -1
                cell_rc[r, c, 1] = -1


def render_from_camera(depth, camera, T_camera_lidar, *, footprint_px=None, max_range_m=None) -> CameraRender:
    """Render the scan from the camera's viewpoint: per pixel the nearest return, with filled footprints.

    Parameters
    ----------
    depth : DepthMatrix
        The scan: ``points`` (H_d, W_d, 3) in the lidar frame (metres) and the ``valid`` mask.
    camera : CameraModel
        Any registered camera model (pinhole with distortion, fisheye, OCam); the render has its image size
        and framing, ``(camera.height, camera.width)``.
    T_camera_lidar : (4, 4) array_like
        Maps lidar points (metres) into the camera frame (OpenCV: x right, y down, z forward).
    footprint_px : int, optional
        Side in pixels of the square every return covers (1: its own pixel only; even sides are taken as the
        next odd one).  None (default): automatic, per return, from the angular spacing of the scan's cells
        there -- the rectangle spans half the way to where the four grid neighbours' beams would project at
        this return's range -- capped at 3 times the median half-width (at least 2 px, at most 64 px), so a
        return does not bleed past a depth edge by more than about half the beam spacing.
    max_range_m : float, optional
        Returns farther than this from the lidar origin (metres) are left out.

    Returns
    -------
    CameraRender
        The nearest return per pixel by distance from the camera centre (a far return never paints over a
        near one).  Pixels with no return: NaN ranges and ``-1`` cells.
    """
    T = as_transform(T_camera_lidar)
    width, height = int(camera.width), int(camera.height)
    if width <= 0 or height <= 0:
        raise CalibError(f"camera image size must be positive, got {width}x{height}")
    if footprint_px is not None and int(footprint_px) < 1:
        raise CalibError(f"footprint_px must be at least 1 pixel, got {footprint_px}")
    if max_range_m is not None and not float(max_range_m) > 0:
        raise CalibError(f"max_range_m must be positive, got {max_range_m}")
    valid = np.asarray(depth.valid, bool)
    points_all = np.asarray(depth.points, np.float64)
    rows, cols = np.nonzero(valid & np.isfinite(points_all).all(axis=2))
    points = points_all[rows, cols]
    norm = _norm(points)
    if max_range_m is not None:
        keep = norm <= float(max_range_m)
        rows, cols, points, norm = rows[keep], cols[keep], points[keep], norm[keep]
    pixels, cam_dist = _project_cells(camera, T, points)
    # Only returns whose largest possible footprint can reach into the image go on (half a scan is behind).
    margin = FOOTPRINT_MAX_HALF_PX if footprint_px is None else int(footprint_px) // 2
    with np.errstate(invalid="ignore"):
        near_image = ((pixels[:, 0] >= -0.5 - margin) & (pixels[:, 0] <= width - 0.5 + margin)
                      & (pixels[:, 1] >= -0.5 - margin) & (pixels[:, 1] <= height - 0.5 + margin))
    keep = np.nonzero(near_image & (cam_dist > 0))[0]
    rows, cols, norm, pixels, cam_dist = rows[keep], cols[keep], norm[keep], pixels[keep], cam_dist[keep]
    if footprint_px is None:
        half_u, half_v = _footprint_half_px(depth, camera, T, pixels, rows, cols, FOOTPRINT_MAX_HALF_PX)
    else:
        half = np.int32(int(footprint_px) // 2)
        half_u = half_v = np.full(rows.size, half, np.int32)
    # Returns whose footprint reaches into the image (centres just outside close the border too).
    col_c = np.floor(pixels[:, 0] + 0.5)
    row_c = np.floor(pixels[:, 1] + 0.5)
    inside = ((col_c + half_u >= 0) & (col_c - half_u <= width - 1)
              & (row_c + half_v >= 0) & (row_c - half_v <= height - 1))
    idx = np.nonzero(inside)[0]
    best_key = np.full((height, width), np.inf, np.float32)
    best_index = np.full((height, width), -1, np.int32)
    _splat_nearest(col_c[idx].astype(np.int32), row_c[idx].astype(np.int32),
                   np.ascontiguousarray(half_u[idx], np.int32), np.ascontiguousarray(half_v[idx], np.int32),
                   cam_dist[idx].astype(np.float32), width, height, best_key, best_index)
    range_img = np.empty((height, width), np.float32)
    cam_img = np.empty((height, width), np.float32)
    cell_rc = np.empty((height, width, 2), np.int32)
    _fill_render(best_index, rows[idx].astype(np.int32), cols[idx].astype(np.int32), norm[idx].astype(np.float32),
                 cam_dist[idx].astype(np.float32), range_img, cam_img, cell_rc)
    edge = _depth_edges(cam_img, cell_rc, _cell_ranges(depth), bool(depth.meta.get("wrap_cols", False)),
                        np.float32(EDGE_RELATIVE_JUMP), RAMP_STEP_RATIO)
    return CameraRender(range_m=range_img, cell_rc=cell_rc, camera_depth_m=cam_img, edge=edge)


def _cell_ranges(depth) -> np.ndarray:
    """(H_d, W_d) float64: distance of every cell's point from the lidar origin, metres; NaN where invalid."""
    pts = np.asarray(depth.points, np.float64)
    return np.where(np.asarray(depth.valid, bool), np.sqrt(np.einsum("ijk,ijk->ij", pts, pts)), np.nan)


# ------------------------------------------------------------------ shading
SHADE_MODES = ("range", "intensity", "ba")


def shade_render(render: CameraRender, depth, mode: str = "range", *, intensity=None, ba_image=None) -> np.ndarray:
    """The render as an RGBA picture for display beside the photo.

    Parameters
    ----------
    render : CameraRender
        From :func:`render_from_camera` on ``depth``.
    depth : DepthMatrix
        The scan rendered (its per-cell intensity, when it has one, is read from ``meta["field_images"]``).
    mode : {"range", "intensity", "ba"}
        ``range``: cv2's TURBO colour map of log range (blue near, red far), stretched over the 1st..99th
        percentile of the shown returns (of an even sample of at most 200,000).  ``intensity``: grey from the scan's per-cell intensity
        (:func:`calib_core.display_images.find_intensity` / ``field_to_gray``, as the app's laser panes).
        ``ba``: grey from ``ba_image`` (:func:`calib_core.bearing_angle.ba_to_display`).
    intensity : (H_d, W_d) float, optional
        Per-cell intensity to use instead of the scan's own field.
    ba_image : (H_d, W_d) float, optional
        A BA image of ``depth`` in radians (NaN invalid); required for ``mode="ba"``.

    Returns
    -------
    (H, W, 4) uint8
        RGBA; depth edges white; pixels with no return fully transparent (alpha 0, RGB 0).
    """
    from .display_images import field_to_gray, find_intensity

    h, w = render.range_m.shape
    shape_d = tuple(depth.shape)
    levels = np.empty((h, w), np.uint8)
    if mode == "range":
        shown_ranges = render.range_m[render.has_return]
        shown_ranges = shown_ranges[::max(1, shown_ranges.size // 200_000)]  # percentiles of a sample suffice
        with np.errstate(invalid="ignore", divide="ignore"):
            log_r = np.log(shown_ranges[shown_ranges > 0])
        lo, hi = np.percentile(log_r, [1.0, 99.0]) if log_r.size else (0.0, 1.0)
        _levels_from_log_range(render.range_m, np.float32(lo), np.float32(1.0 / (hi - lo) if hi > lo else 1.0),
                               levels)
        lut = cv2.cvtColor(cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(-1, 1), cv2.COLORMAP_TURBO),
                           cv2.COLOR_BGR2RGB).reshape(256, 3)
    elif mode in ("intensity", "ba"):
        if mode == "intensity":
            if intensity is None:
                found = find_intensity(depth.meta.get("field_images"))
                if found is None:
                    raise CalibError("the scan has no intensity field; shade by range or ba instead")
                intensity = found[1]
            values = np.asarray(intensity, np.float64)
            if values.shape != shape_d:
                raise CalibError(f"intensity image shape {values.shape} does not match the depth matrix {shape_d}")
            cell_gray = field_to_gray(np.where(depth.valid, values, np.nan))
        else:
            from .bearing_angle import ba_to_display

            if ba_image is None:
                raise CalibError("mode 'ba' needs a BA image (ba_image=...)")
            ba = np.asarray(ba_image)
            if ba.shape != shape_d:
                raise CalibError(f"BA image shape {ba.shape} does not match the depth matrix {shape_d}")
            cell_gray = ba_to_display(ba)
        _levels_from_cells(render.cell_rc, np.ascontiguousarray(cell_gray, np.uint8), levels)
        lut = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, axis=1)
    else:
        raise CalibError(f"unknown shading mode {mode!r}; use one of {', '.join(SHADE_MODES)}")
    out = np.empty((h, w, 4), np.uint8)
    _compose_rgba(levels, np.ascontiguousarray(lut), render.cell_rc, render.edge, out)
    return out


@kernel
def _levels_from_log_range(range_m, lo, scale, levels):
    """``round(255 * clip((log(range) - lo) * scale, 0, 1))`` per pixel; 0 where no range."""
    h, w = range_m.shape
    for r in range(h):
        for c in range(w):
            v = range_m[r, c]
            if v > 0:  # NaN compares False
                x = min(max((np.log(v) - lo) * scale, np.float32(0.0)), np.float32(1.0))
                levels[r, c] = np.uint8(x * np.float32(255.0) + np.float32(0.5))
            else:
                levels[r, c] = 0


@kernel
def _levels_from_cells(cell_rc, cell_gray, levels):
    """The grey level of the cell shown at every pixel (0 where none)."""
    h, w = levels.shape
    for r in range(h):
        for c in range(w):
            i = cell_rc[r, c, 0]
            levels[r, c] = cell_gray[i, cell_rc[r, c, 1]] if i >= 0 else 0


@kernel
def _compose_rgba(levels, lut, cell_rc, edge, out):
    """RGBA: ``lut[level]`` opaque, white on edges, (0, 0, 0, 0) where no return."""
    h, w = levels.shape
    for r in range(h):
        for c in range(w):
            if cell_rc[r, c, 0] < 0:
                out[r, c, 0] = out[r, c, 1] = out[r, c, 2] = out[r, c, 3] = 0
            elif edge[r, c]:
                out[r, c, 0] = out[r, c, 1] = out[r, c, 2] = out[r, c, 3] = 255
            else:
                k = levels[r, c]
                out[r, c, 0], out[r, c, 1], out[r, c, 2] = lut[k, 0], lut[k, 1], lut[k, 2]
                out[r, c, 3] = 255


def warm_up() -> None:
    """Compile (or load from numba's disk cache) this module's kernels on a tiny scene."""
    from .cameras.pinhole import PinholeCamera
    from .lidar.depth_matrix import DepthMatrix

    el, az = np.meshgrid(np.radians([2.0, 0.0, -2.0]), np.radians([2.0, 0.0, -2.0]), indexing="ij")
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=2)
    rng = np.full(el.shape, 5.0)
    depth = DepthMatrix(rng, dirs, dirs * 5.0, np.ones(el.shape, bool), {"wrap_cols": False})
    camera = PinholeCamera(np.array([[100.0, 0, 4], [0, 100.0, 4], [0, 0, 1]]), np.zeros(0), 9, 9)
    T = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
    render = render_from_camera(depth, camera, T)
    shade_render(render, depth, "range")
    shade_render(render, depth, "intensity", intensity=rng)


# ------------------------------------------------------------------ files
RENDER_SUFFIXES = (".png", ".npz")


def check_render_path(path) -> None:
    """Refuse an output path whose suffix is neither ``.png`` nor ``.npz`` (one-line :class:`CalibError`)."""
    from pathlib import Path

    if Path(path).suffix.lower() not in RENDER_SUFFIXES:
        raise CalibError(f"{path}: the render is written as .png (shaded RGBA) or .npz (arrays); got suffix "
                         f"{Path(path).suffix or '(none)'!r}")


def write_render(path, render: CameraRender, rgba: np.ndarray | None = None) -> None:
    """Write a render atomically: ``.png`` the shaded RGBA picture ``rgba`` (from :func:`shade_render`), ``.npz``
    the arrays ``range_m`` (H, W) float32 metres (NaN: no return), ``cell_rc`` (H, W, 2) int32 (-1: none) and
    ``camera_depth_m`` (H, W) float32 metres (NaN: none)."""
    import io
    from pathlib import Path

    from .io.atomic import write_bytes_atomic

    check_render_path(path)
    if Path(path).suffix.lower() == ".npz":
        buf = io.BytesIO()
        np.savez_compressed(buf, range_m=render.range_m.astype(np.float32), cell_rc=render.cell_rc.astype(np.int32),
                            camera_depth_m=render.camera_depth_m.astype(np.float32))
        write_bytes_atomic(path, buf.getvalue())
        return
    if rgba is None or np.asarray(rgba).shape != render.range_m.shape + (4,):
        raise CalibError("a .png render needs the shaded (H, W, 4) RGBA picture")
    ok, data = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgba, np.uint8), cv2.COLOR_RGBA2BGRA))
    if not ok:
        raise CalibError(f"{path}: cannot encode the render as PNG")
    write_bytes_atomic(path, data.tobytes())
