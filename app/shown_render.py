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


def cell_at_pixel(shown: ShownRender | None, u: float, v: float,
                  radius_px: float = NEAREST_PX) -> tuple[int, int] | None:
    """Scan cell ``(row, col)`` render ``shown`` draws at original-size pixel ``(u, v)``, or at the nearest rendered
    pixel within ``radius_px`` render pixels; None if none (or no render)."""
    if shown is None:
        return None
    cells = shown.render.cell_rc
    h, w = cells.shape[:2]
    iu, iv = int(math.floor(u + 0.5)), int(math.floor(v + 0.5))
    r = int(math.ceil(radius_px))
    u0, u1, v0, v1 = max(iu - r, 0), min(iu + r + 1, w), max(iv - r, 0), min(iv + r + 1, h)
    if u0 >= u1 or v0 >= v1:
        return None
    window = cells[v0:v1, u0:u1]
    vv, uu = np.mgrid[v0:v1, u0:u1]
    d2 = np.where(window[..., 0] >= 0, (uu - u) ** 2 + (vv - v) ** 2, np.inf)
    k = int(np.argmin(d2))
    if not np.isfinite(d2.flat[k]) or d2.flat[k] > radius_px * radius_px:
        return None
    row, col = window.reshape(-1, 2)[k]
    return int(row), int(col)


def pixel_of_cells(shown: ShownRender | None, camera: Any, depth: Any, rows_cols: np.ndarray) -> np.ndarray:
    """Original camera pixels ``(N, 2)`` of scan cells ``(N, 2)`` under render ``shown``'s pose (NaN: not in view,
    or no render)."""
    rc = np.asarray(rows_cols, np.int64).reshape(-1, 2)
    out = np.full((len(rc), 2), np.nan)
    if shown is None or not len(rc):
        return out
    uv, ok = project_lidar_points(shown.T_camera_lidar, camera, depth.cell_points(rc))
    out[ok] = uv[ok]
    return out


def loupe_texture(shown: ShownRender | None, camera: Any, u0: int, v0: int, n: int) -> np.ndarray:
    """Render ``shown``'s pixels ``[u0, u0 + n) x [v0, v0 + n)`` (the camera loupe's crop), enlarged by nearest
    neighbour as the camera loupe is; :data:`PAD_RGB` outside the image."""
    h, w = camera.height, camera.width
    pane = (np.full((h, w, 3), NO_RETURN_RGB, np.uint8) if shown is None else pane_texture(shown.rgba))
    us, vs = u0 + np.arange(n), v0 + np.arange(n)
    ok = ((vs >= 0) & (vs < h))[:, None] & ((us >= 0) & (us < w))[None, :]
    crop = pane[np.clip(vs, 0, h - 1)][:, np.clip(us, 0, w - 1)]
    crop = np.where(ok[..., None], crop, np.asarray(PAD_RGB, np.uint8)).astype(np.uint8)
    k = max(1, TEXTURE_TEXELS // n)
    return np.repeat(np.repeat(crop, k, axis=0), k, axis=1)


def loupe_title(shown: ShownRender | None, depth: Any, center: tuple[float, float],
                clicked: tuple[int, int] | None = None) -> str:
    """The laser loupe's title while it shows render ``shown``: the cell a click inside the loupe chose
    (``clicked``, ``(row, col)``), else the cell at the crop's centre; and its range."""
    from .loupe_marks import render_title

    cell = (int(clicked[0]), int(clicked[1])) if clicked is not None else cell_at_pixel(shown, *center)
    return render_title(cell, None if cell is None else float(depth.range_m[cell]))
