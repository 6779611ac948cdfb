"""Start-up of the app: ``ba-calib`` on the sample until it serves its first page (issue 12).

``python -m bench.startup [--runs N]`` starts ``ba-calib serve --port P``
(the console script's own ``app.cli:main``, on the bundled sample) in a new
process and polls ``http://127.0.0.1:P/`` until it answers 200; the time from
the process start to that answer is the start-up.  First with an empty numba
cache directory (every kernel compiled by the background warm-up while the
page is prepared), then with that cache warm.  The compile time itself is
the process's own warm-up log line if it prints one, else the JIT section of
:mod:`bench.solve_vs_opencv` / :mod:`bench.speed` measures it.

The cache is a temporary ``NUMBA_CACHE_DIR`` and the session file goes to a
temporary folder, so the repository is left alone.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np

from .common import REPO, free_port, log

#: Target of issue 12: first page within this many seconds, warm cache.
TARGET_S = 3.0
_CODE = "import sys; from app.cli import main; sys.exit(main(sys.argv[1:]))"


def first_page_seconds(cache_dir: str, timeout_s: float = 300.0) -> float:
    """Seconds from starting ``ba-calib serve`` on the sample to its first HTTP 200 on ``/``."""
    port = free_port()
    with tempfile.TemporaryDirectory(prefix="ba-calib-startup-") as work:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir,
                   PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        cmd = [sys.executable, "-c", _CODE, "serve", "--port", str(port),
               "--session", str(Path(work) / "session.yaml")]
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            while True:
                elapsed = time.perf_counter() - t0
                if proc.poll() is not None:
                    raise RuntimeError(f"ba-calib exited with {proc.returncode}: {proc.stderr.read().decode()[-400:]}")
                if elapsed > timeout_s:
                    raise TimeoutError(f"no page within {timeout_s:.0f} s")
                try:
                    with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as r:
                        if r.status == 200:
                            return time.perf_counter() - t0
                except (urllib.error.URLError, ConnectionError, OSError):
                    pass
                time.sleep(0.02)
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def startup(runs: int = 3) -> dict:
    """``{"cold_s": first page with an empty cache, "warm_s": [warm runs], "load": (before, after)}``."""
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="ba-calib-numba-") as cache:
        cold = first_page_seconds(cache)
        # The cold run's background warm-up may have been cut short by the terminate: fill the cache.
        subprocess.run([sys.executable, "-c", "from calib_core.warm_up import warm_up; warm_up()"],
                       env=dict(os.environ, NUMBA_CACHE_DIR=cache,
                                PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")),
                       cwd=REPO, check=True, timeout=900)
        warm = [first_page_seconds(cache) for _ in range(runs)]
    return {"cold_s": cold, "warm_s": warm, "load": (load0, os.getloadavg()[0])}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.startup", description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=3, help="warm-cache runs (median reported)")
    args = p.parse_args(argv)
    r = startup(args.runs)
    med = float(np.median(r["warm_s"]))
    log(f"ba-calib first page: cold cache {r['cold_s']:.2f} s, warm cache median {med:.2f} s "
        f"({', '.join(f'{w:.2f}' for w in r['warm_s'])}); target <= {TARGET_S:g} s: "
        f"{'PASS' if med <= TARGET_S else 'MISS'}; load {r['load'][0]:.1f} -> {r['load'][1]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
