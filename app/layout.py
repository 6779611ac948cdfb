"""Where the 2-D annotation images sit in the viser scene, and click geometry.

The annotation view is a flat arrangement of scene images in the world plane ``z = 0``, looked at from ``-z``
(camera looking along ``+z`` with up ``-y``), so that world ``+x`` is screen-right and world ``+y`` is screen-down,
like image coordinates.  A viser scene image lies in its node's local XY plane, centred on the node, ``+x``
image-right and ``+y`` image-down.  The camera image (raw or panorama, :data:`CAMERA_WIDTH` wide) is on top, the
camera-view render below it, then the BA images; the loupes in a column on the right.

The BA images are arranged 2 x 2, stacked 4 x 1 when they are very wide (a whole 360 deg lidar scan), or side by
side 1 x 4 when they are tall (a narrow column window): whichever gives the biggest cells once the block is fitted
into a typical browser view.  A BA slot counts pixels in *cells* of the shown window; a cell may be drawn taller
than wide (``cell_aspect``).  Display geometry only (pixels <-> scene positions); no calibration maths.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

CAMERA_WIDTH = 8.0  # world units
GAP = 0.12
LABEL_HEIGHT = 0.22
#: Width / height of the 3-D canvas left of the control panel, typical of a
#: laptop browser; only used to choose the BA grid.
VIEW_ASPECT = 1.2
#: Candidate BA grids: number of images per row.
BA_GRID_COLUMNS = (2, 1, 4)


@dataclass(frozen=True)
class ImageSlot:
    """A scene image of ``width_px`` x ``height_px`` pixels centred at ``center``.

    Pixel ``(u, v)`` (top-left pixel centre = 0, image spans
    ``[-0.5, W - 0.5]``) sits at world
    ``center + ((u + 0.5) / W - 0.5) * render_width`` along x (and likewise v
    along y).
    """

    key: str
    width_px: int
    height_px: int
    center: tuple[float, float, float]
    render_width: float
    render_height: float

    @property
    def units_per_px(self) -> float:
        """World units per pixel along x (image columns)."""
        return self.render_width / self.width_px

    @property
    def units_per_px_y(self) -> float:
        """World units per pixel along y (image rows); differs from x for stretched BA cells."""
        return self.render_height / self.height_px

    def world_from_pixel(self, uv: np.ndarray, z_offset: float = 0.0) -> np.ndarray:
        """World positions ``(N, 3)`` of pixels ``(N, 2)``; ``z_offset`` < 0 is towards the viewer."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        x = self.center[0] + ((uv[:, 0] + 0.5) / self.width_px - 0.5) * self.render_width
        y = self.center[1] + ((uv[:, 1] + 0.5) / self.height_px - 0.5) * self.render_height
        z = np.full(len(uv), self.center[2] + z_offset)
        return np.stack([x, y, z], axis=1)

    def pixel_from_world(self, xyz: np.ndarray) -> np.ndarray:
        """Pixels ``(N, 2)`` of world points ``(N, 3)`` on (or projected onto) the image plane."""
        p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        u = ((p[:, 0] - self.center[0]) / self.render_width + 0.5) * self.width_px - 0.5
        v = ((p[:, 1] - self.center[1]) / self.render_height + 0.5) * self.height_px - 0.5
        return np.stack([u, v], axis=1)

    def pixel_from_ray(self, ray_origin, ray_direction) -> tuple[float, float] | None:
        """Pixel where a click ray meets the image plane (node rotation is identity).

        Returns None when the ray is parallel to the plane or points away from it.
        """
        o = np.asarray(ray_origin, dtype=np.float64)
        d = np.asarray(ray_direction, dtype=np.float64)
        if abs(d[2]) < 1e-12:
            return None
        t = (self.center[2] - o[2]) / d[2]
        if t <= 0:
            return None
        uv = self.pixel_from_world((o + t * d)[None])[0]
        return float(uv[0]), float(uv[1])

    def contains(self, uv) -> bool:
        u, v = float(uv[0]), float(uv[1])
        return -0.5 <= u <= self.width_px - 0.5 and -0.5 <= v <= self.height_px - 0.5

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` in world units."""
        cx, cy, _ = self.center
        return (cx - self.render_width / 2, cy - self.render_height / 2, cx + self.render_width / 2, cy + self.render_height / 2)


def ba_grid_columns(ba_aspect: float, n_images: int = 4, view_aspect: float = VIEW_ASPECT,
                    above_height: float = 0.0) -> int:
    """Images per row for ``n_images`` BA images of width / height ``ba_aspect``.

    Picks, from :data:`BA_GRID_COLUMNS`, the grid whose images are widest once
    the whole block (images, gaps, titles) is fitted into a view of width /
    height ``view_aspect``.  Ties keep the earlier candidate (2 x 2).  With
    ``above_height`` (world units of images above the block: the camera view
    and the camera-view render), the whole page is fitted (that column and the
    loupe column right of it, :func:`loupe_areas`), and the score is the BA
    images' width times the square of the camera image's (all as shown): the
    photo and the render are where a person picks pairs, so a small window
    gives them the room first (by-eye runs: a 1920-wide photo was shown 390 px
    wide at 1400 x 900 with the BA panes 2 x 2 below it).
    """
    best, best_score = BA_GRID_COLUMNS[0], -1.0
    for n_cols in BA_GRID_COLUMNS:
        n_cols = min(n_cols, n_images)
        n_rows = -(-n_images // n_cols)
        slot_w = (CAMERA_WIDTH - (n_cols - 1) * GAP) / n_cols
        block_h = n_rows * (slot_w / ba_aspect + GAP + LABEL_HEIGHT)
        if above_height > 0:
            height = above_height + block_h
            fit = max((CAMERA_WIDTH + 3 * GAP + loupe_side(height)) / view_aspect, height)
            score = slot_w / fit * (CAMERA_WIDTH / fit) ** 2
        else:
            score = slot_w / max(CAMERA_WIDTH / view_aspect, block_h)
        if score > best_score * (1 + 1e-9):
            best, best_score = n_cols, score
    return best


def annotation_layout(
    camera_sizes: dict[str, tuple[int, int]],
    ba_size: tuple[int, int],
    ba_keys: tuple[str, ...],
    cell_aspect: float = 1.0,
    above_height: float = 0.0,
) -> dict[str, ImageSlot]:
    """Slots for the camera image variants and the four BA images.

    Parameters
    ----------
    camera_sizes : dict
        ``{"raw": (W, H), "panorama": (W, H)}`` (panorama optional).  All
        camera variants share the top area; their bottom edges line up.
    ba_size : (W, H)
        Cells shown of the depth matrix (window columns, rows).
    ba_keys : tuple of str
        Keys of the four BA images, in reading order.
    cell_aspect : float
        Drawn height / width of one cell (1 = square).
    above_height : float
        World units of images above the BA block besides the camera views (:func:`ba_grid_columns`).
    """
    slots: dict[str, ImageSlot] = {}
    bw, bh = ba_size
    ba_aspect = bw / (bh * cell_aspect)
    camera_h = max(CAMERA_WIDTH * h / w for w, h in camera_sizes.values())
    n_cols = ba_grid_columns(ba_aspect, len(ba_keys), above_height=above_height and above_height + camera_h + GAP)
    cell_w = (CAMERA_WIDTH - (n_cols - 1) * GAP) / n_cols
    cell_h = cell_w / ba_aspect
    for i, key in enumerate(ba_keys):
        row, col = divmod(i, n_cols)
        cx = -CAMERA_WIDTH / 2 + cell_w / 2 + col * (cell_w + GAP)
        cy = LABEL_HEIGHT + cell_h / 2 + row * (cell_h + GAP + LABEL_HEIGHT)
        slots[key] = ImageSlot(key, bw, bh, (cx, cy, 0.0), cell_w, cell_h)
    for name, (w, h) in camera_sizes.items():
        height = CAMERA_WIDTH * h / w
        slots[name] = ImageSlot(name, w, h, (0.0, -GAP - height / 2, 0.0), CAMERA_WIDTH, height)
    return slots


#: The camera-view render's page slot and click key (:mod:`app.render_pane` draws it).
RENDER_KEY = "render"


def layout_with_render(camera_sizes: dict[str, tuple[int, int]], view_key: str, ba_size: tuple[int, int],
                       ba_keys: tuple[str, ...], cell_aspect: float) -> dict[str, ImageSlot]:
    """The page layout (:func:`annotation_layout`) with the render's slot right below camera view ``view_key``
    (``raw`` or ``panorama``), the same size; the BA panes move down to make room, their grid chosen for the whole
    column (camera view, render, BA panes).

    Stacked rather than side by side: with the loupe column on the right, the camera image gets more screen
    for any image wider than about 3:4, and a corner in the photo lies straight above the same corner in the render.
    """
    view_w, view_h = camera_sizes[view_key]
    render_band = CAMERA_WIDTH * view_h / view_w + GAP + LABEL_HEIGHT
    slots = annotation_layout(camera_sizes, ba_size, ba_keys, cell_aspect=cell_aspect, above_height=render_band)
    view = slots[view_key]
    out = {key: s if s.center[1] < 0.0 else replace(s, center=(s.center[0], s.center[1] + render_band, s.center[2]))
           for key, s in slots.items()}  # the camera views sit above y = 0 and stay
    out[RENDER_KEY] = ImageSlot(RENDER_KEY, view.width_px, view.height_px,
                                (view.center[0], LABEL_HEIGHT + view.render_height / 2, 0.0), view.render_width,
                                view.render_height)
    return out


@dataclass(frozen=True)
class LoupeArea:
    """Where a loupe is drawn: its top-left corner ``(x0, y0)`` and the largest size it may take (world units)."""

    x0: float
    y0: float
    width: float
    height: float


def loupe_areas(main_bounds: tuple[float, float, float, float]) -> dict[str, LoupeArea]:
    """Two loupe areas, ``"camera"`` above ``"ba"``, in a column right of the camera and BA images.

    Each is square, half the height of the main block (titles included, and the camera loupe's legend line
    under it), so that the whole page (images and loupes) fits a typical browser view at once.
    """
    x0, y0, x1, y1 = main_bounds
    top = y0 - LABEL_HEIGHT  # the camera title sits above the camera image
    side = loupe_side(y1 - top)
    left = x1 + 3 * GAP
    return {"camera": LoupeArea(left, y0, side, side),
            "ba": LoupeArea(left, y0 + side + GAP + 2 * LABEL_HEIGHT, side, side)}


def loupe_side(height: float) -> float:
    """The side of each of the two square loupes beside a main block ``height`` world units tall (titles and the
    camera loupe's legend line included)."""
    return min(max((height - GAP - 2 * LABEL_HEIGHT) / 2.0, 2.5), 6.0)


def bounds_of(slots: list[ImageSlot]) -> tuple[float, float, float, float]:
    """Union of the slots' bounds ``(x_min, y_min, x_max, y_max)``."""
    b = np.array([s.bounds() for s in slots])
    return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())
