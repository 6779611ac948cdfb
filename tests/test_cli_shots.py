"""``ba-calib solve`` and ``propose`` with ``--shot SCAN PAIRS`` (issue 21), end to end.

Shots are made from the committed sample (its ground truth is the truth here): two shots of one room
use disjoint laser cells; a third shot's laser points are turned by 3 degrees about the room's
vertical (its scan taken while the rig turned), given as ``laser_xyz`` pairs.
"""

from __future__ import annotations

import dataclasses
import subprocess

import numpy as np
import pytest
import yaml

from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.pairs import Pair, load_pairs_yaml, save_pairs_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.synthetic.picks import laser_picks
from calib_core.transforms import rotation_angle_deg
from repo_paths import SAMPLE
from cli_helpers import run_cli

SCAN, CAMERA = str(SAMPLE / "scan.npz"), str(SAMPLE / "camera.yaml")


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


def _rotation(axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


@pytest.fixture(scope="module")
def shot_files(tmp_path_factory):
    """Pairs files: shots 0 and 1 (even / odd cell columns of the sample), 2 and 3 (turned 3 deg, 20 pairs)."""
    d = tmp_path_factory.mktemp("shots")
    sample = load_sample(SAMPLE)
    rc, _ = laser_picks(sample.depth, sample.corners_lidar)
    rng = np.random.default_rng(5)
    files = []
    for part in (0, 1):
        half = dataclasses.replace(sample, corners_lidar=sample.corners_lidar[rc[:, 1] % 2 == part])
        files.append(d / f"shot{part}.yaml")
        save_pairs_yaml(files[-1], simulate_pairs(half, 12, rng))
    up = np.linalg.inv(sample.T_world_lidar[:3, :3]) @ np.array([0.0, 0.0, 1.0])
    R = _rotation(up, 3.0)
    for name, n in (("turned", 12), ("turned20", 20)):
        pairs = simulate_pairs(sample, n, rng)
        turned = [Pair(None, tuple(float(v) for v in R @ sample.depth.points[p.laser_rc]), p.pixel) for p in pairs]
        files.append(d / f"{name}.yaml")
        save_pairs_yaml(files[-1], turned)
    return files, sample.T_camera_lidar


def test_solve_two_shots_writes_per_shot_residuals_and_leave_one_shot_out(shot_files, tmp_path):
    (p0, p1, _, _), T_true = shot_files
    out = tmp_path / "e.yaml"
    proc = run_cli("solve", "--camera", CAMERA, "--shot", SCAN, str(p0), "--shot", SCAN, str(p1), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "2 shots, one T_camera_lidar" in proc.stdout and "LOSO [px]" in proc.stdout
    doc = load_extrinsics_yaml(out)
    T = doc["T_camera_lidar"]
    rot, trans = rotation_angle_deg(T[:3, :3], T_true[:3, :3]), np.linalg.norm(T[:3, 3] - T_true[:3, 3])
    print(f"CLI two shots x 12 pairs: rotation error {rot:.3f} deg, translation error {100 * trans:.2f} cm")
    assert rot <= 0.5 and trans <= 0.03
    assert doc["quality"]["status"] == "ok"
    shots = doc["shots"]
    assert [s["index"] for s in shots] == [0, 1] and all(s["in_fit"] for s in shots)
    assert [p["shot"] for p in doc["pairs"]] == [0] * 12 + [1] * 12
    # Each shot's leave-one-shot-out: its 12 pairs under the pose fitted to the other shot, checked here
    # against the other shot's own one-shot solve.
    from calib_core.cameras import load_camera

    camera = load_camera(CAMERA)
    for k, other in ((0, p1), (1, p0)):
        loso = shots[k]["leave_one_shot_out"]
        assert loso["n_pairs"] == 12 and len(loso["per_pair"]) == 12
        alone = tmp_path / f"alone{k}.yaml"
        solved = run_cli("solve", "--camera", CAMERA, "--scan", SCAN, "--pairs", str(other), "-o", str(alone))
        assert solved.returncode == 0
        T_other = load_extrinsics_yaml(alone)["T_camera_lidar"]
        from calib_core.io.scan_readers import load_scan
        from calib_core.pairs import resolve_pairs

        points, _, pixels = resolve_pairs(load_pairs_yaml(p0 if k == 0 else p1), load_scan(SCAN), camera)
        uv, _ = camera.project(points @ T_other[:3, :3].T + T_other[:3, 3])
        # Two solves of the same pairs from different starts agree to the LM's stopping rule (the laser
        # term's whitening is a fixed point reached to 1e-6 of the cost), not to rounding: 1e-4 px.
        assert loso["mean_px"] == pytest.approx(np.linalg.norm(uv - pixels, axis=1).mean(), abs=1e-4)
        assert shots[k]["residuals"]["mean_px"] > 0 and "test" in shots[k]
    assert doc["verification"]["n_fit_pairs"] == 24


def test_one_shot_form_equals_the_scan_pairs_form(tmp_path):
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    pairs = str(SAMPLE / "pairs.yaml")
    assert run_cli("solve", "--camera", CAMERA, "--shot", SCAN, pairs, "-o", str(a)).returncode == 0
    assert run_cli("solve", "--camera", CAMERA, "--scan", SCAN, "--pairs", pairs, "-o", str(b)).returncode == 0
    da, db = load_extrinsics_yaml(a), load_extrinsics_yaml(b)
    assert np.max(np.abs(da["T_camera_lidar"] - db["T_camera_lidar"])) <= 1e-12
    assert da["residuals"] == db["residuals"] and da["sigma"] == db["sigma"]
    assert len(da["shots"]) == 1 and "leave_one_shot_out" not in da["shots"][0] and "shots" not in db


def test_a_turned_shot_is_named_in_the_output(shot_files, tmp_path):
    (p0, p1, turned, _), _ = shot_files
    out = tmp_path / "e.yaml"
    proc = run_cli("solve", "--camera", CAMERA, "--shot", SCAN, str(p0), "--shot", SCAN, str(p1),
                   "--shot", SCAN, str(turned), "-o", str(out))
    assert proc.returncode == 0, proc.stderr  # the pose of the two agreeing shots is usable: a warning
    assert "quality: WARNING" in proc.stdout and "shot 2 disagrees with the others by" in proc.stdout
    doc = yaml.safe_load(out.read_text())
    assert doc["quality"]["reasons"][0].startswith("shot 2 disagrees")
    assert [s["in_fit"] for s in doc["shots"]] == [True, True, False]
    assert doc["shots"][2]["test"]["disagrees"] and 2.0 < doc["shots"][2]["test"]["rotation_deg"] < 4.0
    assert doc["verification"]["n_check_pairs"] == 12  # the left-out shot is checked, not fitted


def test_two_shots_that_disagree_exit_3(shot_files, tmp_path):
    (p0, p1, _, turned20), _ = shot_files
    proc = run_cli("solve", "--camera", CAMERA, "--shot", SCAN, str(p0), "--shot", SCAN, str(turned20),
                   "-o", str(tmp_path / "e.yaml"))
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "shots 0 and 1 disagree" in proc.stderr.strip().splitlines()[-1]
    assert (tmp_path / "e.yaml").is_file()


def test_bad_shot_arguments_are_one_line_exit_2(shot_files, tmp_path):
    (p0, p1, _, _), _ = shot_files
    out = str(tmp_path / "e.yaml")
    assert_one_line_error(run_cli("solve", "--camera", CAMERA, "--shot", SCAN, "-o", out),
                          "--shot", "expected 2 arguments")
    assert_one_line_error(run_cli("solve", "--camera", CAMERA, "--shot", SCAN, str(p0), str(p1), "-o", out),
                          "unrecognized arguments")
    assert_one_line_error(run_cli("solve", "--camera", CAMERA, "--shot", SCAN, str(p0), "--pairs", str(p1), "-o", out),
                          "either --shot")
    assert_one_line_error(run_cli("solve", "--camera", CAMERA, "-o", out), "--pairs", "--shot")
    missing = str(tmp_path / "missing.yaml")
    assert_one_line_error(run_cli("solve", "--camera", CAMERA, "--shot", SCAN, missing, "-o", out), "missing.yaml")
    assert_one_line_error(run_cli("propose", "--camera", CAMERA, "--shot", SCAN, str(p0), "--image-for-shot", "1",
                                  str(SAMPLE / "image.png"), "-o", out), "--image-for-shot 1", "1 shots")


def test_propose_across_shots_gives_valid_shot_indices(shot_files, tmp_path):
    (p0, p1, _, _), _ = shot_files
    out = tmp_path / "proposals.yaml"
    proc = run_cli("propose", "--camera", CAMERA, "--shot", SCAN, str(p0), "--shot", SCAN, str(p1),
                   "--image-for-shot", "0", str(SAMPLE / "image.png"), "-n", "12", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    doc = yaml.safe_load(out.read_text())
    props = doc["proposals"]
    assert len(props) == 12 and all(p["shot"] in (0, 1) for p in props)
    assert doc["pose"]["n_pairs"] == 24 and [s["index"] for s in doc["shots"]] == [0, 1]
    used = {0: {tuple(p.laser_rc) for p in load_pairs_yaml(p0)}, 1: {tuple(p.laser_rc) for p in load_pairs_yaml(p1)}}
    for p in props:
        if "replaces" not in p:
            assert tuple(p["laser_rc"]) not in used[p["shot"]]
        else:
            assert 0 <= p["replaces"] < 12
    # Shot 0 has the image: its proposals carry the corner probability, shot 1's do not.
    assert all(("probability" in p) == (p["shot"] == 0) for p in props if "replaces" not in p)
