"""Kernels run their own Python source until compiling pays (calib_core._jit.Kernel): same answers, no compile."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# A noise-free scene through a pinhole camera: the solve must give back the pose it was made from.
_SOLVE = """
import numpy as np
from scipy.spatial.transform import Rotation
from calib_core import compile_events
compile_events.on_first_compile(lambda name: print("first compile:", name))
from calib_core.cameras import PinholeCamera
from calib_core.solve import kernels, solve_extrinsics
rng = np.random.default_rng(7)
R = Rotation.from_rotvec([0.2, -0.1, 0.3]).as_matrix()
t = np.array([0.1, -0.2, 0.3])
cam = PinholeCamera(np.array([[500.0, 0, 319.5], [0, 500, 239.5], [0, 0, 1]]), np.array([-0.1, 0.02, 0.001, -0.002, 0.0]),
                    640, 480)
pixels = np.column_stack([rng.uniform(20, 620, 12), rng.uniform(20, 460, 12)])
bearings = cam.bearing(pixels)
points_camera = bearings * rng.uniform(2.0, 9.0, (12, 1))
points_lidar = (points_camera - t) @ R
res = solve_extrinsics(points_lidar, bearings, camera=cam, pixels=pixels)
print("rotation error", float(np.abs(res.T_camera_lidar[:3, :3] - R).max()))
print("translation error", float(np.abs(res.T_camera_lidar[:3, 3] - t).max()))
print("max px", float(np.nanmax(res.residual_px)))
print("lm compiled", bool(kernels.fit_pose.dispatcher.signatures))
"""


def _run(code: str, cache: Path, **env_extra: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(REPO), **env_extra)
    env.pop("BA_CALIB_INTERPRET_S", None) if "BA_CALIB_INTERPRET_S" not in env_extra else None
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env, cwd=REPO)


def _figures(out: str) -> dict[str, str]:
    return {line.rsplit(" ", 1)[0]: line.rsplit(" ", 1)[1] for line in out.splitlines() if not line.startswith("first")}


def test_a_first_small_solve_runs_interpreted_without_compiling_and_is_exact(tmp_path):
    run = _run(_SOLVE, tmp_path / "numba")
    assert run.returncode == 0, run.stderr
    assert not any(line.startswith("first compile") for line in run.stdout.splitlines()), run.stdout
    fig = _figures(run.stdout)
    assert fig["lm compiled"] == "False"
    assert float(fig["rotation error"]) < 1e-9 and float(fig["translation error"]) < 1e-9
    assert float(fig["max px"]) < 1e-6


def _cache_without(cache: Path, left_out: tuple[str, ...]) -> Path:
    """A numba cache dir (``NUMBA_CACHE_DIR``) holding the test session's cached kernels but those ``left_out``.

    The test session's warm-up (tests/conftest.py) has filled numba's cache: ``__pycache__`` next to each kernel
    module, or under ``NUMBA_CACHE_DIR`` when that is set.  Its files are copied where numba looks for them under
    ``cache`` (a folder per source folder, named by numba's ``UserProvidedCacheLocator``).
    """
    from numba.core.caching import UserProvidedCacheLocator

    def cache_dir(root: Path | None, source_dir: Path) -> Path:
        if root is None:
            return source_dir / "__pycache__"
        return root / UserProvidedCacheLocator.get_suitable_cache_subpath(str(source_dir / "kernels.py"))

    session_root = Path(os.environ["NUMBA_CACHE_DIR"]) if os.environ.get("NUMBA_CACHE_DIR") else None
    skip = tuple(name + "-" for name in left_out)
    for source_dir in [REPO / "calib_core", *(p for p in (REPO / "calib_core").iterdir() if p.is_dir())]:
        target = cache_dir(cache, source_dir)
        target.mkdir(parents=True, exist_ok=True)
        for path in cache_dir(session_root, source_dir).glob("*.nb[ic]"):
            if not path.name.startswith(skip):
                (target / path.name).write_bytes(path.read_bytes())
    return cache


def test_with_no_budget_the_same_solve_compiles_and_agrees(tmp_path):
    """With no budget for interpreting, the solve runs compiled: the kernels from its fused call down to the LM
    (``fit_and_report_probes``, ``fit_and_report``, ``fit_pose``), left out of the cache, compile at the first
    call, and the answers are as exact as the interpreted ones.  The other kernels load from the cache: compiling
    every kernel from nothing (about 40 s of CPU) is what ``.ci/run``'s warm-up does on a fresh checkout, and the
    test session's (tests/conftest.py) fails the session if a kernel does not compile."""
    cache = _cache_without(tmp_path / "numba", ("kernels.fit_and_report_probes", "kernels.fit_and_report",
                                                "kernels.fit_pose"))
    run = _run(_SOLVE, cache, BA_CALIB_INTERPRET_S="0")
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines()[0].startswith("first compile: calib_core.")
    assert run.stdout.splitlines()[0] == "first compile: calib_core.solve.kernels.fit_and_report_probes", (
        f"the copied cache did not serve the other kernels (numba's cache layout changed?): {run.stdout}")
    fig = _figures(run.stdout)
    assert fig["lm compiled"] == "True"
    assert float(fig["rotation error"]) < 1e-9 and float(fig["translation error"]) < 1e-9


def test_arithmetic_python_refuses_goes_to_the_compiled_kernel(tmp_path):
    """A zero bearing: Python's 1 / 0 raises, compiled code (IEEE division) gives NaN frames."""
    code = """
import numpy as np
from calib_core.solve import kernels
F = kernels.bearing_frames(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
print(np.isnan(F[0, :2]).all(), np.allclose(F[1], [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]),
      bool(kernels.bearing_frames.dispatcher.signatures))
"""
    run = _run(code, tmp_path / "numba")
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["True", "True", "True"]
