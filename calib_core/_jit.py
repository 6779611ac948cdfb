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

Interpreted until compiling pays (:func:`tiered_kernel`, :class:`Kernel`): a kernel that is neither
compiled in this process nor in the disk cache runs its own Python source
(the same maths, no second copy) on small inputs, until the process has
spent :data:`INTERPRET_BUDGET_S` of CPU that way; then it compiles.  A
one-shot ``ba-calib solve`` on a few pairs thus never pays the compile
(tens of seconds of CPU for a result that takes milliseconds), while a long
run compiles after a few seconds.  :func:`compiling` forces the compile
(the warm-up, in its own thread, while other threads keep interpreting).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import threading
import time
import warnings
from typing import Any, Callable, Iterator

import numba
import numba.core.event
import numpy as np
from numba.core import types
from numba.extending import typeof_impl

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


def _dispatcher(fn: Callable) -> Any:
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
    warnings.warn(f"no writable numba cache directory: {fn.__name__} is compiled at every start", stacklevel=3)
    return numba.njit(**{**_OPTIONS, "cache": False})(fn)


#: CPU seconds a process may spend running kernels interpreted before they compile (environment
#: variable ``BA_CALIB_INTERPRET_S`` overrides; 0 compiles at once, as plain numba).
INTERPRET_BUDGET_S = float(os.environ.get("BA_CALIB_INTERPRET_S", "3.0"))
#: Largest array (elements) an interpreted call may take (200 pairs of 3-vectors): bulk work compiles at once.
INTERPRET_MAX_ELEMENTS = 600
_spent = [0.0]  # CPU seconds spent interpreting, this process
_local = threading.local()  # .force: compile in this thread; .depth: nesting of interpreted calls


@contextlib.contextmanager
def compiling() -> Iterator[None]:
    """Within this block, this thread compiles (or loads from the cache) every kernel it calls."""
    before = getattr(_local, "force", False)
    _local.force = True
    try:
        yield
    finally:
        _local.force = before


class Kernel:
    """A numba kernel that runs interpreted (its own source) until compiling it pays; see the module notes.

    Inside compiled code it is its dispatcher (numba types it as one); from Python, calls go to the
    compiled code once it is ready (compiled in this process or found in the disk cache), else to
    the Python function while the inputs are small and the budget lasts.
    """

    def __init__(self, fn: Callable) -> None:
        self.dispatcher = _dispatcher(fn)
        self.py_func = fn
        self.__name__, self.__qualname__ = fn.__name__, fn.__qualname__
        self.__module__, self.__doc__, self.__wrapped__ = fn.__module__, fn.__doc__, fn
        self._ready = False
        self._on_disk: bool | None = None

    def __repr__(self) -> str:
        return f"<kernel {self.__module__}.{self.__qualname__}>"

    def _cached_on_disk(self) -> bool:
        if self._on_disk is None:
            # numba's index of the cached signatures: empty when missing or stale (source changed).
            cache_file = getattr(getattr(self.dispatcher, "_cache", None), "_cache_file", None)
            try:
                self._on_disk = bool(cache_file is not None and cache_file._load_index())
            except Exception:  # a private numba API: if it changes, compile as plain numba would
                self._on_disk = True
        return self._on_disk

    def _interpret_now(self, args: tuple) -> bool:
        if getattr(_local, "force", False) or _spent[0] >= INTERPRET_BUDGET_S:
            return False
        if self.dispatcher.signatures or self._cached_on_disk():
            return False
        data = next((a for a in args if isinstance(a, np.ndarray)), None)  # points, pixels, pairs: the work
        return data is None or data.size <= INTERPRET_MAX_ELEMENTS

    def __call__(self, *args: Any) -> Any:
        if self._ready:
            return self.dispatcher(*args)
        if not self._interpret_now(args):
            out = self.dispatcher(*args)
            self._ready = True
            return out
        depth = getattr(_local, "depth", 0)
        if depth:  # inside an interpreted kernel: its caller keeps the time and catches the errors
            _local.depth = depth + 1
            try:
                return self.py_func(*args)
            finally:
                _local.depth = depth
        _local.depth = 1
        start = time.process_time()
        try:
            with np.errstate(all="ignore"):
                return self.py_func(*args)
        except Exception:
            # Python raises where compiled code does not (1 / 0.0 is inf there, error_model="numpy"; no
            # bounds checks): the compiled kernel decides, as it would have without the interpreter.
            _local.depth = 0
            return self.dispatcher(*args)
        finally:
            _local.depth = 0
            _spent[0] += time.process_time() - start


@typeof_impl.register(Kernel)
def _typeof_kernel(val: Kernel, c: Any) -> types.Type:
    """Compiled callers see the dispatcher: they call its compiled code, as with a plain numba kernel."""
    return types.Dispatcher(val.dispatcher)


def kernel(fn: Callable) -> Any:
    """``numba.njit`` with the package's options and an on-disk cache wherever one can be written."""
    return _dispatcher(fn)


def tiered_kernel(fn: Callable) -> Kernel:
    """:func:`kernel` for small-input work (the solve, a few pairs through a camera model): interpreted
    until compiling pays (:class:`Kernel`)."""
    return Kernel(fn)


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

