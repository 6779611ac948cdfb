"""A guided-picking session: pairs so far, the next proposal, accept / skip / not a corner.

What the app's "next pair" action and the benchmark's simulated person
drive: after every accepted pair the pose, its covariance and the proposals
are recomputed.  Rough pairs (clicked without guidance) are proposed for a
re-click in the loupe when that adds more information than a new pair *and*
would clearly help (:meth:`GuidedSession.reclick_worthy`: the pose rests on
the pair, or the pair lands far off the pose fitted without it); the re-click
replaces them.  A re-click skipped or declined once is not proposed again in
the session.  When no new cell passes the screen, :attr:`Proposals.note` says
so (how many candidates were left out, and mostly why).  The candidates of
the scan, and which of them the camera sees, are computed once.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..pairs import Pair, resolve_pairs
from ..solve import CalibrationResult, calibrate
from .candidates import find_candidates
from .corner_probability import laser_features, scan_range_noise_m
from ..solve.calibrate import pair_ids_and_sigmas
from ..solve.quality import MIN_PAIRS_FOR_ERROR
from .evidence import REASON_NO_EVIDENCE, ProposalScreen, local_plane_residual_m, no_new_corner_note
from .image_corners import CornerImage, corner_image
from .pose_state import DEFAULT_CLICK_SIGMA_PX, PoseState, current_pose
from .propose import GUIDED_CLICK_SIGMA_PX, Proposal, Proposals, propose
from .visibility import visible_in_camera

__all__ = ["GuidedSession", "RECLICK_MIN_LEVERAGE", "RECLICK_MIN_LOO_PX"]

#: A re-click helps clearly when the pose rests on the pair: the largest eigenvalue of its 2x2 hat-matrix block
#: is at least this (the pose takes half or more of that click's error, so a precise click moves the pose).
RECLICK_MIN_LEVERAGE = 0.5
#: ... or when the pair lands this far off the pose fitted without it (px; 3x the 1.5 px per axis of a click and
#: a whole-cell laser pick): a precise click there moves the pose (rough by-eye pairs left un-re-clicked bias the
#: solve: tests/test_app_guided_real.py).
RECLICK_MIN_LOO_PX = 4.5


class GuidedSession:
    """Guided picking on one scene.

    Parameters
    ----------
    depth : DepthMatrix
    camera : CameraModel
    pairs : sequence of Pair
        Pairs so far (>= 4, or give ``T_initial``).
    T_initial : (4, 4) ndarray, optional
        Imported extrinsic.
    image : (H, W, 3) uint8, optional
        The camera image: proposals then need an image corner near their pixel.
    click_sigma_px : float
        Click noise of guided pairs (their ``precision_px``).
    reclicks : bool
        Whether rough pairs are proposed for a re-click in the loupe (default True).
    **propose_options
        Passed to :func:`calib_core.guide.propose.propose` (e.g. ``screen``:
        a :class:`calib_core.guide.evidence.ProposalScreen`, or None for no screen);
        :attr:`propose_options` may be changed later.
    """

    def __init__(self, depth, camera, pairs: Sequence[Pair] = (), T_initial: np.ndarray | None = None,
                 image: np.ndarray | None = None, click_sigma_px: float = GUIDED_CLICK_SIGMA_PX,
                 reclicks: bool = True, **propose_options) -> None:
        self.depth, self.camera, self.image = depth, camera, image
        self.pairs: list[Pair] = list(pairs)
        self.T_initial = T_initial
        self.click_sigma_px = float(click_sigma_px)
        self.corners: CornerImage | None = corner_image(image) if image is not None else None
        self.candidates = find_candidates(depth)
        self._laser_evidence = (laser_features(depth, self.candidates, scan_range_noise_m(depth))
                                if self.corners is not None else None)
        self.dropped: list[tuple[int, int]] = []
        self.skipped: list[tuple[int, int]] = []
        self.propose_options = propose_options
        self.reclicks = bool(reclicks)
        self._visible: np.ndarray | None = None
        self._plane_residual: tuple[tuple, np.ndarray] | None = None  # (its parameters, the map)
        self.state: PoseState = self._update_state()

    def _update_state(self) -> PoseState:
        self.state = current_pose(self.pairs, self.depth, self.camera, self.T_initial)
        if self._visible is None:
            scan_points, _ = self.depth.valid_points()
            _, self._visible = visible_in_camera(self.camera, self.state.T_camera_lidar, scan_points,
                                                 self.candidates.points_lidar)
        return self.state

    def _residual_for(self, screen: ProposalScreen | None) -> np.ndarray | None:
        """The scan's local plane residual map for ``screen``'s parameters, computed once per parameters."""
        if screen is None:
            return None
        key = (screen.same_surface_rel, screen.min_plane_neighbours)
        if self._plane_residual is None or self._plane_residual[0] != key:
            self._plane_residual = (key, local_plane_residual_m(self.depth, *key))
        return self._plane_residual[1]

    def proposals(self, n: int = 20) -> Proposals:
        """The ``n`` best next pairs under the current state (skipped ones go last); when there are
        none, :attr:`Proposals.reason` says why."""
        used = [p.laser_rc for p in self.pairs if p.laser_rc is not None] + self.dropped
        # A re-click skipped or declined ("Not a corner") once is not proposed again in this session.
        declined = set(map(tuple, self.dropped)) | set(map(tuple, self.skipped))
        worthy = self.reclick_worthy() if self.reclicks else set()
        rough = [(i, p.laser_rc, DEFAULT_CLICK_SIGMA_PX if p.precision_px is None else p.precision_px)
                 for i, p in enumerate(self.pairs) if p.laser_rc is not None and not p.check
                 and tuple(p.laser_rc) not in declined and i in worthy]
        fit = [p for p in self.pairs if not p.check]
        paired_points = resolve_pairs(fit, self.depth, self.camera)[0] if fit else None
        options = dict(self.propose_options)
        screen = options.setdefault("screen", ProposalScreen())
        props = propose(self.depth, self.camera, self.state, n + len(self.skipped), candidates=self.candidates,
                        exclude_rc=used, click_sigma_px=self.click_sigma_px, corner_image=self.corners,
                        visible=self._visible, reclick=rough, paired_points_lidar=paired_points,
                        laser_evidence=self._laser_evidence, plane_residual=self._residual_for(screen),
                        **options)
        skipped = set(self.skipped)
        if screen is not None and not any(p.replaces is None for p in props):
            # Only the ellipses too large: the rough-alignment reason (with its figures) says what to do.
            rough_alignment = not props and props.reason is not None and props.reason != REASON_NO_EVIDENCE
            props.note = props.reason if rough_alignment else no_new_corner_note(props.screened)
        return props.like(([p for p in props if p.laser_rc not in skipped]
                           + [p for p in props if p.laser_rc in skipped])[:n])

    def reclick_worthy(self) -> set[int]:
        """Indices (in :attr:`pairs`) of the pairs whose re-click in the loupe would clearly help.

        * Fewer than 4 pairs in the fit: none (the pose is the imported extrinsic; the pairs do not enter it yet,
          and new pairs are what is missing).
        * Exactly 4: all (8 equations for 6 unknowns: the pose rests on every pair, mean leverage 0.75).
        * 5 or more: from the solve's leave-one-out check (:class:`calib_core.solve.quality.LeaveOneOut`):
          a pair whose leverage is at least :data:`RECLICK_MIN_LEVERAGE`, or whose error under the pose fitted
          without it is at least :data:`RECLICK_MIN_LOO_PX`; a pair the robust solve left out as an outlier (a re-click at its predicted pixel can set it
          right).  None when the check is not available.
        """
        fit_index = [i for i, p in enumerate(self.pairs) if not p.check]
        if len(fit_index) < MIN_PAIRS_FOR_ERROR - 1:
            return set()
        if len(fit_index) < MIN_PAIRS_FOR_ERROR:
            return set(fit_index)
        loo = getattr(getattr(self.state, "quality", None), "leave_one_out", None)
        if loo is None:
            return set()
        ids, _ = pair_ids_and_sigmas([self.pairs[i] for i in fit_index])  # the ids the solve named its pairs by
        index_of = dict(zip(ids, fit_index))
        worthy = set()
        for pid, err, lev in zip(loo.ids, np.asarray(loo.loo_px, np.float64), np.asarray(loo.leverage, np.float64)):
            far = np.isfinite(err) and err >= RECLICK_MIN_LOO_PX
            carried = (np.isfinite(lev) and lev >= RECLICK_MIN_LEVERAGE) or not np.isfinite(err)
            if (far or carried) and pid in index_of:
                worthy.add(index_of[pid])
        in_fit = {index_of[pid] for pid in loo.ids if pid in index_of}
        return worthy | (set(fit_index) - in_fit)  # the outliers the robust solve left out

    def accept(self, proposal: Proposal, pixel, source: str = "guided", precision_px: float | None = None,
               laser_rc: tuple[int, int] | None = None) -> Pair:
        """Make a pair of the proposal's cell (or ``laser_rc``, the cell the person moved it to)
        and the clicked (or auto-found) pixel; update the pose."""
        rc = proposal.laser_rc if laser_rc is None else (int(laser_rc[0]), int(laser_rc[1]))
        pair = Pair(rc, None, (float(pixel[0]), float(pixel[1])), source=source,
                    precision_px=self.click_sigma_px if precision_px is None else float(precision_px))
        if proposal.replaces is not None:  # a re-click of a rough pair replaces it
            self.pairs[proposal.replaces] = pair
        else:
            self.pairs.append(pair)
        self._update_state()
        return pair

    def skip(self, proposal: Proposal) -> None:
        """Show this proposal again only after the others."""
        self.skipped.append(proposal.laser_rc)

    def not_a_corner(self, proposal: Proposal) -> None:
        """Drop the proposal's cell for good."""
        self.dropped.append(proposal.laser_rc)

    def solve(self) -> CalibrationResult:
        """The calibration from the pairs so far (check pairs left out), each pair weighted by
        its ``precision_px`` and whole-cell laser pick (:func:`calib_core.solve.calibrate`)."""
        fit = [p for p in self.pairs if not p.check]
        return calibrate(fit, self.depth, self.camera, initial_T_camera_lidar=self.state.T_camera_lidar)
