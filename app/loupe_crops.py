"""The loupes' views: which cells (BA loupe) or original-image pixels (camera loupe) each shows, and the names of
their scene nodes and click keys (:mod:`app.loupes` draws them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


def render_crop_of(camera_crop: CameraCrop, n: int | None) -> CameraCrop:
    """The laser loupe's view while it shows the camera-view render: original-image pixels around
    ``camera_crop``'s centre, ``n`` on a side (None: the camera loupe's side); no ellipse."""
    if n is None or n == camera_crop.n:
        return CameraCrop(camera_crop.u0, camera_crop.v0, camera_crop.n, camera_crop.center, None)
    u, v = camera_crop.center
    return CameraCrop(int(round(u)) - n // 2, int(round(v)) - n // 2, int(n), (float(u), float(v)), None)


def camera_crop_texture(image: np.ndarray, c: CameraCrop, gamma: float, texels: int, pad: int) -> np.ndarray:
    """The camera loupe's texture: ``image``'s pixels of crop ``c`` (gray ``pad`` outside the image), their
    shadows lifted by ``gamma`` (``255 * (x / 255) ** (1 / gamma)``; 1: as they are), enlarged by nearest neighbour
    to about ``texels`` texels a side."""
    h, w = image.shape[:2]
    us, vs = c.u0 + np.arange(c.n), c.v0 + np.arange(c.n)
    ok = ((vs >= 0) & (vs < h))[:, None] & ((us >= 0) & (us < w))[None, :]
    crop = image[np.clip(vs, 0, h - 1)][:, np.clip(us, 0, w - 1)]
    if gamma != 1.0:
        crop = np.round(255.0 * (np.arange(256) / 255.0) ** (1.0 / gamma)).astype(np.uint8)[crop]
    crop = np.where(ok[..., None], crop, np.uint8(pad)).astype(np.uint8)
    k = max(1, texels // c.n)
    return np.repeat(np.repeat(crop, k, axis=0), k, axis=1)


def ba_crop_texture(gray: np.ndarray, c: BaCrop, wrap_cols: bool, texels: int, pad: int) -> np.ndarray:
    """The BA loupe's texture: the cells of crop ``c`` of laser image ``gray`` (rows x columns; columns wrap
    around a 360-degree scan with ``wrap_cols``; gray ``pad`` outside), enlarged by nearest neighbour."""
    n_rows, n_cols = gray.shape
    rows = c.row0 + np.arange(c.n_rows)
    cols = c.col0 + np.arange(c.n_cols)
    if wrap_cols:
        cols %= n_cols
    ok_r = (rows >= 0) & (rows < n_rows)
    ok_c = (cols >= 0) & (cols < n_cols)
    crop = gray[np.clip(rows, 0, n_rows - 1)][:, np.clip(cols, 0, n_cols - 1)]
    crop = np.where(ok_r[:, None] & ok_c[None, :], crop, np.uint8(pad)).astype(np.uint8)
    k = max(1, texels // max(c.n_rows, c.n_cols))
    return np.repeat(np.repeat(crop, k, axis=0), k, axis=1)
