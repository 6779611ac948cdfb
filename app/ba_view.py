"""How the app shows a Bearing Angle image: row stretch, column window, texture.

A spinning lidar gives a wide, thin depth matrix (e.g. 64 x 1800 over
360 deg x 40 deg).  Drawn with square cells it is a 28:1 strip whose cells are
a fraction of a screen pixel.  Three display choices make it pickable:

* **Row stretch** (:func:`cell_aspect_from_directions`): a cell is drawn
  ``aspect`` times taller than wide, so that it is about square in angle.
* **Column window** (:class:`ColumnWindow`): only a range of columns is shown,
  e.g. the part the camera sees (:func:`covering_window`).  Display column
  ``u`` is scan column ``(start + u) mod W``.
* **Crisp texture** (:func:`ba_texture`): viser samples image textures
  linearly, so the image is sent enlarged by an integer factor with
  nearest-neighbour sampling; the blur at a cell edge shrinks to
  ``1 / factor`` of a cell.

Display geometry only: clicks still name whole scan cells ``(row, col)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from calib_core.arrays import angle_between_rad

#: Largest texture side (SwiftShader, measured) and texel budget per BA image.
MAX_TEXTURE_SIDE = 8192
MAX_TEXELS = 2_000_000
MAX_TEXTURE_FACTOR = 16
MAX_CELL_ASPECT = 8.0


def cell_aspect_from_directions(directions: np.ndarray) -> float:
    """Display height / width of a depth-matrix cell that makes it about square in angle.

    Parameters
    ----------
    directions : (H, W, 3) float
        Unit beam directions (lidar frame); NaN where unknown.

    Returns
    -------
    float
        Mean angular step between rows divided by the angular step between
        columns, clipped to ``[1/8, 8]``; 1.0 when the directions do not tell.
        The row step is the mean over rows (total vertical extent / (H - 1)),
        so unevenly spaced beams get one average stretch.  The column step is
        taken at the row where it is largest: away from that "equator" the
        same azimuth step is a smaller angle (cos(elevation)).
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 3 or d.shape[0] < 2 or d.shape[1] < 2:
        return 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows or columns
        row_step = np.nanmean(np.nanmedian(angle_between_rad(d[1:], d[:-1]), axis=1))
        col_step = np.nanmax(np.nanmedian(angle_between_rad(d[:, 1:], d[:, :-1]), axis=1))
    if not (np.isfinite(row_step) and np.isfinite(col_step)) or row_step <= 0 or col_step <= 0:
        return 1.0
    return float(np.clip(row_step / col_step, 1.0 / MAX_CELL_ASPECT, MAX_CELL_ASPECT))


@dataclass(frozen=True)
class ColumnWindow:
    """The scan columns shown in the BA panes: display column ``u`` is scan column ``(start + u) mod n_cols``.

    Build with :meth:`make`, which normalises the numbers.
    """

    start: int  # scan column shown at display column 0
    width: int  # number of columns shown (1 ... n_cols)
    n_cols: int  # columns of the depth matrix
    # The scan closes on itself (360 deg): a window may run past the last column into column 0.  Otherwise the
    # window stays inside the scan.
    wrap: bool

    @classmethod
    def make(cls, start: int, width: int, n_cols: int, wrap: bool) -> "ColumnWindow":
        """A valid window near the request: width clipped to ``[1, n_cols]``, start wrapped or clipped."""
        n_cols = int(n_cols)
        width = int(min(max(int(width), 1), n_cols))
        start = int(start)
        if width == n_cols and not wrap:
            start = 0
        elif wrap:
            start %= n_cols
        else:
            start = min(max(start, 0), n_cols - width)
        return cls(start, width, n_cols, bool(wrap))

    @classmethod
    def full(cls, n_cols: int, wrap: bool) -> "ColumnWindow":
        """Every column, from column 0."""
        return cls.make(0, n_cols, n_cols, wrap)

    @property
    def is_full(self) -> bool:
        return self.width == self.n_cols

    @property
    def columns(self) -> np.ndarray:
        """Scan column of every display column, ``(width,)`` int."""
        return (self.start + np.arange(self.width)) % self.n_cols

    def scan_col(self, u: int) -> int:
        """Scan column of display column ``u`` (0 ... width - 1)."""
        return int((self.start + int(u)) % self.n_cols)

    def display_cols(self, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display column of scan columns ``(N,)`` and whether the window shows them."""
        u = (np.asarray(cols, dtype=np.int64).reshape(-1) - self.start) % self.n_cols
        return u.astype(np.float64), u < self.width

    def cell_at(self, uv: tuple[float, float], n_rows: int) -> tuple[int, int]:
        """Scan cell ``(row, col)`` under display pixel ``uv = (u, v)`` of a BA image showing this window.

        Display cell ``(u, v)`` covers ``[u - 0.5, u + 0.5)`` (pixel centres
        at integers, as everywhere in the package); positions on the border of
        the image are clamped to the edge cells.
        """
        u = min(max(int(math.floor(float(uv[0]) + 0.5)), 0), self.width - 1)
        row = min(max(int(math.floor(float(uv[1]) + 0.5)), 0), int(n_rows) - 1)
        return row, self.scan_col(u)


def covering_window(columns_seen: np.ndarray, wrap: bool, margin: int = 0, quantum: int = 1) -> ColumnWindow | None:
    """The narrowest window showing every True column, widened by ``margin`` on each side.

    Parameters
    ----------
    columns_seen : (W,) bool
        Columns to show (e.g. whose points project into the camera image).
    wrap : bool
        The scan closes on itself: the window may run through column 0.
    margin : int
        Extra columns on each side.
    quantum : int
        Both ends are moved outwards to multiples of ``quantum`` columns, so
        that a slightly different set (a new solve) usually gives the same
        window.

    Returns
    -------
    ColumnWindow or None
        None when no column is True.
    """
    seen = np.asarray(columns_seen, dtype=bool).reshape(-1)
    n = len(seen)
    cols = np.flatnonzero(seen)
    if len(cols) == 0:
        return None
    if wrap:
        # The window is the complement of the largest circular gap between shown columns.
        gaps = (np.roll(cols, -1) - cols) % n
        gaps[gaps == 0] = n  # a single shown column
        k = int(np.argmax(gaps))
        first = int(cols[(k + 1) % len(cols)])
        last = first + (n - int(gaps[k]))  # unwrapped, inclusive
    else:
        first, last = int(cols[0]), int(cols[-1])
    first -= int(margin)
    last += int(margin)
    q = max(1, int(quantum))
    first = (first // q) * q
    end = -(-(last + 1) // q) * q  # exclusive, rounded up
    if not wrap:
        first, end = max(first, 0), min(end, n)
    if end - first >= n:  # every column: from column 0, as "All columns" shows them
        return ColumnWindow.full(n, wrap)
    return ColumnWindow.make(first, end - first, n, wrap)


def steady_window(shown: ColumnWindow, wanted: ColumnWindow, slack: float = 1.25) -> ColumnWindow:
    """``wanted``, but with ``shown``'s width when that still covers it and is at most ``slack`` times wider.

    The page's layout follows the window's width, and a new solve changes the camera-facing window by a few
    columns: keeping the width (the window re-centred on ``wanted``) keeps the panes from jumping under the
    person's pointer in the middle of a session.
    """
    if (shown.n_cols != wanted.n_cols or shown.wrap != wanted.wrap or shown.is_full or wanted.is_full
            or not wanted.width <= shown.width <= slack * wanted.width):
        return wanted
    start = wanted.start - (shown.width - wanted.width) // 2
    return ColumnWindow.make(start, shown.width, wanted.n_cols, wanted.wrap)


def texture_factor(width_cells: int, height_cells: int, max_side: int = MAX_TEXTURE_SIDE,
                   max_texels: int = MAX_TEXELS, max_factor: int = MAX_TEXTURE_FACTOR) -> int:
    """Texels per cell side for a nearest-neighbour enlarged texture of ``width_cells`` x ``height_cells`` cells.

    As large as the texel budget allows, no texture side above ``max_side``,
    at least 1.
    """
    w, h = max(int(width_cells), 1), max(int(height_cells), 1)
    k = min(int(math.isqrt(max_texels // (w * h))), max_side // w, max_side // h, max_factor)
    return max(k, 1)


def ba_texture(gray: np.ndarray, window: ColumnWindow, factor: int) -> np.ndarray:
    """The window's columns of a display image, each cell a ``factor`` x ``factor`` block (nearest neighbour).

    Parameters
    ----------
    gray : (H, W) uint8
        Display image of the whole scan (:func:`calib_core.bearing_angle.ba_to_display`).
    window : ColumnWindow
    factor : int
        Texels per cell side (:func:`texture_factor`).

    Returns
    -------
    (H * factor, window.width * factor) uint8
    """
    return enlarged(np.asarray(gray)[:, window.columns], factor)


def enlarged(image: np.ndarray, factor: int) -> np.ndarray:
    """Each pixel of ``image`` as a ``factor`` x ``factor`` block (nearest neighbour: crisp cells and pixels)."""
    k = max(int(factor), 1)
    return np.repeat(np.repeat(image, k, axis=0), k, axis=1)


def crop_texture(image: np.ndarray, rows: np.ndarray, cols: np.ndarray, pad: Any, factor: int,
                 lut: np.ndarray | None = None) -> np.ndarray:
    """A loupe's texture: the ``rows`` x ``cols`` (index arrays) of uint8 ``image`` (grey or RGB; ``pad`` where
    a row or column lies outside it), mapped through ``lut`` (256 levels) if given, :func:`enlarged`."""
    h, w = image.shape[:2]
    ok = ((rows >= 0) & (rows < h))[:, None] & ((cols >= 0) & (cols < w))[None, :]
    crop = image[np.clip(rows, 0, h - 1)][:, np.clip(cols, 0, w - 1)]
    if lut is not None:
        crop = lut[crop]
    ok = ok.reshape(ok.shape + (1,) * (crop.ndim - 2))
    return enlarged(np.where(ok, crop, np.asarray(pad, np.uint8)).astype(np.uint8), factor)
