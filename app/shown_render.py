"""A finished render of the scan from the camera, as the render pane shows it, and pure queries on it.

The render pane publishes a :class:`ShownRender`; the loupes and the pairs panel ask it which scan cell a pixel
shows, where cells land, and what a loupe crop of it looks like, without reaching into the pane.  Pixels are the
camera's original pixels (the top-left pixel's centre is (0, 0)).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np

from calib_core.overlays import project_lidar_points

from .ba_view import crop_texture

#: What the pane shows where the scan has no return (dark, so range colours and white depth edges stand out).
NO_RETURN_RGB = (30, 30, 34)
#: Outside the render in a loupe crop.
PAD_RGB = (60, 60, 60)
#: A click on a pixel without a return takes the nearest rendered pixel this close (render pixels) ...
NEAREST_PX = 4
TEXTURE_TEXELS = 320  # as app.loupes: texels along a loupe texture's side


@dataclasses.dataclass(frozen=True, eq=False)
class ShownRender:
    """A finished render: the pose and shading it was made with, the :class:`calib_core.render.CameraRender`,
    its RGBA shading (alpha 0 where no return), how long it took (seconds) and when it was finished
    (``time.monotonic()`` seconds: a click just after a pose change is checked against it,
    :meth:`app.pose_source.PoseSource.stale_click_reason`)."""

    T_camera_lidar: np.ndarray
    mode: str
    source: str
    render: Any
    rgba: np.ndarray
    seconds: float
    made_at: float = dataclasses.field(default_factory=time.monotonic)


# ---------------------------------------------------------------------- a shown render's pixels and cells
def pane_texture(rgba: np.ndarray) -> np.ndarray:
    """The pane's RGB texture: the shading over :data:`NO_RETURN_RGB` where there is no return."""
    a = rgba[..., 3:4].astype(np.uint16)
    bg = np.asarray(NO_RETURN_RGB, np.uint16)
    return ((rgba[..., :3].astype(np.uint16) * a + bg * (255 - a) + 127) // 255).astype(np.uint8)


#: Near a depth edge a click takes the nearer surface when a pixel this much nearer (camera depth ratio) is within
#: the click's edge radius: the person sees the thin near object, not the one render pixel behind it (run 8: a click
#: on a pole's edge took the wall behind it, 36.96 m instead of about 30 m).
FOREGROUND_RATIO = 1.1


def cell_at_pixel(shown: ShownRender | None, u: float, v: float,
                  radius_px: float = NEAREST_PX, edge_px: float = 0.0) -> tuple[int, int] | None:
    """Scan cell ``(row, col)`` render ``shown`` draws at original-size pixel ``(u, v)`` (the z-buffer's nearest
    return there), or at the nearest rendered pixel within ``radius_px`` render pixels; None if none (or no render).

    ``edge_px``: how far (render pixels) the click may be off what the person aimed at (e.g. one screen pixel of a
    downscaled pane).  A surface nearer than the clicked pixel's by :data:`FOREGROUND_RATIO` within that distance
    wins where the render outlines it (a depth edge, not a smooth surface such as the ground before a wall): the
    foreground's cell, the one drawn over the background."""
    if shown is None:
        return None
    cells = shown.render.cell_rc
    h, w = cells.shape[:2]
    iu, iv = int(math.floor(u + 0.5)), int(math.floor(v + 0.5))
    r = int(math.ceil(max(radius_px, edge_px)))
    u0, u1, v0, v1 = max(iu - r, 0), min(iu + r + 1, w), max(iv - r, 0), min(iv + r + 1, h)
    if u0 >= u1 or v0 >= v1:
        return None
    window = cells[v0:v1, u0:u1]
    vv, uu = np.mgrid[v0:v1, u0:u1]
    dist2 = (uu - u) ** 2 + (vv - v) ** 2
    d2 = np.where(window[..., 0] >= 0, dist2, np.inf)
    k = int(np.argmin(d2))
    if edge_px > 0:
        depth = np.asarray(getattr(shown.render, "camera_depth_m", shown.render.range_m), np.float64)[v0:v1, u0:u1]
        near = (window[..., 0] >= 0) & (dist2 <= edge_px * edge_px) & np.isfinite(depth)
        edges = getattr(shown.render, "edge", None)  # depth edges: a jump, not a smooth surface (ground to wall)
        if near.any():
            front = float(depth[near].min())
            hit = depth.flat[k] if np.isfinite(d2.flat[k]) else np.inf
            outlined = edges is None or bool((near & (depth <= front * FOREGROUND_RATIO) & edges[v0:v1, u0:u1]).any())
            if not hit <= front * FOREGROUND_RATIO and outlined:  # behind the outline of a nearer surface it touches
                k = int(np.argmin(np.where(near & (depth <= front * FOREGROUND_RATIO), dist2, np.inf)))
                return tuple(int(x) for x in window.reshape(-1, 2)[k])  # type: ignore[return-value]
    if not np.isfinite(d2.flat[k]) or d2.flat[k] > radius_px * radius_px:
        return None
    row, col = window.reshape(-1, 2)[k]
    return int(row), int(col)


def pixel_of_cells(shown: ShownRender | None, camera: Any, depth: Any, rows_cols: np.ndarray) -> np.ndarray:
    """Original camera pixels ``(N, 2)`` where render ``shown`` draws scan cells ``(N, 2)``: the cell's point
    projected under the render's pose, moved to the nearest pixel the render draws that cell on within
    :data:`NEAREST_PX` (a footprint is not centred on its point: run 7, a click on a pair's ring took the cell
    beside it), then to the middle of what it draws there (run 8: not on its edge); NaN: not in view, or no
    render."""
    rc = np.asarray(rows_cols, np.int64).reshape(-1, 2)
    out = np.full((len(rc), 2), np.nan)
    if shown is None or not len(rc):
        return out
    uv, ok = project_lidar_points(shown.T_camera_lidar, camera, depth.cell_points(rc))
    out[ok] = uv[ok]
    cells = getattr(shown.render, "cell_rc", None)
    if cells is None or not ok.any():
        return out
    h, w = cells.shape[:2]
    r = NEAREST_PX
    k = np.flatnonzero(ok)
    offsets = np.arange(-r, r + 1)
    us = np.floor(uv[k, 0] + 0.5).astype(np.int64)[:, None, None] + offsets[None, None, :]  # (K, 1, W)
    vs = np.floor(uv[k, 1] + 0.5).astype(np.int64)[:, None, None] + offsets[None, :, None]  # (K, W, 1)
    us, vs = np.broadcast_arrays(us, vs)
    inside = (us >= 0) & (us < w) & (vs >= 0) & (vs < h)
    drawn = cells[np.clip(vs, 0, h - 1), np.clip(us, 0, w - 1)]  # (K, W, W, 2)
    mine = inside & (drawn == rc[k][:, None, None, :]).all(axis=-1)
    d2 = np.where(mine, (us - uv[k, 0, None, None]) ** 2 + (vs - uv[k, 1, None, None]) ** 2, np.inf)
    flat = d2.reshape(len(k), -1)
    best = flat.argmin(axis=1)
    found = flat[np.arange(len(k)), best] <= r * r  # inf: the render draws the cell nowhere near its point
    near_u = us.reshape(len(k), -1)[found, best[found]]
    near_v = vs.reshape(len(k), -1)[found, best[found]]
    out[k[found]] = _footprint_middles(cells, rc[k[found]], near_u, near_v)
    return out


#: How far (render pixels) from a pixel a cell draws :func:`pixel_of_cells` looks for the rest of its footprint.
FOOTPRINT_PX = 16


def _footprint_middles(cells: np.ndarray, rc: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(N, 2)`` pixels: for each cell ``rc[i]`` drawn at pixel ``(u[i], v[i])``, the pixel it draws nearest the
    middle (centroid) of the pixels it draws within :data:`FOOTPRINT_PX`.  Run 8: a mark on the pixel nearest the
    cell's point sat on the cell's edge, and a click 10 screen px beside it, meant for the next cell, took the same
    one ("No change")."""
    if not len(rc):
        return np.empty((0, 2))
    h, w = cells.shape[:2]
    offsets = np.arange(-FOOTPRINT_PX, FOOTPRINT_PX + 1)
    us, vs = np.broadcast_arrays(u[:, None, None] + offsets[None, None, :], v[:, None, None] + offsets[None, :, None])
    inside = (us >= 0) & (us < w) & (vs >= 0) & (vs < h)
    mine = inside & (cells[np.clip(vs, 0, h - 1), np.clip(us, 0, w - 1)] == rc[:, None, None, :]).all(axis=-1)
    count = mine.sum(axis=(1, 2))  # >= 1: (u, v) itself
    mid_u = (us * mine).sum(axis=(1, 2)) / count
    mid_v = (vs * mine).sum(axis=(1, 2)) / count
    d2 = np.where(mine, (us - mid_u[:, None, None]) ** 2 + (vs - mid_v[:, None, None]) ** 2, np.inf)
    d2 = d2.reshape(len(rc), -1)
    best = d2.argmin(axis=1)
    return np.stack([us.reshape(len(rc), -1)[np.arange(len(rc)), best],
                     vs.reshape(len(rc), -1)[np.arange(len(rc)), best]], axis=1).astype(np.float64)


def loupe_texture(shown: ShownRender | None, camera: Any, u0: int, v0: int, n: int) -> np.ndarray:
    """Render ``shown``'s pixels ``[u0, u0 + n) x [v0, v0 + n)`` (the camera loupe's crop), enlarged by nearest
    neighbour as the camera loupe is; :data:`PAD_RGB` outside the image."""
    rows, cols = v0 + np.arange(n), u0 + np.arange(n)
    r0, r1, c0, c1 = max(v0, 0), min(v0 + n, camera.height), max(u0, 0), min(u0 + n, camera.width)
    if r1 <= r0 or c1 <= c0:  # wholly off the image: all padding
        return crop_texture(np.zeros((1, 1, 3), np.uint8), np.full(n, -1), np.full(n, -1), PAD_RGB, TEXTURE_TEXELS // n)
    # Only the crop's pixels are blended: the whole pane took 10-30 ms a click (190 ms at 1920 x 1080 under load).
    if shown is None:
        part = np.full((r1 - r0, c1 - c0, 3), NO_RETURN_RGB, np.uint8)
    else:
        rgba = shown.rgba[r0:r1, c0:c1]
        part = pane_texture(stretched_grey(rgba) if shown.mode != "range" else rgba)
    return crop_texture(part, rows - r0, cols - c0, PAD_RGB, TEXTURE_TEXELS // n)


#: The render loupe's grey shading (intensity, BA) is stretched over its own crop, from this percentile to 100 minus
#: it, onto :data:`STRETCH_MIN_GREY`..255, where it spans fewer than :data:`STRETCH_BELOW` grey levels: on a road,
#: paint is only 20-30 levels above the asphalt in the whole-scan shading (PJLab: crops of the road span 25-55),
#: too faint to find a lane line's crossing of a ring by eye; a crop of mixed objects (KITTI: 150 and more) is
#: left as it is, as the by-eye runs read it.
STRETCH_PERCENTILE = 2.0
STRETCH_MIN_GREY = 24
STRETCH_BELOW = 96


def stretched_grey(rgba: np.ndarray) -> np.ndarray:
    """``rgba`` (H, W, 4) uint8 with its grey returns (alpha > 0, R = G = B, below white: the depth-edge lines stay
    white) stretched linearly from their :data:`STRETCH_PERCENTILE` percentiles onto ``STRETCH_MIN_GREY..255``; as
    it is when fewer than 16 such pixels, or a spread under 4 levels or of :data:`STRETCH_BELOW` and more."""
    r, g, b, a = (rgba[..., k] for k in range(4))
    grey = (a > 0) & (r == g) & (g == b) & (r < 255)
    if grey.sum() < 16:
        return rgba
    lo, hi = np.percentile(r[grey], [STRETCH_PERCENTILE, 100.0 - STRETCH_PERCENTILE])
    if not 4 <= hi - lo < STRETCH_BELOW:
        return rgba
    scaled = np.clip((r.astype(np.float32) - lo) / (hi - lo), 0.0, 1.0) * (255 - STRETCH_MIN_GREY) + STRETCH_MIN_GREY
    out = rgba.copy()
    out[..., :3] = np.where(grey[..., None], np.round(scaled).astype(np.uint8)[..., None], rgba[..., :3])
    return out


def loupe_title(shown: ShownRender | None, depth: Any, center: tuple[float, float],
                clicked: tuple[int, int] | None = None, side_px: int | None = None) -> str:
    """The laser loupe's title while it shows render ``shown``: the cell a click inside the loupe chose
    (``clicked``, ``(row, col)``), else the cell at the crop's centre; its range; and the crop's side ``side_px``."""
    from .loupe_marks import render_title

    cell = (int(clicked[0]), int(clicked[1])) if clicked is not None else cell_at_pixel(shown, *center)
    return render_title(cell, None if cell is None else float(depth.range_m[cell]), side_px)
