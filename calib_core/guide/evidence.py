"""Clear, isolated evidence in both views: the screen a proposal must pass before a person is asked to click it.

A D-optimal proposal is worthless when the person cannot find its corner:
on vegetation (no corner at all), on far background, at the image border,
in clutter of similar corners, or with a 3-sigma ellipse larger than the
loupe it is shown in.  :class:`ProposalScreen` names each test's threshold (its attributes say what
each test does); :func:`calib_core.guide.propose.propose` applies it.  In short:

Laser side
    A locally planar support (:func:`local_plane_residual_m`, :func:`planar_share`: foliage scatters its
    returns in depth and fails; a box face, a wall, a pole, the road pass); a cell step short enough in
    the image (:func:`cell_footprint_px`; for a lidar next to the camera nearly the same at every range,
    both being angles, so far background is left out by range and cell size instead); a corner of its own
    kind (a depth step against returns, at a turn of the near side's outline; a plane junction only on a
    fine scan; nothing on or at the foot of the ground but painted-marking corners well inside the road:
    the by-eye runs declined flat asphalt, curbs, junctions on a flat door, shadows at an object's foot);
    not in the scan's first or last rows, where an object may go on past the beam (a by-eye user met a
    "corner" at row 1).

Image side
    One dominant L or X corner inside the 3-sigma ellipse (:func:`dominant_corner`), not a repeated
    texture (:func:`corner_rivals`: a fence, a railing, foliage, a window grid).

Both
    The 3-sigma box keeps a margin from the image border (and a fisheye's image circle), and the
    3-sigma radius fits the loupe.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import CalibError
from ..solve.whiten import cell_pick_covariance
from .image_corners import CornerImage

__all__ = [
    "ProposalScreen",
    "DEFAULT_MAX_ELLIPSE_PX",
    "REASON_ROUGH_ALIGNMENT",
    "REASON_NO_EVIDENCE",
    "no_new_corner_note",
    "PLAIN_REASONS",
    "local_plane_residual_m",
    "planar_share",
    "cell_footprint_px",
    "corner_peaks",
    "dominant_corner",
    "ellipse_box_margin_px",
    "ground_plane",
    "height_above_ground_m",
    "window_share",
    "normal_span",
    "intensity_corner",
    "corner_rivals",
    "fill_holes",
    "far_side_share",
    "near_edge_turn",
    "intensity_edge_turn",
    "bright_fraction",
]

#: Largest 3-sigma radius (px) of a proposal by default: an 80 px disc, about the app's camera loupe for a
#: 1242-1920 px wide image (47-72 px) zoomed out one step (x 1.5).
DEFAULT_MAX_ELLIPSE_PX = 40.0

#: Why there is no proposal, as the app and the CLI show it.
REASON_ROUGH_ALIGNMENT = (
    "no proposal's 3-sigma ellipse fits the loupe (at most {limit:.0f} px; the smallest is {smallest:.0f} px): "
    "do a better rough alignment first (more pairs, or more careful clicks)"
)
REASON_NO_EVIDENCE = (
    "no laser cell here has clear, isolated corner evidence in both the scan and the image; "
    "pick the next pairs by hand"
)

#: Counts of the screen that are not about new cells (re-clicks of existing pairs).
RECLICK_SCREEN_KEYS = ("reclick ellipse or border",)


#: Each test of the screen in a user's words: what the corners it leaves out are ("most (N) ...").
PLAIN_REASONS = {
    "scan edge": "lie on the scan's top or bottom row, where an object may go on past the beam",
    "far": "are too far away to place",
    "footprint": "fall where the laser's points are too far apart to place a corner",
    "not planar": "are on leaves or clutter, not on a flat surface",
    "junction of fewer than three planes": "are folds between surfaces that the laser's rows are too coarse to place",
    "junction on a coarse scan": "are folds between surfaces that the laser's rows are too coarse to place",
    "depth step too small": "lie along an object's edge, not at its corner",
    "straight depth edge": "lie along an object's edge, not at its corner",
    "depth edge does not turn": "lie along an object's edge, not at its corner",
    "on the ground": "are on the road or at an object's foot, where the photo shows shadow",
    "at the foot of an object": "are on the road or at an object's foot, where the photo shows shadow",
    "intensity corner off the ground": "are patterns in the laser's brightness off the road (signs, frames, shading), "
                                       "which rarely match a corner in the photo",
    "weak intensity corner": "are painted markings the laser blurs, whose corners it cannot place",
    "marking edge does not turn": "are painted markings the laser blurs, whose corners it cannot place",
    "straight marking edge": "are painted markings the laser blurs, whose corners it cannot place",
    "marking corner off the paint": "are painted markings the laser blurs, whose corners it cannot place",
    "marking edge smeared": "are painted markings the laser blurs, whose corners it cannot place",
    "ellipse larger than the loupe": "need a better rough pose before the loupe can show where to look",
    "border": "are too close to the photo's border",
    "no dominant image corner": "have no clear corner in the photo where the laser puts them",
    "repeated image texture": "are among many look-alike corners in the photo (fence, railing, leaves)",
}


def no_new_corner_note(screened: dict) -> str:
    """What the app says when no new cell passes the screen, in a user's words: how many corners the scan
    offered and what most of them are (:data:`PLAIN_REASONS`, tests with the same wording counted together),
    what to do first (a one-line status cuts the end off; by-eye runs 8-10), e.g. "No new corner to propose here;
    pick the next pairs by hand: of 412 corner-like spots in the scan, most (230) are too far away to place".

    Parameters
    ----------
    screened : dict of str to int
        Cells left out per test (:attr:`calib_core.guide.propose.Proposals.screened`).
    """
    counts = {k: int(v) for k, v in screened.items() if k not in RECLICK_SCREEN_KEYS and int(v) > 0}
    if not counts:
        return "No new corner to propose here; pick the next pairs by hand: the scan has no corner in view"
    n = sum(counts.values())
    plain: dict[str, int] = {}
    for test, k in counts.items():
        words = PLAIN_REASONS.get(test, f"fail the check '{test}'")
        plain[words] = plain.get(words, 0) + k
    words = max(plain, key=lambda w: plain[w])
    return (f"No new corner to propose here; pick the next pairs by hand: of {n} corner-like "
            f"spot{'s' if n != 1 else ''} in the scan, most ({plain[words]}) {words}")


@dataclass(frozen=True)
class ProposalScreen:
    """Thresholds of the clear-evidence screen (module docstring).

    Attributes
    ----------
    max_ellipse_px : float
        Largest 3-sigma radius (major half-axis of the pixel ellipse), px.
    border_margin_px : float
        Smallest distance of the 3-sigma box from the image border, px.
    max_footprint_px : float
        Largest image length of one cell step, px.
    max_range_m : float
        Farthest laser range proposed, metres.
    plane_half : int
        Half-size of the support window, cells (2 = 5 x 5).
    same_surface_rel : float
        Neighbours whose range differs from the cell's by at most this fraction are on its surface.
    min_plane_neighbours : int
        Fewest same-surface cells (the cell included) of a 3 x 3 block for a plane fit.
    max_plane_rms_noise : float
        Largest plane-fit RMS of a planar cell, in units of the scan's range noise
        (:func:`calib_core.guide.corner_probability.scan_range_noise_m`).
    min_planar_share : float
        Smallest share (0..1) of the support that is planar.
    min_planar_cells : int
        Fewest planar cells in the support.
    min_corner_strength : float
        Smallest ``lam_min`` of the image corner, grey levels^2 (grey 0..1, 5 x 5 window).
    min_corner_ratio : float
        Smallest ``lam_min / lam_max`` of the image corner (1 = an ideal L or X corner, 0 = an edge).
    min_corner_dominance : float
        The strongest corner in the ellipse must be this many times stronger than the second.
    min_search_px : float
        The corner search covers at least this radius (px) around the prediction, so a tiny
        ellipse cannot hide clutter just next to it.
    scan_edge_rows : int
        Cells in this many first and last rows of the depth matrix are not proposed.
    ground_tol_m : float
        Cells within this distance (m) of the scan's ground plane are ground cells (:func:`height_above_ground_m`).
    max_ground_share : float
        A cell on the ground whose window is more than this share (0..1) ground is not proposed, unless it
        is a corner of a painted marking in the scan's intensity (:func:`intensity_corner`).
    min_height_m : float
        Cells lower than this (m) above the ground plane are not proposed (markings aside): where an object
        meets the road (a tyre, a curb, a door's foot) the photo shows shadow, not a corner.
    min_intensity_corner : float
        Smallest intensity corner measure of a painted-marking corner (:func:`intensity_corner`).
    min_marking_ground_share : float
        A ``marking`` candidate (an intensity corner) is proposed only on a ground cell whose window is at
        least this share ground: a painted corner lies inside the road, not where a wall or a door meets it;
        its bright side's outline must turn by ``min_edge_turn`` (:func:`intensity_edge_turn`: a stripe's
        corner, not its side).
    min_marking_strength : float
        Smallest corner measure of a ``marking`` candidate (:attr:`calib_core.guide.candidates.Candidates.strength`,
        units of the squared gradient clip): rough asphalt makes weaker intensity corners (KITTI 000002's road:
        median 0.74; PJLab manual_calib's crossing stripes: median 1.78).
    min_junction_span : float
        A plane-junction cell needs the smallest eigenvalue of its window's normals' ``mean n n^T``
        (:func:`normal_span`: 0 for one or two planes, above 0 for three) at least this.  Off (0) by
        default: on the sample's box corners the 5 x 5 window often holds only two faces' cells (0.01 lost
        3 of 16 correct guided pairs there), and on coarse scans ``max_junction_footprint_px`` already
        leaves junctions out.
    min_depth_step : float
        A depth-jump cell needs a step of log range of at least this between neighbouring cells
        (:func:`calib_core.guide.candidates.depth_discontinuity`; 0.15 is a 16 % range step: two walls a
        metre apart at 30 m are one surface to a person).
    min_far_share : float
        A depth-jump cell needs at least this share of its 7 x 7 window to be returns behind the step
        (:func:`far_side_share`): no corners against dropouts or glass.
    max_convex_share, min_concave_share : float
        The near side of the step (dropouts filled, :func:`fill_holes`) must cover at most the first or at
        least the second share of the 7 x 7 window (:func:`calib_core.guide.candidates.near_fraction`):
        a corner of the object, not a straight stretch of its edge; the same shares hold for a ``marking``
        cell's bright side (:func:`bright_fraction`).
    min_edge_turn : float
        A depth-jump cell's near-side outline must turn by at least this (:func:`near_edge_turn`, 0 along a
        straight edge, 0.5-0.6 at a box's corner): a roof line or a pole's side is no corner, however it
        steps through the cells.
    max_junction_footprint_px : float
        Plane-junction cells are proposed only where one cell step is at most this long in the image
        (:func:`cell_footprint_px`): on a 64-beam scan (5-8 px per cell) the normals of a 5 x 5 window mix
        several objects and cannot tell a three-plane corner from a flat door (the by-eye runs declined
        every junction proposed; the benchmark's verdict found none of 20 to be a corner); a dense
        rotating scanner's (the sample's, under 2 px) show the corners of boxes and rooms.
    rival_radius_px, rival_fraction : float
        Image corners within ``rival_radius_px`` of the dominant corner with at least ``rival_fraction`` of
        its strength are its rivals (:func:`corner_rivals`)...
    max_rivals : int
        ...and a corner with more rivals is a repeated texture (fence, railing, foliage), not proposed.
    max_marking_edge_cells : float
        A ``marking`` cell's intensity edges may be smeared over at most this many cells along the rings
        (:func:`calib_core.guide.marking_corner.edge_width_cells`; about one for a sharp edge under a beam one
        cell wide).  A wider smear puts the corner-looking cell a cell or two outside the paint's corner:
        measured (``python -m bench.guide_by_eye --summary --trials 8``), none of the 21 stripe corners
        proposed on PJLab manual_calib from 8 rough starts, nor of the 9 offered continuing its by-eye
        sessions, lay within 3 px of a clean photo corner under the published pose; all are smeared wider.
    """

    max_ellipse_px: float = DEFAULT_MAX_ELLIPSE_PX
    border_margin_px: float = 10.0
    max_footprint_px: float = 10.0
    max_range_m: float = 30.0
    plane_half: int = 2
    same_surface_rel: float = 0.15
    min_plane_neighbours: int = 5
    max_plane_rms_noise: float = 2.5
    min_planar_share: float = 0.6
    min_planar_cells: int = 4
    min_corner_strength: float = 0.01
    min_corner_ratio: float = 0.3
    min_corner_dominance: float = 3.0
    min_search_px: float = 4.0
    scan_edge_rows: int = 3
    ground_tol_m: float = 0.2
    max_ground_share: float = 0.5
    min_height_m: float = 0.3
    min_intensity_corner: float = 0.25
    min_marking_ground_share: float = 0.9
    min_marking_strength: float = 1.0
    min_junction_span: float = 0.0
    min_depth_step: float = 0.15
    max_junction_footprint_px: float = 3.0
    min_edge_turn: float = 0.3
    min_far_share: float = 0.15
    max_convex_share: float = 0.4
    min_concave_share: float = 0.7
    rival_radius_px: float = 12.0
    rival_fraction: float = 0.3
    max_rivals: int = 1
    max_marking_edge_cells: float = 1.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
                raise CalibError(f"proposal screen: {name} must be a finite number >= 0, got {value!r}")
        if self.max_ellipse_px <= 0:
            raise CalibError(f"proposal screen: max_ellipse_px must be a positive number of pixels, "
                             f"got {self.max_ellipse_px!r}")


def _neighbours(a: np.ndarray, wrap: bool, fill) -> np.ndarray:
    """The 3 x 3 neighbourhood of every cell: ``(H, W, 9, ...)`` (``fill`` outside the scan; columns wrap if ``wrap``)."""
    H, W = a.shape[:2]
    out = []
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            s = np.roll(a, (-dr, -dc), axis=(0, 1))
            if dr == 1:
                s[H - 1] = fill
            elif dr == -1:
                s[0] = fill
            if not wrap and dc == 1:
                s[:, W - 1] = fill
            elif not wrap and dc == -1:
                s[:, 0] = fill
            out.append(s)
    return np.stack(out, axis=2)


def local_plane_residual_m(depth, same_surface_rel: float = 0.15, min_neighbours: int = 5) -> np.ndarray:
    """RMS distance (m) of each cell's same-surface 3 x 3 neighbours from their least-squares plane, (H, W).

    Neighbours are on the cell's surface when their range differs from its
    range by at most ``same_surface_rel`` (a fraction).  NaN where the cell
    is not valid, where fewer than ``min_neighbours`` cells (itself included)
    are on its surface, or where those span a single row or column (a line
    fits any plane through it).
    """
    valid = np.asarray(depth.valid, dtype=bool)
    wrap = bool(depth.meta.get("wrap_cols", False))
    r = np.where(valid, depth.range_m, np.nan).astype(np.float64)
    R = _neighbours(r, wrap, np.nan)
    with np.errstate(invalid="ignore"):
        same = np.isfinite(R) & (np.abs(R - r[:, :, None]) <= same_surface_rel * r[:, :, None])
    n = same.sum(axis=2)
    rows_used = same.reshape(*same.shape[:2], 3, 3).any(axis=3).sum(axis=2)
    cols_used = same.reshape(*same.shape[:2], 3, 3).any(axis=2).sum(axis=2)
    P = _neighbours(np.where(valid[:, :, None], np.nan_to_num(depth.points), 0.0), wrap, 0.0)
    w = same[..., None]
    mean = np.where(w, P, 0.0).sum(axis=2) / np.maximum(n, 1)[..., None]
    D = np.where(w, P - mean[:, :, None, :], 0.0)
    cov = np.einsum("hwki,hwkj->hwij", D, D) / np.maximum(n, 1)[..., None, None]
    smallest = np.linalg.eigvalsh(cov)[..., 0]
    ok = valid & (n >= min_neighbours) & (rows_used >= 2) & (cols_used >= 2)
    return np.where(ok, np.sqrt(np.maximum(smallest, 0.0)), np.nan)


def _support(depth, rows_cols: np.ndarray, half: int, step_log: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, cols ``(N, k, k)`` of each window and its support mask: the near side of a depth step
    (log range below the window's midpoint, when it spans at least ``step_log``), else every valid cell."""
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    H, W = depth.shape
    off = np.arange(-half, half + 1)
    rows = rc[:, 0, None, None] + off[None, :, None] + 0 * off[None, None, :]
    cols = rc[:, 1, None, None] + off[None, None, :] + 0 * off[None, :, None]
    inside = (rows >= 0) & (rows < H)
    if depth.meta.get("wrap_cols", False):
        cols = np.mod(cols, W)
    else:
        inside &= (cols >= 0) & (cols < W)
    rows, cols = np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)
    ok = inside & np.asarray(depth.valid)[rows, cols]
    lr = np.log(np.where(ok, depth.range_m[rows, cols], 1.0))
    lo = np.where(ok, lr, np.inf).min(axis=(1, 2))
    hi = np.where(ok, lr, -np.inf).max(axis=(1, 2))
    any_ok = ok.any(axis=(1, 2))
    step = any_ok & (np.where(any_ok, hi - lo, 0.0) >= step_log)
    near = lr < np.where(any_ok, 0.5 * (lo + hi), 0.0)[:, None, None]
    support = ok & np.where(step[:, None, None], near, True)
    return rows, cols, support


def planar_share(depth, rows_cols: np.ndarray, residual_m: np.ndarray, tol_m: float,
                 half: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Share of each cell's support (:func:`_support`) that is planar, and the number of planar cells.

    Parameters
    ----------
    depth : DepthMatrix
    rows_cols : (N, 2) int
    residual_m : (H, W) ndarray
        :func:`local_plane_residual_m` of ``depth``.
    tol_m : float
        Largest residual (m) of a planar cell.
    half : int
        Half-size of the window, cells.

    Returns
    -------
    share : (N,) float
        0..1 (0 where the support is empty).
    n_planar : (N,) int
    """
    rows, cols, support = _support(depth, rows_cols, half)
    res = np.asarray(residual_m)[rows, cols]
    with np.errstate(invalid="ignore"):
        planar = support & np.isfinite(res) & (res <= tol_m)
    n_support = support.sum(axis=(1, 2))
    n_planar = planar.sum(axis=(1, 2))
    return np.where(n_support > 0, n_planar / np.maximum(n_support, 1), 0.0), n_planar


def cell_footprint_px(depth, rows_cols: np.ndarray, J_point: np.ndarray) -> np.ndarray:
    """Image length (px) of one cell step at each cell, the larger of the row and the column step, (N,).

    The step is the change of the beam direction over one row (column) times
    the range (:func:`calib_core.solve.whiten.cell_pick_covariance` with a
    one-cell offset), mapped to the image by ``J_point`` (``d pixel / d
    X_lidar``, px/m, :func:`.information.pixel_jacobians`).
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    out = np.zeros(len(rc))
    for sigma in ((1.0, 0.0), (0.0, 1.0)):
        cov = cell_pick_covariance(depth, rc, sigma, 0.0)
        px = np.einsum("nai,nij,naj->n", J_point, cov, J_point)
        out = np.maximum(out, np.sqrt(np.maximum(px, 0.0)))
    return out


def corner_peaks(ci: CornerImage) -> np.ndarray:
    """``lam_min`` at its local maxima within a window-sized neighbourhood (one value per corner), 0 elsewhere."""
    k = 2 * ci.window + 1
    lam = np.asarray(ci.lam_min, dtype=np.float32)
    peak = (lam >= cv2.dilate(lam, np.ones((k, k), np.uint8))) & (lam > 0)
    return np.where(peak, lam, 0.0).astype(np.float32)


def dominant_corner(ci: CornerImage, peaks: np.ndarray, pixels: np.ndarray, pixel_cov: np.ndarray,
                    min_search_px: float = 4.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The strongest and second-strongest image corners inside each 3-sigma ellipse.

    Parameters
    ----------
    ci : CornerImage
    peaks : (H, W) ndarray
        :func:`corner_peaks` of ``ci``.
    pixels : (N, 2) ndarray
        Predicted ``(u, v)``.
    pixel_cov : (N, 2, 2) ndarray
        Their covariances, px^2; the ellipse is ``d^T C^-1 d <= 9``, grown
        to a disc of ``min_search_px`` where smaller.

    Returns
    -------
    peak_uv : (N, 2) float
        The strongest corner's pixel (the prediction where there is none).
    first, second : (N,) float
        ``lam_min`` of the strongest and second-strongest corner (0 where none).
    ratio : (N,) float
        ``lam_min / lam_max`` at the strongest corner.
    """
    p = np.nan_to_num(np.asarray(pixels, dtype=np.float64).reshape(-1, 2))
    C = np.nan_to_num(np.asarray(pixel_cov, dtype=np.float64).reshape(-1, 2, 2)) + 1e-9 * np.eye(2)
    n = len(p)
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0)
    major = np.sqrt(np.maximum(np.linalg.eigvalsh(C)[:, -1], 0.0))
    R = int(np.ceil(max(3.0 * float(major.max()), min_search_px)))
    H, W = peaks.shape
    off = np.arange(-R, R + 1, dtype=np.float64)
    du, dv = np.meshgrid(off, off)  # (k, k): du along columns
    Ci = np.linalg.inv(C)
    m2 = Ci[:, 0, 0, None, None] * du**2 + 2 * Ci[:, 0, 1, None, None] * du * dv + Ci[:, 1, 1, None, None] * dv**2
    inside = (m2 <= 9.0) | ((du**2 + dv**2) <= min_search_px**2)[None]
    u0 = np.rint(p[:, 0]).astype(np.int64)
    v0 = np.rint(p[:, 1]).astype(np.int64)
    us = u0[:, None, None] + du.astype(np.int64)[None]
    vs = v0[:, None, None] + dv.astype(np.int64)[None]
    on_image = (us >= 0) & (us < W) & (vs >= 0) & (vs < H)
    vals = np.where(inside & on_image, peaks[np.clip(vs, 0, H - 1), np.clip(us, 0, W - 1)], 0.0).reshape(n, -1)
    best = np.argmax(vals, axis=1)
    first = vals[np.arange(n), best]
    second = -np.partition(-vals, 1, axis=1)[:, 1] if vals.shape[1] > 1 else np.zeros(n)
    bu = us.reshape(n, -1)[np.arange(n), best]
    bv = vs.reshape(n, -1)[np.arange(n), best]
    peak_uv = np.where((first > 0)[:, None], np.stack([bu, bv], axis=1).astype(np.float64), p)
    lam_max = np.asarray(ci.lam_max)[np.clip(bv, 0, H - 1), np.clip(bu, 0, W - 1)]
    ratio = np.where(first > 0, first / np.maximum(lam_max, 1e-30), 0.0)
    return peak_uv, first.astype(np.float64), second.astype(np.float64), ratio.astype(np.float64)


def ellipse_box_margin_px(pixels: np.ndarray, pixel_cov: np.ndarray, width: int, height: int) -> np.ndarray:
    """Distance (px) from each 3-sigma box (``u +- 3 sqrt(C_uu)``, ``v +- 3 sqrt(C_vv)``) to the image border, (N,);
    negative where the box crosses it, NaN pixels give -inf.  Pixel centres run 0..width-1, 0..height-1."""
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    C = np.asarray(pixel_cov, dtype=np.float64).reshape(-1, 2, 2)
    hu = 3.0 * np.sqrt(np.maximum(C[:, 0, 0], 0.0))
    hv = 3.0 * np.sqrt(np.maximum(C[:, 1, 1], 0.0))
    m = np.minimum.reduce([p[:, 0] - hu, (width - 1) - (p[:, 0] + hu), p[:, 1] - hv, (height - 1) - (p[:, 1] + hv)])
    return np.where(np.isfinite(m), m, -np.inf)


def ground_plane(depth, tol_m: float, bottom_share: float = 0.25,
                 min_inliers: float = 0.3) -> tuple[np.ndarray, float] | None:
    """The scan's ground plane ``n . x = d`` (unit ``n`` facing the sensor side, lidar frame, metres), or None.

    The ground is the plane most of the bottom rows' points lie on (the lowest
    beams of a vehicle lidar hit the road): the median surface normal of the
    cells in the last ``bottom_share`` of the rows and the median offset
    ``n . x``, refined twice by a least-squares fit to the points within
    ``tol_m`` (metres).  It is a ground plane only when at least
    ``min_inliers`` of those bottom cells lie on it.
    """
    from .candidates import surface_normals

    valid = np.asarray(depth.valid, dtype=bool)
    H = depth.shape[0]
    bottom = valid.copy()
    bottom[: H - max(int(round(bottom_share * H)), 1)] = False
    if bottom.sum() < 10:
        return None
    normals = surface_normals(depth)[bottom]
    P = depth.points[bottom]
    n = np.median(normals, axis=0)
    if np.linalg.norm(n) < 1e-6:
        return None
    n /= np.linalg.norm(n)
    d = float(np.median(P @ n))
    for _ in range(2):  # least-squares refinement on the inliers
        inl = np.abs(P @ n - d) <= tol_m
        if inl.sum() < 3:
            return None
        Q = P[inl]
        centre = Q.mean(axis=0)
        m = np.linalg.eigh(np.cov((Q - centre).T))[1][:, 0]
        n = m if m @ n >= 0 else -m
        d = float(centre @ n)
    if np.mean(np.abs(P @ n - d) <= tol_m) < min_inliers:
        return None
    if d > 0:  # face the sensor: the lidar origin on the positive side (n . 0 - d > 0)
        n, d = -n, -d
    return n, d


def height_above_ground_m(depth, plane: tuple[np.ndarray, float] | None) -> np.ndarray:
    """Signed distance (m) of every cell's point from the ground plane, positive on the sensor's side, (H, W);
    +inf everywhere without a plane, NaN at invalid cells."""
    if plane is None:
        return np.full(depth.shape, np.inf)
    n, d = plane
    h = np.nan_to_num(depth.points) @ n - d
    return np.where(np.asarray(depth.valid, dtype=bool), h, np.nan)


def window_share(mask: np.ndarray, depth, rows_cols: np.ndarray, half: int = 2) -> np.ndarray:
    """Share of the valid cells of each cell's ``(2 half + 1)^2`` window where ``mask`` holds, (N,)."""
    rows, cols, support = _support(depth, rows_cols, half, step_log=np.inf)
    m = np.asarray(mask, dtype=bool)[rows, cols] & support
    return m.sum(axis=(1, 2)) / np.maximum(support.sum(axis=(1, 2)), 1)


def normal_span(depth, rows_cols: np.ndarray, half: int = 2) -> np.ndarray:
    """Eigenvalues (N, 3), ascending, of the mean ``n n^T`` of the surface normals in each cell's window.

    One plane: two eigenvalues near 0.  Two planes (an edge where they meet,
    e.g. a wall on the ground, or a fold of one surface): the smallest near 0.
    Three planes (a box or building corner): all three clearly above 0.
    """
    from .candidates import surface_normals

    rows, cols, support = _support(depth, rows_cols, half, step_log=np.inf)
    N = surface_normals(depth)[rows, cols]  # (n, k, k, 3)
    w = support[..., None].astype(np.float64)
    M = np.einsum("nabi,nabj->nij", N * w, N) / np.maximum(support.sum(axis=(1, 2)), 1)[:, None, None]
    return np.linalg.eigvalsh(M)


def intensity_corner(depth, rows_cols: np.ndarray, min_strength: float = 0.25, window: int = 3) -> np.ndarray:
    """Whether each cell is a corner of the scan's intensity image (painted marking), (N,) bool.

    The Shi-Tomasi measure of the log intensity
    (:func:`calib_core.guide.candidates.intensity_log_image`, gradients
    clipped at 0.5, i.e. a 65 % contrast step) over a ``window``-cell box,
    at least ``min_strength`` in units of the squared clip, anywhere in the
    cell's 3 x 3 neighbourhood.  All False when the scan has no intensity.
    """
    from .candidates import corner_response, intensity_log_image

    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    found = intensity_log_image(depth)
    if found is None or len(rc) == 0:
        return np.zeros(len(rc), dtype=bool)
    clip = 0.5
    resp = corner_response(found[0], found[1], window, clip) / clip**2
    resp = cv2.dilate(resp.astype(np.float32), np.ones((3, 3), np.uint8))
    return resp[rc[:, 0], rc[:, 1]] >= min_strength


def corner_rivals(peaks: np.ndarray, peak_uv: np.ndarray, strength: np.ndarray, radius_px: float,
                  fraction: float) -> np.ndarray:
    """Number of other image corners within ``radius_px`` of each corner at least ``fraction`` of its strength, (N,).

    A corner of a fence, a railing, a window grid or foliage has many such
    rivals (a repeated texture); an isolated corner has none.  Peaks within
    2 px of the corner itself are its own.
    """
    p = np.asarray(peak_uv, dtype=np.float64).reshape(-1, 2)
    if len(p) == 0:
        return np.zeros(0, dtype=np.int64)
    R = int(np.ceil(radius_px))
    H, W = peaks.shape
    off = np.arange(-R, R + 1)
    du, dv = np.meshgrid(off, off)
    ring = ((du**2 + dv**2) <= radius_px**2) & ((du**2 + dv**2) > 4)
    us = np.rint(p[:, 0]).astype(np.int64)[:, None, None] + du[None]
    vs = np.rint(p[:, 1]).astype(np.int64)[:, None, None] + dv[None]
    on = (us >= 0) & (us < W) & (vs >= 0) & (vs < H) & ring[None]
    vals = np.where(on, peaks[np.clip(vs, 0, H - 1), np.clip(us, 0, W - 1)], 0.0)
    thr = fraction * np.asarray(strength, dtype=np.float64)
    return ((vals >= np.maximum(thr, 1e-12)[:, None, None]) & (vals > 0)).sum(axis=(1, 2))


def fill_holes(depth, min_valid_neighbours: int = 5):
    """The depth matrix with isolated no-return cells (dropouts inside a surface) filled, a copy.

    A no-return cell with at least ``min_valid_neighbours`` returns among
    its 8 neighbours gets their median range (and the point along its own
    beam), so a dropout does not read as a depth step; larger no-return
    regions (sky, glass, beyond range) stay.
    """
    import dataclasses

    valid = np.asarray(depth.valid, dtype=bool)
    wrap = bool(depth.meta.get("wrap_cols", False))
    R = _neighbours(np.where(valid, depth.range_m, np.nan).astype(np.float64), wrap, np.nan)
    R = np.delete(R, 4, axis=2)  # the cell itself
    n = np.isfinite(R).sum(axis=2)
    hole = ~valid & (n >= min_valid_neighbours) & np.all(np.isfinite(depth.directions), axis=2)
    if not hole.any():
        return depth
    with np.errstate(all="ignore"):
        med = np.nanmedian(R[hole], axis=1)
    rng_m = np.array(depth.range_m, dtype=np.float64, copy=True)
    rng_m[hole] = med
    pts = np.array(depth.points, dtype=np.float64, copy=True)
    pts[hole] = med[:, None] * depth.directions[hole]
    return dataclasses.replace(depth, range_m=rng_m, points=pts, valid=valid | hole)


def far_side_share(depth, rows_cols: np.ndarray, min_step: float, half: int = 3) -> np.ndarray:
    """Share of each cell's ``(2 half + 1)^2`` window that is a *return* at least ``min_step`` farther in log
    range than the cell, (N,).

    A corner a person can see in both views has a background behind it; a
    "step" against no-return cells (dropouts on dark asphalt, glass) shows
    nothing in the photo.
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    rows, cols, support = _support(depth, rc, half, step_log=np.inf)
    lr = np.log(np.where(support, depth.range_m[rows, cols], 1.0))
    own = np.log(np.maximum(depth.range_m[rc[:, 0], rc[:, 1]], 1e-6))
    far = support & (lr >= own[:, None, None] + min_step)
    return far.mean(axis=(1, 2))


def near_edge_turn(depth, rows_cols: np.ndarray, half: int = 3) -> np.ndarray:
    """How much the near side's outline turns inside each cell's window: ``lam_min / lam_max`` of the structure
    tensor of the near-side mask (Sobel over the ``(2 half + 1)^2`` window), (N,), 0..1.

    Near 0 along a straight depth edge, however slanted or stair-stepped in the
    cells (a roof line, a wall's side); clearly above 0 where the outline turns
    (an object's corner).  The near side is the cells below the midpoint of the
    window's log ranges (no return counts as far); 0 without a step.
    """
    from .candidates import _log_range_windows

    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    if len(rc) == 0:
        return np.zeros(0)
    lr, _ = _log_range_windows(depth, rc, half + 1)
    lo, hi = lr.min(axis=(1, 2)), lr.max(axis=(1, 2))
    near = (lr < (0.5 * (lo + hi))[:, None, None]).astype(np.float64)
    return np.where(hi - lo >= 0.005, _mask_turn(near), 0.0)


def _log_intensity_windows(depth, rc: np.ndarray, half: int):
    """The scan's log intensity (:func:`calib_core.guide.candidates.intensity_log_image`) in each cell's
    ``(2 half + 1)^2`` window, (N, k, k) with NaN where a cell has none, and which cells have it; None
    without intensity."""
    from .candidates import intensity_log_image, window_cells

    found = intensity_log_image(depth)
    if found is None:
        return None
    log_i, ok = found
    rows, cols = window_cells(depth.shape, rc, half)
    inside = ok[rows, cols]
    return np.where(inside, log_i[rows, cols], np.nan), inside


def intensity_edge_turn(depth, rows_cols: np.ndarray, half: int = 3) -> np.ndarray:
    """:func:`near_edge_turn` of the bright side of the scan's log intensity
    (:func:`calib_core.guide.candidates.intensity_log_image`, split at the window's
    midpoint), (N,): clearly above 0 at a painted marking's corner, near 0 along a
    stripe's side; 0 without intensity or contrast (a 0.5 step of log intensity), or where the bright
    side is speckle (fewer than 70 % of its cells have two bright 4-neighbours, or fewer than 4 cells)."""
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    found = _log_intensity_windows(depth, rc, half + 1) if len(rc) else None
    if found is None:
        return np.zeros(len(rc))
    li, _ = found
    with np.errstate(invalid="ignore"):
        lo, hi = np.nanmin(li, axis=(1, 2)), np.nanmax(li, axis=(1, 2))
        bright = (li > (0.5 * (lo + hi))[:, None, None]).astype(np.float64)
    # A marking is a solid bright region: most of its cells have two or more bright 4-neighbours.
    # Speckle (noise on dark asphalt, retro-reflector bloom) has isolated bright cells.
    pad = np.pad(bright, ((0, 0), (1, 1), (1, 1)))
    neighbours = pad[:, :-2, 1:-1] + pad[:, 2:, 1:-1] + pad[:, 1:-1, :-2] + pad[:, 1:-1, 2:]
    n_bright = bright.sum(axis=(1, 2))
    solid = ((neighbours >= 2) & (bright > 0)).sum(axis=(1, 2)) / np.maximum(n_bright, 1)
    coherent = (n_bright >= 4) & (solid >= 0.7)
    return np.where((np.nan_to_num(hi - lo) >= 0.5) & coherent, _mask_turn(bright), 0.0)


def bright_fraction(depth, rows_cols: np.ndarray, half: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Share of each cell's ``(2 half + 1)^2`` window that is bright in the scan's log intensity
    (:func:`calib_core.guide.candidates.intensity_log_image`): above the window's midpoint and within 0.5 of
    its brightest cell; cells without intensity count as dark, (N,); NaN without contrast (a 0.5 step).
    Also whether the cell or one of its 8 neighbours is bright, (N,) bool: a corner of the paint, not a
    response peak on the asphalt two rows off it.

    The intensity analogue of :func:`calib_core.guide.candidates.near_fraction`: about 1/4 at a painted
    marking's corner, 1/2 along a stripe's side, where the rings' different gains (a 64-beam scan's stripes
    are banded row by row) make corner-like peaks that are no corner of the paint.
    """
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    found = _log_intensity_windows(depth, rc, half) if len(rc) else None
    if found is None:
        return np.full(len(rc), np.nan), np.zeros(len(rc), dtype=bool)
    li, inside = found
    with np.errstate(invalid="ignore"):
        lo, hi = np.nanmin(li, axis=(1, 2)), np.nanmax(li, axis=(1, 2))
        # Within 0.5 (a 40 % intensity step) of the brightest: paint, not the rough asphalt's bright grains.
        bright = inside & (li > np.maximum(0.5 * (lo + hi), hi - 0.5)[:, None, None])
    share = np.where(np.nan_to_num(hi - lo) >= 0.5, bright.mean(axis=(1, 2)), np.nan)
    return share, bright[:, half - 1:half + 2, half - 1:half + 2].any(axis=(1, 2))


def _mask_turn(mask: np.ndarray) -> np.ndarray:
    """``lam_min / lam_max`` of the structure tensor of binary windows ``(N, k, k)`` (gradients at the inner cells)."""
    near = mask
    # Central differences inside the (2 half + 3)^2 window: gradients at the inner (2 half + 1)^2 cells.
    gx = 0.5 * (near[:, 1:-1, 2:] - near[:, 1:-1, :-2])
    gy = 0.5 * (near[:, 2:, 1:-1] - near[:, :-2, 1:-1])
    a, b, c = (gx * gx).sum(axis=(1, 2)), (gx * gy).sum(axis=(1, 2)), (gy * gy).sum(axis=(1, 2))
    root = np.sqrt(np.maximum(0.25 * (a - c) ** 2 + b * b, 0.0))
    lam_max, lam_min = 0.5 * (a + c) + root, 0.5 * (a + c) - root
    return np.where(lam_max > 0, lam_min / np.maximum(lam_max, 1e-12), 0.0)
