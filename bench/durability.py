"""kill -9 durability at full size: 50 trials of ``tests/test_app_durability.py``'s kill -9 test (issue 22).

CI runs that test with 10 trials to keep its time down; the target is 0 of 50 acknowledged changes lost, so
``python -m bench.durability [--trials N]`` runs the same test with ``BA_CALIB_KILL_TRIALS=N`` (default 50) and
prints its result line.  The test itself is the measurement: one definition, two sizes.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

from .common import REPO


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=50)
    args = ap.parse_args(argv)
    env = dict(os.environ, BA_CALIB_KILL_TRIALS=str(args.trials))
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider",
                          "tests/test_app_durability.py::test_no_acknowledged_change_is_lost_to_kill_9"],
                         cwd=REPO, env=env, capture_output=True, text=True)
    lines = [line for line in run.stdout.splitlines() if "kill -9 after" in line or "passed" in line
             or "failed" in line]
    print("\n".join(lines) or run.stdout[-2000:])
    return run.returncode


if __name__ == "__main__":
    sys.exit(main())
