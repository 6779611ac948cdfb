"""What the Guide panel (:mod:`app.guide_panel`) computes off the UI: the proposals job, the loupe's ellipse limit,
the live solve's verdict.  No widgets here; the maths is :mod:`calib_core.guide`."""

from __future__ import annotations

from typing import Any

from calib_core.guide import GUIDED_CLICK_SIGMA_PX, current_pose
from calib_core.guide.auto_accept import AutoGate, auto_accept
from calib_core.guide.evidence import ProposalScreen
from calib_core.guide.session import GuidedSession
from calib_core.pairs import Pair

from .loupes import default_camera_crop_px

__all__ = ["N_PROPOSALS", "pair_counts_line", "AUTO_PRECISION_PX", "MAX_LOUPE_ZOOM_OUT", "ELLIPSE_MARGIN_PX", "max_ellipse_px_for",
           "rank_proposals", "live_quality"]

#: Proposals computed per update.
N_PROPOSALS = 20
#: 1-sigma given to an auto-accepted pixel (cv2.cornerSubPix on a gated clean corner).  The gate accepts
#: no proposal on the sample, so this is not measured there; it is set above the guided click's 0.3 px.
AUTO_PRECISION_PX = 0.5
#: The camera loupe zooms out at most this much to show a proposal's 3-sigma ellipse whole.  1: no zoom-out, the
#: ellipse fits the loupe as it is.  Measured (``python -m bench.guide_by_eye --summary --trials 8``, KITTI 000002):
#: with one zoom step (x ZOOM_FACTOR) allowed, 7 of 10 new cells proposed lay within 3 px of a clean photo corner
#: (median 3-sigma radius 23.3 px, half fitting the loupe at zoom 1); at zoom 1, 5 of 5 (19.9 px, all fitting).
MAX_LOUPE_ZOOM_OUT = 1.0
#: Image pixels shown beyond the ellipse, both sides together (a framed ellipse does not touch the loupe's edge).
ELLIPSE_MARGIN_PX = 4.0


def max_ellipse_px_for(width: int, height: int) -> float:
    """Largest 3-sigma radius (px) of a proposal the app shows for a ``width`` x ``height`` image: half the
    camera loupe's side at zoom 1, zoomed out by :data:`MAX_LOUPE_ZOOM_OUT`."""
    return 0.5 * default_camera_crop_px(width, height) * MAX_LOUPE_ZOOM_OUT


def pair_counts_line(picks: list) -> str:
    """``"Pairs: 12 clicked (3 re-clicked by guidance), 0 guided, 0 auto"`` for the complete ``picks``.

    A re-clicked pair keeps its source (a hand pair stays "clicked"), so the re-clicks are counted apart: a
    "clicked" pair with the guided click's precision (:data:`calib_core.guide.GUIDED_CLICK_SIGMA_PX`), which only
    a re-click at a guided proposal gives a clicked pair (run 5: "12 clicked, 0 guided" after 3 re-clicks).
    """
    counts = {s: 0 for s in ("clicked", "guided", "auto")}
    for pick in picks:
        counts[pick.source] = counts.get(pick.source, 0) + 1
    reclicked = sum(1 for p in picks if p.source == "clicked" and p.precision_px == GUIDED_CLICK_SIGMA_PX)
    words = [f"{v} {k}" + (f" ({reclicked} re-clicked by guidance)" if k == "clicked" and reclicked else "")
             for k, v in counts.items()]
    return "Pairs: " + ", ".join(words)


def rank_proposals(session: GuidedSession, pairs: list, T0, skipped: list, dropped: list, screen: ProposalScreen,
                   auto_gate: AutoGate | None) -> tuple:
    """Sync ``session`` with the pairs and rank (on the guide's worker thread).

    Returns
    -------
    props : calib_core.guide.Proposals
        At most :data:`N_PROPOSALS`, with the reason when empty.
    auto_pairs : list of Pair
        Proposals ``auto_gate`` accepts (none without a gate, or while the solve is unreliable).
    reclick_of : dict
        Cell -> pick id of the pair each re-click proposal replaces.
    quality : (pairs, status, reasons) or None
        The session's own solve of ``pairs`` (None with an imported extrinsic alone).
    """
    s = session
    s.propose_options["screen"] = screen
    s.pairs, s.T_initial = list(pairs), T0
    s.state = current_pose(s.pairs, s.depth, s.camera, T0)
    s.skipped, s.dropped = list(skipped), list(dropped)
    q = s.state.quality
    quality = None if q is None else (tuple(pairs), q.status, list(q.reasons))
    # "Not a corner" on a re-click means: do not offer re-clicking that pair again.
    gone = set(map(tuple, dropped))
    ranked = s.proposals(N_PROPOSALS + len(gone))
    props = ranked.like([p for p in ranked if p.replaces is None or tuple(p.laser_rc) not in gone][:N_PROPOSALS])
    # A re-click proposal names the pair it replaces by its index in ``pairs``: keep the pick id.
    reclick_of = {tuple(p.laser_rc): pairs[p.replaces].id for p in props if p.replaces is not None}
    auto_pairs: list[Pair] = []
    unreliable = quality is not None and quality[1] == "unreliable"
    if auto_gate is not None and props and s.corners is not None and not unreliable:  # (never re-clicks)
        ok, pixels = auto_accept(s.corners, props, auto_gate, image=s.image, depth=s.depth, camera=s.camera,
                                 T_camera_lidar=s.state.T_camera_lidar)
        auto_pairs = [Pair(tuple(p.laser_rc), None, (float(px[0]), float(px[1])), source="auto",
                           precision_px=AUTO_PRECISION_PX) for p, good, px in zip(props, ok, pixels) if good]
    return props, auto_pairs, reclick_of, quality


def live_quality(app: Any) -> tuple | None:
    """``(pairs solved, status, reasons)`` of the live solve shown, or None (none yet)."""
    bundle = app.solve_bundle
    quality = getattr(getattr(bundle, "result", None), "quality", None)
    return None if quality is None else (tuple(bundle.pairs), quality.status, list(quality.reasons))


class ShotGuide:
    """Guided picking across the shots of a session (issue 21), on the guide's worker thread.

    Proposals are :func:`calib_core.shots.propose_shots` (what ``ba-calib propose --shot`` ranks): every
    shot's scan searched under the joint pose of all shots' pairs, merged by one D-optimal gain.  Each
    shot's candidate cells and its photo's corner image are found once and kept.

    Parameters
    ----------
    depths, images : lists, one per shot
        Each shot's depth matrix and RGB photo.
    camera : CameraModel
        The one camera of every shot.
    """

    def __init__(self, depths: list, images: list, camera: Any) -> None:
        self.depths, self.images, self.camera = list(depths), list(images), camera
        self._cache: dict[int, dict] = {}

    def _options(self, k: int, screen: ProposalScreen) -> dict:
        from calib_core.guide.candidates import find_candidates
        from calib_core.guide.image_corners import corner_image

        if k not in self._cache:
            self._cache[k] = {"candidates": find_candidates(self.depths[k]),
                              "corner_image": corner_image(self.images[k])}
        return {**self._cache[k], "screen": screen}

    def rank(self, pairs_by_shot: list, ids_by_shot: list, T0, dropped: list, active: int,
             screen: ProposalScreen) -> tuple:
        """Proposals over every shot for the pairs ``pairs_by_shot`` (each shot's, ids ``ids_by_shot``).

        Returns
        -------
        props : calib_core.guide.Proposals
            At most :data:`N_PROPOSALS`, best first; cells of the shown shot ``active`` in ``dropped``
            ("Not a corner") left out.
        shot_of : list of int
            The shot of each proposal.
        reclick_of : dict
            Cell -> pick id of the pair each re-click proposal of the shown shot replaces.
        """
        from calib_core.guide.propose import Proposals
        from calib_core.shots import Shot, propose_shots

        shots = [Shot.from_pairs(pairs, self.depths[k], self.camera, name=f"shot {k}")
                 for k, pairs in enumerate(pairs_by_shot)]
        gone = set(map(tuple, dropped))
        ranked, _ = propose_shots(shots, self.camera, N_PROPOSALS + len(gone), T_initial=T0,
                                  shot_options={k: self._options(k, screen) for k in range(len(shots))})
        kept = [sp for sp in ranked if not (sp.shot == active and tuple(sp.proposal.laser_rc) in gone)][:N_PROPOSALS]
        props = Proposals([sp.proposal for sp in kept], None if kept else "no cell of any shot qualifies")
        reclick_of = {tuple(sp.proposal.laser_rc): ids_by_shot[active][sp.proposal.replaces]
                      for sp in kept if sp.shot == active and sp.proposal.replaces is not None}
        return props, [sp.shot for sp in kept], reclick_of
