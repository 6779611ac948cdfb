"""Calibrate the two real PJLab OpenCalib scenes and compare with their published extrinsic.

Data: ``../shared/data/pjlab_opencalib_lidar2camera/{auto_calib,manual_calib}``
(a 64-beam spinning lidar and a 1920x1200 pinhole camera with OpenCV
distortion), read in place.  The published lidar -> camera matrix is parsed
here from the dataset's JSON, independently of the code under test.

The pairs are the committed ``real_data/pairs/*_calib_pairs.yaml``; how they
were made is in ``real_data/README.md`` (method (b): laser cells at foreground
corners chosen by a fixed rule, pixels projected with the published
calibration plus 1 px noise).  The bounds are the issue's: 0.5 deg and 5 cm.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from calib_core.cameras import load_camera
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import load_pairs_yaml, resolve_pairs
from calib_core.solve import solve_extrinsics


REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "pjlab_opencalib_lidar2camera"
PAIRS = REPO / "real_data" / "pairs"

# scene -> (scan file, load_scan options, image-size override, CLI options)
SCENES = {
    "auto_calib": ("calib.pcd", {}, None, []),
    # 0.pcd has no ring field: 64 beams by elevation clustering.  Its JSON
    # claims 1920x1080 but the image is 1920x1200.
    "manual_calib": ("0.pcd", {"beams": 64}, (1920, 1200), ["--beams", "64", "--image-size", "1920", "1200"]),
}
pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(
        not all((DATA / scene / files[0]).is_file() for scene, files in SCENES.items()),
        reason=f"real data not found at {DATA} (the PJLab OpenCalib scenes of ../shared/data)",
    ),
]

MAX_ROTATION_DEG = 0.5
MAX_TRANSLATION_M = 0.05


def _scene_dir(scene: str) -> Path:
    return DATA / scene


def published_T(scene_dir: Path) -> np.ndarray:
    """The dataset's 4x4 lidar -> camera matrix, straight from its JSON."""
    data = json.loads((scene_dir / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    T = np.array(data["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], dtype=float)
    assert T.shape == (4, 4)
    return T


def pose_errors(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """Rotation error (deg, angle of R_ref^T R_est, from the trace) and translation error (m)."""
    cos_angle = (np.trace(T_ref[:3, :3].T @ T_est[:3, :3]) - 1.0) / 2.0
    rotation_deg = float(np.degrees(np.arccos(np.clip(cos_angle, -1.0, 1.0))))
    return rotation_deg, float(np.linalg.norm(T_est[:3, 3] - T_ref[:3, 3]))


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_real_scene_matches_published_extrinsic(scene):
    scene_dir = _scene_dir(scene)
    scan_name, options, image_size, _ = SCENES[scene]
    depth = load_scan(scene_dir / scan_name, **options)
    assert depth.shape[0] == 64 and 1700 <= depth.shape[1] <= 1900, depth.shape
    camera = load_camera(scene_dir / "center_camera-intrinsic.json", image_size=image_size)
    assert (camera.width, camera.height) == (1920, 1200)

    pairs = load_pairs_yaml(PAIRS / f"{scene}_pairs.yaml")
    assert 10 <= len(pairs) <= 12
    points, bearings, pixels = resolve_pairs(pairs, depth, camera)
    result = solve_extrinsics(points, bearings, camera=camera, pixels=pixels)

    rotation_deg, translation_m = pose_errors(result.T_camera_lidar, published_T(scene_dir))
    print(
        f"\n{scene}: {len(pairs)} pairs; rotation error {rotation_deg:.3f} deg, "
        f"translation error {100 * translation_m:.2f} cm; reprojection {result.mean_px:.2f} +/- {result.std_px:.2f} px"
    )
    assert rotation_deg < MAX_ROTATION_DEG
    assert translation_m < MAX_TRANSLATION_M
    # Pixels were made with 1 px noise per axis: a mean residual far above
    # that would mean the cells or the camera model are read wrongly.
    assert result.mean_px < 3.0


def test_cli_solve_on_real_scene(tmp_path):
    scene = "manual_calib"
    scene_dir = _scene_dir(scene)
    scan_name, _, _, cli_options = SCENES[scene]
    out = tmp_path / "extrinsics.yaml"
    cmd = [
        sys.executable, "-m", "app.cli", "solve",
        "--scan", str(scene_dir / scan_name),
        "--camera", str(scene_dir / "center_camera-intrinsic.json"),
        "--pairs", str(PAIRS / f"{scene}_pairs.yaml"),
        "-o", str(out),
        *cli_options,
    ]  # fmt: skip
    run = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "reprojection error" in run.stdout
    written = yaml.safe_load(out.read_text())
    T = np.array(written["T_camera_lidar"]["matrix"], dtype=float)
    rotation_deg, translation_m = pose_errors(T, published_T(scene_dir))
    print(f"\nCLI on {scene}: rotation error {rotation_deg:.3f} deg, translation error {100 * translation_m:.2f} cm")
    assert rotation_deg < MAX_ROTATION_DEG
    assert translation_m < MAX_TRANSLATION_M
