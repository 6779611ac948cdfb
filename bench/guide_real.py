"""Guided picking on real scenes (PJLab OpenCalib auto_calib, KITTI object 000002), against their published calibrations.

A trial: 5 rough pairs (the committed real_data pairs' cells, pixels = their
projection under the published extrinsic + 3 px Gaussian noise), then 20
guided pairs: each proposal is clicked at its laser point's projection under
the published extrinsic + 0.5 px noise (the issue's simulated person).  The
published calibration is not ground truth, but it is what the clicks are
simulated from, so a correct guide converges to it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from calib_core.cameras import load_camera
from calib_core.guide.session import GuidedSession
from calib_core.io.images import load_image_rgb
from calib_core.io.kitti_calib import read_kitti_camera2
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import Pair, load_pairs_yaml
from calib_core.transforms import rotation_angle_deg, transform_points

from .common import REPO

DATA = REPO.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"
PAIRS = REPO / "real_data" / "pairs" / "auto_calib_pairs.yaml"
KITTI = REPO.parent / "shared" / "data" / "kitti_object_000002"
KITTI_PAIRS = REPO / "real_data" / "pairs" / "kitti_000002_pairs.yaml"
KITTI_CAMERA = REPO / "real_data" / "kitti_000002_camera.yaml"


@dataclass
class RealScene:
    depth: object
    camera: object
    image: np.ndarray
    T_published: np.ndarray
    pairs: list


def available() -> bool:
    return (DATA / "calib.pcd").is_file() and PAIRS.is_file()


def kitti_available() -> bool:
    return (KITTI / "velodyne" / "000002.bin").is_file() and KITTI_PAIRS.is_file() and KITTI_CAMERA.is_file()


def load_kitti() -> RealScene:
    """KITTI object 000002: the rectified left colour camera; the published pose is
    ``[I | K^-1 P2[:, 3]] @ R0_rect @ Tr_velo_to_cam`` parsed from calib/000002.txt."""
    _, T = read_kitti_camera2(KITTI / "calib" / "000002.txt")
    return RealScene(load_scan(KITTI / "velodyne" / "000002.bin"), load_camera(KITTI_CAMERA),
                     load_image_rgb(KITTI / "image_2" / "000002.png"), T, load_pairs_yaml(KITTI_PAIRS))


def load_pjlab() -> RealScene:
    """The auto_calib scene; the published matrix is read straight from the dataset's JSON."""
    data = json.loads((DATA / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    T = np.array(data["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], dtype=float)
    return RealScene(load_scan(DATA / "calib.pcd"), load_camera(DATA / "center_camera-intrinsic.json"),
                     load_image_rgb(DATA / "calib.png"), T, load_pairs_yaml(PAIRS))


def _in_image(camera, uv, margin_px: float = 1.5) -> bool:
    """Whether a pixel and its 0.5 px click noise (3 sigma) stay on the picture."""
    return bool(margin_px <= uv[0] <= camera.width - 1 - margin_px and margin_px <= uv[1] <= camera.height - 1 - margin_px)


def real_trial(scene: RealScene, rng: np.random.Generator, n_rough: int = 5, rough_px: float = 3.0,
               n_guided: int = 20, click_px: float = 0.5, use_image: bool = False) -> tuple[float, float, int, float]:
    """One trial against the published pose: rotation error (deg), translation error (m), guided
    pairs made, and the share of the proposals' true pixels inside their 3-sigma ellipses."""
    T = scene.T_published
    pick = rng.choice(len(scene.pairs), size=n_rough, replace=False)
    rough = []
    for i in pick:
        rc = scene.pairs[i].laser_rc
        uv, _ = scene.camera.project(transform_points(T, scene.depth.points[rc[0], rc[1]][None]))
        uv = uv[0] + rng.normal(0.0, rough_px, 2)
        uv = np.clip(uv, [0, 0], [scene.camera.width - 1, scene.camera.height - 1])
        rough.append(Pair(rc, None, (float(uv[0]), float(uv[1])), precision_px=rough_px))
    session = GuidedSession(scene.depth, scene.camera, rough, image=scene.image if use_image else None,
                            click_sigma_px=click_px)
    made, inside = 0, []
    while made < n_guided:
        props = session.proposals(1)
        if not props:
            break
        p = props[0]
        uv, ok = scene.camera.project(transform_points(T, np.asarray(p.laser_xyz)[None]))
        if not (ok[0] and _in_image(scene.camera, uv[0])):  # the person cannot click a point off the picture
            session.not_a_corner(p)
            continue
        d = uv[0] - p.pixel
        inside.append(float(d @ np.linalg.solve(p.pixel_cov, d)) <= 9.0)
        click = np.clip(uv[0] + rng.normal(0.0, click_px, 2), 0, [scene.camera.width - 1, scene.camera.height - 1])
        session.accept(p, click)
        made += 1
    est = session.solve().T_camera_lidar
    share = float(np.mean(inside)) if inside else float("nan")
    return rotation_angle_deg(est[:3, :3], T[:3, :3]), float(np.linalg.norm(est[:3, 3] - T[:3, 3])), made, share


def auto_accept_check(scene: RealScene, rng: np.random.Generator, gate=None, n_rough: int = 5, n_guided: int = 20,
                      click_px: float = 0.5) -> tuple[int, list[tuple[float, float]]]:
    """The auto-accept gate on a real scene after 5 rough + ``n_guided`` guided pairs (as :func:`real_trial`,
    with the image filter on): the number of proposals judged and, for every proposal (up to 200) that passes, the distance (px) from the
    corner it found to the cell's projection under the published calibration, and that distance in
    sigmas of the proposal's ellipse (a pass more than 3 sigma off is a wrong match; within, it is
    consistent with the published calibration, which is not ground truth)."""
    from calib_core.guide.auto_accept import auto_accept

    T = scene.T_published
    pick = rng.choice(len(scene.pairs), size=n_rough, replace=False)
    rough = []
    for i in pick:
        rc = scene.pairs[i].laser_rc
        uv, _ = scene.camera.project(transform_points(T, scene.depth.points[rc[0], rc[1]][None]))
        uv = np.clip(uv[0] + rng.normal(0.0, 3.0, 2), [0, 0], [scene.camera.width - 1, scene.camera.height - 1])
        rough.append(Pair(rc, None, (float(uv[0]), float(uv[1])), precision_px=3.0))
    session = GuidedSession(scene.depth, scene.camera, rough, image=scene.image, click_sigma_px=click_px)
    made = 0
    while made < n_guided:
        props = session.proposals(1)
        if not props:
            break
        uv, ok = scene.camera.project(transform_points(T, np.asarray(props[0].laser_xyz)[None]))
        if not (ok[0] and _in_image(scene.camera, uv[0])):
            session.not_a_corner(props[0])
            continue
        session.accept(props[0], np.clip(uv[0] + rng.normal(0.0, click_px, 2), 0,
                                         [scene.camera.width - 1, scene.camera.height - 1]))
        made += 1
    props = session.proposals(200)
    passed, pixels = auto_accept(session.corners, props, gate, image=scene.image, depth=scene.depth,
                                 camera=scene.camera, T_camera_lidar=session.state.T_camera_lidar)
    out = []
    for p, ok, px in zip(props, passed, pixels):
        if ok:
            uv, _ = scene.camera.project(transform_points(T, np.asarray(p.laser_xyz)[None]))
            d = px - uv[0]
            out.append((float(np.linalg.norm(d)), float(np.sqrt(d @ np.linalg.solve(p.pixel_cov, d)))))
    return len(props), out
