"""What the app's parts share: layout and marker constants, markdown escaping, the solve bundles, ring markers."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calib_core.pairs import Pair

from .ba_view import ColumnWindow

BA_TITLES = {
    "horizontal": "BA horizontal",
    "vertical": "BA vertical",
    "diag_pos45": "BA +45 deg",
    "diag_neg45": "BA -45 deg",
}
MIN_PAIRS = 4
#: The 3-D pane's content sits far behind the annotation camera, so both
#: share one scene without seeing each other.
CLOUD_ORIGIN = np.array([0.0, 0.0, -5000.0])
#: Width (CSS px) kept free on the right for the floating control panel.
PANEL_PX = 400
MARKER_SIZE = 0.075  # world units (the camera image is 8 units wide): reprojection overlays
#: Pick markers are hollow rings (screen-thin lines), so they never hide the
#: picked cell: radius RING_CELLS cells, at least RING_MIN_RADIUS world units.
RING_CELLS = 1.5
RING_MIN_RADIUS = 0.03
RING_SEGMENTS = 20
#: Shift+click / drag this many ring radii from a marker selects it.
PICK_RADII = 2.5
#: The pick-number labels' em on screen (CSS px): viser draws a screen-sized label at 12 px per em times its
#: ``font_screen_scale`` (0.8 in :mod:`app.scene_nodes`).
LABEL_EM_SCREEN_PX = 12.0 * 0.8


def ring_radius(units_per_px: float, units_per_px_y: float) -> float:
    """Pick-marker ring radius (world units) on a slot of ``units_per_px`` x ``units_per_px_y`` world units per
    display pixel: a few cells, never vanishingly small."""
    return max(RING_CELLS * max(units_per_px, units_per_px_y), RING_MIN_RADIUS)


def pick_tolerance_px(units_per_px: float, units_per_px_y: float) -> float:
    """How far (display pixels along x) from a pick marker a Shift+click or a drag still takes it, on a slot of
    ``units_per_px`` x ``units_per_px_y`` world units per display pixel: :data:`PICK_RADII` ring radii."""
    return PICK_RADII * ring_radius(units_per_px, units_per_px_y) / units_per_px


def units_per_screen_px(camera: Any) -> float | None:
    """World units per canvas pixel on the annotation plane for a tab's ``camera`` (looking along +z at it), or
    None when it has not reported one."""
    try:
        dist = abs(float(camera.look_at[2]) - float(camera.position[2]))
        units = 2.0 * dist * math.tan(float(camera.fov) / 2.0) / max(int(camera.image_height), 1)
    except (AssertionError, AttributeError, TypeError, ValueError):
        return None
    return units if math.isfinite(units) and units > 0.0 else None
#: "Zoom: on last click" magnifies by ZOOM_STEP per press, up to this many
#: screen pixels per BA cell (narrow side) or per camera-image pixel.
ZOOM_PX_PER_CELL = 14.0
ZOOM_PX_PER_IMAGE_PX = 4.0
ZOOM_STEP = 2.0
EDGE_MIN_SIZE = 0.012  # world units
SNAP_RADIUS_PX = 4.0
#: The answers of the import question (the buttons of its modal).
IMPORT_CHOICES = ("Append", "Replace all", "Cancel")


#: The quality verdict as the result panel shows it (fixed strings: no user text), coloured text rather than
#: an emoji, which the page's fonts lack (it drew as an empty box).
QUALITY_BADGES = {
    "ok": '### <span style="color:#2b8a3e">Quality: ok</span>',
    "warning": '### <span style="color:#d9480f">Quality: warning</span>',
    "unreliable": '### <span style="color:#c92a2a">Quality: UNRELIABLE (do not use this pose)</span>',
}


#: The app's displayed Quality keeps its last status while the left-out error stays within this share of its
#: limit (:data:`calib_core.solve.quality.LOO_NOISY_PX`): in run 4 it flipped ok / warning on a 1-2 px re-click
#: (5.71 vs 6.06 px at 6 px).  Display only: exports carry calib_core's plain verdict.
QUALITY_HOLD_MARGIN = 0.10


class HeldQuality:
    """The Quality status one panel shows, with hysteresis on the left-out limit (:data:`QUALITY_HOLD_MARGIN`).

    Only a verdict that the left-out error decides alone (no other reason) is held: an "ok" stays "ok" until the
    left-out mean passes the limit by the margin, a "warning" stays until it falls below it by the margin.
    """

    def __init__(self) -> None:
        self._shown: str | None = None

    def status(self, quality: Any) -> tuple[str, str]:
        """``(status to show, note)`` for ``quality`` (:class:`calib_core.solve.quality.Quality` or None); the note
        (plain text, "" if none) says when the shown status is held against the plain one."""
        from calib_core.solve.quality import LOO_NOISY_PX

        plain = str(getattr(quality, "status", "ok"))
        loo = getattr(quality, "leave_one_out", None)
        mean = float("nan") if loo is None else float(loo.mean_px)
        limit = f"(above {LOO_NOISY_PX:g} px"
        others = [r for r in getattr(quality, "reasons", []) if limit not in str(r)]
        shown, note = plain, ""
        if plain != "unreliable" and not others and np.isfinite(mean) and self._shown in ("ok", "warning"):
            band = QUALITY_HOLD_MARGIN * LOO_NOISY_PX
            if plain != self._shown and abs(mean - LOO_NOISY_PX) <= band:
                shown = self._shown
                note = (f"{shown} held: left out {mean:.2f} px is within {100 * QUALITY_HOLD_MARGIN:.0f} % of the "
                        f"{LOO_NOISY_PX:g} px limit (the export says {plain})")
        self._shown = shown if quality is not None else None
        return shown, note


def page_url(host: str, port: int, token: str | None) -> str:
    """The address to open for a server bound to ``host:port`` (a wildcard bind is shown as loopback)."""
    from .security import TOKEN_QUERY

    shown = "127.0.0.1" if host in ("0.0.0.0", "", "::") else host
    if ":" in shown:
        shown = f"[{shown}]"
    return f"http://{shown}:{port}" + ("" if token is None else f"/?{TOKEN_QUERY}={token}")


#: What :func:`md_escape` writes for each character markdown or HTML would read.
_MD_ESCAPES = {ord("&"): "&amp;", ord("<"): "&lt;", ord(">"): "&gt;",
               **{ord(c): "\\" + c for c in "\\`*_{}[]()#+-.!|~"}}


def md_escape(text: str) -> str:
    """Text safe to show literally inside viser markdown (no HTML, no markup)."""
    return str(text).replace("\r", " ").replace("\n", " ").translate(_MD_ESCAPES)


def _fmt(x: float, digits: int = 3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


@dataclass(eq=False)
class SolveBundle:
    """One finished solve and what the error display and 2-D overlays need from it (computed off the UI thread)."""

    pick_ids: list[int]
    pairs: list[Pair]
    result: Any  # calib_core.solve.CalibrationResult
    pixels: np.ndarray  # (N, 2) clicked, original image
    points_camera: np.ndarray  # (N, 3) laser points moved by the solved pose
    edges_camera: np.ndarray  # (M, 3) BA-edge points moved by the solved pose
    seconds: float  # time of the solve job (resolve, solve, move the points)
    shots: Any = None  # calib_core.shots.ShotsResult when the session has several shots (app.shot_solve)


@dataclass(frozen=True, eq=False)
class SolveShown:
    """What the live solve shows now (:meth:`app.live_coordinator.LiveSolveCoordinator.subscribe` passes it).

    ``bundle``: the last good solve, or None; ``error``: the last solve's failure, or None; ``solving``: a solve
    of newer pairs runs; ``n_complete``: the complete pairs of every shot."""

    bundle: SolveBundle | None
    error: str | None
    solving: bool
    n_complete: int


@dataclass(eq=False)
class CloudUpdate:
    """What the 3-D pane and the camera-facing BA window need from a solve; computed after it is shown."""

    bundle: SolveBundle
    colors: np.ndarray | None  # (K, 3) uint8 display-cloud colours; None: not asked for
    facing_done: bool  # whether ``facing`` was computed
    facing: ColumnWindow | None  # scan columns whose points project into the camera image
    seconds: float


def marker_segments(centres: np.ndarray, radius: float, cell_half_size: tuple[float, float] | None = None,
                    ticks: bool = True) -> np.ndarray:
    """Line segments ``(N * K, 2, 3)`` of a ring marker around each world point ``centres (N, 3)``.

    A ring of :data:`RING_SEGMENTS` segments; with ``ticks``, four ticks from
    the ring towards the centre that stop short of it; with
    ``cell_half_size = (hx, hy)``, the outline of the rectangle ``+-hx, +-hy``
    around the centre (the picked cell).  Lines lie in the plane z = const.
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    hs = None if cell_half_size is None else (float(cell_half_size[0]), float(cell_half_size[1]))
    segs = _marker_shape(float(radius), hs, bool(ticks))  # (K, 2, 3)
    return (c[:, None, None, :] + segs[None]).reshape(-1, 2, 3)


@functools.lru_cache(maxsize=64)
def _marker_shape(radius: float, cell_half_size: tuple[float, float] | None, ticks: bool) -> np.ndarray:
    """The segments ``(K, 2, 3)`` of one marker around the origin (read-only; a redraw reuses it)."""
    a = np.linspace(0.0, 2.0 * np.pi, RING_SEGMENTS + 1)
    circle = radius * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    shape = [np.stack([circle[:-1], circle[1:]], axis=1)]
    if ticks:
        d = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
        shape.append(np.stack([radius * d, 0.4 * radius * d], axis=1))
    if cell_half_size is not None:
        hx, hy = cell_half_size
        corners = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]])
        shape.append(np.stack([corners, np.roll(corners, -1, axis=0)], axis=1))
    segs = np.concatenate(shape)
    segs.flags.writeable = False
    return segs


def segment_colours(colours: np.ndarray, n_segments: int) -> np.ndarray:
    """Colours ``(n_segments, 2, 3)`` of the segments of equal markers, one ``(3,)`` colour per marker."""
    colours = np.asarray(colours, np.uint8).reshape(-1, 3)
    return np.repeat(colours, n_segments // max(len(colours), 1) * 2, axis=0).reshape(-1, 2, 3)


def draw_ring_markers(nodes: Any, key: str, world: np.ndarray, colours: np.ndarray, radius: float,
                      selected: list[int], cell_half_size: tuple[float, float] | None = None) -> None:
    """The pick markers of slot ``key``: a ring (:func:`marker_segments`) on a dark halo at each world point in its
    colour, and a white ring around the rows ``selected``."""
    segs = marker_segments(world, radius, cell_half_size=cell_half_size)
    seg_colours = segment_colours(colours, len(segs))
    nodes.lines(f"/annot/markers/{key}/halo", segs + np.array([0.0, 0.0, 0.002]),
                np.full(seg_colours.shape, 25, np.uint8), thickness=4.5)
    nodes.lines(f"/annot/markers/{key}/ring", segs, seg_colours, thickness=2.0)
    sel_segs = marker_segments(world[selected] + [0.0, 0.0, 0.003], 1.5 * radius)
    nodes.lines(f"/annot/selected/{key}", sel_segs, np.full(sel_segs.shape, 255, np.uint8), thickness=4.0)


class _Action:
    """A queued viser event plus the widget value at the moment it fired."""

    def __init__(self, event: Any, value: Any) -> None:
        self.event = event
        self.value = value
        self.client = getattr(event, "client", None)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.event, name)


def outlier_change_note(before: list[int], after: list[int], in_solve: list[int]) -> str:
    """What changed in the pairs a solve left out as outliers, from the ids ``before`` to ``after`` (``in_solve``:
    the ids of the pairs the new solve had; a pair deleted meanwhile is not "back in"), e.g. "Pair 3 now left out
    as an outlier; pair 2 back in the fit."; "" when nothing changed."""
    out = sorted(set(after) - set(before))
    back = sorted((set(before) - set(after)) & set(in_solve))

    def ids(values: list[int]) -> str:
        return f"pair{'s' if len(values) > 1 else ''} {', '.join(map(str, values))}"

    parts = ([f"{ids(out)} now left out as {'outliers' if len(out) > 1 else 'an outlier'}"] if out else []) + (
        [f"{ids(back)} back in the fit"] if back else [])
    if not parts:
        return ""
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."
