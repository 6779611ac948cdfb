"""Extrinsics YAML: the round trip loses nothing, and bad files get clear errors."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from calib_core.errors import CalibError
from calib_core.io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml
from calib_core.pairs import Pair


def _T(yaw_deg=30.0, t=(0.21, 0.04, 0.14)):
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


def test_round_trip_is_exact_and_forms_agree(tmp_path):
    T = _T(166.95, (0.207, 0.042, 0.139))
    pairs = [Pair((3, 4), None, (1.5, 2.25))]
    path = tmp_path / "e.yaml"
    save_extrinsics_yaml(path, T, pairs=pairs)
    doc = load_extrinsics_yaml(path)
    np.testing.assert_array_equal(doc["T_camera_lidar"], T)
    block = doc["T_camera_lidar_block"]
    # Hand-computed forms of a pure yaw of 166.95 deg.
    np.testing.assert_allclose(block["rpy_deg"], [0, 0, 166.95], atol=1e-9)
    half = np.radians(166.95) / 2
    np.testing.assert_allclose(np.abs(block["quaternion_xyzw"]), [0, 0, np.sin(half), np.cos(half)], atol=1e-12)
    assert block["translation_m"] == [0.207, 0.042, 0.139]
    assert doc["pairs"] == [{"laser_rc": [3, 4], "pixel": [1.5, 2.25]}]
    # Saving what was loaded writes the identical document again.
    path2 = tmp_path / "e2.yaml"
    save_extrinsics_yaml(path2, doc["T_camera_lidar"], pairs=[Pair.from_dict(p, "p") for p in doc["pairs"]])
    assert yaml.safe_load(path.read_text()) == yaml.safe_load(path2.read_text())


def test_translation_and_rpy_alone_are_accepted(tmp_path):
    path = tmp_path / "e.yaml"
    path.write_text("T_camera_lidar:\n  translation_m: [1, 2, 3]\n  rpy_deg: [0, 0, 90]\n")
    T = load_extrinsics_yaml(path)["T_camera_lidar"]
    # yaw 90 deg maps the lidar x axis onto the camera y axis.
    np.testing.assert_allclose(T[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [1, 2, 3])


@pytest.mark.parametrize(
    "body, fragment",
    [
        ("foo: 1\n", "missing top-level key 'T_camera_lidar'"),
        ("T_camera_lidar: 3\n", "expected a mapping"),
        ("T_camera_lidar:\n  matrix: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]\n", "4x4"),
        ("T_camera_lidar:\n  matrix: [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n", "not a proper rotation"),
        ("T_camera_lidar:\n  matrix: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]\n", "last row"),
        ("T_camera_lidar:\n  matrix: [[1, 0, 0, .nan], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n", "finite"),
        (
            "T_camera_lidar:\n  matrix: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n"
            "  translation_m: [0, 0, 0]\n  rpy_deg: [0, 0, 10]\n",
            "disagrees",
        ),
        ("T_camera_lidar:\n  translation_m: [0, 0, 0]\n  quaternion_xyzw: [0, 0, 0, 2]\n", "unit norm"),
        ("T_camera_lidar: {}\n", "needs 'matrix'"),
    ],
)
def test_bad_files_name_the_problem(tmp_path, body, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(body)
    with pytest.raises(CalibError) as err:
        load_extrinsics_yaml(path)
    assert fragment in str(err.value) and str(path) in str(err.value)
