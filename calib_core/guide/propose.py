"""Next-pair proposals: which laser cell to pair next, and where its pixel should be.

Ranking is sequential D-optimal design: each proposal is the candidate that
most increases ``log det F`` (:func:`.information.d_optimal_gain`) given the
current pose covariance *and the proposals ranked before it*, so the list
does not repeat one region.  A candidate's noise is the click noise of a
guided pair plus the error of a careful laser pick (:data:`.laser_noise.PICK_CELL_SIGMA`): near features
carry more translation information and, on sparse lidars, smaller cells,
which the gain accounts for; cells wider than ``max_cell_m`` are dropped
(no corner can be placed within them).

Each proposal's ``pixel_cov`` is the covariance of the true feature's pixel
about the predicted one: the pose covariance propagated to the pixel plus the
offset of the proposed cell from the feature (``cell_sigma`` cells, default
one: a detected corner cell may sit a cell or two off; with the screen, a
``marking`` cell that touches its paint corner :data:`MARKING_CELL_SIGMA`),
``J_pose C J_pose^T + J_X Sigma_L J_X^T`` (px^2).

With a :class:`.evidence.ProposalScreen` (the default) only cells with
clear, isolated evidence in both views are proposed (:mod:`.evidence`:
locally planar structure in the scan, one dominant corner in the image
inside the ellipse, a cell footprint and a range the loupe can resolve,
clear of the image border), and only where the 3-sigma ellipse fits the
loupe (``max_ellipse_px``).  The result (:class:`Proposals`, a list) says
why it is empty: :data:`.evidence.REASON_ROUGH_ALIGNMENT` when only the
ellipses were too large, :data:`.evidence.REASON_NO_EVIDENCE` otherwise.
``screen=None`` proposes as before the screen (kept for the benchmark).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from ..errors import CalibError
from ..io.atomic import write_yaml_atomic
from .candidates import KINDS, Candidates, depth_discontinuity, find_candidates, near_fraction
from .corner_probability import WEIGHTS, corner_features, corner_probability, laser_features, scan_range_noise_m
from .evidence import (REASON_NO_EVIDENCE, REASON_ROUGH_ALIGNMENT, ProposalScreen, bright_fraction,
                       cell_footprint_px, corner_peaks, corner_rivals, dominant_corner, ellipse_box_margin_px,
                       far_side_share, fill_holes, ground_plane, height_above_ground_m, intensity_corner,
                       intensity_edge_turn, local_plane_residual_m, near_edge_turn, normal_span, planar_share,
                       window_share)
from .image_corners import CornerImage, content_mask, strongest_near
from .marking_corner import edge_width_cells
from .information import d_optimal_gain, pair_noise, pixel_jacobians, pose_pixel_covariance
from .laser_noise import DEFAULT_CELL_SIGMA, DEFAULT_RANGE_SIGMA_M, PICK_CELL_SIGMA, cell_covariance
from .pose_state import PoseState
from .visibility import visible_in_camera

__all__ = ["Proposal", "Proposals", "propose", "proposals_to_dict", "save_proposals_yaml", "GUIDED_CLICK_SIGMA_PX"]

#: Click noise of a guided pair (magnified loupe, known target), pixels.
GUIDED_CLICK_SIGMA_PX = 0.3
#: Cells wider than this (metres) are not proposed.
DEFAULT_MAX_CELL_M = 0.2
#: Offset (cells, 1-sigma) of a screened ``marking`` cell from its paint corner: the screen keeps only cells that
#: touch the paint at a corner of it (:func:`.evidence.bright_fraction`), not the two cells' slack of a detected
#: peak (:data:`.laser_noise.DEFAULT_CELL_SIGMA`).  Measured on PJLab manual_calib's stripe corners offered from
#: the by-eye starts: 5-12.6 px (0.7-1.7 cells) from the photo's nearest corner at 7.5 px per cell.
MARKING_CELL_SIGMA = 1.0
#: Image-corner evidence needed at a proposal (structure-tensor lam_min, grey levels^2), when an image is given.
DEFAULT_MIN_IMAGE_CORNER = 0.005


@dataclass(frozen=True)
class Proposal:
    """One proposed pair.

    Attributes
    ----------
    laser_rc : (int, int)
        Depth-matrix cell.
    laser_xyz : (3,) ndarray
        Its point, lidar frame, metres.
    pixel : (2,) ndarray
        Predicted ``(u, v)`` under the current pose.
    pixel_cov : (2, 2) ndarray
        Covariance of the feature's true pixel about ``pixel``, px^2.
    gain : float
        Increase of ``log det`` of the pose information if this pair is
        added after the proposals ranked before it (nats).
    kind : str
        Feature kind (:data:`calib_core.guide.candidates.KINDS`), or
        ``"reclick"`` for re-clicking an existing rough pair in the loupe.
    image_corner : float
        Strongest image-corner measure near ``pixel`` (NaN without an image).
    strength : float
        The laser candidate's corner measure (:attr:`Candidates.strength`; NaN for a re-click).
    replaces : int or None
        For ``"reclick"``: index of the pair (in the list given to
        :func:`propose`) that the new click replaces.
    probability : float
        Probability that the cell is a corner the person can click
        (:mod:`.corner_probability`; 1 for a re-click; NaN without an image).
    planar_share : float
        Share of the cell's support that is locally planar (:func:`.evidence.planar_share`; NaN unscreened).
    footprint_px : float
        Image length of one cell step, px (:func:`.evidence.cell_footprint_px`; NaN unscreened).
    corner_dominance : float
        Strongest over second-strongest image corner in the ellipse (:func:`.evidence.dominant_corner`;
        inf with a single corner, NaN unscreened or without an image).
    """

    laser_rc: tuple[int, int]
    laser_xyz: np.ndarray = field(repr=False)
    pixel: np.ndarray
    pixel_cov: np.ndarray = field(repr=False)
    gain: float
    kind: str
    image_corner: float = float("nan")
    strength: float = float("nan")
    replaces: int | None = None
    probability: float = float("nan")
    planar_share: float = float("nan")
    footprint_px: float = float("nan")
    corner_dominance: float = float("nan")

    def ellipse_sigma_px(self) -> np.ndarray:
        """1-sigma half-axes (major, minor) of the pixel ellipse, px."""
        return np.sqrt(np.maximum(np.linalg.eigvalsh(self.pixel_cov)[::-1], 0.0))

    @property
    def radius_3sigma_px(self) -> float:
        """The 3-sigma radius: three times the ellipse's major 1-sigma half-axis, px."""
        return 3.0 * float(self.ellipse_sigma_px()[0])

    def to_dict(self) -> dict:
        return {
            "laser_rc": [int(self.laser_rc[0]), int(self.laser_rc[1])],
            "laser_xyz": [float(x) for x in self.laser_xyz],
            "pixel": [float(x) for x in self.pixel],
            "pixel_cov": [[float(x) for x in row] for row in self.pixel_cov],
            "gain": float(self.gain),
            "kind": self.kind,
            "radius_3sigma_px": self.radius_3sigma_px,
            **({"probability": float(self.probability)} if np.isfinite(self.probability) else {}),
            **({"replaces": int(self.replaces)} if self.replaces is not None else {}),
        }


class Proposals(list):
    """The ranked proposals (a list of :class:`Proposal`, best first) and why there are none.

    Attributes
    ----------
    reason : str or None
        Set when the list is empty: what the person should do
        (:data:`.evidence.REASON_ROUGH_ALIGNMENT` or :data:`.evidence.REASON_NO_EVIDENCE`).
    screened : dict of str to int
        Cells left out by each test of the screen (empty without a screen).
    note : str or None
        Set when no *new* cell passed the screen, even if re-clicks of existing pairs are proposed
        (:func:`.evidence.no_new_corner_note`): the app shows it instead of cycling through re-clicks.
    left_out : ((M, 2) int ndarray, (M,) str ndarray)
        The cells the screen left out and the first test each failed (the names of :attr:`screened`).
    """

    def __init__(self, items=(), reason: str | None = None, screened: dict | None = None,
                 note: str | None = None, left_out: tuple | None = None) -> None:
        super().__init__(items)
        self.reason = reason
        self.screened = dict(screened or {})
        self.note = note
        self.left_out = left_out if left_out is not None else (np.zeros((0, 2), np.int64), np.zeros(0, str))

    def like(self, items) -> "Proposals":
        """Other items with this result's reason (when they are empty), counts, note and left-out cells."""
        items = list(items)
        return Proposals(items, None if items else (self.note or self.reason or "no proposal left"), self.screened,
                         self.note, self.left_out)


def _cell_extent_m(laser_cov: np.ndarray, range_sigma_m: float, cell_sigma: float) -> np.ndarray:
    """Approximate largest cell extent (m) from its pick covariance (inverse of the cell model)."""
    w = np.linalg.eigvalsh(laser_cov)[:, -1]
    return np.sqrt(np.maximum(w - range_sigma_m**2, 0.0)) / cell_sigma


def propose(
    depth,
    camera,
    state: PoseState,
    n: int = 20,
    *,
    candidates: Candidates | None = None,
    exclude_rc: Sequence[tuple[int, int]] = (),
    click_sigma_px: float = GUIDED_CLICK_SIGMA_PX,
    corner_image: CornerImage | None = None,
    min_image_corner: float = DEFAULT_MIN_IMAGE_CORNER,
    max_cell_m: float = DEFAULT_MAX_CELL_M,
    range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
    cell_sigma: float = DEFAULT_CELL_SIGMA,
    visible: np.ndarray | None = None,
    reclick: Sequence[tuple[int, tuple[int, int], float]] = (),
    order: str = "d_optimal",
    paired_points_lidar: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
    corner_weights=WEIGHTS,
    laser_evidence: np.ndarray | None = None,
    screen: ProposalScreen | None = ProposalScreen(),
    plane_residual: np.ndarray | None = None,
) -> Proposals:
    """The ``n`` best next pairs, best first (module docstring).

    Parameters
    ----------
    depth : DepthMatrix
    camera : CameraModel
    state : PoseState
        Current pose and covariance (:func:`calib_core.guide.current_pose`).
    n : int
        Number of proposals.
    candidates : Candidates, optional
        Precomputed :func:`find_candidates` of ``depth`` (computed if None).
    exclude_rc : sequence of (row, col)
        Cells already paired; candidates within 2 cells of them are skipped.
    click_sigma_px : float
        Click noise assumed for the proposed pairs, pixels.
    corner_image : CornerImage, optional
        The camera image's corners: when given, only candidates with an image
        corner of at least ``min_image_corner`` within their 3-sigma ellipse
        (2..12 px) are proposed.
    max_cell_m, range_sigma_m, cell_sigma : float
        Laser pick model (:mod:`.laser_noise`).
    visible : (len(candidates),) bool, optional
        Which candidates the camera sees, if already known (a session
        computes it once; it barely changes as the pose is refined).
    reclick : sequence of (pair index, (row, col), sigma_px)
        Existing pairs clicked with noise ``sigma_px`` (> ``click_sigma_px``)
        that a re-click in the loupe may make precise.  Such a proposal is
        ranked by the information it adds over the rough pair: its noise
        ``S`` satisfies ``S^-1 = S_new^-1 - S_old^-1``.
    order : {"d_optimal", "farthest", "random"}
        ``"d_optimal"`` (the method); for comparisons, ``"farthest"``: the
        candidate whose camera bearing is farthest from those of
        ``paired_points_lidar`` and of the proposals before it (what a
        person spreading clicks does), or ``"random"`` (needs ``rng``).
        Gains are reported under every order.  With ``corner_image``, the
        D-optimal order maximises the expected gain ``gain x P`` with ``P``
        the probability that the cell is a clickable corner
        (:mod:`.corner_probability`), i.e. information per UI action.
    corner_weights : (float, sequence of float)
        Logistic weights of :func:`.corner_probability.corner_probability`.
    laser_evidence : (len(candidates), 5) ndarray, optional
        :func:`.corner_probability.laser_features` of the candidates, if
        already known (a session computes it once).
    screen : ProposalScreen or None
        The clear-evidence screen (:mod:`.evidence`; its ``max_ellipse_px``
        is the loupe's limit).  Re-clicks pass only its ellipse and border
        tests: their corner was chosen by the person, and a rough pair left
        un-re-clicked biases the solve (measured: PJLab auto_calib from 5
        by-eye pairs ended 0.42 deg off the published pose when re-clicks of
        pairs beyond ``max_range_m`` were left out, 0.02 deg with them).  None: the behaviour
        before the screen (``corner_image`` then needs an image corner of
        ``min_image_corner`` within 2..12 px).
    plane_residual : (H, W) ndarray, optional
        :func:`.evidence.local_plane_residual_m` of ``depth`` with the
        screen's ``same_surface_rel`` and ``min_plane_neighbours``, if
        already known (a session computes it once).

    Returns
    -------
    Proposals
        A list of :class:`Proposal`, possibly fewer than ``n`` (or none,
        with the reason in :attr:`Proposals.reason`).
    """
    if n < 1:
        raise CalibError(f"the number of proposals must be at least 1, got {n}")
    if not (np.isfinite(click_sigma_px) and click_sigma_px > 0):
        raise CalibError(f"click noise must be a positive number of pixels, got {click_sigma_px}")
    cand = find_candidates(depth) if candidates is None else candidates
    keep = np.ones(len(cand), dtype=bool)
    if len(exclude_rc):
        ex = np.asarray(exclude_rc, dtype=np.int64).reshape(-1, 2)
        near = np.abs(cand.rows_cols[:, None, :] - ex[None, :, :]).max(axis=2) <= 2
        keep &= ~near.any(axis=1)
    if visible is None:
        scan_points, _ = depth.valid_points()
        _, visible = visible_in_camera(camera, state.T_camera_lidar, scan_points, cand.points_lidar)
    keep &= visible
    cand = cand.subset(keep)
    if corner_image is not None:
        if laser_evidence is None:
            laser_evidence = laser_features(depth, cand, scan_range_noise_m(depth))
        else:
            laser_evidence = np.asarray(laser_evidence)[keep]
    pixels, J_pose, J_point = pixel_jacobians(camera, state.T_camera_lidar, cand.points_lidar)
    laser_cov = cell_covariance(depth, cand.rows_cols, cell_sigma, range_sigma_m)
    offset_cov = laser_cov.copy()
    if screen is not None:  # a screened marking touches the paint's corner
        marking = cand.kind == KINDS.index("marking")
        offset_cov[marking] = cell_covariance(depth, cand.rows_cols[marking], min(cell_sigma, MARKING_CELL_SIGMA),
                                              range_sigma_m)
    laser_px = J_point @ offset_cov @ np.swapaxes(J_point, 1, 2)
    pixel_cov = pose_pixel_covariance(J_pose, state.covariance) + laser_px
    ok = np.all(np.isfinite(J_pose), axis=(1, 2)) & np.all(np.isfinite(pixel_cov), axis=(1, 2))
    ok &= _cell_extent_m(laser_cov, range_sigma_m, cell_sigma) <= max_cell_m
    strength = np.full(len(cand), np.nan)
    screened: dict[str, int] = {}
    evidence = {name: np.full(len(cand), np.nan) for name in ("planar", "footprint", "dominance")}
    smallest_ellipse, some_fit = np.inf, False
    why = np.full(len(cand), "", dtype=object)
    if screen is not None:
        ok, smallest_ellipse, some_fit = _screen(depth, camera, cand, pixels, pixel_cov, J_point, ok, screen,
                                                 corner_image, plane_residual, screened, strength, evidence, why)
    elif corner_image is not None:
        major = np.sqrt(np.maximum(np.linalg.eigvalsh(np.where(ok[:, None, None], pixel_cov, 0.0))[:, -1], 0.0))
        radius = np.clip(3.0 * major, 2.0, 12.0)
        for r in np.unique(np.ceil(radius)):  # a few distinct radii
            sel = np.ceil(radius) == r
            strength[sel] = strongest_near(corner_image, pixels[sel], float(r))[1]
        ok &= strength >= min_image_corner
        # The 3-sigma disc must lie inside the picture: the rim of a fisheye's image circle is no corner.
        inside = cv2.distanceTransform(content_mask(np.rint(corner_image.gray * 255).astype(np.uint8), 0)
                                       .astype(np.uint8), cv2.DIST_L2, 5)
        H_img, W_img = inside.shape
        pu = np.clip(np.rint(np.nan_to_num(pixels[:, 0])).astype(np.int64), 0, W_img - 1)
        pv = np.clip(np.rint(np.nan_to_num(pixels[:, 1])).astype(np.int64), 0, H_img - 1)
        ok &= inside[pv, pu] >= np.maximum(radius, 6.0)
    left_out = (cand.rows_cols[why != ""], why[why != ""].astype(str))
    probability = np.full(len(cand), np.nan)
    if corner_image is not None and ok.any():
        sel = np.flatnonzero(ok)
        feats = corner_features(laser_evidence[sel], corner_image, pixels[sel], pixel_cov[sel])
        probability[sel] = corner_probability(feats, corner_weights)
    idx = np.flatnonzero(ok)
    # The pair's own noise: a guided pair ends on the corner's cell (careful pick).
    whole = cell_covariance(depth, cand.rows_cols[idx], PICK_CELL_SIGMA, range_sigma_m)
    S = pair_noise(click_sigma_px, J_point[idx], whole)
    J = J_pose[idx]
    # Reclicks are of existing pairs: certainly corners.
    P = np.where(np.isfinite(probability[idx]), probability[idx], 1.0)
    entries = [("candidate", int(i)) for i in idx]
    rows_re = [(int(i), (int(rc[0]), int(rc[1])), float(sg)) for i, rc, sg in reclick if sg > click_sigma_px]
    extra: dict = {}
    if rows_re:
        rc_re = np.array([r[1] for r in rows_re], dtype=np.int64)
        pts_re = depth.points[rc_re[:, 0], rc_re[:, 1]]
        pix_re, Jp_re, Jx_re = pixel_jacobians(camera, state.T_camera_lidar, pts_re)
        whole_re = cell_covariance(depth, rc_re, PICK_CELL_SIGMA, range_sigma_m)
        S_new = pair_noise(click_sigma_px, Jx_re, whole_re)
        S_old = pair_noise(np.array([r[2] for r in rows_re]), Jx_re, whole_re)
        S_eff = np.linalg.inv(np.linalg.inv(S_new) - np.linalg.inv(S_old))
        cov_re = pose_pixel_covariance(Jp_re, state.covariance) + Jx_re @ whole_re @ np.swapaxes(Jx_re, 1, 2)
        fine = np.all(np.isfinite(Jp_re), axis=(1, 2)) & np.all(np.isfinite(S_eff), axis=(1, 2))
        if screen is not None:  # the person chose the corner (even a far one); the loupe must still show where
            major_re = 3.0 * np.sqrt(np.maximum(np.linalg.eigvalsh(np.nan_to_num(cov_re))[:, -1], 0.0))
            fits = (major_re <= screen.max_ellipse_px) & (
                ellipse_box_margin_px(pix_re, cov_re, camera.width, camera.height) >= screen.border_margin_px)
            screened["reclick ellipse or border"] = int((fine & ~fits).sum())
            if (fine & ~fits).any():
                smallest_ellipse = min(smallest_ellipse, float(major_re[fine & ~fits].min()))
            some_fit |= bool((fine & fits).any())
            fine &= fits
        for k in np.flatnonzero(fine):
            extra[len(entries)] = (rows_re[k], rc_re[k], pts_re[k], pix_re[k], cov_re[k])
            entries.append(("reclick", int(k)))
        S = np.concatenate([S, S_eff[fine]])
        P = np.concatenate([P, np.ones(int(fine.sum()))])
        J = np.concatenate([J, Jp_re[fine]])
    if not entries:
        # Rough alignment only when no ellipse fitted: else other tests left the cells out.
        if screen is not None and np.isfinite(smallest_ellipse) and not some_fit:
            reason = REASON_ROUGH_ALIGNMENT.format(limit=screen.max_ellipse_px, smallest=smallest_ellipse)
        else:
            reason = REASON_NO_EVIDENCE
        return Proposals([], reason, screened, left_out=left_out)
    if order not in ("d_optimal", "farthest", "random"):
        raise CalibError(f"unknown proposal order {order!r}; use d_optimal, farthest or random")
    if order == "random" and rng is None:
        raise CalibError("order='random' needs a random generator")
    if order == "farthest":
        pts = np.concatenate([cand.points_lidar[idx]] + ([depth.points[rc_re[fine, 0], rc_re[fine, 1]]] if rows_re else []))
        R, t = state.T_camera_lidar[:3, :3], state.T_camera_lidar[:3, 3]
        bear = pts @ R.T + t
        bear /= np.linalg.norm(bear, axis=1, keepdims=True)
        max_cos = np.full(len(bear), -1.0)
        if paired_points_lidar is not None and len(paired_points_lidar):
            pb = np.asarray(paired_points_lidar, dtype=np.float64) @ R.T + t
            pb /= np.linalg.norm(pb, axis=1, keepdims=True)
            max_cos = (bear @ pb.T).max(axis=1)
    C = state.covariance.copy()
    chosen: list[int] = []
    gains: list[float] = []
    alive = np.ones(len(entries), dtype=bool)
    for _ in range(min(n, len(entries))):  # n is a few tens; each step is vectorised over the candidates
        g = d_optimal_gain(J, S, C)
        g = np.where(alive & np.isfinite(g), g, -np.inf)
        if order == "d_optimal":
            k = int(np.argmax(np.where(np.isfinite(g), g * P, -np.inf)))
        elif order == "farthest":
            k = int(np.argmin(np.where(np.isfinite(g), max_cos, np.inf)))
            max_cos = np.maximum(max_cos, bear @ bear[k])
        else:
            live = np.flatnonzero(np.isfinite(g))
            k = int(rng.choice(live)) if live.size else 0
        if not np.isfinite(g[k]):
            break
        chosen.append(k)
        gains.append(float(g[k]))
        alive[k] = False
        # Information update of the pair just ranked (Woodbury on the covariance).
        Jk = J[k]
        G = C @ Jk.T @ np.linalg.inv(S[k] + Jk @ C @ Jk.T)
        C = C - G @ Jk @ C
        C = 0.5 * (C + C.T)
    out = []
    for k, gain in zip(chosen, gains):
        if entries[k][0] == "reclick":
            (pair_index, _, _), rc, pt, pix, cov = extra[k]
            out.append(Proposal((int(rc[0]), int(rc[1])), pt.copy(), pix.copy(), cov.copy(), gain, "reclick",
                                replaces=pair_index, probability=1.0 if corner_image is not None else float("nan")))
            continue
        i = entries[k][1]
        out.append(Proposal(
            laser_rc=(int(cand.rows_cols[i, 0]), int(cand.rows_cols[i, 1])),
            laser_xyz=cand.points_lidar[i].copy(),
            pixel=pixels[i].copy(),
            pixel_cov=pixel_cov[i].copy(),
            gain=gain,
            kind=KINDS[int(cand.kind[i])],
            image_corner=float(strength[i]),
            strength=float(cand.strength[i]),
            probability=float(probability[i]),
            planar_share=float(evidence["planar"][i]),
            footprint_px=float(evidence["footprint"][i]),
            corner_dominance=float(evidence["dominance"][i]),
        ))
    return Proposals(out, None if out else REASON_NO_EVIDENCE, screened, left_out=left_out)


def _screen(depth, camera, cand: Candidates, pixels, pixel_cov, J_point, ok, screen: ProposalScreen,
            corner_image: CornerImage | None, plane_residual, screened: dict, strength, evidence: dict,
            left_out: np.ndarray | None = None):
    """Apply the clear-evidence screen (:mod:`.evidence`) to the candidates still ``ok``.

    Fills ``screened`` (cells left out per test), ``strength`` (the dominant
    image corner's ``lam_min``) and ``evidence`` (planar share, footprint,
    dominance) in place.  Returns the new ``ok``, the smallest 3-sigma
    radius among the cells with laser evidence that the ellipse test left
    out (inf when it left none out) and whether any such cell's ellipse fitted.
    """
    ok = ok.copy()

    def cut(name: str, passes: np.ndarray) -> None:
        nonlocal ok
        screened[name] = screened.get(name, 0) + int((ok & ~passes).sum())
        if left_out is not None:
            left_out[ok & ~passes] = name
        ok &= passes

    rows = cand.rows_cols[:, 0]
    cut("scan edge", (rows >= screen.scan_edge_rows) & (rows < depth.shape[0] - screen.scan_edge_rows))
    rng_m = np.linalg.norm(cand.points_lidar, axis=1)
    cut("far", rng_m <= screen.max_range_m)
    foot = cell_footprint_px(depth, cand.rows_cols, np.nan_to_num(J_point))
    evidence["footprint"][:] = foot
    cut("footprint", foot <= screen.max_footprint_px)
    if plane_residual is None:
        plane_residual = local_plane_residual_m(depth, screen.same_surface_rel, screen.min_plane_neighbours)
    tol_m = screen.max_plane_rms_noise * scan_range_noise_m(depth)
    share, n_planar = planar_share(depth, cand.rows_cols, plane_residual, tol_m, screen.plane_half)
    evidence["planar"][:] = share
    cut("not planar", (share >= screen.min_planar_share) & (n_planar >= screen.min_planar_cells))
    # The kind's own evidence: a real depth step, or three planes (not a fold of one surface).
    junction = cand.kind == KINDS.index("junction")
    marking = cand.kind == KINDS.index("marking")
    sel = np.flatnonzero(ok)
    span = np.zeros(len(ok))
    step = np.zeros(len(ok))
    far = np.zeros(len(ok))
    near_share = np.full(len(ok), 0.5)
    turn = np.zeros(len(ok))
    if sel.size:
        filled = fill_holes(depth)
        span[sel] = normal_span(depth, cand.rows_cols[sel], screen.plane_half)[:, 0]
        step[sel] = depth_discontinuity(filled, cand.rows_cols[sel])
        far[sel] = far_side_share(filled, cand.rows_cols[sel], screen.min_depth_step)
        near_share[sel] = np.nan_to_num(near_fraction(filled, cand.rows_cols[sel]), nan=0.5)
        turn[sel] = near_edge_turn(filled, cand.rows_cols[sel])
    cut("junction of fewer than three planes", ~junction | (span >= screen.min_junction_span))
    cut("junction on a coarse scan", ~junction | (foot <= screen.max_junction_footprint_px))
    depth_jump = ~junction & ~marking
    cut("depth step too small", ~depth_jump | ((step >= screen.min_depth_step) & (far >= screen.min_far_share)))
    cut("straight depth edge", ~depth_jump | (near_share <= screen.max_convex_share)
        | (near_share >= screen.min_concave_share))
    cut("depth edge does not turn", ~depth_jump | (turn >= screen.min_edge_turn))
    # Nothing on the ground unless it is a painted-marking corner in intensity.
    sel = np.flatnonzero(ok)
    if sel.size:
        plane = ground_plane(depth, screen.ground_tol_m)
        height = height_above_ground_m(depth, plane)
        with np.errstate(invalid="ignore"):
            ground = np.abs(height) <= screen.ground_tol_m
        on_ground = np.zeros(len(ok), dtype=bool)
        inside_road = np.zeros(len(ok), dtype=bool)
        rc = cand.rows_cols[sel]
        share_ground = window_share(ground, depth, rc, screen.plane_half)
        on_ground[sel] = ground[rc[:, 0], rc[:, 1]] & (share_ground > screen.max_ground_share)
        inside_road[sel] = ground[rc[:, 0], rc[:, 1]] & (share_ground >= screen.min_marking_ground_share)
        painted = marking.copy()
        g = np.flatnonzero(on_ground & ~marking)
        if g.size:
            painted[g] = intensity_corner(depth, cand.rows_cols[g], screen.min_intensity_corner)
        cut("on the ground", ~on_ground | painted)
        low = np.zeros(len(ok), dtype=bool)
        low[sel] = np.nan_to_num(height[rc[:, 0], rc[:, 1]], nan=np.inf) < screen.min_height_m
        cut("at the foot of an object", ~low | marking)
        # Intensity corners off the road are door frames, retro-reflectors, shading: not painted markings.
        cut("intensity corner off the ground", ~marking | inside_road)
        cut("weak intensity corner", ~marking | (cand.strength >= screen.min_marking_strength))
        mark_turn = np.zeros(len(ok))
        m = np.flatnonzero(ok & marking)
        if m.size:
            mark_turn[m] = intensity_edge_turn(depth, cand.rows_cols[m])
        cut("marking edge does not turn", ~marking | (mark_turn >= screen.min_edge_turn))
        # A corner of the paint (its bright side covers about 1/4 or 3/4 of the window), touching the cell: not
        # a stripe's side banded ring by ring, nor a response peak on the asphalt next to the paint.
        bright, touches = np.full(len(ok), 0.5), np.zeros(len(ok), dtype=bool)
        m = np.flatnonzero(ok & marking)
        if m.size:
            share_m, touches[m] = bright_fraction(depth, cand.rows_cols[m])
            bright[m] = np.nan_to_num(share_m, nan=0.5)
        cut("straight marking edge", ~marking | (bright <= screen.max_convex_share)
            | (bright >= screen.min_concave_share))
        cut("marking corner off the paint", ~marking | touches)
        m = np.flatnonzero(ok & marking)
        if m.size:
            width = np.zeros(len(ok))
            width[m] = np.nan_to_num(edge_width_cells(depth, cand.rows_cols[m]), nan=np.inf)
            cut("marking edge smeared", ~marking | (width <= screen.max_marking_edge_cells))
    radius = 3.0 * np.sqrt(np.maximum(np.linalg.eigvalsh(np.where(ok[:, None, None], pixel_cov, 0.0))[:, -1], 0.0))
    fits = radius <= screen.max_ellipse_px
    too_big = ok & ~fits
    smallest = float(radius[too_big].min()) if too_big.any() else np.inf
    some_fit = bool((ok & fits).any())
    cut("ellipse larger than the loupe", fits)
    cut("border", ellipse_box_margin_px(pixels, pixel_cov, camera.width, camera.height) >= screen.border_margin_px)
    if corner_image is not None and ok.any():
        # The rim of a fisheye's image circle is a border too.
        gray8 = np.rint(corner_image.gray * 255).astype(np.uint8)
        inside = cv2.distanceTransform(content_mask(gray8, 0).astype(np.uint8), cv2.DIST_L2, 5)
        H_img, W_img = inside.shape
        pu = np.clip(np.rint(np.nan_to_num(pixels[:, 0])).astype(np.int64), 0, W_img - 1)
        pv = np.clip(np.rint(np.nan_to_num(pixels[:, 1])).astype(np.int64), 0, H_img - 1)
        cut("border", inside[pv, pu] >= radius + screen.border_margin_px)
        sel = np.flatnonzero(ok)
        peaks = corner_peaks(corner_image)
        peak_uv, first, second, ratio = dominant_corner(corner_image, peaks, pixels[sel], pixel_cov[sel],
                                                        screen.min_search_px)
        rivals = corner_rivals(peaks, peak_uv, first, screen.rival_radius_px, screen.rival_fraction)
        strength[sel] = first
        with np.errstate(divide="ignore", invalid="ignore"):
            dominance = np.where(second > 0, first / np.where(second > 0, second, 1.0), np.inf)
        evidence["dominance"][sel] = dominance
        clean = np.zeros(len(ok), dtype=bool)
        clean[sel] = ((first >= screen.min_corner_strength) & (ratio >= screen.min_corner_ratio)
                      & (dominance >= screen.min_corner_dominance))
        cut("no dominant image corner", clean)
        isolated = np.ones(len(ok), dtype=bool)
        isolated[sel] = rivals <= screen.max_rivals
        cut("repeated image texture", isolated)
    return ok, smallest, some_fit


def proposals_to_dict(proposals: Sequence[Proposal], state: PoseState | None = None) -> dict:
    """The ``proposals:`` document (best first), with the pose they were computed from."""
    doc: dict = {"proposals": [p.to_dict() for p in proposals]}
    reason = getattr(proposals, "reason", None)
    if not proposals and reason:
        doc["reason"] = str(reason)
    if state is not None:
        doc["pose"] = {
            "T_camera_lidar": [[float(x) for x in row] for row in state.T_camera_lidar],
            "from": state.source,
            "n_pairs": int(state.n_pairs),
        }
    return doc


def save_proposals_yaml(path: str | os.PathLike, proposals: Sequence[Proposal], state: PoseState | None = None) -> None:
    """Write the proposals file atomically."""
    write_yaml_atomic(path, proposals_to_dict(proposals, state))
