"""Running the ``ba-calib`` command in a subprocess, as the CLI tests share it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from repo_paths import REPO


def run_cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    """``python -m app.cli ARGS`` with text output, from ``cwd`` (the repository root by default)."""
    return subprocess.run([sys.executable, "-m", "app.cli", *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd)


def one_error_line(proc: subprocess.CompletedProcess) -> str:
    """The one ``error:`` line of a run that must exit 2 (asserted), to check its wording."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-500:], proc.stderr[-500:])
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    return lines[0]
