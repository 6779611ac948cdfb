"""Warm-up of the package's compiled kernels: each module with kernels warms its own, this calls them.

numba compiles a kernel on its first call, or loads it from the disk cache
(:mod:`._jit`).  The app runs :func:`warm_up` in a background thread at
start-up so that no click waits for a compile (until it is done, small calls
run interpreted: :class:`._jit.Kernel`); ``.ci/run`` and the test session
run it ahead of the tests.  The layering: :mod:`._jit` (the
decorator) below every module with kernels, this module above them all, so
that no module with kernels imports another one back.
"""

from __future__ import annotations

import importlib
import time
from typing import Iterable

#: The modules with kernels, each with its own ``warm_up()``, in the order the app needs them after
#: start-up: camera models, BA images and colouring, the camera-view render (the page's first
#: image), then the solve (the first click).
KERNEL_MODULES = (
    "calib_core.cameras",
    "calib_core.bearing_angle",
    "calib_core.overlays",
    "calib_core.render",
    "calib_core.solve",
)


def warm_up(modules: Iterable[str] = KERNEL_MODULES) -> dict[str, float]:
    """Compile (or load from numba's disk cache) the kernels of ``modules`` on tiny inputs.

    Safe to call from a background thread; a kernel called meanwhile from
    another thread waits for its compile instead of compiling twice.

    Parameters
    ----------
    modules : iterable of str
        Names from :data:`KERNEL_MODULES` (default: all of them), warmed in
        the order given.  Each is imported only when its turn comes.

    Returns
    -------
    dict[str, float]
        Seconds spent per module, by module name, for the start-up log and
        the benchmark.

    Raises
    ------
    ValueError
        A name that is not in :data:`KERNEL_MODULES`.
    """
    modules = tuple(modules)
    unknown = [name for name in modules if name not in KERNEL_MODULES]
    if unknown:
        raise ValueError(f"no kernels to warm up in {', '.join(unknown)}; known: {', '.join(KERNEL_MODULES)}")
    from ._jit import compiling

    seconds = {}
    for name in modules:
        t0 = time.perf_counter()
        with compiling():  # this thread compiles; others run the kernels interpreted meanwhile
            importlib.import_module(name).warm_up()
        seconds[name] = time.perf_counter() - t0
    return seconds
