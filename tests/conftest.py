"""Shared test setup."""

import os
import sys
from pathlib import Path

# The test driver (tests/app_driver) and helpers (browser_helpers, bag_helpers, ...) are imported by name from
# tests/; bench-only code that tests check (bench.guide_snap, bench.guide_junction) from the repository root.
# pytest's default import mode and ``python -m pytest`` put them on sys.path; this says so whatever the mode.
TESTS_DIR = Path(__file__).resolve().parent
for _path in (TESTS_DIR.parent, TESTS_DIR):
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

# Before numpy loads: see calib_core/__init__.py (single-threaded BLAS).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def pytest_sessionstart(session):
    """Compile every numba kernel once, before the first test.

    On a fresh checkout numba's disk cache is empty and compiling all kernels
    takes about half a minute of CPU (longer on a loaded machine).  Under
    pytest-xdist each worker does this (``.ci/run`` fills the cache first).  The app compiles them
    in a background thread, so without this the first app test's wait for its
    live solve would also wait for the compiler, and could time out.  With a
    warm cache this loads the kernels in about a second.
    """
    import sys

    if getattr(session.config.option, "numprocesses", None) and not hasattr(session.config, "workerinput"):
        return  # the pytest-xdist controller runs no test: each worker warms up (loads the cache) itself
    from app.warm_up import WarmUp  # what the app runs at start-up, here run to the end first

    warm = WarmUp()
    warm.wait()
    if warm.error is not None:
        raise warm.error
    print(f"numba kernels compiled or loaded from the cache in {sum(warm.seconds.values()):.1f} s", file=sys.stderr)
