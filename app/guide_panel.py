"""The Guide panel: guided picking in the app (issue 9; how it is used: docs/app.md, "Guided picking").

A :class:`calib_core.guide.session.GuidedSession`, built once per scene, ranks the laser cells worth pairing next;
the proposals are recomputed in a worker thread after every change of the pairs (never on a viser callback), and
only while someone is guided or auto-accepts.  Beyond what docs/app.md says: after a re-click the next re-click is
not started by itself (its pair is not selected behind the person's back: "Next pair" selects it); "Next pair"
while a proposal is started skips it; ending a re-click's selection (Cancel pair) declines it for good; one undo
takes back a guided click with the precision the panel gives it; the camera loupe zooms out (never in) to show a
proposal's ellipse whole and keeps that zoom until "Stop".  With several shots: :mod:`app.guide_shots`.

All maths is :mod:`calib_core.guide`; this module routes buttons and draws text.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

import numpy as np

from calib_core.errors import CalibError
from calib_core.guide import GUIDED_CLICK_SIGMA_PX, Proposal
from calib_core.guide.auto_accept import AutoGate
from calib_core.guide.evidence import ProposalScreen
from calib_core.guide.session import GuidedSession
from calib_core.pairs import Pair

from .guide_shots import GuideShotsMixin
from .guide_support import ELLIPSE_MARGIN_PX, live_quality, max_ellipse_px_for, pair_counts_line, rank_proposals
from .live_solver import LiveSolver
from .state import AnnotationState
from .ui_common import MIN_PAIRS, md_escape

BUTTONS = ("Next pair", "Skip", "Not a corner", "Stop")


class GuidePanel(GuideShotsMixin):
    """The "Guided picking" folder of one :class:`app.server.CalibrationApp` (``app.guide``) and the guided flow.

    Parameters
    ----------
    app : app.app_services.AppServices
        Used: ``state`` (the panel subscribes to it), ``depth``, ``camera``, ``image``, ``guard`` and ``post`` (the
        ordered action worker), the imported rough pose, the live solve's verdict, with several shots every shot's
        scene; ``camera_click_source`` (a guided pair clicked on the full image gets the default precision and waits
        for a refining click in the camera loupe, which makes it 0.3 px, before the next proposal is framed) and
        ``forget_last_picks`` (after a guided half pick is started, a loupe click completes it).
    loupes : callable
        ``loupes()`` -> the app's loupes (``frame_ba(key, row, col)``, ``frame_camera(u, v, cov_px2=None)``).
    on_status : callable
        ``on_status(guiding, lines, actions=...)``: the guided line of the pair bar, and the buttons it repeats.
    """

    def __init__(self, app: Any, *, loupes: Callable[[], Any], on_status: Callable) -> None:
        self._init_shots(None if len(app.shot_scenes) < 2 else lambda: (
            [sc.depth for sc in app.shot_scenes], [sc.image for sc in app.shot_scenes], app.active_shot))
        self.state, self.depth, self.camera, self.image = app.state, app.depth, app.camera, app.image
        self._solve_quality, self._on_status = (lambda: live_quality(app)), on_status  # the live verdict; pair bar
        self._job_quality: tuple | None = None  # (pairs, status, reasons) of the guide's own solve, last job
        self._reason: str | None = None  # why the last proposals are empty
        #: The screen of the proposals; its 3-sigma limit follows the camera loupe (:func:`max_ellipse_px_for`).
        self.screen = ProposalScreen(max_ellipse_px=max_ellipse_px_for(app.camera.width, app.camera.height))
        self._post, self._loupes, self._ba_key = app.post, loupes, app.ba_keys[0]
        self._initial_T = lambda: app.initial_T_camera_lidar  # the imported rough pose, or None
        self._on_start, self._click_source = app.forget_last_picks, app.camera_click_source
        self._watch: list | None = None  # [id, pixel seen] of the guided pick started last
        self._refine: int | None = None  # a guided pick clicked on the full image, not yet refined in the loupe
        self._reclick: int | None = None  # the rough pair selected for a re-click
        self._reclick_from: tuple | None = None  # (pixel, laser cell) at selection; both unchanged: declined
        self._hands_off = False  # the next start follows an accepted re-click: a re-click then waits for Next pair
        self._moved_on: str | None = None  # what the last Next pair or Cancel pair skipped, shown once
        self._reclick_of: dict[tuple[int, int], int] = {}  # cell -> pick id of the re-click proposals
        self.auto_gate = AutoGate()  #: the auto-accept gate (the strict one of calib_core.guide.auto_accept)
        self._auto_tried: set[tuple[int, int]] = set()  # cells auto-accepted once: never again (an undo sticks)
        self._lock = threading.RLock()
        self._session: GuidedSession | None = None  # only touched on the worker thread
        self._proposals, self._index = [], 0  # list of Proposal, the one shown
        self._skipped, self._dropped = [], []  # cells (row, col): new cells skipped; re-clicks and cells declined
        self._submitted: tuple | None = None  # key of the newest job
        self._job_no = 0
        self._shown_key: tuple | None = None  # key the proposals were computed for
        self._busy, self._error = False, None  # a job running; why the last one failed
        self._guiding = False  # "Next pair" pressed, not stopped: frame the next proposal after each pair
        self._want_next = False
        self._pending_posts, self._auto = 0, False
        self._auto_pairs: list[Pair] = []
        self._guided_side = 0.0  # the camera loupe's side (px) during this guided session: never shrinks
        self._callbacks: dict[str, Callable] = {}

        gui, guard = app.server.gui, app.guard
        folder = gui.add_folder("Guided picking", order=app.pairs_folder.order + 0.5)
        with folder:
            # The buttons come first: the status text below them changes height with every proposal, and
            # buttons under it would jump between a person's look and their click (by-eye trial, issue 20).
            self._buttons = {}
            for label in BUTTONS:
                button = gui.add_button(label)
                self._callbacks[label] = guard(lambda action, label=label: self._on_button(label))
                button.on_click(self._callbacks[label])
                self._buttons[label] = button
            self._cb_auto = gui.add_checkbox(
                "Auto-accept clean corners", initial_value=False,
                hint="Add proposals whose camera corner passes a strict quality gate without a click (tagged auto)")
            self._callbacks["auto"] = guard(lambda action: self._on_auto(bool(action.value)))
            self._cb_auto.on_update(self._callbacks["auto"])
            self._md = gui.add_markdown("")
        self._worker = LiveSolver(self._job, self._on_done, name="ba-calib-guide")
        app.state.subscribe(self._on_state_change)
        self._on_state_change(app.state)

    # ---------------------------------------------------------------- reading
    @property
    def current(self) -> Proposal | None:
        """The proposal shown (the one "Next pair" starts), or None."""
        with self._lock:  # none once every proposal left was skipped (run 6: a lone skipped one came back at once)
            return self._proposals[self._index] if self._index < len(self._proposals) and not self._spent else None

    @property
    def proposals(self) -> list[Proposal]:
        """The current proposals, best first."""
        with self._lock:
            return list(self._proposals)

    @property
    def text(self) -> str:
        """What the panel shows."""
        return str(self._md.content)

    def callback(self, name: str) -> Callable:
        """The viser callback of button ``name`` (:data:`BUTTONS`) or of the ``"auto"`` checkbox."""
        return self._callbacks[name]

    @property
    def idle(self) -> bool:
        """No proposal computation running or queued, and nothing posted to the action worker."""
        with self._lock:
            return self._worker.idle and not self._busy and self._pending_posts == 0

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until :attr:`idle` (False on timeout)."""
        deadline = time.monotonic() + timeout
        while not self.idle:
            if time.monotonic() > deadline:
                return False
            self._worker.wait_idle(max(0.0, min(0.05, deadline - time.monotonic())))
            time.sleep(0.005)
        return True

    def update(self) -> None:
        """Recompute the proposals if their inputs changed: call after importing an initial extrinsic
        (changes of the pairs are seen by themselves)."""
        self._on_state_change(self.state)

    def stop(self) -> None:
        self._worker.stop()

    # ---------------------------------------------------------------- state -> job
    def _active(self, n_complete: int) -> bool:
        return n_complete >= MIN_PAIRS or self._initial_T() is not None

    def _on_state_change(self, state: AnnotationState) -> None:
        """After any change of the pairs: resubmit the proposals when the complete pairs changed."""
        pairs = self._pairs_now(state)  # the shown shot's, or with several shots every shot's
        T0 = self._initial_T()
        key = (tuple(pairs), None if T0 is None else np.asarray(T0, dtype=np.float64).tobytes(), self._auto)
        with self._lock:
            self._declined_by_deselect(state)
            watch = self._watch
            pick = next((p for p in state.picks if watch is not None and p.id == watch[0]), None)
            if watch is not None and pick is None:
                self._watch = None
            elif pick is not None and pick.pixel is not None and pick.pixel != watch[1]:
                # Judged after the click's action, once the app has noted where the click landed.
                watch[1] = pick.pixel
                self._pending_posts += 1
                self._post(lambda: self._after_click(pick.id))
            # Proposals cost a core: they are computed only while someone is guided (or auto-accepts).
            wanted = self._guiding or self._auto
            if key != self._submitted and (wanted or not self._active(len(pairs))):
                self._submitted = key
                if self._active(len(pairs)):
                    self._busy = True
                    self._job_no += 1
                    self._worker.submit(self._job_no, (key, pairs, T0, list(self._skipped), list(self._dropped),
                                                       self._auto))
                else:
                    self._proposals, self._index, self._shown_key = [], 0, None
        self._refresh()

    def _after_click(self, pick_id: int) -> None:
        """A camera click set the guided pick's pixel: its precision, and whether to move on."""
        try:
            pick = next((p for p in self.state.picks if p.id == pick_id), None)
            if pick is None or pick.pixel is None:
                return
            full = self._click_source(pick_id) == "full" and self._loupes() is not None
            precision = None if full or self._click_source(pick_id) is None else GUIDED_CLICK_SIGMA_PX
            # The watched pick is a guided half (tagged "guided" at its start) or a re-clicked pair, which keeps its
            # source (a hand pair stays "clicked"); the precision joins the click's undo step (run 5).
            if pick.precision_px != precision:
                self.state.move_pixel(pick_id, *pick.pixel, precision_px=precision, same_step=True)
            self._hands_off, self._moved_on = pick_id == self._reclick, None  # run 5: after a re-click
            if pick_id == self._reclick:
                self._end_reclick()
            self._refine = pick_id if full else None
            if not full:  # done: an undo of this click must not look like a new click
                self._watch = None
            self._want_next = self._guiding and not full  # the new proposals then frame the next pair
            self._refresh()
        finally:
            with self._lock:
                self._pending_posts -= 1

    def _job(self, payload: tuple) -> tuple:
        """On the worker: sync the session with the pairs, rank, and (optionally) gate for auto-accept."""
        if self._shots is not None:
            return self._shots_job(payload)
        key, pairs, T0, skipped, dropped, auto = payload
        if self._session is None:
            self._session = GuidedSession(self.depth, self.camera, pairs, T_initial=T0, image=self.image)
        return (key,) + rank_proposals(self._session, pairs, T0, skipped, dropped, self.screen,
                                       self.auto_gate if auto else None)

    def _on_done(self, job: int, result: tuple | None, error: BaseException | None) -> None:
        with self._lock:
            if job != self._job_no:
                return  # a newer job is queued; its result follows
            if error is not None:
                self._busy = False
                self._error = " ".join(str(error).split()) if isinstance(error, CalibError) else (
                    f"{type(error).__name__}: {error}")
                self._refresh()
                return
            key, props, auto_pairs, self._reclick_of, self._job_quality = result
            self._busy = False
            self._error = None
            self._reason = props.reason or getattr(props, "note", None)  # the note: no new corner passed the screen
            # A guided pick still waiting for its click (e.g. after an undo) keeps its proposal shown.
            half = self._guided_half()
            waiting = half.laser_rc if half is not None else next(
                (rc for rc, pid in self._reclick_of.items() if pid == self._reclick), None)
            cells = [tuple(p.laser_rc) for p in props]
            index = self._first_index(props, cells, waiting)
            self._proposals, self._index, self._shown_key, self._spent = props, index, key, False
            self._auto_pairs = auto_pairs
            self._pending_posts += 1
        self._post(self._advance)

    # ---------------------------------------------------------------- on the action worker
    def _advance(self) -> None:
        """New proposals are in: add auto-accepted pairs, or start and frame the next guided pair."""
        try:
            with self._lock:
                auto_pairs, self._auto_pairs = self._auto_pairs, []
            pending = self.state.pending()
            skip = self._auto_tried | ({pending.laser_rc} if pending is not None else set())
            auto_pairs = [p for p in auto_pairs if p.laser_rc not in skip]
            if auto_pairs and self._auto:
                self._auto_tried.update(p.laser_rc for p in auto_pairs)
                self.state.import_pairs(auto_pairs)  # one undoable step; the new proposals follow
                return
            with self._lock:  # proposals of pairs that changed since (e.g. a re-click's new tag) wait for theirs
                fresh = self._shown_key == self._submitted
            if self._want_next and self._guiding and fresh:
                self._want_next = False
                if self._unreliable() is not None:  # a guided session stops framing; the panel says why
                    self._guiding = False
                    self._drop_unfinished()
                    return
                self._start_current(quiet=True)
            self._refresh()
        finally:
            with self._lock:
                self._pending_posts -= 1

    def _start_current(self, quiet: bool = False) -> None:
        """Make (or move) the guided half pick at the shown proposal -- or, for a re-click, select the rough
        pair so the next camera click moves its pixel -- and frame the loupes on it."""
        p = self.current
        self._end_reclick()
        if self._elsewhere(p):  # in another shot: that shot is shown, and its panel goes on
            return
        if p is None:
            self._refresh()
            return
        half = self._guided_half()
        rid = self._reclick_id(p)
        if rid is not None and self._hands_off:  # run 5: a pair selected by itself got moved by a plain click
            self._refresh()
            return
        if rid is not None:
            if half is not None:
                self.state.delete(half.id)  # the half pick of the proposal shown before
            elif self.state.pending() is not None:
                if quiet:
                    self._refresh()
                    return
                raise CalibError(f"pair {self.state.pending().id} is not finished; complete or undo it first")
            self.state.select(rid)
            self._reclick, half = rid, self.state.get(rid)
            self._watch, self._refine, self._reclick_from = [rid, half.pixel], None, (half.pixel, half.laser_rc)
        elif half is not None:
            if half.laser_rc != tuple(p.laser_rc):
                self.state.move_laser(half.id, *p.laser_rc)
        elif self.state.pending() is not None:
            if quiet:  # the person started a pair of their own meanwhile: leave it alone
                self._refresh()
                return
            raise CalibError(f"pair {self.state.pending().id} is not finished; complete or undo it first")
        else:
            half = self.state.get(self.state.start_pick(*p.laser_rc, source="guided",
                                                        precision_px=GUIDED_CLICK_SIGMA_PX))
        if rid is None:
            self._watch, self._refine = [half.id, None], None
        self._on_start()
        self._frame(p)
        self._refresh()

    def _frame(self, p: Any) -> None:
        """Frame both loupes on proposal ``p``: its cell, and its pixel with the 3-sigma ellipse."""
        loupes = self._loupes()
        if loupes is not None:
            loupes.frame_ba(self._ba_key, int(p.laser_rc[0]), int(p.laser_rc[1]))
            # Zoomed out (never in) so the whole 3-sigma ellipse, and a margin, shows; the side only grows
            # during a guided session, so the zoom stays steady from one proposal to the next.
            self._guided_side = max(self._guided_side, 2.0 * p.radius_3sigma_px + ELLIPSE_MARGIN_PX)
            loupes.frame_camera(float(p.pixel[0]), float(p.pixel[1]), cov_px2=np.asarray(p.pixel_cov),
                                min_side_px=self._guided_side)

    def _on_button(self, label: str) -> None:
        if label == "Stop":
            if self._guiding and self.current is not None and self.current.replaces is not None:
                self._drop_current(self.current)  # a re-click declined: not offered again
            self._guiding = self._want_next = False
            self._guided_side = 0.0
            self._drop_unfinished()
            return
        if not self._active(self._n_complete()):
            raise CalibError(f"guided picking starts after {MIN_PAIRS} pairs (or an imported initial extrinsic), once "
                             "the calibration is reliable")
        reason = self._unreliable()
        if reason is not None:
            self._guiding = self._want_next = False
            self._drop_unfinished()
            raise CalibError(f"guided picking waits for a reliable calibration: {reason}")
        self._guiding, self._hands_off, self._moved_on = True, False, None  # proposals follow every change from now
        self._spent = self._spent and label != "Next pair"  # Next pair shows a skipped proposal again
        self.update()  # an initial extrinsic imported since the last change is used from now on
        with self._lock:
            ready = not self._busy and self._shown_key == self._submitted
            p = self.current if ready else self._decline_while_busy(label)
            moving_on = label == "Next pair" and p is not None and self._started(p)  # run 5: skip it, go on
            if moving_on:
                self._moved_on = self._what(p)
            if (label in ("Skip", "Not a corner") or moving_on) and p is not None:
                if label != "Not a corner" and p.replaces is None:  # a skipped re-click goes for good (no cycling back)
                    self._skip_new_cell(p)
                else:
                    self._drop_current(p)
        if not ready:  # framed as soon as the proposals are in
            self._want_next = True
            self.update()  # a decline while busy ranks again
            self._refresh()
            return
        if self.current is None:
            self._drop_unfinished()
            return
        if moving_on:
            self._start_current()
        else:
            self._start_unless_reclick_after(label, p)

    def _on_auto(self, on: bool) -> None:
        self._refuse_auto_across_shots(on)
        self._auto = on
        self._on_state_change(self.state)  # recompute with (or without) the gate

    # ---------------------------------------------------------------- drawing
    def _refresh(self) -> None:
        active = self._active(self._n_complete())
        with self._lock:
            busy, error, props, index, reason = self._busy, self._error, self._proposals, self._index, self._reason
        unreliable = self._unreliable() if active else None
        lines, shown = ["**Guided picking**"], False  # shown: a proposal is, so the pair bar repeats its actions
        if not active:
            lines.append(f"Starts after {MIN_PAIRS} pairs or an imported initial extrinsic.")
        elif unreliable is not None:
            lines.append(f"Not offered while the calibration is UNRELIABLE: {md_escape(unreliable)}. "
                         "Fix or add pairs first.")
        elif error is not None:
            lines.append(f"Proposals failed: {md_escape(error)}")
        elif busy and (self._guiding or self._auto):
            lines.append("Computing proposals…")
        elif not (self._guiding or self._auto):
            lines.append("Press **Next pair**: the tool proposes where to click next and frames it in the loupes.")
        elif not props:
            shown = md_escape(reason or "none left")
            lines.append(f"{shown}." if shown.startswith("No new") else f"No proposal: {shown}.")
        elif not self._guiding:
            lines.append(f"{len(props)} proposals for auto-accept.")
        elif self._spent:
            lines.append(self.SPENT_NOTE)
        else:
            p, shown = props[index], True
            major = 3.0 * float(p.ellipse_sigma_px()[0])
            what = self._what(p)
            lines += [f"Skipped the {md_escape(self._moved_on)}."] if self._moved_on else []
            lines.append(f"Proposal {index + 1} of {len(props)}: cell (row {p.laser_rc[0]}, col {p.laser_rc[1]}), "
                         f"{what}, gain {p.gain:.3f}")
            lines.append(f"Predicted pixel ({p.pixel[0]:.1f}, {p.pixel[1]:.1f}), 3σ ±{major:.1f} px")
            lines += self.shot_lines(p) + ([f"{md_escape(props.note)}."] if getattr(props, "note", None) else [])
            half = self.state.pending()
            if self._reclick is not None and self._reclick_id(p) == self._reclick == self.state.selected:
                lines.append(f"Pair {self._reclick} (selected): re-click its corner in the camera loupe "
                             "(**Next pair** or **Cancel pair** skips this re-click).")
            elif half is not None and half.source == "guided" and half.laser_rc == tuple(p.laser_rc):
                lines.append(f"Pair {half.id}: click the corner in the camera loupe.")
            elif self._refine is not None:
                lines.append(f"Pair {self._refine}: refine its pixel in the camera loupe (a click on the full "
                             f"image is coarse), or press **Next pair**.")
            elif self._guiding and self._reclick_id(p) is not None:
                lines.append(f"Press **Next pair** to re-click pair {self._reclick_id(p)} (nothing is selected "
                             "until then), or **Skip**.")
            elif self._guiding:
                lines.append("Press **Next pair** to continue.")
        self._on_status(self._guiding, [self._bar_line(active, unreliable, busy, props, index)],  # Skip...Stop too:
                        actions={k: self._callbacks[k] for k in BUTTONS[1:]} if shown else None)
        lines.append(pair_counts_line(self.state.complete_picks()))
        self._md.content = "  \n".join(lines)
