"""The loupes' views: which cells (BA loupe) or original-image pixels (camera loupe) each shows, the names of
their scene nodes and click keys (:mod:`app.loupes` draws them), and the marks that follow a view (the camera
loupe's framed centre and ellipse, the BA loupe's outline on its BA image)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calib_core.predict import ellipse_outline

from .ba_view import crop_texture
from .loupe_marks import tick_segments

#: The camera loupe's crop side for a 640 px wide image (original-image px, zoom 1).
CAMERA_LOUPE_PX = 36


def default_camera_crop_px(width: int, height: int) -> int:
    """The camera loupe's crop side (original-image px) at zoom 1: bigger images get a wider crop,
    so a rough prediction still falls inside it."""
    return int(min(max(CAMERA_LOUPE_PX, round(CAMERA_LOUPE_PX * max(width, height) / 640 / 1.5)), 160))


def node_name(kind: str) -> str:
    """Scene node of loupe ``kind`` (``"ba"`` or ``"camera"``)."""
    return f"/annot/loupe_{kind}"


def slot_key(kind: str) -> str:
    """The click-routing key of loupe ``kind`` (what the app's click handler receives)."""
    return f"loupe_{kind}"


@dataclass(frozen=True)
class BaCrop:
    """The BA loupe's view: image ``key``, top-left cell ``(row0, col0)``, ``n_rows`` x ``n_cols`` cells."""

    key: str
    row0: int
    col0: int
    n_rows: int
    n_cols: int
    center: tuple[int, int]  # (row, col) framed


@dataclass(frozen=True)
class CameraCrop:
    """The camera loupe's view: original-image pixels ``[u0, u0 + n)`` x ``[v0, v0 + n)``."""

    u0: int
    v0: int
    n: int
    center: tuple[float, float]
    cov_px2: tuple | None  # 2x2 covariance of the framed point (pixels^2), drawn as a 3-sigma ellipse


def crop_around(u: float, v: float, n: int, cov_px2: tuple | None = None) -> CameraCrop:
    """Original-image pixels ``n`` on a side around ``(u, v)`` (the camera loupe's view, or the laser loupe's while
    it shows the render; ``cov_px2``: the ellipse drawn, :class:`CameraCrop`)."""
    return CameraCrop(int(round(u)) - n // 2, int(round(v)) - n // 2, int(n), (float(u), float(v)), cov_px2)


def render_crop_of(camera_crop: CameraCrop, n: int | None) -> CameraCrop:
    """The laser loupe's view while it shows the camera-view render: original-image pixels around
    ``camera_crop``'s centre, ``n`` on a side (None: the camera loupe's side); no ellipse."""
    if n is None or n == camera_crop.n:
        return CameraCrop(camera_crop.u0, camera_crop.v0, camera_crop.n, camera_crop.center, None)
    return crop_around(*camera_crop.center, n)


def camera_crop_texture(image: np.ndarray, c: CameraCrop, gamma: float, texels: int, pad: int) -> np.ndarray:
    """The camera loupe's texture: ``image``'s pixels of crop ``c`` (gray ``pad`` outside the image), their
    shadows lifted by ``gamma`` (``255 * (x / 255) ** (1 / gamma)``; 1: as they are), enlarged by nearest neighbour
    to about ``texels`` texels a side."""
    lut = None if gamma == 1.0 else np.round(255.0 * (np.arange(256) / 255.0) ** (1.0 / gamma)).astype(np.uint8)
    return crop_texture(image, c.v0 + np.arange(c.n), c.u0 + np.arange(c.n), pad, texels // c.n, lut)


def ba_crop_texture(gray: np.ndarray, c: BaCrop, wrap_cols: bool, texels: int, pad: int) -> np.ndarray:
    """The BA loupe's texture: the cells of crop ``c`` of laser image ``gray`` (rows x columns; columns wrap
    around a 360-degree scan with ``wrap_cols``; gray ``pad`` outside), enlarged by nearest neighbour."""
    cols = c.col0 + np.arange(c.n_cols)
    if wrap_cols:
        cols %= gray.shape[1]
    return crop_texture(gray, c.row0 + np.arange(c.n_rows), cols, pad, texels // max(c.n_rows, c.n_cols))


def draw_camera_centre(app: Any, s: Any, c: CameraCrop) -> None:
    """The camera loupe's framed centre (four black-white ticks: neither a click's cross nor a laser point's ring)
    and its 3-sigma ellipse, for crop ``c`` shown in loupe slot ``s``: they follow the crop."""
    nodes = app.nodes
    centre = s.world_from_pixel(np.array([c.center]) - [c.u0, c.v0], z_offset=-0.012)
    rr = max(2.0, 0.05 * c.n) * s.units_per_px
    hollow = tick_segments(centre, rr)
    nodes.lines("/annot/loupe/camera_centre_halo", hollow + [0, 0, 0.001], np.full(hollow.shape, 0, np.uint8),
                thickness=4.0)
    nodes.lines("/annot/loupe/camera_centre", hollow, np.full(hollow.shape, 255, np.uint8), thickness=1.5)
    ell = np.empty((0, 2, 3))
    if c.cov_px2 is not None:
        pts = ellipse_outline(c.center, np.array(c.cov_px2)) - [c.u0, c.v0]
        inside = np.array([s.contains(p) for p in pts], bool)
        w = s.world_from_pixel(pts, z_offset=-0.011)
        ell = np.stack([w[:-1], w[1:]], axis=1)[inside[:-1] & inside[1:]]  # only inside the loupe
    nodes.lines("/annot/loupe/ellipse", ell, np.full(ell.shape, (255, 200, 0), np.uint8), thickness=1.0)


def draw_ba_outline(app: Any, c: BaCrop) -> None:
    """Where the BA loupe looks (crop ``c``), as a thin rectangle on its main BA image (context)."""
    segs = np.empty((0, 2, 3))
    u, shown = app.ba_window.display_cols(np.array([c.col0 + c.n_cols // 2]) % app.depth.shape[1])
    if shown[0]:
        slot = app.slots[c.key]
        x0 = u[0] - c.n_cols // 2 - 0.5
        corners = np.array([[x0, c.row0 - 0.5], [x0 + c.n_cols, c.row0 - 0.5],
                            [x0 + c.n_cols, c.row0 + c.n_rows - 0.5], [x0, c.row0 + c.n_rows - 0.5]])
        corners[:, 0] = np.clip(corners[:, 0], -0.5, slot.width_px - 0.5)
        corners[:, 1] = np.clip(corners[:, 1], -0.5, slot.height_px - 0.5)
        w = slot.world_from_pixel(corners, z_offset=-0.02)
        segs = np.stack([w, np.roll(w, -1, axis=0)], axis=1)
    app.nodes.lines("/annot/loupe/ba_outline", segs, np.full(segs.shape, (255, 120, 0), np.uint8), thickness=2.0)
