"""The ordered action worker: viser callbacks only queue their work, one thread applies it in arrival order and
turns a CalibError into a notification for the tab that caused it (the app keeps running).  And the redraw lock
(:class:`UiLock`) that the worker, the live solve's threads and the render worker hold while they redraw."""

from __future__ import annotations

import queue
import threading
import time
import traceback
from types import SimpleNamespace
from typing import Any, Callable

import viser

from calib_core.errors import CalibError

from .ui_common import _Action


def notify_tabs(server: Any, client: Any, title: str, body: str, color: str = "red") -> None:
    """Show a notification in one tab (``client``) or, with None, in every tab of ``server`` (the text as is)."""
    body = " ".join(str(body).split())
    targets = [client] if client is not None else list(server.get_clients().values())
    for c in targets:
        try:
            c.add_notification(title, body, color=color, auto_close_seconds=8.0, with_close_button=True)
        except Exception:
            pass


class UiLock:
    """A re-entrant lock that knows whether the calling thread holds it.

    The redraw lock of the app: a thread that holds it must not wait for another thread's redraw
    (:meth:`app.live_coordinator.LiveSolveCoordinator.on_change`), so it asks :meth:`held_here` first.
    """

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._owner: int | None = None  # written only by the holder, so a reader sees its own id or another
        self._depth = 0

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        got = self._lock.acquire(blocking, timeout)
        if got:
            self._owner = threading.get_ident()
            self._depth += 1
        return got

    def release(self) -> None:
        if self._owner != threading.get_ident():
            raise RuntimeError("UiLock released by a thread that does not hold it")
        self._depth -= 1
        if self._depth == 0:
            self._owner = None
        self._lock.release()

    def held_here(self) -> bool:
        """Does the calling thread hold the lock?"""
        return self._owner == threading.get_ident()

    def __enter__(self) -> "UiLock":
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


class ActionQueue:
    """The app's one ordered worker for user actions (its thread starts here; :meth:`stop` ends it).

    Parameters
    ----------
    notify : callable
        ``notify(client, title, body)``: how a refused or failed action is told to its tab.

    Attributes
    ----------
    last_action_timing : tuple of float or None
        ``(wall seconds, thread CPU seconds)`` of the last applied action (None before).
    """

    def __init__(self, notify: Callable[[Any, str, str], None]) -> None:
        self._notify = notify
        self._queue: queue.Queue = queue.Queue()
        self.last_action_timing: tuple[float, float] | None = None
        self._thread = threading.Thread(target=self._run, name="ba-calib-actions", daemon=True)
        self._thread.start()

    def guard(self, fn: Callable) -> Callable:
        """Wrap a callback: queue it for the ordered action worker.

        Viser runs plain callbacks on a thread pool, where two quick clicks
        can be handled out of order (a BA, camera, BA sequence would then pair
        the wrong ends).  This async wrapper runs on the event loop, in arrival
        order, and only snapshots the widget value and queues the work.
        """

        async def enqueue(event: Any) -> None:
            target = getattr(event, "target", None)
            value = getattr(target, "value", None) if not isinstance(target, viser.SceneNodeHandle) else None
            self._queue.put((fn, _Action(event, value)))

        return enqueue

    def post(self, fn: Callable[[], Any], client: Any = None, wait: bool = False) -> None:
        """Run ``fn()`` on the action worker, after the actions queued before it.

        A CalibError it raises becomes a notification for ``client`` (every tab
        if None).  With ``wait``, return once the queue is drained.
        """
        self._queue.put((lambda action: fn(), _Action(SimpleNamespace(client=client), None)))
        if wait:
            self._queue.join()

    def join(self) -> None:
        """Return once every queued action is applied."""
        self._queue.join()

    @property
    def busy(self) -> bool:
        """True while queued actions are not all applied."""
        return bool(self._queue.unfinished_tasks)

    def stop(self, timeout: float = 5.0) -> None:
        """Apply what is queued, then end the worker thread."""
        self._queue.put(None)
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=timeout)

    def _run(self) -> None:
        """The action worker: applies queued user actions one by one; errors become notifications."""
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                fn, action = item
                t0, c0 = time.perf_counter(), time.thread_time()
                try:
                    fn(action)
                except CalibError as exc:
                    self._notify(action.client, "Not accepted", str(exc))
                except Exception as exc:  # never let a click kill anything
                    traceback.print_exc()
                    self._notify(action.client, "Internal error", f"{type(exc).__name__}: {exc}")
            finally:
                if item is not None:
                    # The worker's own share: wall time, and CPU time of this thread (immune to other processes).
                    self.last_action_timing = (time.perf_counter() - t0, time.thread_time() - c0)
                self._queue.task_done()
