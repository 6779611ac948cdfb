"""The camera views the page can show: the raw image, or for ``ocam`` / ``fisheye`` cameras the image unwrapped
into a panorama.  Both answer the same questions (:class:`CameraView`), so the app has no panorama branches.

*Display* pixels are pixels of the view shown; *original* pixels are of the camera image, where pairs and
errors live.  The maths is :class:`calib_core.panorama.Panorama` and the camera model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import cv2
import numpy as np


class CameraView(Protocol):
    """One way of showing the camera image."""

    key: str  #: the view's slot key in the layout (``"raw"`` or ``"panorama"``)
    image: np.ndarray  #: (H, W, 3) uint8, what is shown
    gray: np.ndarray  #: (H, W) uint8, for snapping clicks to corners

    def title(self) -> str:
        """The view's title on the page."""

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display pixels ``(N, 2)`` of original pixels, and which are shown."""

    def pixels_from_display(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Original pixels ``(N, 2)`` of display pixels, and which the camera sees."""

    def display_from_camera_points(self, points_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display pixels of points in the camera frame (metres), and which the camera sees."""

    def shown(self, raw: np.ndarray) -> np.ndarray:
        """An array of the original image's shape ``(H, W[, C])`` (e.g. a render) as this view shows it: each
        display pixel takes the nearest original pixel; 0 where the camera sees nothing."""


@dataclass(eq=False)
class RawView:
    """The camera image as recorded."""

    camera: Any
    image: np.ndarray
    gray: np.ndarray
    key: str = "raw"

    def title(self) -> str:
        return f"Camera image ({self.camera.model}, {self.camera.width}x{self.camera.height})"

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        return p, np.isfinite(p).all(axis=1)

    def pixels_from_display(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.display_from_pixels(uv)

    def shown(self, raw: np.ndarray) -> np.ndarray:
        return raw

    def display_from_camera_points(self, points_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pts = np.asarray(points_camera, dtype=np.float64).reshape(-1, 3)
        if len(pts) == 0:
            return np.empty((0, 2)), np.zeros(0, bool)
        return self.camera.project(pts)


@dataclass(eq=False)
class PanoramaView:
    """The image unwrapped to azimuth x elevation (:class:`calib_core.panorama.Panorama`)."""

    camera: Any
    panorama: Any
    image: np.ndarray
    gray: np.ndarray
    key: str = "panorama"

    def title(self) -> str:
        return f"Camera, unwrapped panorama ({self.camera.model}); errors are measured in the original image"

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        if len(p) == 0:
            return p, np.zeros(0, bool)
        return self.panorama.from_camera_pixels(p)

    def pixels_from_display(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.panorama.to_camera_pixels(np.asarray(uv, dtype=np.float64).reshape(-1, 2))

    def shown(self, raw: np.ndarray) -> np.ndarray:
        return self.panorama.render(raw, interpolation=cv2.INTER_NEAREST)  # crisp cells and edges

    def display_from_camera_points(self, points_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pts = np.asarray(points_camera, dtype=np.float64).reshape(-1, 3)
        if len(pts) == 0:
            return np.empty((0, 2)), np.zeros(0, bool)
        uv, ok = self.panorama.project(pts)
        return uv, ok & self.camera.project(pts)[1]  # only directions the camera model sees (the panorama is wider)


def camera_views(scene: Any) -> dict[str, CameraView]:
    """The views of a :class:`app.prepared_scene.PreparedScene`: ``raw`` always, ``panorama`` when it has one."""
    views: dict[str, CameraView] = {"raw": RawView(scene.camera, scene.image, scene.image_gray)}
    if scene.panorama is not None:
        views["panorama"] = PanoramaView(scene.camera, scene.panorama, scene.pano_image, scene.pano_gray)
    return views
