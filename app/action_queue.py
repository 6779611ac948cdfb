"""The ordered action worker: viser callbacks only queue their work, one thread applies it in arrival order and
turns a CalibError into a notification for the tab that caused it (the app keeps running)."""

from __future__ import annotations

import time
import traceback
from types import SimpleNamespace
from typing import Any, Callable

import viser

from calib_core.errors import CalibError

from .ui_common import _Action


class ActionQueue:
    """Part of :class:`app.server.CalibrationApp` (a mixin: it uses the app's attributes).

    ``last_action_timing`` is ``(wall seconds, thread CPU seconds)`` of the last applied action (None before).
    """

    last_action_timing: tuple[float, float] | None = None

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
            self._actions.put((fn, _Action(event, value)))

        return enqueue

    def post(self, fn: Callable[[], Any], client: Any = None, wait: bool = False) -> None:
        """Run ``fn()`` on the action worker, after the actions queued before it.

        A CalibError it raises becomes a notification for ``client`` (every tab
        if None).  With ``wait``, return once the queue is drained.
        """
        self._actions.put((lambda action: fn(), _Action(SimpleNamespace(client=client), None)))
        if wait:
            self._actions.join()

    def _run_actions(self) -> None:
        """The action worker: applies queued user actions one by one; errors become notifications."""
        while True:
            item = self._actions.get()
            try:
                if item is None:
                    return
                fn, action = item
                t0, c0 = time.perf_counter(), time.thread_time()
                try:
                    fn(action)
                except CalibError as exc:
                    self.notify(action.client, "Not accepted", str(exc))
                except Exception as exc:  # never let a click kill anything
                    traceback.print_exc()
                    self.notify(action.client, "Internal error", f"{type(exc).__name__}: {exc}")
            finally:
                if item is not None:
                    # The worker's own share: wall time, and CPU time of this thread (immune to other processes).
                    self.last_action_timing = (time.perf_counter() - t0, time.thread_time() - c0)
                self._actions.task_done()

    def _on_save_error(self, message: str) -> None:
        # On the compactor's thread; the journal holds every change, the compaction is retried.
        if hasattr(self, "server") and not getattr(self, "_stopped", True):
            self.notify(None, "Session file not updated (retrying; no change lost)", message)

    def notify(self, client: Any, title: str, body: str, color: str = "red") -> None:
        """Show a notification in one tab (``client``) or, with None, in every tab (the text is shown as is)."""
        body = " ".join(str(body).split())
        targets = [client] if client is not None else list(self.server.get_clients().values())
        for c in targets:
            try:
                c.add_notification(title, body, color=color, auto_close_seconds=8.0, with_close_button=True)
            except Exception:
                pass

    # The old private names, still used by app/testing.py.
