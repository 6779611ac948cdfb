"""Compile the numba kernels in the background at start-up, so the first click never waits on a JIT compile.

The page is served at once; a solve or redraw that needs a kernel before the
warm-up reaches it simply waits for that compile (numba compiles each
kernel once, under its own lock).
"""

from __future__ import annotations

import threading
import time
import traceback


class WarmUp:
    """One daemon thread running :func:`calib_core._jit.warm_up`, :func:`calib_core.solve.warm_up` and
    :func:`calib_core.render.warm_up` (the camera-view render's kernels)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.error: BaseException | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ba-calib-warm-up", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            from calib_core import _jit, render, solve

            self.seconds.update(_jit.warm_up())
            t0 = time.perf_counter()
            render.warm_up()  # the first render of the page comes right after start-up
            self.seconds["calib_core.render"] = time.perf_counter() - t0
            warm_solve = getattr(solve, "warm_up", None)
            if warm_solve is not None:
                t0 = time.perf_counter()
                warm_solve()
                self.seconds["calib_core.solve"] = time.perf_counter() - t0
        except BaseException as exc:  # a failed warm-up only costs the first click its compile time
            self.error = exc
            traceback.print_exc()
        finally:
            self._done.set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the warm-up has finished (or failed) and its thread has ended; False on timeout."""
        if not self._done.wait(timeout):
            return False
        self._thread.join()  # it only returns after setting the event: a moment at most
        return True
