"""Run the calibration in a worker thread, coalescing rapid changes.

Viser callbacks must never wait for a solve.  :meth:`LiveSolver.submit` only
stores the newest job and wakes the worker; while a solve runs, newer jobs
replace each other, so after a burst of clicks only the latest state is
solved.  Results (or errors) go to a callback on the worker thread, tagged
with the job's version so the UI can tell which state they belong to.
"""

from __future__ import annotations

import threading
import traceback
from typing import Any, Callable


class LiveSolver:
    """One background thread that solves the newest submitted job.

    Parameters
    ----------
    solve : callable
        ``solve(payload) -> result``; may raise.  Runs on the worker thread.
    on_done : callable
        ``on_done(version, result, error)``: ``error`` is None on success,
        else the exception (``result`` is then None).
    name : str
        Name of the worker thread.
    """

    def __init__(self, solve: Callable[[Any], Any], on_done: Callable[[int, Any, BaseException | None], None],
                 name: str = "ba-calib-solver") -> None:
        self._solve = solve
        self._on_done = on_done
        self._cond = threading.Condition()
        self._job: tuple[int, Any] | None = None
        self._busy = False
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, version: int, payload: Any) -> None:
        """Queue a job, replacing any job not yet started.  Never blocks for long."""
        with self._cond:
            self._job = (version, payload)
            self._cond.notify_all()

    @property
    def idle(self) -> bool:
        """True when no job is queued or running."""
        with self._cond:
            return self._job is None and not self._busy

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until no job is queued or running; False on timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: self._job is None and not self._busy, timeout)

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._job is not None or self._stopped)
                if self._stopped:
                    return
                version, payload = self._job  # type: ignore[misc]
                self._job = None
                self._busy = True
            result, error = None, None
            try:
                result = self._solve(payload)
            except BaseException as exc:  # a failed solve must never kill the worker
                error = exc
            try:
                self._on_done(version, result, error)
            except Exception:
                traceback.print_exc()
            with self._cond:
                self._busy = False
                self._cond.notify_all()
