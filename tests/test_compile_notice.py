"""A first run compiles the kernels (about half a minute of CPU for all): the CLI says so once, and a cached run says nothing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# A small kernel: compiled in about a second with an empty cache, loaded in milliseconds from a full one.
_PROBE = """
import numpy as np
from calib_core import compile_events
compile_events.on_first_compile(lambda name: print("first compile:", name))
from calib_core.solve import kernels
kernels.so3_exp(np.array([0.1, 0.2, 0.3]))
kernels.so3_exp(np.array([0.3, 0.2, 0.1]))
print("done")
"""


def _run(code: str, cache: Path) -> subprocess.CompletedProcess:
    # BA_CALIB_INTERPRET_S=0: compile at the first call (else a few small calls run interpreted, uncompiled).
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(REPO), BA_CALIB_INTERPRET_S="0")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env, cwd=REPO)


def test_the_first_compile_is_reported_once_and_a_cache_hit_is_silent(tmp_path):
    cold = _run(_PROBE, tmp_path / "numba")
    assert cold.returncode == 0, cold.stderr
    assert cold.stdout.splitlines() == ["first compile: calib_core.solve.kernels.so3_exp", "done"]
    warm = _run(_PROBE, tmp_path / "numba")  # the same cache, now holding the kernel
    assert warm.returncode == 0, warm.stderr
    assert warm.stdout.splitlines() == ["done"]


def test_the_cli_notice_reaches_the_terminal_while_library_noise_is_collected(tmp_path):
    """``Noise.say`` writes past the fd-2 capture that keeps C libraries' chatter for the end of a command."""
    code = """
import os
from app.cli_guard import Noise
noise = Noise()
with noise:
    noise.say("notice now")
    os.write(2, b"libpng chatter\\n")
noise.say("after")
print(noise.lines)
"""
    out = _run(code, tmp_path / "numba")
    assert out.returncode == 0, out.stderr
    assert out.stderr.splitlines() == ["notice now", "after"]
    assert out.stdout.strip() == "['libpng chatter']"
