"""The live-solve coordinator: every change of the pairs is solved in a worker thread
(:class:`app.live_solver.LiveSolver`) and shown when done, in one redraw that also draws the change itself.  The
overlays and panels subscribe to what the solve shows (:meth:`LiveSolveCoordinator.subscribe`) and to each
finished solve (:meth:`~LiveSolveCoordinator.subscribe_solved`), as they subscribe to the pairs with
``state.subscribe``.  Then the 3-D pane's camera frame and cloud colours (published, :meth:`subscribe_cloud`, to
:class:`app.cloud_pane.CloudPane`; at once only while a tab shows 3-D), the camera-facing column window and the scan projected for the loupes' predictions are
computed in their own thread.  The maths is :func:`calib_core.solve.calibrate` and :mod:`calib_core.overlays`."""

from __future__ import annotations

import threading
import time
import traceback
from typing import Any, Callable

import numpy as np

from calib_core.errors import CalibError
from calib_core.overlays import colorize_points
from calib_core.pairs import resolve_pairs
from calib_core.solve import calibrate
from calib_core.transforms import transform_points

from .live_solver import LiveSolver
from .shot_solve import checked_bundle, joint_bundle, pairs_in_3d
from .state import AnnotationState
from .ui_common import MIN_PAIRS, SolveBundle, SolveShown, CloudUpdate

#: How long a change of the pairs waits for its solve's redraw (which draws the change too) before the changing
#: thread redraws it itself: one redraw per click when the solve is quick, the moved marker never later than this.
SHOW_WAIT_S = 0.03
#: Several shots: show the joint fit first and check the shots against each other in the solver's next job
#: (False: both in one job, as before issue 21's speed target; ``bench.app_click --shots-in-one-job``).
CHECKS_FOLLOW = True


class _CheckShots:
    """The solver's second job of a change in a session of several shots: the shown joint fit's shot checks."""

    def __init__(self, bundle: SolveBundle) -> None:
        self.bundle = bundle


class LiveSolveCoordinator:
    """The live solve of one :class:`app.server.CalibrationApp` (``app.live``): it owns the solve shown and its
    two worker threads (:meth:`start`, :meth:`stop`)."""

    def __init__(self, app: Any) -> None:
        self.app = app
        self._bundle: SolveBundle | None = None
        self.solve_error: str | None = None  # the last solve's failure (the last good bundle stays shown)
        self.solving = False
        self._submitted: tuple | None = None
        self._job = 0
        self._result_floor = 0
        self._change_time: tuple[int, float] = (0, 0.0)  # (job, perf_counter) of the last change of the pairs
        self._last_update: tuple[float, float] | None = None  # (click-to-update seconds, perf_counter published)
        self._last_checks: float | None = None  # seconds from the change to its shots' checks shown
        self._shot_cache: dict = {}  # each shot's resolved pairs (app.shot_solve.make_shots)
        #: CPU seconds of the solver thread's last jobs, by kind ("solve", "joint fit", "shot checks"): benchmarks.
        self.solve_cpu: dict[str, float] = {}
        self._stopped = False
        self._shown = threading.Condition()  # notified when a solve has been shown (redrawn)
        self._shown_job = 0  # the newest job whose solve was shown
        self._solver: LiveSolver | None = None
        self._cloud_worker: LiveSolver | None = None
        self._shown_listeners: list[Callable[[SolveShown], None]] = []
        self._solved_listeners: list[Callable[[SolveShown], None]] = []
        self._facing_listeners: list[Callable[[], None]] = []
        self._cloud_listeners: list[Callable[[str, Any], None]] = []
        self._cloud_shown = False  # some tab shows the 3-D pane (show_3d)
        self._cloud_colored_by: SolveBundle | None = None  # the solve whose cloud colours were last published

    def subscribe(self, listener: Callable[[SolveShown], None]) -> None:
        """Call ``listener(shown)`` whenever what the solve shows is redrawn: a solve finished or failed, a solve
        started, the pairs changed, the pose predictions use changed.  Called under the UI lock, inside the
        redraw's one message batch, in the order subscribed; the markers and overlays first, then the panels."""
        self._shown_listeners.append(listener)

    def subscribe_solved(self, listener: Callable[[SolveShown], None]) -> None:
        """Call ``listener(shown)`` after each finished solve (or failed one) has been shown, outside the UI lock:
        for follow-up work that must not hold up the redraw (the camera-view render)."""
        self._solved_listeners.append(listener)

    def subscribe_facing(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` when the camera-facing column window (``app.pose_source.facing``) was recomputed while the BA
        panes follow it (``ba_window_mode == "camera"``); on the cloud worker's thread: post UI work."""
        self._facing_listeners.append(listener)

    def subscribe_cloud(self, listener: Callable[[str, Any], None]) -> None:
        """Call ``listener(what, value)`` with what the 3-D pane shows, under the UI lock: ``("camera", T)``, the
        solved ``T_camera_lidar`` (None: no solve, grey cloud), ``("pairs", (points_lidar, labels, shots))``,
        ``("colors", (bundle, colors))``, the cloud's colours ``(K, 3)`` uint8 from solve ``bundle``
        (:meth:`app.cloud_pane.CloudPane.show`)."""
        self._cloud_listeners.append(listener)

    def _publish_cloud(self, what: str, value: Any) -> None:
        if what == "colors":
            self._cloud_colored_by = value[0]
        elif what == "camera" and value is None:
            self._cloud_colored_by = None  # the pane greys its cloud
        for listener in list(self._cloud_listeners):
            listener(what, value)

    def show_3d(self, shown: bool) -> None:
        """Some tab shows the 3-D pane (``shown``) or none does; one that does gets the current solve's colours."""
        self._cloud_shown = bool(shown)
        self.request_cloud()

    def shown(self) -> SolveShown:
        """What the solve shows now."""
        n_complete = sum(1 for p in self.app.state.all_picks if p.complete)
        return SolveShown(self._bundle, self.solve_error, self.solving, n_complete)

    @staticmethod
    def _publish(listeners: list, shown: SolveShown) -> None:
        """Call every listener, even after one failed (the panels follow the state even if a drawing failed);
        then raise the first failure."""
        failure = None
        for listener in list(listeners):
            try:
                listener(shown)
            except Exception as exc:
                failure = failure or exc
        if failure is not None:
            raise failure

    def start(self) -> None:
        """Start the solver thread and, after each solve shown, the cloud colours' and facing window's thread."""
        self._solver = LiveSolver(self._solve_job, self._on_solved)
        self._cloud_worker = LiveSolver(self._cloud_job, self._on_cloud_done, name="ba-calib-cloud")

    def stop(self) -> None:
        """Stop both worker threads; results that arrive later are dropped."""
        self._stopped = True
        with self._shown:
            self._shown.notify_all()
        for worker in (self._solver, self._cloud_worker):
            if worker is not None:
                worker.stop()

    @property
    def bundle(self) -> SolveBundle | None:
        """The last good solve with what was solved (pick ids, pairs), or None."""
        return self._bundle

    def on_state_change(self, state: AnnotationState) -> None:
        """Submit the complete pairs for solving when they changed, then redraw (subscribed to the state).

        When a solve was submitted to an idle solver, the redraw that shows it (markers, overlays, panels from the
        state as it is then) also shows this change: it is awaited for up to :data:`SHOW_WAIT_S`, and only if it
        is later than that is the change drawn here first.  A click thus costs one redraw, not two.
        """
        app = self.app
        picks = [p for p in state.all_picks if p.complete]  # every shot's: one joint solve
        key = tuple((p.id, p.shot, p.to_pair()) for p in picks)
        solve_job = None
        with app.ui_lock:
            if key != self._submitted:
                self._submitted = key
                self._job += 1
                if len(picks) >= MIN_PAIRS:
                    self.solving = True
                    # Worth awaiting only if the solver is free: else it first finishes (and shows) an older job.
                    solver_free = self._solver.idle
                    self._solver.submit(self._job, ([p.id for p in picks], [p.to_pair() for p in picks],
                                                    [p.shot for p in picks]))
                    # From the start of the change, its disk write included.
                    self._change_time = (self._job, state.last_change_started or time.perf_counter())
                    solve_job = self._job if solver_free else None
                else:
                    # Too few pairs: results of older jobs no longer describe these pairs.
                    self._result_floor = self._job
                    self._bundle = None
                    self.solve_error = None
                    self.solving = False
                    self._publish_cloud("camera", None)
        if (solve_job is None and not self.solving and self._cloud_worker is not None
                and not self._stopped):  # the 3-D pane's pair marks (a solve's cloud job draws them too)
            self._cloud_worker.submit(0, self._bundle)
        # Not while this thread holds the UI lock: the solver could not redraw before the wait ends.
        if solve_job is not None and not app.ui_lock.held_here() and self._wait_shown(solve_job, SHOW_WAIT_S):
            return
        self.redraw()

    def redraw(self) -> None:
        """Redraw markers, overlays and the panels from the state as it is now (every :meth:`subscribe` listener)."""
        app = self.app
        with app.ui_lock, app.server.atomic():
            self._publish(self._shown_listeners, self.shown())

    def _wait_shown(self, job: int, timeout: float) -> bool:
        """Wait until the solve of ``job`` (or a newer one) has been shown; False on timeout."""
        with self._shown:
            return self._shown.wait_for(lambda: self._shown_job >= job or self._stopped, timeout) and not self._stopped

    def _solve_job(self, payload: Any) -> SolveBundle:
        """The solve and what the error display and the 2-D overlays need (the cloud comes later)."""
        c0 = time.thread_time()
        kind = ("shot checks" if isinstance(payload, _CheckShots) else
                "joint fit" if len(self.app.shot_scenes) > 1 and CHECKS_FOLLOW else "solve")
        try:
            return self._solve_payload(payload)
        finally:
            self.solve_cpu[kind] = time.thread_time() - c0

    def _solve_payload(self, payload: Any) -> SolveBundle:
        app = self.app
        if isinstance(payload, _CheckShots):  # the shown joint fit's leave-one-shot-out and disagreement test
            return checked_bundle(app, payload.bundle)
        ids, pairs, shot_of = payload
        if len(app.shot_scenes) > 1:
            # Several shots: the joint fit is shown first; its shots' checks are this thread's next job
            # (_on_solved), so a click costs the joint fit, and the status is never "ok" before the checks ran.
            if not CHECKS_FOLLOW:
                return joint_bundle(app, ids, pairs, shot_of)
            return joint_bundle(app, ids, pairs, shot_of, checks=False, cache=self._shot_cache)
        t0 = time.perf_counter()
        points, _, pixels = resolve_pairs(pairs, app.depth, app.camera)
        # The pairs carry their pick ids, so the solve names outliers and warnings by the ids the page shows.
        result = calibrate(pairs, app.depth, app.camera)
        T = result.T_camera_lidar
        edges = app.scene_data.edge_points_lidar
        return SolveBundle(
            pick_ids=ids, pairs=pairs, result=result, pixels=pixels,
            points_camera=transform_points(T, points),
            edges_camera=transform_points(T, edges) if len(edges) else np.empty((0, 3)),
            seconds=time.perf_counter() - t0,
        )

    def _on_solved(self, job: int, bundle: SolveBundle | None, error: BaseException | None) -> None:
        """Show a finished solve: errors, table, 2-D overlays first; then queue the cloud work."""
        app = self.app
        with app.ui_lock:
            if job < self._result_floor or self._stopped:
                return
            self.solving = job < self._job
            # One message batch: viser's event loop is woken once, when all of it is queued.
            with app.server.atomic():
                if error is not None:
                    msg = str(error) if isinstance(error, CalibError) else f"{type(error).__name__}: {error}"
                    self.solve_error = " ".join(msg.split())
                    if not isinstance(error, CalibError):
                        traceback.print_exception(error)
                else:
                    self._bundle = bundle
                    self.solve_error = None
                    if bundle.shots is not None and not bundle.shots.solved.checked and job == self._job:
                        self._solver.submit(job, _CheckShots(bundle))  # under the UI lock: no newer change lost
                    if self._cloud_shown:  # a tab shows 3-D; else the hidden pane gets it with its colours (cloud job)
                        self._publish_cloud("camera", bundle.result.T_camera_lidar)
                self.redraw()
            change_job, change_time = self._change_time
            if job == change_job:  # after the batch was handed to viser
                now = time.perf_counter()
                if bundle is not None and bundle.shots is not None and bundle.shots.solved.checked:
                    self._last_checks = now - change_time
                    if len(bundle.shots.shots) < 2 or self._last_update is None or self._last_update[1] < change_time:
                        self._last_update = (now - change_time, now)  # no unchecked fit was shown first
                else:
                    self._last_update = (now - change_time, now)
        with self._shown:
            self._shown_job = max(self._shown_job, job)
            self._shown.notify_all()
        self.request_cloud()
        self._publish(self._solved_listeners, self.shown())  # e.g. the camera-view render follows the solve shown

    def request_cloud(self) -> None:
        """Queue what the current solve still owes: cloud colours if a tab shows 3-D, the facing window in camera
        mode, the scan projected for the loupes' camera-to-cell predictions."""
        bundle = self._bundle
        if bundle is None or self._stopped:
            return
        self._cloud_worker.submit(0, bundle)

    def _cloud_colors(self, T_camera_lidar: np.ndarray) -> np.ndarray:
        """Display-cloud colours ``(K, 3)`` uint8 from the camera image; grey where the camera does not see."""
        app = self.app
        colors, has_color = colorize_points(app.cloud_points_lidar, app.image, app.camera, T_camera_lidar,
                                            occlusion=True)
        # Pure black is the unlit border of a fisheye image, not scene colour: show it grey too.
        has_color &= colors.any(axis=1)
        return np.where(has_color[:, None], colors, np.uint8(110)).astype(np.uint8)

    def _cloud_job(self, bundle: SolveBundle | None) -> CloudUpdate | None:
        # Decided when the job runs: a tab may have left or entered the 3-D view meanwhile.
        app = self.app
        pairs = pairs_in_3d(app)
        with app.ui_lock:
            self._publish_cloud("pairs", pairs)
        if bundle is None:  # only the pair marks (no solve shown)
            return None
        t0 = time.perf_counter()
        T = bundle.result.T_camera_lidar
        colors = self._cloud_colors(T) if self._cloud_shown and self._cloud_colored_by is not bundle else None
        facing_done = app.state.view.ba_window_mode == "camera" and app.pose_source.facing_due(bundle)
        view_T = app.pose_source.view_pose()[0]  # the rough pose while the solve is unreliable
        facing = app.pose_source.facing_window(view_T) if facing_done else None
        app.pose_source.projection(view_T)  # the loupes' camera-to-cell predictions, ready before the next click
        return CloudUpdate(bundle, colors, facing_done, facing, time.perf_counter() - t0)

    def _on_cloud_done(self, job: int, update: CloudUpdate | None, error: BaseException | None) -> None:
        if error is not None:
            traceback.print_exception(error)
            return
        app = self.app
        if update is None:
            return
        with app.ui_lock:
            if self._stopped or update.bundle is not self._bundle:
                return  # superseded: the newer solve queued its own
            with app.server.atomic():  # the 3-D pane in one batch: the solved camera's frame and the colours
                self._publish_cloud("camera", update.bundle.result.T_camera_lidar)
                if update.colors is not None:
                    self._publish_cloud("colors", (update.bundle, update.colors))
            if update.facing_done:
                app.pose_source.set_facing(update.bundle, update.facing)
        if update.facing_done and app.state.view.ba_window_mode == "camera" and not self._stopped:
            for listener in list(self._facing_listeners):
                listener()

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until queued user actions are applied and the live solver and the cloud worker are idle."""
        deadline = time.monotonic() + timeout
        actions = self.app.actions
        while True:
            while actions.busy:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.01)
            for worker in (self._solver, self._cloud_worker):
                if not worker.wait_idle(max(0.0, deadline - time.monotonic())):
                    return False
            # A finished solve queues cloud work, finished cloud work may queue a view update.
            if not actions.busy and self._solver.idle and self._cloud_worker.idle:
                return True

    def last_click_to_update(self) -> float | None:
        """Seconds from the last change of the pairs to its solve shown: error display, table, 2-D overlays.

        Measured from the start of the change in the state (before its
        journal write) to the moment the result was handed to viser (sending it to
        the browsers is not counted, nor is the 3-D cloud recolouring that
        follows).  None before the first solve of a change.
        """
        last = self._last_update
        return None if last is None else last[0]

    def last_checks_shown(self) -> float | None:
        """Seconds from the last change of the pairs to its shots' checks shown (several shots), else None."""
        return self._last_checks

    @property
    def last_update_time(self) -> float | None:
        """``time.perf_counter()`` when the newest change's solve was shown (see :meth:`last_click_to_update`)."""
        last = self._last_update
        return None if last is None else last[1]
