"""``ba-calib solve``: quality in the YAML, outliers named and kept, exit code 3 when unreliable."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.transforms import rotation_angle_deg
from repo_paths import REPO, SAMPLE


def _run(pairs_file: Path, out: Path) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "app.cli", "solve", "--scan", str(SAMPLE / "scan.npz"),
           "--camera", str(SAMPLE / "camera.yaml"), "--pairs", str(pairs_file), "-o", str(out)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=REPO)


def _sample_pairs() -> list[dict]:
    entries = yaml.safe_load((SAMPLE / "pairs.yaml").read_text())["pairs"]
    for k, e in enumerate(entries):
        e["id"] = 40 + k
    return entries


def test_clean_sample_is_ok(tmp_path):
    pairs = tmp_path / "pairs.yaml"
    pairs.write_text(yaml.safe_dump({"pairs": _sample_pairs()}))
    proc = _run(pairs, tmp_path / "e.yaml")
    assert proc.returncode == 0, proc.stderr
    doc = yaml.safe_load((tmp_path / "e.yaml").read_text())
    assert doc["quality"] == {"status": "ok", "reasons": []}
    assert doc["outliers"] == []
    assert "quality: OK" in proc.stdout


def test_one_wrong_pair_is_named_left_out_and_kept(tmp_path):
    entries = _sample_pairs()
    entries[3]["pixel"] = [entries[3]["pixel"][0] + 90.0, entries[3]["pixel"][1] - 60.0]  # a stray click
    pairs = tmp_path / "pairs.yaml"
    pairs.write_text(yaml.safe_dump({"pairs": entries}))
    proc = _run(pairs, tmp_path / "e.yaml")
    assert proc.returncode == 0, proc.stderr
    doc = yaml.safe_load((tmp_path / "e.yaml").read_text())
    assert doc["quality"]["status"] == "warning"
    assert any("pairs 43 left out as outliers" in r for r in doc["quality"]["reasons"])
    assert [(o["index"], o["id"]) for o in doc["outliers"]] == [(3, 43)]
    assert doc["outliers"][0]["px"] > 50
    assert len(doc["pairs"]) == 10 and doc["pairs"][3]["id"] == 43  # kept in the file
    assert doc["residuals"]["n_inliers"] == 9 and doc["residuals"]["per_pair"][3]["outlier"] is True
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    T = load_extrinsics_yaml(tmp_path / "e.yaml")["T_camera_lidar"]
    assert rotation_angle_deg(T[:3, :3], truth[:3, :3]) < 1.0 and np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.05
    assert "<- outlier, left out of the fit" in proc.stdout


def test_half_wrong_exits_3_and_still_writes(tmp_path):
    entries = _sample_pairs()
    rng = np.random.default_rng(0)
    for k in (0, 2, 5, 6, 9):  # five stray clicks, far from their corners
        u, v = entries[k]["pixel"]
        entries[k]["pixel"] = [float(np.clip(u + rng.choice([-1, 1]) * rng.uniform(60, 120), 100, 540)),
                               float(np.clip(v + rng.choice([-1, 1]) * rng.uniform(60, 120), 60, 420))]
    pairs = tmp_path / "pairs.yaml"
    pairs.write_text(yaml.safe_dump({"pairs": entries}))
    out = tmp_path / "e.yaml"
    proc = _run(pairs, out)
    assert proc.returncode == 3, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    err_lines = proc.stderr.strip().splitlines()
    assert len(err_lines) == 1 and err_lines[0].startswith("unreliable: ")
    doc = yaml.safe_load(out.read_text())
    assert doc["quality"]["status"] == "unreliable" and doc["quality"]["reasons"]
    assert "quality: UNRELIABLE" in proc.stdout


def test_check_pairs_are_not_fitted_and_reported_apart(tmp_path):
    from calib_core.pairs import Pair, load_pairs_yaml
    from calib_core.solve import calibrate
    from calib_core.synthetic import load_sample

    scene = load_sample(SAMPLE)
    pairs = load_pairs_yaml(SAMPLE / "pairs.yaml")
    marked = [Pair(p.laser_rc, p.laser_xyz, p.pixel, id=60 + k, check=k in (2, 7)) for k, p in enumerate(pairs)]
    res = calibrate(marked, scene.depth, scene.camera)
    without = calibrate([p for k, p in enumerate(marked) if k not in (2, 7)], scene.depth, scene.camera)
    # Not fitted: the pose is the one of the other 8 pairs; reported apart with their ids.
    np.testing.assert_allclose(res.T_camera_lidar, without.T_camera_lidar, atol=1e-12)
    assert res.n_pairs == 8 and res.check_ids == [62, 67] and res.check_positions == [2, 7]
    # Their errors at the pose, checked against an independent projection.
    T = res.T_camera_lidar
    p = scene.depth.points[pairs[2].laser_rc[0], pairs[2].laser_rc[1]]
    uv, _ = scene.camera.project((T[:3, :3] @ p + T[:3, 3])[None])
    assert abs(res.check_residual_px[0] - np.linalg.norm(uv[0] - np.asarray(pairs[2].pixel))) < 1e-9
    # In the YAML: per-pair rows keep the file's positions, check pairs in their own block.
    entries = _sample_pairs()
    for k in (2, 7):
        entries[k]["check"] = True
    f = tmp_path / "pairs.yaml"
    f.write_text(yaml.safe_dump({"pairs": entries}))
    proc = _run(f, tmp_path / "e.yaml")
    assert proc.returncode == 0, proc.stderr
    doc = yaml.safe_load((tmp_path / "e.yaml").read_text())
    assert [c["index"] for c in doc["check_pairs"]] == [2, 7] and [c["id"] for c in doc["check_pairs"]] == [42, 47]
    assert [r["index"] for r in doc["residuals"]["per_pair"]] == [0, 1, 3, 4, 5, 6, 8, 9]
    assert "check pair (not in the fit)" in proc.stdout
