"""Quality overlays: BA-edge points (paper Fig. 8) and the coloured cloud (Fig. 9)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from ._jit import kernel
from .bearing_angle import PREVIOUS_NEIGHBOUR, ba_to_uint8
from .arrays import as_transform
from .errors import CalibError
from .io.atomic import write_bytes_atomic
from .transforms import transform_points


def ba_edge_points(
    ba_rad: np.ndarray, depth, max_points: int | None = None, median_px: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Laser points on the edges of a BA image (paper Fig. 8).

    Edges are found with Canny on the 8-bit BA image after a median filter:
    range noise makes BA speckle on flat surfaces (a 1 cm error over a
    2.6 cm beam spacing is tens of degrees), and the median removes it while
    keeping the steps at plane intersections.  The Canny thresholds come from
    Otsu's threshold of the image itself, so the same call works on any
    scene.  Cells next to an invalid cell are dropped: the border of a
    no-return region is an artefact, not a scene edge.

    Parameters
    ----------
    ba_rad : (H, W) float
        One BA image in radians, NaN where invalid.
    depth : DepthMatrix
        The depth matrix the BA image was computed from.
    max_points : int, optional
        Keep at most this many points (evenly subsampled), for display.
    median_px : int, optional
        Aperture of the median filter (odd; 1 = none).  Default 5, or 3 for
        scans under 128 rows (a spinning lidar's few rings are far apart).

    Returns
    -------
    points_lidar : (M, 3) float64
        Edge points in the lidar frame, metres.
    rows_cols : (M, 2) int64
        Their depth-matrix cells.
    """
    ba = np.asarray(ba_rad)
    if ba.shape != depth.shape:
        raise CalibError(f"BA image shape {ba.shape} does not match the depth matrix {depth.shape}")
    gray = ba_to_uint8(ba)
    valid = np.isfinite(ba) & depth.valid
    if not valid.any():
        return np.empty((0, 3)), np.empty((0, 2), dtype=np.int64)
    if median_px is None:
        median_px = 5 if ba.shape[0] >= 128 else 3
    smooth = cv2.medianBlur(gray, median_px) if median_px > 1 else gray
    otsu, _ = cv2.threshold(smooth[valid].reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    edges = cv2.Canny(smooth, 0.5 * otsu, otsu) > 0
    interior = cv2.erode(valid.astype(np.uint8), np.ones((3, 3), np.uint8), borderValue=1) > 0
    rows, cols = np.nonzero(edges & interior)
    if max_points is not None and rows.size > max_points:
        keep = np.linspace(0, rows.size - 1, max_points).astype(np.int64)
        rows, cols = rows[keep], cols[keep]
    return depth.points[rows, cols], np.stack([rows, cols], axis=1).astype(np.int64)


def trace_spacing_ok(depth, direction: str, min_spacing_m: float = 0.025) -> np.ndarray:
    """Cells far enough from their trace neighbour for the BA to mean something.

    The BA compares two ranges a distance ``rho * dphi`` apart; where that is
    not well above the range noise (about 1 cm for common scanners; 2.5 cm by default), the BA
    is noise -- near the poles of a rotating scanner, on the ground right
    under it.  Returns ``(H, W)`` bool: ``range_m * dphi >= min_spacing_m``,
    with ``dphi`` the true angle to the previous beam of ``direction``.
    """
    d_row, d_col = PREVIOUS_NEIGHBOUR[direction]
    dirs = depth.directions
    h, w = depth.shape
    rows = np.arange(h) + d_row
    cols = np.arange(w) + d_col
    if depth.meta.get("wrap_cols", False):
        cols = cols % w
    r_ok, c_ok = (rows >= 0) & (rows < h), (cols >= 0) & (cols < w)
    prev = dirs[np.clip(rows, 0, h - 1)][:, np.clip(cols, 0, w - 1)]
    with np.errstate(invalid="ignore"):
        dphi = np.arccos(np.clip(np.einsum("ijk,ijk->ij", dirs, prev), -1.0, 1.0))
        ok = depth.range_m * dphi >= min_spacing_m
    return ok & r_ok[:, None] & c_ok[None, :]


def ba_edge_points_consensus(
    ba_images: dict[str, np.ndarray], depth, min_votes: int = 2, max_points: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """BA-edge points confirmed by several BA directions.

    Range noise makes spurious edges that differ from one direction to the
    next, while a plane intersection shows in most of them.  A cell is kept
    when it is an edge (:func:`ba_edge_points`) of some direction whose beam
    spacing there is sound (:func:`trace_spacing_ok`) and at least
    ``min_votes`` directions have an edge within one cell of it.

    Returns
    -------
    points_lidar : (M, 3) float64
    rows_cols : (M, 2) int64
    """
    h, w = depth.shape
    kernel = np.ones((3, 3), np.uint8)
    maps = {}
    for name, ba in ba_images.items():
        m = np.zeros((h, w), np.uint8)
        _, rc = ba_edge_points(ba, depth)
        m[rc[:, 0], rc[:, 1]] = 1
        maps[name] = m & trace_spacing_ok(depth, name)
    if not maps:
        return np.empty((0, 3)), np.empty((0, 2), dtype=np.int64)
    votes = sum(cv2.dilate(m, kernel) for m in maps.values())
    keep = np.logical_or.reduce([m > 0 for m in maps.values()]) & (votes >= min_votes)
    rows, cols = np.nonzero(keep)
    if max_points is not None and rows.size > max_points:
        pick = np.linspace(0, rows.size - 1, max_points).astype(np.int64)
        rows, cols = rows[pick], cols[pick]
    return depth.points[rows, cols], np.stack([rows, cols], axis=1).astype(np.int64)


def project_lidar_points(T_camera_lidar: np.ndarray, camera, points_lidar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of lidar points under ``T_camera_lidar``: ``(pixels (N, 2), valid (N,))``."""
    pts = np.asarray(points_lidar, dtype=np.float64).reshape(-1, 3)
    if pts.shape[0] == 0:
        return np.empty((0, 2)), np.empty(0, dtype=bool)
    return camera.project(transform_points(T_camera_lidar, pts))


def _packed_rgbx(image) -> np.ndarray:
    """``image`` (H, W, 3 or 4) uint8 as (H, W) int32, one pixel per item: one load per pixel in the sampler."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8:
        raise CalibError(f"camera image must be an (H, W, 3) uint8 array, got {img.shape} {img.dtype}")
    if img.shape[2] == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2RGBA)
    return np.ascontiguousarray(img).view(np.int32)[..., 0]


_FINE_CELL_PX = 4  # occupancy grid of the automatic z-buffer cell size (even: a min-pool of 2-pixel cells)


@kernel
def _min_pool(grid, k):
    """Minimum over ``k`` x ``k`` blocks of a 2-D float32 grid, the last block row/column partial."""
    h, w = grid.shape
    out = np.full((-(-h // k), -(-w // k)), np.inf, np.float32)
    for r in range(h):
        for c in range(w):
            out[r // k, c // k] = min(out[r // k, c // k], grid[r, c])
    return out


def _cell_px_from_occupancy(occupied_cells: int, n_points: int) -> int:
    """Z-buffer cell size from the density of projected points.

    ``occupied_cells`` is the number of :data:`_FINE_CELL_PX` cells that hold
    a projected point.  A z-buffer cell must hold about one laser point, or
    background points seen through the gaps of a sparse foreground would be
    taken as visible.
    """
    spacing = np.sqrt(occupied_cells * _FINE_CELL_PX**2 / max(n_points, 1))
    return int(np.clip(np.ceil(1.5 * spacing), 2, 32))


def _grid_shape(width: int, height: int, cell: int) -> tuple[int, int]:
    """Shape ``(grid_h, grid_w)`` of the grid of ``cell``-pixel cells over a ``width`` x ``height`` image.

    A pixel ``(u, v)`` (centres at integers, inside the image) lies in cell
    ``(int(v + 0.5) // cell, int(u + 0.5) // cell)``: truncation from the
    top-left edge, and the edge pixels at ``width - 0.5`` join the last
    column (their ``u`` is clamped to ``width - 1`` first).
    """
    return -(-height // cell), -(-width // cell)


# ------------------------------------------------------------------ kernels
#: Unsigned array indices: numba adds a negative-index wrap-around to every
#: signed index, which costs instructions and keeps loops off SIMD lanes.
_U = np.uintp


@kernel
def _to_camera(points, M, xyz, dist):
    """``xyz (3, N) = M[:, :3] @ p + M[:, 3]`` per point ``p`` of ``points (N, 3)``, and ``dist = |xyz|``.

    The transform in float64, stored float32 (the projection of the whole
    cloud runs in float32); the distance from the stored float32 values.
    NaN points give NaN; coordinates beyond float32 give inf.
    """
    m00, m01, m02, m03 = M[0, 0], M[0, 1], M[0, 2], M[0, 3]
    m10, m11, m12, m13 = M[1, 0], M[1, 1], M[1, 2], M[1, 3]
    m20, m21, m22, m23 = M[2, 0], M[2, 1], M[2, 2], M[2, 3]
    for i_ in range(points.shape[0]):
        i = _U(i_)
        px, py, pz = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        x = np.float32(m00 * px + m01 * py + m02 * pz + m03)
        y = np.float32(m10 * px + m11 * py + m12 * pz + m13)
        z = np.float32(m20 * px + m21 * py + m22 * pz + m23)
        xyz[0, i], xyz[1, i], xyz[2, i] = x, y, z
        dist[i] = np.sqrt(x * x + y * y + z * z)


@kernel
def _cell_of(u, v, cell, grid_w):
    """Row-major index of the grid cell (see :func:`_grid_shape`) of a pixel clamped into the image.

    ``float32`` division, not integer division (one instruction for 8 points
    on SIMD lanes): exact here, as the quotient of two integers below 2^24
    is rounded correctly and is never within rounding of the next integer.
    """
    half = np.float32(0.5)
    col = np.float32(np.int32(u + half)) / cell
    row = np.float32(np.int32(v + half)) / cell
    return np.int32(row) * grid_w + np.int32(col)


@kernel
def _zbuffer(pixels, valid, dist, width, height, cell, grid_w, n_cells):
    """Z-buffer of the valid pixels: the smallest ``dist`` per grid cell (see :func:`_grid_shape`).

    Returns (n_cells,) float32, inf where empty.
    """
    zbuf = np.full(n_cells, np.inf, np.float32)
    fcell, gw = np.float32(cell), np.int32(grid_w)
    u_max, v_max = np.float32(width - 1), np.float32(height - 1)
    for i in range(pixels.shape[0]):
        if valid[i]:
            k = _cell_of(min(pixels[i, 0], u_max), min(pixels[i, 1], v_max), fcell, gw)
            zbuf[_U(k)] = min(zbuf[_U(k)], dist[i])  # a store every time: a branch here is mispredicted
    return zbuf


#: Points per chunk of :func:`_colour_visible`: its buffers stay in L1 cache.
_CHUNK = 256


@kernel
def _colour_visible(pixels, valid, dist, cell_px, grid_w, limit, image, colors, coloured):
    """Colour the valid points no farther than the depth ``limit`` of their ``cell_px`` grid cell (see
    :func:`_grid_shape`; ``grid_w`` cells a row).

    Bilinear colours of the packed RGBX ``image`` (H, W) int32 (channel 0
    in the low byte) at ``pixels`` (N, 2) float32 ``(u, v)`` into ``colors``
    (N, 3) uint8, rounded to nearest, zero where not coloured; the border
    pixels repeat outside the image (OpenCV's BORDER_REPLICATE).  Writes
    which points were coloured into ``coloured`` (N,) bool.

    By chunks, every point alike (no branch on visibility): indices and
    fractions (SIMD lanes), the gathers alone, then the depth test and the
    arithmetic (SIMD lanes; int32, not uint32, channels: x86 converts
    signed integers to float on SIMD lanes, unsigned ones one at a time).
    """
    height, width = image.shape
    flat = image.ravel()
    n = pixels.shape[0]
    cell = np.empty(_CHUNK, np.int32)
    index = np.empty(_CHUNK, np.int32)
    down = np.empty(_CHUNK, np.int32)
    right = np.empty(_CHUNK, np.int32)
    frac_u = np.empty(_CHUNK, np.float32)
    frac_v = np.empty(_CHUNK, np.float32)
    lim = np.empty(_CHUNK, np.float32)
    q0, q1 = np.empty(_CHUNK, np.int32), np.empty(_CHUNK, np.int32)
    q2, q3 = np.empty(_CHUNK, np.int32), np.empty(_CHUNK, np.int32)
    out = np.empty((3, _CHUNK), np.uint8)
    u_max, v_max = np.float32(width - 1), np.float32(height - 1)
    half, zero, one = np.float32(0.5), np.float32(0.0), np.float32(1.0)
    w32, last_row, last_col = np.int32(width), np.int32(height - 1), np.int32(width - 1)
    fcell, gw = np.float32(cell_px), np.int32(grid_w)
    mask = np.int32(255)
    for start in range(0, n, _CHUNK):
        count = min(_CHUNK, n - start)
        for k in range(count):
            i, k_ = _U(start + k), _U(k)
            u, v = pixels[i, 0], pixels[i, 1]
            # Into the image; NaN (invalid points) -> 0: never an index.
            u = u if u > zero else zero
            v = v if v > zero else zero
            u = u if u < u_max else u_max
            v = v if v < v_max else v_max
            cell[k_] = _cell_of(u, v, fcell, gw)
            c0, r0 = np.int32(u), np.int32(v)
            index[k_] = r0 * w32 + c0
            down[k_] = w32 if r0 < last_row else np.int32(0)
            right[k_] = np.int32(1) if c0 < last_col else np.int32(0)
            frac_u[k_] = u - np.float32(c0)
            frac_v[k_] = v - np.float32(r0)
        for k in range(count):  # random reads alone: many in flight
            k_ = _U(k)
            j = index[k_]
            lim[k_] = limit[_U(cell[k_])]
            q0[k_] = flat[_U(j)]
            q1[k_] = flat[_U(j + right[k_])]
            q2[k_] = flat[_U(j + down[k_])]
            q3[k_] = flat[_U(j + down[k_] + right[k_])]
        for k in range(count):
            i, k_ = _U(start + k), _U(k)
            ok = valid[i] & (dist[i] <= lim[k_])
            coloured[i] = ok
            keep = one if ok else zero
            x, y = frac_u[k_], frac_v[k_]
            a0, a1, a2, a3 = q0[k_], q1[k_], q2[k_], q3[k_]
            for c in range(3):  # unrolled by LLVM
                shift = np.int32(8 * c)
                a = np.float32((a0 >> shift) & mask)
                b = np.float32((a1 >> shift) & mask)
                d = np.float32((a2 >> shift) & mask)
                e = np.float32((a3 >> shift) & mask)
                top = a + x * (b - a)
                bottom = d + x * (e - d)
                out[c, k_] = np.uint8(np.int32((top + y * (bottom - top) + half) * keep))
        for k in range(count):
            i, k_ = _U(start + k), _U(k)
            colors[i, 0] = out[0, k_]
            colors[i, 1] = out[1, k_]
            colors[i, 2] = out[2, k_]


#: Clouds of at least this many points are coloured on two threads (below, the hand-over costs more).
_THREADED_POINTS = 200_000
_POOL = None
_POOL_LOCK = threading.Lock()


def _threads(n: int) -> int:
    return 2 if n >= _THREADED_POINTS and (os.cpu_count() or 1) >= 2 else 1


def _run(fn, items) -> list:
    """``[fn(x) for x in items]``, the first on this thread and the others on a worker thread."""
    global _POOL
    items = list(items)
    if len(items) == 1:
        return [fn(items[0])]
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ba-calib-colour")
    rest = [_POOL.submit(fn, x) for x in items[1:]]
    return [fn(items[0])] + [f.result() for f in rest]


def colorize_points(
    points_lidar: np.ndarray,
    image: np.ndarray,
    camera,
    T_camera_lidar: np.ndarray,
    occlusion: bool = True,
    cell_px: int | None = None,
    depth_tolerance: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """Colour laser points from the camera image (paper Fig. 9).

    A point gets a colour only if it projects inside the image and, with
    ``occlusion``, passes a depth test: it must be no farther than
    ``(1 + depth_tolerance)`` times the nearest point projected into the
    surrounding z-buffer cells (3x3 cells of ``cell_px`` pixels).  Camera and
    lidar see from different places, so a projection alone would paint
    background points with the colour of the object in front of them.

    Clouds of at least 200k points are split in two halves on two threads
    (results identical); under load from other processes that gains nothing
    and loses up to about 10 %, on an idle second core it saves a third.

    The points are transformed in float64 and projected in float32
    (``camera.project`` on float32 points): pixels are within about 5e-4 px
    of the float64 projection, and the memory traffic is halved.  The
    transform, the z-buffer, the depth test and the sampling are compiled
    loops; the projection is the camera model's own.

    Parameters
    ----------
    points_lidar : (N, 3) float
        Points in the lidar frame, metres (NaN rows are never coloured).
    image : (H, W, 3) uint8
        The camera image, RGB.
    camera : CameraModel
    T_camera_lidar : (4, 4) float
    occlusion : bool
        Apply the depth test.
    cell_px : int, optional
        Z-buffer cell size in pixels; by default from the point density.
    depth_tolerance : float
        Relative depth margin of the test (plus 5 cm absolute).

    Returns
    -------
    colors : (N, 3) uint8
        Bilinear image colour, zero where there is none.
    has_color : (N,) bool
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8:
        raise CalibError(f"camera image must be an (H, W, 3) uint8 array, got {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    if (w, h) != (camera.width, camera.height):
        raise CalibError(f"image is {w}x{h} but the camera model is {camera.width}x{camera.height}")
    T = as_transform(T_camera_lidar)
    packed = _packed_rgbx(img)
    pts = np.asarray(points_lidar)
    if pts.dtype not in (np.float32, np.float64):
        pts = pts.astype(np.float64)
    pts = np.ascontiguousarray(pts.reshape(-1, 3))
    n = pts.shape[0]

    # Large clouds in two halves on two threads (the kernels release the GIL);
    # each half keeps its own contiguous arrays, the z-buffers are merged.
    bounds = np.linspace(0, n, _threads(n) + 1).astype(np.int64)
    parts = list(zip(bounds[:-1], bounds[1:]))
    M = np.ascontiguousarray(T[:3])

    def project(part):
        a, b = part
        # Camera frame as three contiguous float32 rows (the camera's element-wise
        # maths runs on contiguous data), and the distance of every point.
        xyz, dist = np.empty((3, b - a), np.float32), np.empty(b - a, np.float32)
        _to_camera(pts[a:b], M, xyz, dist)
        pixels, valid = camera.project(xyz.T)
        return np.ascontiguousarray(pixels, dtype=np.float32), np.ascontiguousarray(valid, dtype=np.bool_), dist

    projected = _run(project, parts)
    if not occlusion:  # one cell over the whole image, without a depth limit
        cell, grid_w = max(w, h) + 1, 1
        limit = np.full(1, np.inf, np.float32)
    else:
        # One z-buffer pass at the finest cell; the occupancy that sets the
        # cell size, and any even cell size, are min-pools of it (a cell of
        # 2k pixels is exactly k x k cells of 2 pixels, edges included).
        def zbuffer(c):
            g = _grid_shape(w, h, c)
            bufs = _run(lambda pvd: _zbuffer(*pvd, w, h, c, g[1], g[0] * g[1]), projected)
            return np.minimum.reduce(bufs).reshape(g) if len(bufs) > 1 else bufs[0].reshape(g)

        fine = _FINE_CELL_PX // 2
        zbuf = zbuffer(fine)
        cell = cell_px
        if cell is None:
            occupied = np.count_nonzero(_min_pool(zbuf, _FINE_CELL_PX // fine) < np.inf)
            cell = _cell_px_from_occupancy(occupied, sum(int(np.count_nonzero(v)) for _, v, _ in projected))
        cell = int(cell)
        if cell != fine:
            zbuf = _min_pool(zbuf, cell // fine) if cell % fine == 0 else zbuffer(cell)
        # Min over 3x3 cells: a gap in a sparse foreground must not let the background through.
        limit = cv2.erode(zbuf, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE).ravel()
        limit = limit * np.float32(1.0 + depth_tolerance) + np.float32(0.05)
        grid_w = zbuf.shape[1]
    colors = np.empty((n, 3), np.uint8)
    has_color = np.empty(n, np.bool_)

    def colour(k):
        (a, b), (pixels, valid, dist) = parts[k], projected[k]
        _colour_visible(pixels, valid, dist, cell, grid_w, limit, packed, colors[a:b], has_color[a:b])

    _run(colour, range(len(parts)))
    return colors, has_color


def warm_up() -> None:
    """Compile (or load from numba's disk cache) this module's kernels on a few points."""
    from .cameras.pinhole import PinholeCamera

    camera = PinholeCamera(np.array([[4.0, 0, 2], [0, 4.0, 2], [0, 0, 1]]), np.zeros(0), 4, 4)
    image = np.zeros((4, 4, 3), np.uint8)
    for dtype in (np.float64, np.float32):  # the clouds come in both
        points = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 2.0], [np.nan, 0.0, 1.0]], dtype)
        colorize_points(points, image, camera, np.eye(4))


def export_colored_ply(
    path: str | os.PathLike,
    points: np.ndarray,
    colors: np.ndarray,
    has_color: np.ndarray | None = None,
    uncolored_rgb: tuple[int, int, int] = (128, 128, 128),
) -> None:
    """Write a coloured point cloud as binary PLY (trimesh), atomically.

    Points without colour are written grey; NaN points are dropped.
    """
    import trimesh

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rgb = np.asarray(colors, dtype=np.uint8).reshape(-1, 3).copy()
    if has_color is not None:
        rgb[~np.asarray(has_color, bool)] = uncolored_rgb
    keep = np.isfinite(pts).all(axis=1)
    if not keep.any():
        raise CalibError("no valid points to export")
    rgba = np.concatenate([rgb[keep], np.full((int(keep.sum()), 1), 255, np.uint8)], axis=1)
    cloud = trimesh.PointCloud(pts[keep], colors=rgba)
    write_bytes_atomic(path, cloud.export(file_type="ply"))


def export_colored_scan(
    path: str | os.PathLike, depth, image: np.ndarray, camera, T_camera_lidar: np.ndarray, occlusion: bool = True
) -> tuple[int, int]:
    """Colour every valid point of ``depth`` from ``image`` and write it as a PLY (Fig. 9); ``(coloured, points)``.

    The one coloured-PLY export: ``ba-calib colorize`` and the app's download both call it.
    """
    points, _ = depth.valid_points()
    colors, has_color = colorize_points(points, image, camera, T_camera_lidar, occlusion=occlusion)
    export_colored_ply(path, points, colors, has_color)
    return int(np.count_nonzero(has_color)), len(points)


def columns_seen_by_camera(depth, camera, T_camera_lidar: np.ndarray) -> np.ndarray:
    """``(n_cols,)`` bool: the depth-matrix columns with a valid point that projects into the camera image.

    Frames: ``T_camera_lidar`` maps lidar points (metres) into the camera frame.
    """
    points, rows_cols = depth.valid_points()
    _, in_image = project_lidar_points(T_camera_lidar, camera, points)
    seen = np.zeros(depth.shape[1], bool)
    seen[rows_cols[in_image, 1]] = True
    return seen
