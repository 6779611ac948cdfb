"""Compile the numba kernels in the background at start-up, so the first click never waits on a JIT compile.

The page is served at once; a solve or redraw that needs a kernel before the
warm-up reaches it simply waits for that compile (numba compiles each
kernel once, under its own lock).
"""

from __future__ import annotations

import threading
import traceback


class WarmUp:
    """One daemon thread running :func:`calib_core.warm_up.warm_up` on every module with kernels
    (:data:`calib_core.warm_up.KERNEL_MODULES`: camera models, BA images, colouring, render, solve)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.error: BaseException | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ba-calib-warm-up", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            from calib_core.warm_up import KERNEL_MODULES, warm_up

            for module in KERNEL_MODULES:  # one at a time: what is done shows in ``seconds`` at once
                self.seconds.update(warm_up([module]))
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
