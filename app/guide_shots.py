"""Guided picking across the shots of a session (issue 21), and small helpers of the guided flow: a mixin of
:class:`app.guide_panel.GuidePanel` (which stays within the file-size limit).

With several shots the proposals are ranked across all of them (:class:`app.guide_support.ShotGuide`, the
ranking of ``ba-calib propose --shot``) and guided picking starts once all shots together have 4 pairs (or an
initial extrinsic is imported), whatever the shown shot has.  When the proposal to frame next is in another
shot, the panel asks the app to show that shot (``show_shot``, set by :class:`app.shots_panel.ShotsPanel`);
the page restarts on it and the new panel resumes the guided session (:meth:`GuideShotsMixin.resume`),
framing the best proposal of the shot it now shows.
"""

from __future__ import annotations

from typing import Any, Callable

from calib_core.errors import CalibError

from .guide_support import ShotGuide
from .ui_common import md_escape


class GuideShotsMixin:
    """What :class:`app.guide_panel.GuidePanel` does differently with several shots (``shots`` given)."""

    def _init_shots(self, shots: Callable[[], Any] | None) -> None:
        #: ``shots()`` -> ``(depths, images, active shot)`` of every shot; None: a one-shot session.
        self._shots = shots
        #: ``show_shot(k)`` asks the app to show shot ``k`` (set by the Shots folder); None: not offered.
        self.show_shot: Callable[[int], None] | None = None
        self._prop_shots: list[int] | None = None  # the shot of each proposal (several shots)
        self._shot_guide: ShotGuide | None = None  # only touched on the worker thread
        self._resumed = False  # the page was switched to this shot by a guided session: frame its best
        self._spent = False  # every proposal left was skipped: none shown until Next pair or new proposals

    #: The Guided text once every proposal left was skipped (like the note when no new corner passes).
    SPENT_NOTE = ("No other proposal is left: the skipped ones may come back after new pairs. Go on by hand, or "
                  "press **Next pair** to see them again.")

    @property
    def active_shot(self) -> int:
        return 0 if self._shots is None else int(self._shots()[2])

    def joint_pairs(self, state: Any) -> tuple:
        """Every shot's complete picks as ``(shot, id, Pair)``, in shot order then creation order (the live
        joint solve's row order)."""
        picks = [p for p in state.all_picks if p.complete]
        return tuple((p.shot, p.id, p.to_pair()) for p in sorted(picks, key=lambda p: p.shot))

    def _pairs_now(self, state: Any) -> tuple:
        """The pairs guided picking follows: the shown shot's (one shot) or every shot's."""
        return tuple(state.pairs()) if self._shots is None else self.joint_pairs(state)

    def _n_complete(self) -> int:
        return len(self._pairs_now(self.state))

    def _quality_pairs(self) -> tuple:
        """The pairs as the live solve lists them (its verdict is about those)."""
        if self._shots is None:
            return tuple(self.state.pairs())
        return tuple(pair for _, _, pair in self.joint_pairs(self.state))

    def _shots_job(self, payload: tuple) -> tuple:
        """On the worker: proposals across every shot (no auto-accept, no guide-side verdict)."""
        key, joint, T0, skipped, dropped, auto = payload
        depths, images, active = self._shots()
        if self._shot_guide is None:
            self._shot_guide = ShotGuide(depths, images, self.camera)
        n = len(depths)
        pairs_by_shot = [[pair for s, _, pair in joint if s == k] for k in range(n)]
        ids_by_shot = [[i for s, i, _ in joint if s == k] for k in range(n)]
        props, shot_of, reclick_of = self._shot_guide.rank(pairs_by_shot, ids_by_shot, T0, dropped, active,
                                                           self.screen)
        props.shots = shot_of
        return key, props, [], reclick_of, None

    def _first_index(self, props: Any, cells: list, waiting: Any) -> int:
        """Which proposal to show first: the one a guided half pick waits for, after a switch the best of the
        shown shot, else the best."""
        shots = getattr(props, "shots", None)
        self._prop_shots = shots
        if shots is None:
            return cells.index(waiting) if waiting in cells else 0
        here = [i for i, k in enumerate(shots) if k == self.active_shot]
        hit = [i for i in here if cells[i] == waiting]
        if hit:
            return hit[0]
        if self._resumed and here:
            self._resumed = False
            return here[0]
        return 0

    def shot_of(self, p: Any) -> int:
        """The shot of proposal ``p`` (the shown shot with one shot)."""
        shots = self._prop_shots
        if shots is not None:
            for q, k in zip(self._proposals, shots):
                if q is p:
                    return k
        return self.active_shot

    def _delete_proposal(self, index: int) -> None:
        del self._proposals[index]
        if self._prop_shots is not None:
            del self._prop_shots[index]

    def _elsewhere(self, p: Any) -> bool:
        """The proposal to frame is in another shot: ask for that shot (the panel there resumes guiding)."""
        if p is None or self.shot_of(p) == self.active_shot:
            return False
        self._drop_unfinished()
        if self.show_shot is not None and self._guiding:
            self.show_shot(self.shot_of(p))
        self._refresh()
        return True

    def _refuse_auto_across_shots(self, on: bool) -> None:
        """Auto-accept gates a proposal on the shown photo's corners; across shots it is not offered (yet)."""
        if on and self._shots is not None:
            self._cb_auto.value = False
            raise CalibError("auto-accept is not offered in a session of several shots: use Next pair")

    def resume(self) -> None:
        """Go on with a guided session started on another shot's page: frame this shot's best proposal."""
        self._guiding = self._want_next = self._resumed = True
        self.update()

    def shot_lines(self, p: Any) -> list[str]:
        """The panel's lines about the shown proposal's shot (several shots), markdown."""
        if self._shots is None:
            return []
        k, shown = self.shot_of(p), self.active_shot
        if k == shown:
            return [f"In shot {k} (shown); proposals are ranked across all shots."]
        if self.show_shot is not None and self._guiding:
            return [f"**Next proposal is in shot {k}**: showing shot {k} (the page reconnects)."]
        return [f"**Next proposal is in shot {k}**: show shot {k} (Shots folder) to pick it."]

    # ---------------------------------------------------------------- the guided flow's small steps
    def _bar_line(self, active: bool, unreliable: str | None, busy: bool, props: Any, index: int) -> str:
        """Guided picking's status in one short line for the pair bar (markdown, fixed words and numbers only); the
        full text stays in the Guided picking folder (run 6: the bar grew to about 300 px with it)."""
        if not active or unreliable is not None or self._error is not None:
            return ("not offered while the calibration is UNRELIABLE" if active and unreliable is not None
                    else f"proposals failed: {md_escape(self._error)}" if active else "see Guided picking")
        if busy:
            return "computing proposals…"
        if not props:  # the reason itself (run 7: "no proposal; see Guided picking" sent the person scrolling)
            reason = md_escape(self._reason or "none left")
            return reason[0].lower() + reason[1:] if reason.startswith("No new") else f"no proposal: {reason}"
        if self._spent:
            return "no other proposal left; go on by hand"
        p, rid, half = props[index], self._reclick_id(props[index]), self.state.pending()
        head = (f"Skipped the {self._moved_on}; " if self._moved_on else "") + f"proposal {index + 1} of {len(props)}"
        if self.shot_of(p) != self.active_shot:
            return f"{head} is in shot {self.shot_of(p)}"
        if self._reclick is not None and rid == self._reclick == self.state.selected:
            todo = f"re-click pair {rid} (selected)"
        elif half is not None and half.source == "guided" and half.laser_rc == tuple(p.laser_rc):
            todo = f"click pair {half.id}'s corner in the camera loupe"
        elif self._refine is not None:
            todo = f"refine pair {self._refine} in the camera loupe, or **Next pair**"
        else:
            todo = f"**Next pair** re-clicks pair {rid}" if rid is not None else "press **Next pair**"
        return f"{head} — {todo}"

    def _skip_new_cell(self, p: Any) -> None:
        """Skip the shown new-cell proposal ``p`` (under the panel's lock): the next one is shown, unless it was
        skipped too -- then nothing is (run 6: "Skipped the marking. Proposal 1 of 1" showed the same cell)."""
        self._skipped.append(tuple(p.laser_rc))
        self._index = (self._index + 1) % len(self._proposals)
        self._spent = tuple(self._proposals[self._index].laser_rc) in set(map(tuple, self._skipped))

    def _decline_while_busy(self, label: str) -> None:
        """Skip or Not a corner pressed while new proposals are computed (under the panel's lock): the shown
        proposal is declined all the same, and the ranking in flight, which does not know it, is redone (run 8,
        PJLab: such a Skip was lost and the re-click came back: pairs 2, 1, 3, 1, each a Skip).  Returns None
        (no proposal to move on from)."""
        shown = self.current
        if shown is None or label not in ("Skip", "Not a corner"):
            return None
        declined = self._skipped if label == "Skip" and shown.replaces is None else self._dropped
        declined.append(tuple(shown.laser_rc))
        self._submitted = None
        return None

    def _guided_half(self):
        """The pending pick if it is a guided half (laser end only), else None."""
        p = self.state.pending()
        return p if p is not None and p.source == "guided" and p.pixel is None else None

    def _start_unless_reclick_after(self, label: str, declined: Any) -> None:
        """Start the shown proposal, except a re-click right after the re-click ``declined`` was skipped or refused
        (``label``): its pair is not selected behind the person's back (run 4: a plain click then moved it);
        **Next pair** selects it."""
        if label in ("Skip", "Not a corner") and getattr(declined, "replaces", None) is not None \
                and self._reclick_id(self.current) is not None:
            self._end_reclick()
            if self.shot_of(self.current) == self.active_shot:  # runs 12 and 13: they stayed on the skipped one
                self._frame(self.current)
            self._refresh()
            return
        self._start_current()

    def _end_reclick(self) -> None:
        if self._reclick is not None:
            self._reclick = None
            self.state.select(None)

    def _drop_unfinished(self) -> None:
        """End a re-click, delete the guided pair still waiting for its camera click and take the proposal's
        ellipse off the camera loupe."""
        self._end_reclick()
        half = self._guided_half()
        if half is not None:
            self.state.delete(half.id)
        loupes = self._loupes()
        if loupes is not None and loupes.camera_crop.cov_px2 is not None:
            loupes.frame_camera(*loupes.camera_crop.center)
        self._refresh()

    def _reclick_id(self, p: Any) -> int | None:
        """The pick id of the pair proposal ``p`` re-clicks (None: a new cell, or in another shot)."""
        if p is None or p.replaces is None or self.shot_of(p) != self.active_shot:
            return None
        return self._reclick_of.get(tuple(p.laser_rc))

    def _what(self, p: Any) -> str:
        """What proposal ``p`` is, in words (its kind, or "re-click of pair N")."""
        return p.kind if p.replaces is None else f"re-click of pair {self._reclick_id(p)}"

    def _started(self, p: Any) -> bool:
        """Is proposal ``p`` started: its pair selected for the re-click, or a guided half pick at its cell?"""
        rid = self._reclick_id(p)
        if rid is not None:
            return self._reclick == rid and self.state.selected == rid
        half = self._guided_half()
        return half is not None and half.laser_rc == tuple(p.laser_rc)

    def _declined_by_deselect(self, state: Any) -> None:
        """A re-click's selection ended without a click that moved either end (Cancel pair, Deselect, another pair
        selected, the pair undone): that re-click is declined for good, like Skip (run 5: Cancel pair then Next
        pair offered the same re-click again).  Called under the panel's lock after every change."""
        rid = self._reclick
        if rid is None or state.selected == rid:
            return
        pick = next((q for q in state.picks if q.id == rid), None)
        if pick is not None and pick.pixel != self._reclick_from[0]:
            return  # the re-click's own click: :meth:`_after_click` follows
        self._reclick = None
        index = next((i for i, q in enumerate(self._proposals) if self._reclick_id(q) == rid), None)
        if index is not None:
            self._dropped.append(tuple(self._proposals[index].laser_rc))
            self._delete_proposal(index)
            self._index = self._index - 1 if index < self._index else self._index
            self._index = 0 if self._index >= len(self._proposals) else self._index
        if pick is not None and pick.laser_rc != self._reclick_from[1]:
            # Run 8: a click in the render loupe moved the laser end: the re-click was made there, not skipped
            # (and, like a made re-click, not offered again at its new cell).
            self._dropped.append(tuple(pick.laser_rc))
            self._hands_off, self._moved_on, self._submitted = True, None, None  # resubmit: the move was ranked first
            return
        self._moved_on = f"re-click of pair {rid}"

    def _drop_current(self, p: Any) -> None:
        with self._lock:  # the shown proposal ``p``, for good
            self._dropped.append(tuple(p.laser_rc))
            self._delete_proposal(self._index)
            self._index = 0 if self._index >= len(self._proposals) else self._index

    def _unreliable(self) -> str | None:
        """The first reason why the calibration of the current pairs is unreliable (the live solve's verdict,
        else the guide's own solve of the same pairs), or None (reliable, or not known yet)."""
        pairs = self._quality_pairs()
        for known in (self._solve_quality(), self._job_quality):
            if known is not None and tuple(known[0]) == pairs:
                return (str(known[2][0]) if known[2] else "the solve's verdict") if known[1] == "unreliable" else None
        return None
