"""By-eye run 6 (docs/by_eye.md): "Laser points lie near one plane: add pairs off that plane" did not say where.
The reason now names the plane (level, across or along the view) and where off-plane pairs would go; checked on
the sample's floor corners against the image rows, columns and ranges computed here from the ground truth."""

from __future__ import annotations

import re

import numpy as np
import yaml

from calib_core.pairs import Pair
from calib_core.solve.calibrate import calibrate
from calib_core.synthetic import load_sample
from calib_core.transforms import transform_points
from repo_paths import SAMPLE


def test_the_one_plane_reason_says_where_to_add_pairs():
    scene = load_sample(SAMPLE)
    cam, truth = scene.camera, scene.T_camera_lidar
    xyz = np.array([c["xyz"] for c in yaml.safe_load((SAMPLE / "corners.yaml").read_text())["corners"]])
    floor = xyz[np.abs(xyz[:, 1] - xyz[:, 1].min()) < 0.02]  # lidar y is vertical: the floor's corners
    seen = 0
    for k in range(12):
        rng = np.random.default_rng([6, k])
        pick = floor[rng.choice(len(floor), 5, replace=False)]
        uv, ok = cam.project(transform_points(truth, pick))
        if not ok.all():
            continue
        clicked = uv + rng.normal(0.0, 0.5, uv.shape)
        pairs = [Pair(None, tuple(map(float, p)), tuple(map(float, c)), id=i + 1) for i, (p, c) in
                 enumerate(zip(pick, clicked))]
        res = calibrate(pairs, None, cam)
        plane = [r for r in res.quality.reasons if "near one plane" in r]
        assert plane, res.quality.reasons
        reason = plane[0]
        seen += 1
        # The floor is level in the camera frame (its normal along the camera's y, up-down).
        normal = np.linalg.svd(transform_points(truth, pick) - transform_points(truth, pick).mean(0))[2][2]
        assert abs(normal[1]) > 0.8
        if res.quality.status == "unreliable":  # the solved pose may be far off: the plane is not named from it
            assert "the plane is" not in reason and "add pairs in the image's empty thirds" in reason, reason
        else:
            assert "the plane is level (like the ground)" in reason, reason
            # Off-plane pairs go above the pairs' rows.
            m = re.search(r"add pairs above image row (\d+)", reason)
            assert m and abs(int(m.group(1)) - clicked[:, 1].min()) <= 1.0, reason
        # The range band is the pairs' (from the lidar).
        band = re.search(r"the pairs (\d+\.\d)-(\d+\.\d) m from the lidar", reason)
        ranges = np.linalg.norm(pick, axis=1)
        assert band and abs(float(band.group(1)) - ranges.min()) <= 0.051, reason
        assert abs(float(band.group(2)) - ranges.max()) <= 0.051, reason
        # The image's thirds with no pair are named, and only those.
        for name, lo in (("top", 0.0), ("middle", cam.height / 3), ("bottom", 2 * cam.height / 3)):
            has = ((clicked[:, 1] >= lo - 0.5) & (clicked[:, 1] < lo + cam.height / 3 - 0.5)).any()
            assert (f"{name} third" in reason) != has, (name, reason)
        assert res.quality.status in ("warning", "unreliable")  # the verdict itself is unchanged
    assert seen >= 4
