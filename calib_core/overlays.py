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
    n = len(pixels)
    # cv2.remap maps are limited to 32767 per side: lay the N samples out as rows of 4096.
    cols = 4096
    rows = -(-n // cols)
    grid = np.zeros((rows * cols, 2), np.float32)
    grid[:n] = pixels
    out = cv2.remap(image, grid.reshape(rows, cols, 2), None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(rows * cols, -1)[:n]


def _auto_cell_px(pixels: np.ndarray, width: int, height: int) -> int:
    """Z-buffer cell size from the density of projected points.

    A cell must hold about one laser point, or background points seen
    through the gaps of a sparse foreground would be taken as visible.
    """
    fine = 4
    cells = (pixels[:, 1] // fine).astype(np.int64) * ((width + fine - 1) // fine) + (pixels[:, 0] // fine).astype(np.int64)
    occupied_area = np.count_nonzero(np.bincount(cells)) * fine * fine
    spacing = np.sqrt(occupied_area / max(len(pixels), 1))
    return int(np.clip(np.ceil(1.5 * spacing), 2, 32))


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
    pts = np.asarray(points_lidar, dtype=np.float64).reshape(-1, 3)
    n = pts.shape[0]
    colors = np.zeros((n, 3), np.uint8)
    has_color = np.zeros(n, bool)
    # A sum is finite only if every term is (4x faster than isfinite().all(axis=1)).
    idx = np.flatnonzero(np.isfinite(pts[:, 0] + pts[:, 1] + pts[:, 2]))
    if idx.size == 0:
        return colors, has_color
    X_cam = transform_points(T_camera_lidar, pts[idx])
    pixels, valid = camera.project(X_cam)
    X_cam = X_cam[valid]
    idx, pixels = idx[valid], pixels[valid]
    dist = np.sqrt(np.einsum("ij,ij->i", X_cam, X_cam))
    if idx.size == 0:
        return colors, has_color
    if occlusion:
        cell = cell_px or _auto_cell_px(pixels + 0.5, w, h)
        gw, gh = (w + cell - 1) // cell, (h + cell - 1) // cell
        cu = np.clip(((pixels[:, 0] + 0.5) // cell).astype(np.int64), 0, gw - 1)
        cv_ = np.clip(((pixels[:, 1] + 0.5) // cell).astype(np.int64), 0, gh - 1)
        flat = cv_ * gw + cu
        zbuf = np.full(gw * gh, np.inf, np.float32)
        np.minimum.at(zbuf, flat, dist.astype(np.float32))
        # Min over 3x3 cells: a gap in a sparse foreground must not let the background through.
        zmin = cv2.erode(zbuf.reshape(gh, gw), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE).ravel()
        visible = dist <= zmin[flat] * (1.0 + depth_tolerance) + 0.05
        idx, pixels = idx[visible], pixels[visible]
    colors[idx] = sample_bilinear(img[..., :3], pixels)
    has_color[idx] = True
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
