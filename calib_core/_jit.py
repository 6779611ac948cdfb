"""Compiled kernels: one decorator for every numba kernel of the package.

numba compiles a kernel on its first call (hundreds of milliseconds each);
with ``cache=True`` the machine code is written to disk and later processes
load it in milliseconds.  numba looks for a writable cache directory next to
the source (``__pycache__``), then in the user's cache directory
(``~/.cache/numba``), or where ``NUMBA_CACHE_DIR`` says.  A read-only
install with no writable home finds none, and ``cache=True`` would raise at
import; :func:`kernel` then falls back to a per-user directory under the
system temp directory, and as a last resort compiles without a disk cache.

The app calls :func:`calib_core.warm_up.warm_up` in a background thread at
start-up, so the first BA image or colouring does not stall on a compile.
This module stays below every module with kernels: it imports none of them.

What a fresh process pays before the first kernel runs, even with every
kernel cached (bench/organize.py measures it): ``import numba`` and, once
per process, numba's set-up of its compiler registries, which imports all of
numba's array and math implementations and, for its BLAS check,
``scipy.linalg``.  Profilers put that set-up inside the first disk-cache
load (``load_overload``); loading a cached kernel itself takes milliseconds,
so fusing or dropping kernels hardly changes start-up.
"""

from __future__ import annotations

import os
import tempfile
import threading
import warnings
from typing import Callable

import numba
import numba.core.event

from . import compile_events

#: numba options shared by all kernels.  numba keys its disk cache by the
#: kernel's own source file: after changing these options, delete the
#: ``*.nbi``/``*.nbc`` files (or touch the kernel modules) to recompile.  ``error_model="numpy"``: IEEE
#: division (x / 0 is inf or NaN, no exception check, which would also stop
#: the loops from running on SIMD lanes).  No ``fastmath``: its "no NaN" flag
#: would let LLVM drop the NaN propagation that marks invalid pixels.
_OPTIONS = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")


def _temp_cache_dir() -> str:
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    return os.path.join(tempfile.gettempdir(), f"ba-calib-numba-cache-{uid}")


def kernel(fn: Callable) -> Callable:
    """``numba.njit`` with the package's options and an on-disk cache wherever one can be written."""
    try:
        return numba.njit(**_OPTIONS)(fn)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        pass
    if not os.environ.get("NUMBA_CACHE_DIR"):
        numba.config.CACHE_DIR = _temp_cache_dir()
        try:
            return numba.njit(**_OPTIONS)(fn)
        except RuntimeError:
            pass
    warnings.warn(f"no writable numba cache directory: {fn.__name__} is compiled at every start", stacklevel=2)
    return numba.njit(**{**_OPTIONS, "cache": False})(fn)


class _FirstCompile(numba.core.event.Listener):
    """Reports the process's first compile of one of the package's kernels to :mod:`.compile_events`."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fired = False

    def on_start(self, event) -> None:
        data = event.data if isinstance(event.data, dict) else {}
        func = getattr(data.get("dispatcher"), "py_func", None)
        if func is None or not getattr(func, "__module__", "").startswith("calib_core."):
            return
        with self._lock:
            if self._fired:
                return
            self._fired = True
        compile_events.first_compile(f"{func.__module__}.{func.__qualname__}")

    def on_end(self, event) -> None:
        pass


# numba fires "numba:compile" only on a disk-cache miss, around the compile itself.
numba.core.event.register("numba:compile", _FirstCompile())

