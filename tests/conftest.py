"""Shared test setup."""

import os
import sys
import time
from pathlib import Path

import pytest  # does not load numpy: the BLAS variables below still come first

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


#: The test files that take longest (tens of seconds each in CI), slowest first.  Under pytest-xdist (``.ci/run``:
#: ``--dist loadfile --no-loadscope-reorder``) they are handed out first, so that none of them starts last and runs
#: alone while the other workers idle.  The fuzz corpus (its cases have a 10 s limit) is followed by files that
#: drive no browser, so that it first shares the machine with one Python process, not with Chromium; then
#: browser files alternate with the others.  Only the order changes: a file not listed keeps its place after these.
SLOW_FILES_FIRST = (
    "test_fuzz_corpus.py",
    "test_shots_app.py",
    "test_e2e_align.py",
    "test_shots_app_guided.py",
    "test_e2e_loupes.py",
    "test_app_durability.py",
    "test_e2e_defects.py",
    "test_install.py",
    "test_e2e_guided.py",
    "test_app_concurrency.py",
    "test_e2e_verify.py",
    "test_e2e_shots.py",
    "test_app_guided.py",
    "test_app_real_scene.py",
    "test_cli_serve_bag.py",
    "test_e2e_browser.py",
    "test_shots.py",
    "test_e2e_frictions.py",
    "test_shots_guided.py",
    "test_cli_shots.py",
    "test_shots_live.py",
    "test_guide.py",
    "test_bag_frames.py",
)


def pytest_collection_modifyitems(config, items):
    """Under a pytest-xdist worker, put :data:`SLOW_FILES_FIRST` first (a stable sort: the rest keep their order)."""
    if not hasattr(config, "workerinput"):
        return
    rank = {name: k for k, name in enumerate(SLOW_FILES_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


#: Under pytest-xdist, in the controller: ``(worker, test file) -> [start, end]`` (``time.monotonic()`` seconds),
#: from the reports the workers send, for the schedule lines of the terminal summary.
_FILE_SPANS: dict[tuple[str, str], list[float]] = {}
_RUN_START = time.monotonic()


def pytest_runtest_logreport(report):
    node = getattr(report, "node", None)  # the worker that ran it: set in the pytest-xdist controller only
    if node is None:
        return
    now = time.monotonic()
    span = _FILE_SPANS.setdefault((node.gateway.id, report.nodeid.split("::", 1)[0]), [now, now])
    span[0], span[1] = min(span[0], now - report.duration), now


def pytest_terminal_summary(terminalreporter):
    """Under pytest-xdist: when each worker ran its last test, and when the longest files ran (seconds from the
    start): a worker idle at the end while another runs a long file shows here (the order: SLOW_FILES_FIRST)."""
    if not _FILE_SPANS:
        return
    ends: dict[str, float] = {}
    for (worker, _), (_, end) in _FILE_SPANS.items():
        ends[worker] = max(ends.get(worker, 0.0), end - _RUN_START)
    last = max(ends.values())
    terminalreporter.write_line("xdist schedule: " + ", ".join(
        f"{w} done at {t:.0f} s (idle {last - t:.0f} s)" for w, t in sorted(ends.items())))
    longest = sorted(_FILE_SPANS.items(), key=lambda kv: kv[1][0] - kv[1][1])[:8]
    terminalreporter.write_line("longest files: " + ", ".join(
        f"{name.rsplit('/', 1)[-1]} {w} {a - _RUN_START:.0f}-{b - _RUN_START:.0f} s" for (w, name), (a, b) in longest))


@pytest.fixture(scope="session")
def second_shot(tmp_path_factory):
    """``shots_helpers.write_second_shot``, once per test run (about 10 s of CPU: ray casting).

    The several-shot test files share these scenes and files and only read them.  Under pytest-xdist the workers
    of one run share the parent of their temp folders: the first worker that needs the scenes writes them there
    (files and a pickle of what the helper returns, under a lock), the others load them.
    """
    from shots_helpers import write_second_shot

    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return write_second_shot(tmp_path_factory.mktemp("second_shot"))
    import fcntl
    import pickle

    shared = tmp_path_factory.getbasetemp().parent / "second_shot"
    shared.mkdir(exist_ok=True)
    with open(shared / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        done = shared / "second_shot.pickle"
        if done.exists():
            return pickle.loads(done.read_bytes())
        scenes = write_second_shot(shared)
        done.with_suffix(".partial").write_bytes(pickle.dumps(scenes))
        done.with_suffix(".partial").replace(done)
        return scenes


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


# ---------------------------------------------------------------------- fixtures several app test modules share
# (a module's own fixture of the same name takes precedence; imports stay inside: numpy must not load before the
# BLAS variables above are set)
@pytest.fixture(scope="module")
def scene():
    """The sample scene (scan, camera, ground truth)."""
    from calib_core.synthetic import load_sample
    from repo_paths import SAMPLE

    return load_sample(SAMPLE)


@pytest.fixture
def app(tmp_path):
    """A fresh app on the sample with its own session file, stopped after the test."""
    from app_driver import sample_app

    a = sample_app(tmp_path / "session.yaml")
    yield a
    a.stop()
