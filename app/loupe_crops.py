"""The loupes' views: which cells (BA loupe) or original-image pixels (camera loupe) each shows, and the names of
their scene nodes and click keys (:mod:`app.loupes` draws them)."""

from __future__ import annotations

from dataclasses import dataclass

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
