"""A plain (not editable) install, run from another folder, serves the bundled sample.

One slow test (a minute or two: a wheel build, then the sample generated into
an empty cache).  The wheel is built from a copy of the sources and installed
with ``--no-deps`` into a fresh virtual environment; the dependencies come
from the running environment through a ``.pth`` line, which adds only its
site-packages folder (an editable install of this project there is not
activated: ``.pth`` files in folders added that way are not processed).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import time
import urllib.request
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from browser_helpers import free_port
from repo_paths import REPO, SAMPLE


pytestmark = pytest.mark.install


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, **kw)


def test_wheel_install_serves_the_sample_from_another_folder(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(REPO / name, src / name)
    for pkg in ("calib_core", "app"):
        shutil.copytree(REPO / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    proc = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(src)])
    assert proc.returncode == 0, proc.stderr
    (wheel,) = (tmp_path / "dist").glob("ba_calib-*.whl")
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
    assert any(n.endswith("/LICENSE") and ".dist-info/" in n for n in names), "the wheel carries the licence"
    assert not any(n.startswith(("tests/", "sample_data/")) for n in names)
    # No test scaffolding in the installed package (the test driver lives in tests/app_driver).
    assert "app/server.py" in names and "calib_core/__init__.py" in names, names
    scaffolding = [n for n in names if n.endswith(".py") and Path(n).name.startswith(("testing", "test_", "conftest"))]
    assert scaffolding == [] and not any("app_driver" in n for n in names), scaffolding

    venv = tmp_path / "venv"
    assert _run([sys.executable, "-m", "venv", "--without-pip", str(venv)]).returncode == 0
    py = venv / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "zz_test_dependencies.pth").write_text("\n".join(sorted(deps)) + "\n")
    # Without PYTHONPATH: a source tree on it (with its egg-info) would make pip find ba-calib installed already.
    pip_env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = _run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "--no-index", "-q", str(wheel)],
                env=pip_env)
    if proc.returncode != 0 and "no such option: --python" in proc.stderr:  # pip < 22.3
        proc = _run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q", "--prefix", str(venv), str(wheel)],
                    env=pip_env)
    assert proc.returncode == 0, proc.stderr

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(XDG_CACHE_HOME=str(tmp_path / "cache"), HOME=str(tmp_path / "home"), PATH=f"{venv / 'bin'}:{env['PATH']}")
    where = _run([str(py), "-c", "import app, calib_core; print(app.__file__); print(calib_core.__file__)"], cwd=elsewhere, env=env)
    assert where.returncode == 0, where.stderr
    assert all(line.startswith(str(venv)) for line in where.stdout.split()), where.stdout

    exe = venv / "bin" / "ba-calib"
    version = _run([str(exe), "--version"], cwd=elsewhere, env=env)
    assert version.returncode == 0 and version.stdout.startswith("ba-calib "), version.stderr

    port = free_port()
    server = subprocess.Popen(
        [str(exe), "serve", "--port", str(port)], cwd=elsewhere, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    try:
        deadline = time.monotonic() + 540
        page = None
        while time.monotonic() < deadline and server.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as resp:
                    page = resp.status
                    break
            except OSError:
                time.sleep(0.2)  # (the sample is generated first: seconds)
        assert page == 200, f"server exited with {server.poll()} or never answered"
    finally:
        server.terminate()
        try:
            out, _ = server.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
            out, _ = server.communicate()
    sample = tmp_path / "cache" / "ba-calib" / "sample"
    assert "Generating the sample scene" in out, out
    for name in ("scan.npz", "image.png", "camera.yaml", "ground_truth.yaml", "pairs.yaml"):
        assert (sample / name).is_file(), name
    # The generated sample is the committed one (seed 0).
    got = np.array(yaml.safe_load((sample / "ground_truth.yaml").read_text())["T_camera_lidar"]["matrix"])
    ref = np.array(yaml.safe_load((SAMPLE / "ground_truth.yaml").read_text())["T_camera_lidar"]["matrix"])
    assert np.array_equal(got, ref)
    # A headless command of the installed package on it.
    solved = _run(
        [str(exe), "solve", "--scan", str(sample / "scan.npz"), "--camera", str(sample / "camera.yaml"),
         "--pairs", str(sample / "pairs.yaml"), "-o", "e.yaml"], cwd=elsewhere, env=env,
    )  # fmt: skip
    assert solved.returncode == 0, solved.stderr
    # A fresh install has no compiled solve yet (the server was stopped long before its warm-up reached it): the
    # solve's small kernels run their Python source instead of compiling first, so the command neither waits for
    # the compiler nor announces it (calib_core._jit's tiered kernels; tests/test_compile_notice.py covers the notice).
    assert "compiling the numba kernels" not in solved.stderr, solved.stderr
    T = np.array(yaml.safe_load((elsewhere / "e.yaml").read_text())["T_camera_lidar"]["matrix"])
    assert np.linalg.norm(T[:3, 3] - ref[:3, 3]) < 0.05
