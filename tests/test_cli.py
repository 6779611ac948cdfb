"""The headless ``ba-calib`` commands on the committed sample, and their errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.io.images import load_image_rgb
from calib_core.transforms import rotation_angle_deg
from repo_paths import SAMPLE


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).resolve().parents[1],
    )


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, f"expected one line, got:\n{proc.stderr}"
    assert lines[0].startswith("error: ")
    assert "Traceback" not in proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


def test_solve_on_the_sample_recovers_ground_truth(tmp_path):
    out = tmp_path / "extrinsics.yaml"
    proc = run_cli(
        "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
        "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(out),
    )
    assert proc.returncode == 0, proc.stderr
    assert "reprojection error" in proc.stdout and "yaw [deg]" in proc.stdout
    got = load_extrinsics_yaml(out)
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    T = got["T_camera_lidar"]
    rot = rotation_angle_deg(T[:3, :3], truth[:3, :3])
    trans = np.linalg.norm(T[:3, 3] - truth[:3, 3])
    print(f"CLI solve on sample_data/pairs.yaml: rotation error {rot:.4f} deg, translation error {100 * trans:.2f} cm")
    assert rot <= 0.5 and trans <= 0.05
    assert len(got["pairs"]) == len(got["residuals"]["per_pair"]) >= 4
    assert got["camera"]["model"] == "ocam"


def test_ba_images_writes_four_pngs(tmp_path):
    proc = run_cli("ba-images", "--scan", str(SAMPLE / "scan.npz"), "-o", str(tmp_path / "ba"))
    assert proc.returncode == 0, proc.stderr
    pngs = sorted((tmp_path / "ba").glob("*.png"))
    assert [p.name for p in pngs] == sorted(
        ["ba_horizontal.png", "ba_vertical.png", "ba_diag_pos45.png", "ba_diag_neg45.png"]
    )
    shapes = {load_image_rgb(p).shape[:2] for p in pngs}
    assert shapes == {(180, 720)}


def test_colorize_writes_a_coloured_ply(tmp_path):
    out = tmp_path / "cloud.ply"
    proc = run_cli(
        "colorize", "--scan", str(SAMPLE / "scan.npz"), "--image", str(SAMPLE / "image.png"),
        "--camera", str(SAMPLE / "camera.yaml"), "--extrinsics", str(SAMPLE / "ground_truth.yaml"), "-o", str(out),
    )
    assert proc.returncode == 0, proc.stderr
    cloud = trimesh.load(out)
    assert len(cloud.vertices) > 50_000
    grey = (cloud.colors[:, :3] == 128).all(axis=1)
    assert 0.1 < 1 - grey.mean() < 1.0, "some points coloured, and some left grey (outside the view or occluded)"


def test_missing_scan_file(tmp_path):
    proc = run_cli("ba-images", "--scan", str(tmp_path / "nope.npz"), "-o", str(tmp_path))
    assert_one_line_error(proc, "nope.npz")


def test_malformed_pairs_file(tmp_path):
    bad = tmp_path / "pairs.yaml"
    bad.write_text("pairs:\n  - laser_rc: [1, 2]\n")
    proc = run_cli(
        "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
        "--pairs", str(bad), "-o", str(tmp_path / "e.yaml"),
    )
    assert_one_line_error(proc, "pairs.yaml", "missing pixel")
    assert not (tmp_path / "e.yaml").exists()


def test_too_few_pairs(tmp_path):
    import yaml

    pairs = yaml.safe_load((SAMPLE / "pairs.yaml").read_text())
    few = tmp_path / "few.yaml"
    few.write_text(yaml.safe_dump({"pairs": pairs["pairs"][:3]}))
    proc = run_cli(
        "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
        "--pairs", str(few), "-o", str(tmp_path / "e.yaml"),
    )
    assert_one_line_error(proc, "4")


def test_malformed_camera_file(tmp_path):
    cam = tmp_path / "cam.yaml"
    cam.write_text("model: pinhole\nwidth: 640\n")
    proc = run_cli(
        "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(cam),
        "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(tmp_path / "e.yaml"),
    )
    assert_one_line_error(proc, "cam.yaml")


def test_pairs_with_cells_need_a_scan(tmp_path):
    proc = run_cli(
        "solve", "--camera", str(SAMPLE / "camera.yaml"), "--pairs", str(SAMPLE / "pairs.yaml"),
        "-o", str(tmp_path / "e.yaml"),
    )
    assert_one_line_error(proc, "--scan")


def test_version_is_the_package_version():
    from calib_core import __version__

    proc = run_cli("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"ba-calib {__version__}"


def test_closed_pipe_loses_no_result(tmp_path):
    out = tmp_path / "e.yaml"
    cmd = [sys.executable, "-m", "app.cli", "solve", "--scan", str(SAMPLE / "scan.npz"),
           "--camera", str(SAMPLE / "camera.yaml"), "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=SAMPLE.parent)
    proc.stdout.readline()  # read one line, then hang up like `| head -1`
    proc.stdout.close()
    assert proc.wait(timeout=300) == 0
    stderr = proc.stderr.read().decode()
    assert "Traceback" not in stderr and "internal error" not in stderr
    assert load_extrinsics_yaml(out)["T_camera_lidar"].shape == (4, 4)
