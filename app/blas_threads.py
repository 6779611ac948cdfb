"""One BLAS thread while an app runs (:func:`limit`, :func:`unlimit`): the app's own worker threads share the cores.

OpenBLAS runs a large matrix product (moving the 100k-point scan for the loupes' predictions after every solve) on
every core and then keeps its worker threads spinning for about 0.1 s.  On a 2-core machine that spin took one
core from the next click's solve and redraw (in back-to-back clicks on the sample the process used 70-78 ms of
CPU per click, against 22 ms with one BLAS thread); the app's products are too small to gain from threads.
The limit is process-wide (that is how BLAS libraries work), so it is counted: the last app to stop restores it.
"""

from __future__ import annotations

import threading
from typing import Any

from threadpoolctl import threadpool_limits

_lock = threading.Lock()
_users = 0
_limits: Any = None


def limit() -> None:
    """Run BLAS single-threaded until the matching :func:`unlimit` (nested calls are counted)."""
    global _users, _limits
    with _lock:
        if _users == 0:
            _limits = threadpool_limits(limits=1, user_api="blas")
        _users += 1


def unlimit() -> None:
    """End one :func:`limit`; the last one restores the BLAS thread counts from before."""
    global _users, _limits
    with _lock:
        if _users == 0:
            return
        _users -= 1
        if _users == 0 and _limits is not None:
            _limits.restore_original_limits()
            _limits = None
