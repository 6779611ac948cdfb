"""Hear when the package first compiles a numba kernel, without importing numba.

A kernel found in numba's disk cache loads in milliseconds; a cache miss (the
first run after an install or an update) compiles for seconds; the whole solve
for about 25 s of CPU.  A command-line tool registers a callback here before it
starts, so it can say why it is quiet (:mod:`calib_core._jit` reports the
first compile of the process).
"""

from __future__ import annotations

from typing import Callable

__all__ = ["on_first_compile"]

_callbacks: list[Callable[[str], None]] = []


def on_first_compile(callback: Callable[[str], None]) -> None:
    """Call ``callback(kernel_name)`` when this process first compiles one of the package's kernels.

    At most once per process; the callback runs on the compiling thread (a
    background warm-up thread in the app) and should only print or log.
    """
    _callbacks.append(callback)


def first_compile(kernel_name: str) -> None:
    """Tell every registered callback (called by :mod:`calib_core._jit`, once per process)."""
    for callback in list(_callbacks):
        callback(kernel_name)
