"""Run fuzz cases as ``ba-calib`` processes, fast: a fork server that has imported the package.

Starting Python and importing numpy, OpenCV, SciPy and the package costs about 0.8 s per
process; the corpus has hundreds of cases.  So each worker (``python -m tests.fuzz.runner
--worker``) imports everything once and then, per case, forks a child that runs ``app.cli``
exactly as ``python -m app.cli ARGV`` would (``runpy`` with ``__name__ == "__main__"``),
with its own stdin, stdout and stderr files and its own empty working folder.

The worker also loads every numba kernel (``calib_core.warm_up.warm_up``: from numba's disk cache,
which ``.ci/run`` and the test session fill first) before it forks.  A fresh process would load
each kernel it calls from that cache too, the same machine code; what it pays once for numba's
set-up (about 0.4 s of CPU, measured per case) is paid once per worker instead: half or more of a
solving case's CPU, for 150-odd cases.  So a case's CPU time excludes that set-up, as it excludes
the imports; the 10 s limit is far above both (the slowest case takes about 3 s).
:func:`run_cases` starts one worker first and the others once it is ready, so that a cold cache is
compiled once, not once per worker; a worker that compiled starts again (its compiler's memory would
count in every child's RSS).

The worker watches each child: it is killed when it runs longer than the time limit or its
resident memory (``/proc/PID/status`` VmRSS, polled every 10 ms) passes the memory limit,
and its peak RSS is read from ``os.wait4``'s ``ru_maxrss`` when it ends.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from .case import FuzzCase

REPO = Path(__file__).resolve().parents[2]

#: Modules the worker imports before forking (what the commands import lazily).
PRELOAD = (
    "numpy", "scipy.optimize", "scipy.spatial", "cv2", "yaml", "trimesh", "PIL.Image",
    "app.cli", "calib_core.cameras", "calib_core.pairs", "calib_core.io.extrinsics", "calib_core.io.images",
    "calib_core.io.scan_readers", "calib_core.solve", "calib_core.bearing_angle", "calib_core.overlays",
    "app.server",  # viser: serve cases (sessions) would otherwise spend seconds importing it
)

#: Text kept of a child's stdout / stderr.
KEEP_BYTES = 8192


@dataclass(frozen=True)
class CaseResult:
    """How one case ended.

    Attributes
    ----------
    name : str
        The case's name.
    returncode : int
        Exit code (negative: killed by that signal).
    stdout, stderr : str
        The first :data:`KEEP_BYTES` bytes of each, decoded with replacement.
    seconds : float
        Wall time from fork to exit.
    cpu_seconds : float
        The child's CPU time (user + system, ``os.wait4``'s rusage): what a case costs, whatever else the
        machine runs.
    peak_rss_mb : float
        Peak resident memory, MiB (``ru_maxrss``; the larger of it and the polled VmRSS).
    killed : str or None
        ``"timeout"`` or ``"memory"`` when the worker killed the child.
    """

    name: str
    returncode: int
    stdout: str
    stderr: str
    seconds: float
    peak_rss_mb: float
    killed: str | None
    cpu_seconds: float = 0.0


# ----------------------------------------------------------------------------- worker side
def _vm_rss_kb(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmRSS:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return 0


def _child(argv: list[str], stdin_path: str, out_path: str, err_path: str, cwd: str) -> None:
    """In the forked child: become ``python -m app.cli ARGV`` and exit."""
    code = 1
    try:
        os.chdir(cwd)
        for fd, path, flags in ((0, stdin_path, os.O_RDONLY), (1, out_path, os.O_WRONLY), (2, err_path, os.O_WRONLY)):
            new = os.open(path, flags)
            os.dup2(new, fd)
            os.close(new)
        # The worker's stdin object may hold read-ahead protocol lines: start from the new fd 0.
        sys.stdin = sys.__stdin__ = open(0, "r", closefd=False)
        import runpy
        import traceback

        sys.argv = ["ba-calib", *argv]
        sys.modules.pop("app.cli", None)  # run afresh as __main__ (its imports stay loaded)
        try:
            runpy.run_module("app.cli", run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as exc:
            if exc.code is None:
                code = 0
            elif isinstance(exc.code, int):
                code = exc.code
            else:  # as the interpreter does
                print(exc.code, file=sys.stderr)
                code = 1
        except BaseException:  # noqa: BLE001 - what the interpreter would print
            traceback.print_exc()
            code = 1
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except BaseException:  # noqa: BLE001
                pass
    finally:
        os._exit(code & 0xFF)


def _read_head(path: str) -> str:
    with open(path, "rb") as f:
        return f.read(KEEP_BYTES).decode("utf-8", "replace")


def run_in_fork(case: dict, timeout: float, rss_limit_mb: float, scratch: Path) -> dict:
    """Run one case (as a dict) in a forked child of this process; the result as a dict."""
    scratch.mkdir(parents=True, exist_ok=True)
    case_dir = Path(tempfile.mkdtemp(prefix="case-", dir=scratch))
    stdin_path = str(case_dir / ".stdin")
    with open(stdin_path, "wb") as f:
        f.write(bytes.fromhex(case["stdin"]) if case.get("stdin") else b"")
    out_path, err_path = str(case_dir / ".stdout"), str(case_dir / ".stderr")
    for p in (out_path, err_path):
        open(p, "wb").close()
    work = case_dir / "work"
    work.mkdir()
    sys.stdout.flush()
    sys.stderr.flush()
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:
        _child(list(case["argv"]), stdin_path, out_path, err_path, str(work))
    killed = None
    polled_kb = 0
    pause = 0.001  # most cases end in well under a second: poll fast first, then every 20 ms
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        polled_kb = max(polled_kb, _vm_rss_kb(pid))
        if killed is None and time.monotonic() - t0 > timeout:
            killed = "timeout"
            os.kill(pid, signal.SIGKILL)
        elif killed is None and polled_kb > rss_limit_mb * 1024:
            killed = "memory"
            os.kill(pid, signal.SIGKILL)
        time.sleep(pause)
        pause = min(0.02, pause * 1.5)
    seconds = time.monotonic() - t0
    code = os.waitstatus_to_exitcode(status)
    return {
        "name": case["name"],
        "returncode": code,
        "stdout": _read_head(out_path),
        "stderr": _read_head(err_path),
        "seconds": seconds,
        "peak_rss_mb": max(usage.ru_maxrss, polled_kb) / 1024.0,
        "killed": killed,
        "cpu_seconds": usage.ru_utime + usage.ru_stime,
    }


def worker_main() -> None:
    """Read cases as JSON lines on stdin, answer results as JSON lines on stdout."""
    import importlib
    import warnings

    code_root = os.environ.get("BA_CALIB_FUZZ_CODE")
    if code_root:  # run the corpus against another checkout's calib_core/app (e.g. before a fix)
        sys.path.insert(0, code_root)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in PRELOAD:
            importlib.import_module(name)
    from calib_core import compile_events
    from calib_core.warm_up import warm_up

    compiled: list[str] = []
    compile_events.on_first_compile(compiled.append)
    warm_up()  # every kernel, loaded once here instead of in every child (see the module notes)
    if compiled and not os.environ.get("BA_CALIB_FUZZ_RESTARTED"):
        # A cold cache: compiling left the compiler's memory (about 300 MiB) in this process, so in every child's
        # RSS.  Start afresh, loading the kernels from the cache this filled (once: a cache that cannot be
        # written would compile again).
        os.environ["BA_CALIB_FUZZ_RESTARTED"] = "1"
        sys.stdout.flush()
        os.execv(sys.executable, [sys.executable, "-m", "tests.fuzz.runner", "--worker"])
    out = sys.stdout
    print(json.dumps({"ready": True}), file=out, flush=True)
    for line in sys.stdin:
        msg = json.loads(line)
        result = run_in_fork(msg["case"], msg["timeout"], msg["rss_limit_mb"], Path(msg["scratch"]))
        print(json.dumps(result), file=out, flush=True)


# ----------------------------------------------------------------------------- client side
def _case_message(case: FuzzCase) -> dict:
    return {"name": case.name, "argv": list(case.argv), "stdin": case.stdin.hex() if case.stdin else ""}


def run_cases(
    cases: Iterable[FuzzCase],
    scratch: str | os.PathLike,
    workers: int = 2,
    timeout: float = 10.0,
    rss_limit_mb: float = 1024.0,
) -> list[CaseResult]:
    """Run every case in ``workers`` fork-server processes; results in the order of ``cases``.

    Parameters
    ----------
    cases : iterable of FuzzCase
    scratch : path-like
        Folder for the per-case working folders and output files.
    workers : int
        Worker processes (cases run in parallel, one per worker).
    timeout : float
        Seconds after which a case is killed (``killed == "timeout"``).
    rss_limit_mb : float
        Resident memory (MiB) above which a case is killed (``killed == "memory"``).
    """
    cases = list(cases)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])

    def start_worker() -> subprocess.Popen:
        return subprocess.Popen(
            [sys.executable, "-m", "tests.fuzz.runner", "--worker"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=REPO, env=env, text=True, bufsize=1,
        )

    # The first worker alone until it is ready: if numba's disk cache is cold, it compiles the kernels once
    # and the others load them.  It gets its first case below, before the loop waits for the others' ready lines.
    procs = [start_worker()]
    if not procs[0].stdout.readline():
        raise RuntimeError(f"fuzz worker 0 did not start (exit {procs[0].wait()})")
    procs += [start_worker() for _ in range(max(1, min(workers, len(cases))) - 1)]
    results: dict[int, CaseResult] = {}
    sel = selectors.DefaultSelector()
    pending = list(enumerate(cases))[::-1]
    busy: dict[int, int] = {}  # worker index -> case index

    def send(w: int) -> None:
        if not pending:
            procs[w].stdin.close()
            return
        i, case = pending.pop()
        busy[w] = i
        msg = {"case": _case_message(case), "timeout": timeout, "rss_limit_mb": rss_limit_mb, "scratch": str(scratch)}
        procs[w].stdin.write(json.dumps(msg) + "\n")
        procs[w].stdin.flush()

    try:
        for w, p in enumerate(procs):
            sel.register(p.stdout, selectors.EVENT_READ, w)
        send(0)  # its ready line was read above
        open_workers = len(procs)
        while open_workers:
            for key, _ in sel.select():
                w = key.data
                line = procs[w].stdout.readline()
                if not line:
                    sel.unregister(key.fileobj)
                    open_workers -= 1
                    if w in busy:
                        raise RuntimeError(f"fuzz worker {w} died while running {cases[busy[w]].name}")
                    continue
                msg = json.loads(line)
                if not msg.get("ready"):
                    results[busy.pop(w)] = CaseResult(**msg)
                send(w)
    finally:
        for p in procs:
            if p.poll() is None:
                try:
                    p.stdin.close()
                except OSError:
                    pass
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
    return [results[i] for i in range(len(cases))]


if __name__ == "__main__":
    if sys.argv[1:] == ["--worker"]:
        worker_main()
    else:
        sys.exit("usage: python -m tests.fuzz.runner --worker   (started by run_cases)")
