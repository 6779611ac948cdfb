"""``ba-calib solve`` writes the ``verification:`` block: checked against hand computations on the sample."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import yaml

from calib_core.cameras import load_camera
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import load_pairs_yaml, resolve_pairs
from calib_core.solve import solve_extrinsics
from repo_paths import REPO, SAMPLE


def test_solve_writes_the_verification_block(tmp_path):
    doc = yaml.safe_load((SAMPLE / "pairs.yaml").read_text())
    entries = doc["pairs"] if isinstance(doc, dict) else doc
    entries[2]["check"] = True  # a check pair: left out of the fit
    pairs_file = tmp_path / "pairs.yaml"
    pairs_file.write_text(yaml.safe_dump(doc))
    out = tmp_path / "extrinsics.yaml"
    proc = subprocess.run([sys.executable, "-m", "app.cli", "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera",
                           str(SAMPLE / "camera.yaml"), "--pairs", str(pairs_file), "-o", str(out)],
                          capture_output=True, text=True, timeout=300, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    written = load_extrinsics_yaml(out)
    T = written["T_camera_lidar"]
    v = written["verification"]
    pairs = load_pairs_yaml(pairs_file)
    camera, depth = load_camera(SAMPLE / "camera.yaml"), load_scan(SAMPLE / "scan.npz")
    points, bearings, pixels = resolve_pairs(pairs, depth, camera)
    ids = [p.id if p.id is not None else i for i, p in enumerate(pairs)]
    assert v["n_fit_pairs"] == len(pairs) - 1 and v["n_check_pairs"] == 1
    # The check pair's error under the written pose, by hand.
    uv, _ = camera.project(points[2:3] @ T[:3, :3].T + T[:3, 3])
    assert v["check_pairs"][0]["id"] == ids[2]
    assert v["check_pairs"][0]["px"] == pytest.approx(float(np.linalg.norm(uv[0] - pixels[2])), abs=1e-6)
    # Leave-one-out of a fit pair: the refit of the other fit pairs, by hand.
    fit = [i for i in range(len(pairs)) if i != 2]
    loo = {e["id"]: e["px"] for e in v["leave_one_out"]}
    assert set(loo) == {ids[i] for i in fit}
    for i in (fit[0], fit[-1]):
        keep = [j for j in fit if j != i]
        Ti = solve_extrinsics(points[keep], bearings[keep], camera=camera, pixels=pixels[keep],
                              initial_T_camera_lidar=T).T_camera_lidar
        uv, _ = camera.project(points[i:i + 1] @ Ti[:3, :3].T + Ti[:3, 3])
        assert loo[ids[i]] == pytest.approx(float(np.linalg.norm(uv[0] - pixels[i])), abs=1e-6)
    assert v["error_vs_pair_count"]["n_pairs"] == list(range(5, len(fit) + 1))
    assert "check pair" in proc.stdout
