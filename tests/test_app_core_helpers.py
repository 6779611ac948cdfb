"""Maths the app used to hold, now in calib_core: checked on the sample against its ground truth."""

from __future__ import annotations


import numpy as np
import trimesh

from calib_core.cameras import PinholeCamera, load_camera
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.io.images import load_image_rgb
from calib_core.io.scan_readers import load_scan
from calib_core.overlays import columns_seen_by_camera, export_colored_scan
from calib_core.pairs import load_pairs_yaml
from repo_paths import SAMPLE


def scene():
    depth = load_scan(SAMPLE / "scan.npz")
    camera = load_camera(SAMPLE / "camera.yaml")
    T = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    return depth, camera, T


def test_columns_seen_by_camera_holds_every_clicked_pair():
    depth, camera, T = scene()
    seen = columns_seen_by_camera(depth, camera, T)
    assert seen.shape == (depth.shape[1],) and seen.dtype == bool
    cols = [p.laser_rc[1] for p in load_pairs_yaml(SAMPLE / "pairs.yaml")]
    assert seen[cols].all()  # every pair was clicked in the image, so its column is seen


def test_columns_seen_by_a_narrow_camera_match_a_column_by_column_check():
    depth, _, T = scene()
    narrow = PinholeCamera(np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]]), np.zeros(5), 640, 480)
    seen = columns_seen_by_camera(depth, narrow, T)
    assert 0 < seen.sum() < 0.5 * len(seen)  # about 94 deg of 360
    for col in range(0, depth.shape[1], 37):  # one column at a time, its own points
        rows = np.flatnonzero(depth.valid[:, col])
        pts = depth.points[rows, col]
        cam = pts @ T[:3, :3].T + T[:3, 3]
        ok = narrow.project(cam)[1]
        assert seen[col] == bool(ok.any()), col


def test_export_colored_scan_writes_every_valid_point(tmp_path):
    depth, camera, T = scene()
    image = load_image_rgb(SAMPLE / "image.png")
    coloured, n = export_colored_scan(tmp_path / "c.ply", depth, image, camera, T)
    cloud = trimesh.load(tmp_path / "c.ply")
    assert n == int(depth.valid.sum()) == len(cloud.vertices)
    assert 0 < coloured < n
