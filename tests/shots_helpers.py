"""A second shot of the sample's rig, as files: room 1 of the synthetic generator seen with the sample's
``T_camera_lidar`` (one rig, two scenes), with its ground truth, for the app's several-shot tests.

The scan is room 1's (in the lidar frame, whatever the camera); the photo is rendered here with the
sample's camera at the sample's extrinsics, so both shots share one camera and one ``T_camera_lidar``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from calib_core.io.images import save_image_rgb
from calib_core.lidar import save_depth_npz
from calib_core.synthetic import load_sample
from calib_core.synthetic.picks import CIRCLE_MARGIN_PX, MAX_LASER_PICK_ERROR_M, laser_picks
from calib_core.synthetic.render import image_circle_mask, render_image, render_scan
from calib_core.synthetic.sample import (IMAGE_CIRCLE_RADIUS_PX, MAX_RANGE_M, RANGE_NOISE_M, SCANNER_DX_M,
                                         SCANNER_DZ_M, SampleScene, _corners, scanner_angles_grid)
from calib_core.synthetic.scene import build_room
from calib_core.transforms import transform_points
from repo_paths import SAMPLE


def on_rig(scene: SampleScene) -> SampleScene:
    """The scene's corners the rig's camera sees inside its image circle and the scan picks well."""
    corners = np.asarray(scene.corners_lidar, dtype=np.float64)
    pix, ok = scene.camera.project(transform_points(scene.T_camera_lidar, corners))
    ok &= np.all(np.isfinite(pix), axis=1)
    ok[ok] &= image_circle_mask(scene.camera, pix[ok], IMAGE_CIRCLE_RADIUS_PX - CIRCLE_MARGIN_PX)
    ok &= laser_picks(scene.depth, corners)[1] <= MAX_LASER_PICK_ERROR_M
    return dataclasses.replace(scene, corners_lidar=corners[ok], corner_labels=[])


def write_second_shot(out_dir: Path) -> tuple[SampleScene, SampleScene, Path, Path]:
    """Write room 1 on the sample's rig: ``(sample on its rig, room 1 on the rig, scan.npz, image.png)``."""
    sample = load_sample(SAMPLE)
    room = dataclasses.replace(build_room(1), T_camera_lidar=sample.T_camera_lidar.copy())
    theta, phi = scanner_angles_grid(1)
    depth = render_scan(room, theta, phi, SCANNER_DX_M, SCANNER_DZ_M, np.random.default_rng([room.seed, 2]),
                        RANGE_NOISE_M, MAX_RANGE_M)
    image = render_image(room, sample.camera, IMAGE_CIRCLE_RADIUS_PX, np.random.default_rng([room.seed, 3]))
    corners, labels = _corners(room, sample.camera, depth, 1)  # seen by both sensors, unoccluded
    scene = SampleScene(depth, image, sample.camera, sample.T_camera_lidar.copy(), room.T_world_lidar.copy(),
                        corners, labels, room.seed, room)
    out_dir.mkdir(parents=True, exist_ok=True)
    scan_path, image_path = out_dir / "scan1.npz", out_dir / "image1.png"
    save_depth_npz(scan_path, depth)
    save_image_rgb(image_path, image)
    return on_rig(sample), on_rig(scene), scan_path, image_path


def sample_shot_server(session_path: Path, *more_shots: tuple[Path, Path], **options):
    """A :class:`app.serving.ShotServer` on the sample (shot 0) and ``more_shots`` ``(scan, image)``, the sample's
    camera, a free port unless ``port`` is given."""
    from app.serving import ShotServer

    options.setdefault("port", 0)
    return ShotServer([(SAMPLE / "scan.npz", SAMPLE / "image.png"), *more_shots], SAMPLE / "camera.yaml",
                      session_path=session_path, **options)
