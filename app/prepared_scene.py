"""A scene loaded and precomputed for the app, with no viser: scan, camera, image, BA images, panorama, edges.

Everything here comes from :mod:`calib_core`; the app only shows it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from calib_core.bearing_angle import BA_DIRECTIONS, ba_to_display, bearing_angle_images
from calib_core.cameras import load_camera
from calib_core.display_images import field_to_gray, find_intensity
from calib_core.errors import CalibError
from calib_core.io.images import load_image_rgb
from calib_core.overlays import ba_edge_points_consensus
from calib_core.panorama import Panorama

from .ba_view import cell_aspect_from_directions

if TYPE_CHECKING:
    from .view_settings import ViewSettings

#: Display points of the 3-D cloud (software WebGL slows down beyond ~100k).
MAX_CLOUD_POINTS = 100_000
MAX_EDGE_POINTS = 3000


@dataclass(eq=False)
class PreparedScene:
    """The inputs of one calibration and what the views need from them."""

    scan_path: Path
    image_path: Path
    camera_path: Path
    depth: Any  # DepthMatrix: the organised scan (lidar frame, metres)
    camera: Any  # CameraModel
    image: np.ndarray  # (H, W, 3) uint8: the camera image
    ba_rad: dict  # Bearing Angle images (R, C) float (radians) per direction
    ba_keys: tuple  # the directions present
    ba_gray: dict  # the BA images as shown, (R, C) uint8
    image_gray: np.ndarray
    panorama: Panorama | None  # the unwrapping of an ocam / fisheye image, with pano_image (RGB) and pano_gray
    pano_image: np.ndarray | None
    pano_gray: np.ndarray | None
    edge_points_lidar: np.ndarray  # (M, 3) BA-edge points for the overlay (lidar frame, metres)
    all_points_lidar: np.ndarray  # (N, 3) the valid scan points (lidar frame, metres) ...
    all_rows_cols: np.ndarray  # (N, 2) int: ... and their cells
    cloud_points_lidar: np.ndarray  # (K, 3) the subsample shown in the 3-D pane
    ba_cell_aspect: float  # row stretch that makes cells about square in angle
    wrap_cols: bool  # the scan's columns wrap around (a full revolution)
    # Other grey views (R, C) uint8 of the scan for the BA loupe: "Range" always, "Intensity" when the scan has a
    # reflectance field (0 where no value).
    laser_images: dict
    image_valid: np.ndarray  # (H, W) bool: pixels the camera lights (not the black border of a fisheye circle)

    @classmethod
    def load(
        cls,
        scan_path: str | os.PathLike,
        image_path: str | os.PathLike,
        camera_path: str | os.PathLike,
        *,
        scan_options: dict | None = None,
        image_size: tuple[int, int] | None = None,
        kitti_camera: int | None = None,
        max_cloud_points: int = MAX_CLOUD_POINTS,
    ) -> "PreparedScene":
        """Read the three files and precompute.  CalibError on unreadable or inconsistent inputs."""
        from calib_core.io.scan_readers import load_scan

        scan_path, image_path, camera_path = Path(scan_path), Path(image_path), Path(camera_path)
        depth = load_scan(scan_path, **(scan_options or {}))
        camera = load_camera(camera_path, image_size=image_size, kitti_camera=kitti_camera)
        image = load_image_rgb(image_path)
        h, w = image.shape[:2]
        if (w, h) != (camera.width, camera.height):
            raise CalibError(
                f"{image_path}: image is {w}x{h} but the camera model {camera_path} is {camera.width}x{camera.height}"
            )
        ba_rad = bearing_angle_images(depth)
        ba_keys = tuple(k for k in BA_DIRECTIONS if k in ba_rad)
        panorama = pano_image = pano_gray = None
        if camera.model in ("ocam", "fisheye"):
            panorama = Panorama.for_camera(camera, image_mask=image.max(axis=2) > 0, oversample=2.0)
            pano_image = panorama.render(image)
            pano_gray = pano_image.mean(axis=2).astype(np.uint8)
        edge_points, _ = ba_edge_points_consensus(ba_rad, depth, max_points=MAX_EDGE_POINTS)
        points, rows_cols = depth.valid_points()
        laser_images = {"Range": field_to_gray(np.where(depth.valid, depth.range_m, np.nan), log=True)}
        intensity = find_intensity(depth.meta.get("field_images"))
        if intensity is not None:
            laser_images["Intensity"] = field_to_gray(intensity[1])
        stride = max(1, int(math.ceil(len(points) / max(1, int(max_cloud_points)))))
        return cls(
            scan_path=scan_path, image_path=image_path, camera_path=camera_path, depth=depth, camera=camera,
            image=image, ba_rad=ba_rad, ba_keys=ba_keys, ba_gray={k: ba_to_display(ba_rad[k]) for k in ba_keys},
            image_gray=image.mean(axis=2).astype(np.uint8), panorama=panorama, pano_image=pano_image,
            pano_gray=pano_gray, edge_points_lidar=edge_points, all_points_lidar=points, all_rows_cols=rows_cols,
            cloud_points_lidar=points[::stride], ba_cell_aspect=cell_aspect_from_directions(depth.directions),
            wrap_cols=bool(depth.meta.get("wrap_cols", False)), laser_images=laser_images,
            image_valid=image.max(axis=2) > 0,
        )

    def default_view(self) -> "ViewSettings":
        """The view settings of a new session on this scene.

        The BA panes show the columns the camera sees (under the rough pose, else the "+x" preset).  The
        render is shaded by intensity where the scan has it: in the by-eye trials range shading hid the
        doors, bins and boxes that intensity shows, and every clicker switched (docs/by_eye.md).
        """
        from .view_settings import ViewSettings

        return ViewSettings(up_axis="+y" if self.depth.meta.get("model") == "rotating_2d" else "+z",
                            ba_window_mode="camera",
                            render_mode="intensity" if "Intensity" in self.laser_images else "range")
