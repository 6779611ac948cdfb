"""PreparedScene loads and precomputes a scene without viser (issue 11, "Structure")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from calib_core.errors import CalibError
from repo_paths import SAMPLE

ROOT = Path(__file__).resolve().parents[1]


def test_prepared_scene_loads_the_sample_without_importing_viser():
    code = (
        "import sys\n"
        "from app.prepared_scene import PreparedScene\n"
        f"s = PreparedScene.load({str(SAMPLE / 'scan.npz')!r}, {str(SAMPLE / 'image.png')!r}, "
        f"{str(SAMPLE / 'camera.yaml')!r}, max_cloud_points=1000)\n"
        "assert 'viser' not in sys.modules, 'viser imported'\n"
        "print(len(s.ba_keys), s.depth.shape, s.panorama is not None, len(s.cloud_points_lidar) <= 1000,"
        " len(s.all_points_lidar) == int(s.depth.valid.sum()))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    n_keys = out.stdout.strip().split(" ", 1)[0]
    assert out.stdout.strip().endswith("True True True"), out.stdout
    assert int(n_keys) == 4


def test_image_and_camera_size_mismatch_is_one_clear_error(tmp_path):
    from PIL import Image

    from app.prepared_scene import PreparedScene

    Image.new("RGB", (10, 10)).save(tmp_path / "small.png")
    with pytest.raises(CalibError, match=r"small\.png: image is 10x10 but the camera model"):
        PreparedScene.load(SAMPLE / "scan.npz", tmp_path / "small.png", SAMPLE / "camera.yaml")
