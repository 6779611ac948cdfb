"""The loupes' titles, legend and camera-loupe marks (what :mod:`app.loupes` draws over its textures).

By-eye walkthrough (issue 20): the laser loupe's title ("Camera-view laser loupe (same crop as the camera loupe):
row 4, column 893, range 10...") ran under the control panel, and after a refining click it was not clear which
mark was the photo point and which the projected laser point.  So the titles are short (they fit the loupe's
width: :data:`TITLE_MAX_CHARS`), and the camera loupe draws each pair's **click as a cross** ("+") and its **laser
point projected** under the current pose **as a plain ring** ("O"), with a legend line under the loupe; the
loupe's framed centre is four ticks only (a crosshair gap, neither of the two).  Display only: the projection is
:func:`calib_core.overlays.project_lidar_points`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calib_core.overlays import project_lidar_points

from .ui_common import marker_segments, segment_colours

#: The longest loupe title, characters.  The titles' font is viser's 12 CSS px screen em x 0.9 (about 6 px a
#: character, 7 at most); at 1400 x 900 a loupe is about 320 (KITTI) to 410 (PJLab) screen px wide
#: (``tests/test_loupe_titles.py``), and the old 60-105 character titles ran on under the control panel.
TITLE_MAX_CHARS = 44
#: The line under the camera loupe saying which mark is which (printable ASCII and the middle dot only:
#: no glyph the page's fonts may lack).
LEGEND = "+ your click · O laser point projected"


def _cell_text(row: int, col: int, range_m: float | None) -> str:
    """``"r4 c893 · 10.20 m"``: a scan cell and its range (``range_m`` None or NaN: "no return")."""
    shown = "no return" if range_m is None or not np.isfinite(range_m) else f"{range_m:.2f} m"
    return f"r{row} c{col} · {shown}"


def ba_title(name: str, row: int, col: int, range_m: float | None) -> str:
    """The laser loupe's title for scan cell ``(row, col)`` of the ``name`` image: e.g.
    ``"Range loupe · r4 c893 · 10.20 m"``; ``range_m`` None: no return there."""
    return f"{name} loupe · {_cell_text(row, col, range_m)}"


def render_title(cell: tuple[int, int] | None, range_m: float | None, side_px: int | None = None) -> str:
    """The laser loupe's title while it shows the camera-view render: the cell and its range, and with ``side_px``
    the crop's side in image px, as the photo loupe's title gives its own (run 13: the two scales could not be
    compared); "loupe" is left out then, so the title keeps within :data:`TITLE_MAX_CHARS`."""
    where = "no return here" if cell is None else _cell_text(cell[0], cell[1], range_m)
    return f"Render loupe · {where}" if side_px is None else f"Render · {where} · {int(side_px)} px"


def camera_title(u: float, v: float, n: int) -> str:
    """The camera loupe's title: the original-image pixel named (click or centre) and the crop side, px."""
    return f"Photo loupe · ({u:.1f}, {v:.1f}) · {n} px"


def cross_segments(centres: np.ndarray, half: float) -> np.ndarray:
    """Line segments ``(N * 2, 2, 3)`` of a "+" of half-length ``half`` (world units) at each world point."""
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    arms = np.array([[[-half, 0, 0], [half, 0, 0]], [[0, -half, 0], [0, half, 0]]], dtype=np.float64)
    return (c[:, None, None, :] + arms[None]).reshape(-1, 2, 3)


def edge_segments(pixels: np.ndarray, edge_deg: np.ndarray, half_px: float) -> np.ndarray:
    """An edge pair's photo mark, in pixels ``(N * 2, 2, 2)``: a line of half-length ``2.5 half_px`` along the edge
    (``edge_deg``, degrees from +u towards +v) and a short bar across it, at each pixel ``(N, 2)``."""
    c = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    a = np.radians(np.asarray(edge_deg, dtype=np.float64).reshape(-1))
    along = np.stack([np.cos(a), np.sin(a)], axis=1)
    across = np.stack([-along[:, 1], along[:, 0]], axis=1)
    arms = np.stack([2.5 * half_px * along, 0.5 * half_px * across], axis=1)  # (N, 2, 2)
    return np.stack([c[:, None] - arms, c[:, None] + arms], axis=2).reshape(-1, 2, 2)


def tick_segments(centres: np.ndarray, radius: float) -> np.ndarray:
    """Four ticks from ``radius`` to ``0.4 * radius`` around each world point (a crosshair with a gap, no ring)."""
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    d = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
    ticks = np.stack([radius * d, 0.4 * radius * d], axis=1)
    return (c[:, None, None, :] + ticks[None]).reshape(-1, 2, 3)


def draw_camera_marks(app: Any, slot: Any, crop: Any, picks: list, pose: np.ndarray | None) -> None:
    """The camera loupe's marks: each pair's clicked pixel as a cross (a pair on an edge: a line along the edge)
    and its laser cell projected under ``pose`` as a ring, both in the pair's colour (only those the loupe shows)."""
    nodes = app.nodes
    r_px = max(3.0, 0.06 * crop.n)
    r = r_px * slot.units_per_px
    clicked = [p for p in picks if p.pixel is not None]
    px = np.array([p.pixel for p in clicked], np.float64).reshape(-1, 2) - [crop.u0, crop.v0]
    cols = np.array([p.color for p in clicked], np.uint8).reshape(-1, 3)
    inside = np.array([slot.contains(p) for p in px], bool)
    on_edge = np.array([p.edge_deg is not None for p in clicked], bool)
    corner, edge = inside & ~on_edge, inside & on_edge
    segs = cross_segments(slot.world_from_pixel(px[corner], z_offset=-0.01), r)
    ends = edge_segments(px[edge], [p.edge_deg for p, e in zip(clicked, edge) if e], r_px).reshape(-1, 2)
    segs = np.concatenate([segs, slot.world_from_pixel(ends, z_offset=-0.01).reshape(-1, 2, 3)])
    seg_cols = np.concatenate([segment_colours(cols[corner], 2 * int(corner.sum())),
                               segment_colours(cols[edge], 2 * int(edge.sum()))])
    nodes.lines("/annot/loupe/camera_marks", segs, seg_cols, thickness=2.5)
    cells = [p for p in picks if p.laser_rc is not None]
    segs, seg_cols = np.empty((0, 2, 3)), np.empty((0, 2, 3), np.uint8)
    if pose is not None and cells:
        uv, ok = project_lidar_points(pose, app.camera, app.depth.cell_points(np.array([p.laser_rc for p in cells])))
        xy = np.asarray(uv, np.float64).reshape(-1, 2) - [crop.u0, crop.v0]
        keep = np.asarray(ok, bool) & np.array([slot.contains(p) for p in xy], bool)
        segs = marker_segments(slot.world_from_pixel(xy[keep], z_offset=-0.009), 0.8 * r, ticks=False)
        seg_cols = segment_colours(np.array([p.color for p in cells], np.uint8).reshape(-1, 3)[keep], len(segs))
    nodes.lines("/annot/loupe/camera_laser", segs, seg_cols, thickness=2.0)


def draw_camera_outline(app: Any, c: Any) -> None:
    """Where the camera loupe looks (its crop ``c``, :class:`app.loupe_crops.CameraCrop`), on the main camera
    view of ``app`` (curved on a panorama)."""
    t = np.linspace(0.0, 1.0, 9)
    a, b = c.u0 - 0.5, c.u0 + c.n - 0.5
    top, bottom = c.v0 - 0.5, c.v0 + c.n - 0.5
    ring = np.concatenate([np.stack([a + (b - a) * t, np.full_like(t, top)], 1),
                           np.stack([np.full_like(t, b), top + (bottom - top) * t], 1),
                           np.stack([b - (b - a) * t, np.full_like(t, bottom)], 1),
                           np.stack([np.full_like(t, a), bottom - (bottom - top) * t], 1)])
    disp, ok = app.display_from_pixels(ring)
    segs = np.empty((0, 2, 3))
    if ok.all():
        w = app.camera_slot().world_from_pixel(disp, z_offset=-0.02)
        segs = np.stack([w[:-1], w[1:]], axis=1)
    app.nodes.lines("/annot/loupe/camera_outline", segs, np.full(segs.shape, (255, 120, 0), np.uint8),
                    thickness=2.0)
