"""Quality overlays: BA-edge points (paper Fig. 8) and the coloured cloud (Fig. 9)."""

from __future__ import annotations

import os

import cv2
import numpy as np

from .bearing_angle import PREVIOUS_NEIGHBOUR, ba_to_uint8
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


def sample_bilinear(image: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Bilinear colours of ``image`` at ``(u, v)`` pixels: ``(N, C)``, same dtype."""
    pixels = np.asarray(pixels)
    return _sample_bilinear_uv(image, pixels[:, 0], pixels[:, 1])


def _sample_bilinear_uv(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`sample_bilinear` with the columns ``u`` and rows ``v`` as separate arrays."""
    n = len(u)
    # cv2.remap maps are limited to 32767 per side: lay the N samples out as rows.
    cols = _REMAP_COLS
    rows = max(1, -(-n // cols))
    map_u = np.zeros(rows * cols, np.float32)
    map_v = np.zeros(rows * cols, np.float32)
    map_u[:n], map_v[:n] = u, v
    out = cv2.remap(image, map_u.reshape(rows, cols), map_v.reshape(rows, cols), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(rows * cols, -1)[:n]


#: Points per block in :func:`colorize_points`: the temporaries of a block stay
#: in cache, where full-size ones (a dozen arrays of N floats) cost more in
#: allocation and cache misses than the arithmetic.
_COLOR_BLOCK = 1 << 16

_FINE_CELL_PX = 4  # occupancy grid of the automatic z-buffer cell size
_REMAP_COLS = 4096  # samples per row of the cv2.remap maps


def _blocks(n: int):
    return (slice(start, min(start + _COLOR_BLOCK, n)) for start in range(0, n, _COLOR_BLOCK))


def _cell_px_from_occupancy(occupied_cells: int, n_points: int) -> int:
    """Z-buffer cell size from the density of projected points.

    ``occupied_cells`` is the number of :data:`_FINE_CELL_PX` cells that hold
    a projected point.  A z-buffer cell must hold about one laser point, or
    background points seen through the gaps of a sparse foreground would be
    taken as visible.
    """
    spacing = np.sqrt(occupied_cells * _FINE_CELL_PX**2 / max(n_points, 1))
    return int(np.clip(np.ceil(1.5 * spacing), 2, 32))


def _cell_index(u_edge: np.ndarray, v_edge: np.ndarray, cell: int, grid_w: int, grid_h: int) -> np.ndarray:
    """Row-major int32 index of the ``cell``-pixel cell of each point.

    ``u_edge, v_edge`` are measured from the image's top-left edge, so that
    truncation is the floor for every point inside the image; other points
    (NaN, negative, huge) get some cell of the grid, to be masked by the caller.
    """
    with np.errstate(invalid="ignore"):
        col = u_edge.astype(np.int32)
        row = v_edge.astype(np.int32)
    col //= cell
    np.clip(col, 0, grid_w - 1, out=col)
    row //= cell
    np.clip(row, 0, grid_h - 1, out=row)
    row *= grid_w
    row += col
    return row


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

    The points are transformed and projected in float32: pixels are within
    about 5e-4 px of the float64 projection, finer than the 1/32 px steps of
    OpenCV's bilinear weights, and the memory traffic is halved.

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
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    if T.shape != (4, 4):
        raise CalibError(f"T_camera_lidar must be a 4x4 matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise CalibError("T_camera_lidar contains NaN or infinite values")
    pts = np.asarray(points_lidar).reshape(-1, 3)
    n = pts.shape[0]
    M = T[:3].astype(np.float32)

    # Pass 1: project.  u, v from the image's top-left edge (pixel centre + 0.5);
    # dist = inf where not projectable, so those points never enter the z-buffer.
    u, v, dist = np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)
    valid = np.empty(n, bool)
    fine_w, fine_h = -(-w // _FINE_CELL_PX) + 1, -(-h // _FINE_CELL_PX) + 1  # + the edge pixels' cells
    occupancy = np.zeros(fine_w * fine_h + 1, np.intp)  # last bin: points outside the image
    for b in _blocks(n):
        block = np.ascontiguousarray(pts[b], dtype=np.float32).reshape(-1, 1, 3)
        # Camera frame, one contiguous row per coordinate (the camera's
        # element-wise maths then runs on contiguous data); NaN rows stay NaN
        # and are not projectable.
        xyz = cv2.transform(block, M).reshape(-1, 3).T.copy()
        pixels, ok = camera.project(xyz.T)
        valid[b] = ok
        with np.errstate(over="ignore"):  # float64 pixels far outside the image may overflow float32
            np.add(pixels[:, 0], 0.5, out=u[b], casting="unsafe")
            np.add(pixels[:, 1], 0.5, out=v[b], casting="unsafe")
        if occlusion:
            with np.errstate(over="ignore"):  # absurd coordinates (1e30) give inf: never projectable
                d = xyz[0] * xyz[0]
                d += xyz[1] * xyz[1]
                d += xyz[2] * xyz[2]
            np.sqrt(d, out=d)
            d[~ok] = np.inf
            dist[b] = d
            if cell_px is None:
                cells = _cell_index(u[b], v[b], _FINE_CELL_PX, fine_w, fine_h)
                cells[~ok] = occupancy.size - 1
                occupancy += np.bincount(cells, minlength=occupancy.size)
    has_color = np.zeros(n, bool)
    if not valid.any():
        return np.zeros((n, 3), np.uint8), has_color

    if occlusion:
        # Pass 2: z-buffer of the nearest distance per cell.
        cell = cell_px or _cell_px_from_occupancy(np.count_nonzero(occupancy[:-1]), np.count_nonzero(valid))
        gw, gh = -(-w // cell), -(-h // cell)
        zbuf = np.full(gw * gh, np.inf, np.float32)
        flat = np.empty(n, np.int32)
        for b in _blocks(n):
            flat[b] = _cell_index(u[b], v[b], cell, gw, gh)  # edge pixels go to the last cell
            np.minimum.at(zbuf, flat[b], dist[b])
        # Min over 3x3 cells: a gap in a sparse foreground must not let the background through.
        zmin = cv2.erode(zbuf.reshape(gh, gw), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE).ravel()
        zmin *= 1.0 + depth_tolerance
        zmin += 0.05

    # Pass 3: colours of the visible points.  OpenCV's remap has SIMD code
    # for 4-channel images, twice as fast as for 3; each colour is then
    # scattered as one 4-byte item, and the 4th channel dropped at the end.
    rgba = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2RGBA)
    colors4 = np.zeros((-(-n // _REMAP_COLS) * _REMAP_COLS, 4), np.uint8)
    colors32 = colors4.view(np.uint32).ravel()
    for b in _blocks(n):
        visible = valid[b]
        if occlusion:
            visible = visible & (dist[b] <= zmin.take(flat[b]))
        has_color[b] = visible
        ids = np.flatnonzero(visible)
        if ids.size:
            sampled = _sample_bilinear_uv(rgba, u[b].take(ids) - 0.5, v[b].take(ids) - 0.5)
            np.put(colors32, ids + b.start, sampled.view(np.uint32).ravel())
    # (A wide 2-D layout: cvtColor is slow on a single column.)
    colors = cv2.cvtColor(colors4.reshape(-1, _REMAP_COLS, 4), cv2.COLOR_RGBA2RGB).reshape(-1, 3)[:n]
    return colors, has_color


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
