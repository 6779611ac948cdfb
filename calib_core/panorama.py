"""Unwrapped panorama of a wide-angle camera image (azimuth x elevation).

An omnidirectional or fisheye image is hard to read and to click on: straight
lines bend and the scene is squeezed towards the rim.  The panorama resamples
it on a grid that is linear in azimuth (columns) and elevation (rows) about a
chosen *up* axis, like a cylinder unrolled (equirectangular layout).

Panorama geometry, all directions in the OpenCV camera frame:

* ``up``: the cylinder axis (default ``-y``, the camera's up for an upright
  camera looking horizontally); ``forward``: azimuth 0 (default ``+z``), made
  orthogonal to ``up``; ``right = forward x up`` (``+x`` by default).
* A bearing ``b`` has azimuth ``atan2(b.right, b.forward)`` (positive to the
  right) and elevation ``asin(b.up)`` (positive up).
* Pixel ``(u, v)`` (top-left pixel centre = 0): ``u = -0.5`` is the smallest
  azimuth and ``u = W - 0.5`` the largest; ``v = -0.5`` is the largest
  elevation and ``v = H - 0.5`` the smallest.

A click on the panorama is turned into a bearing through this geometry
(:meth:`Panorama.bearing`); errors are always measured in the original image
(``camera.project(bearing)``), never in the panorama.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from .arrays import as_rows
from .errors import CalibError

_DEFAULT_MAX_WIDTH = 4096
_RANGE_GRID = 256  # samples per image side when measuring the field of view


def _unit(v: Any, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.isfinite(a).all() or np.linalg.norm(a) < 1e-12:
        raise CalibError(f"{name} must be a non-zero 3-vector, got {v!r}")
    return a / np.linalg.norm(a)


@dataclass(eq=False)
class Panorama:
    """Azimuth x elevation panorama of one camera, with cached resampling maps.

    Build it with :meth:`for_camera`.

    Attributes
    ----------
    camera : CameraModel
        The camera whose raw image is unwrapped.
    width, height : int
        Panorama size in pixels.
    up_camera, forward_camera, right_camera : (3,) float64
        Orthonormal axes of the panorama in the OpenCV camera frame.
    azimuth_range_rad, elevation_range_rad : (float, float)
        ``(min, max)`` covered by the panorama, radians.
    map_x, map_y : (height, width) float32
        Raw-image ``u`` and ``v`` of every panorama pixel, for ``cv2.remap``;
        -1e6 where the camera does not see that direction.
    seen : (height, width) bool
        The camera sees the panorama pixel's direction.
    """

    camera: Any
    width: int
    height: int
    up_camera: np.ndarray
    forward_camera: np.ndarray
    right_camera: np.ndarray
    azimuth_range_rad: tuple[float, float]
    elevation_range_rad: tuple[float, float]
    map_x: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    map_y: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    seen: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]

    # ------------------------------------------------------------ construction
    @classmethod
    def for_camera(
        cls,
        camera: Any,
        width: int | None = None,
        height: int | None = None,
        *,
        up_camera: Any = (0.0, -1.0, 0.0),
        forward_camera: Any = (0.0, 0.0, 1.0),
        azimuth_range_rad: tuple[float, float] | None = None,
        elevation_range_rad: tuple[float, float] | None = None,
        max_elevation_rad: float = np.deg2rad(80.0),
        max_width: int = _DEFAULT_MAX_WIDTH,
        oversample: float = 1.0,
        image_mask: np.ndarray | None = None,
    ) -> "Panorama":
        """Panorama of ``camera`` about the axis ``up_camera``.

        Parameters
        ----------
        camera : CameraModel
        width, height : int, optional
            Panorama size in pixels.  By default the angular pixel size matches
            the camera's at its image centre (square pixels), at most
            ``max_width`` columns.  Given only one, the other keeps pixels
            square.
        up_camera : (3,) array_like
            Cylinder axis in the OpenCV camera frame (default ``-y``).  For a
            catadioptric camera looking up, use its optical axis.
        forward_camera : (3,) array_like
            Direction of azimuth 0; its component along ``up_camera`` is removed.
        azimuth_range_rad, elevation_range_rad : (min, max), optional
            Angular extent, radians.  By default the extent of the directions the
            camera sees: the azimuth range of those within 45 deg of the
            horizon, the elevation range of those within that azimuth range,
            clipped to ``max_elevation_rad`` (the poles of the cylinder are
            degenerate).
        max_width : int
            Cap on the automatic width (a browser texture is at most 8192 px).
        oversample : float
            Panorama pixels per camera pixel (at the image centre) for the
            automatic size, e.g. 2 for a smoother display.
        image_mask : (camera.height, camera.width) bool array, optional
            Raw pixels that show the scene (e.g. inside the image circle of a
            fisheye lens); only their directions define the automatic extent.
        """
        up = _unit(up_camera, "up_camera")
        fwd = _unit(forward_camera, "forward_camera")
        fwd = _unit(fwd - float(fwd @ up) * up, "forward_camera (not parallel to up_camera)")
        right = np.cross(fwd, up)

        if azimuth_range_rad is None or elevation_range_rad is None:
            az_auto, el_auto = _field_of_view(camera, up, fwd, right, float(max_elevation_rad), image_mask)
            azimuth_range_rad = azimuth_range_rad or az_auto
            elevation_range_rad = elevation_range_rad or el_auto
        az = (float(azimuth_range_rad[0]), float(azimuth_range_rad[1]))
        el = (float(elevation_range_rad[0]), float(elevation_range_rad[1]))
        if not (az[0] < az[1] and az[1] - az[0] <= 2 * np.pi + 1e-9):
            raise CalibError(f"azimuth range {az} rad must be increasing and span at most 2 pi")
        if not (-np.pi / 2 <= el[0] < el[1] <= np.pi / 2):
            raise CalibError(f"elevation range {el} rad must be increasing within [-pi/2, pi/2]")

        if width is None or height is None:
            if not oversample > 0:
                raise CalibError(f"oversample must be positive, got {oversample}")
            step = _pixel_angle(camera) / float(oversample)
            aspect = (az[1] - az[0]) / (el[1] - el[0])
            if width is None and height is None:
                width = int(np.clip(round((az[1] - az[0]) / step), 16, max_width))
            if width is None:
                width = max(16, int(round(int(height) * aspect)))  # type: ignore[arg-type]
            if height is None:
                height = max(16, int(round(int(width) / aspect)))
        width, height = int(width), int(height)
        if width < 2 or height < 2:
            raise CalibError(f"panorama size {width}x{height} is too small")
        pano = cls(camera, width, height, up, fwd, right, az, el)
        pano._build_maps()
        return pano

    def _build_maps(self) -> None:
        """Raw-image pixel of every panorama pixel (computed once, reused by render)."""
        us, vs = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        grid = np.stack([us.ravel(), vs.ravel()], axis=1)
        raw, valid = self.camera.project(self.bearing(grid))
        raw = np.where(valid[:, None], raw, -1e6)
        self.map_x = raw[:, 0].reshape(self.height, self.width).astype(np.float32)
        self.map_y = raw[:, 1].reshape(self.height, self.width).astype(np.float32)
        self.seen = valid.reshape(self.height, self.width)

    # ---------------------------------------------------------------- geometry
    def angles(self, pano_pixels: Any) -> tuple[np.ndarray, np.ndarray]:
        """Azimuth and elevation (radians) of panorama pixels ``(N, 2)``."""
        uv = as_rows(pano_pixels, "panorama pixels", 2)
        (a0, a1), (e0, e1) = self.azimuth_range_rad, self.elevation_range_rad
        az = a0 + (uv[:, 0] + 0.5) / self.width * (a1 - a0)
        el = e1 - (uv[:, 1] + 0.5) / self.height * (e1 - e0)
        return az, el

    def bearing(self, pano_pixels: Any) -> np.ndarray:
        """Unit bearings (OpenCV camera frame) of panorama pixels.

        Parameters
        ----------
        pano_pixels : (N, 2) array_like
            ``(u, v)`` in the panorama.

        Returns
        -------
        (N, 3) ndarray
            NaN rows for pixels outside the panorama.
        """
        uv = as_rows(pano_pixels, "panorama pixels", 2)
        az, el = self.angles(uv)
        ce = np.cos(el)
        b = (ce * np.cos(az))[:, None] * self.forward_camera + (ce * np.sin(az))[:, None] * self.right_camera
        b = b + np.sin(el)[:, None] * self.up_camera
        with np.errstate(invalid="ignore"):
            tol = 1e-6
            inside = (uv[:, 0] >= -0.5 - tol) & (uv[:, 0] <= self.width - 0.5 + tol)
            inside &= (uv[:, 1] >= -0.5 - tol) & (uv[:, 1] <= self.height - 0.5 + tol)
        b[~inside] = np.nan
        return b

    def project(self, bearings_camera: Any) -> tuple[np.ndarray, np.ndarray]:
        """Panorama pixels of directions.

        Parameters
        ----------
        bearings_camera : (N, 3) array_like
            Directions (any length) or points in the OpenCV camera frame.

        Returns
        -------
        pano_pixels : (N, 2) ndarray
            ``(u, v)``; NaN for zero or non-finite input.
        valid : (N,) bool ndarray
            The pixel lies inside the panorama.
        """
        b = as_rows(bearings_camera, "bearings", 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            b = b / np.linalg.norm(b, axis=1, keepdims=True)
            az = np.arctan2(b @ self.right_camera, b @ self.forward_camera)
            el = np.arcsin(np.clip(b @ self.up_camera, -1.0, 1.0))
            (a0, a1), (e0, e1) = self.azimuth_range_rad, self.elevation_range_rad
            if a1 - a0 > 2 * np.pi - 1e-9:
                az = a0 + np.mod(az - a0, 2 * np.pi)  # full turn: no seam gaps
            elif a1 > np.pi:
                az = np.where(az < a0, az + 2 * np.pi, az)
            elif a0 < -np.pi:
                az = np.where(az > a1, az - 2 * np.pi, az)
            u = (az - a0) / (a1 - a0) * self.width - 0.5
            v = (e1 - el) / (e1 - e0) * self.height - 0.5
            pixels = np.stack([u, v], axis=1)
            valid = np.isfinite(pixels).all(axis=1)
            tol = 1e-6  # rounding at the borders
            valid &= (u >= -0.5 - tol) & (u <= self.width - 0.5 + tol) & (v >= -0.5 - tol) & (v <= self.height - 0.5 + tol)
        return pixels, valid

    def to_camera_pixels(self, pano_pixels: Any) -> tuple[np.ndarray, np.ndarray]:
        """Original-image pixels of panorama pixels: ``camera.project(self.bearing(.))``."""
        return self.camera.project(self.bearing(pano_pixels))

    def from_camera_pixels(self, pixels: Any) -> tuple[np.ndarray, np.ndarray]:
        """Panorama pixels of original-image pixels: ``self.project(camera.bearing(.))``."""
        return self.project(self.camera.bearing(as_rows(pixels, "pixels", 2)))

    # --------------------------------------------------------------- resampling
    def render(self, image: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """The panorama of a raw camera image (black where the camera sees nothing).

        Parameters
        ----------
        image : (camera.height, camera.width[, C]) array
            The raw image, any dtype ``cv2.remap`` accepts.
        """
        img = np.asarray(image)
        if img.shape[:2] != (self.camera.height, self.camera.width):
            raise CalibError(
                f"image is {img.shape[1]}x{img.shape[0]} but the camera model is {self.camera.width}x{self.camera.height}"
            )
        return cv2.remap(img, self.map_x, self.map_y, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def _pixel_angle(camera: Any) -> float:
    """Angle (rad) between the rays of two neighbouring pixels at the image centre."""
    cu, cv = (camera.width - 1) / 2.0, (camera.height - 1) / 2.0
    b = camera.bearing(np.array([[cu - 0.5, cv], [cu + 0.5, cv], [cu, cv - 0.5], [cu, cv + 0.5]]))
    if not np.isfinite(b).all():
        return float(np.deg2rad(0.1))
    step = 0.5 * (np.arccos(np.clip(b[0] @ b[1], -1, 1)) + np.arccos(np.clip(b[2] @ b[3], -1, 1)))
    return float(max(step, 1e-5))


def _field_of_view(
    camera: Any, up: np.ndarray, fwd: np.ndarray, right: np.ndarray, max_el: float, image_mask: np.ndarray | None
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Azimuth and elevation ranges (rad) of the directions the camera sees."""
    n = _RANGE_GRID
    us, vs = np.meshgrid(np.linspace(0.0, camera.width - 1.0, n), np.linspace(0.0, camera.height - 1.0, n))
    grid = np.stack([us.ravel(), vs.ravel()], axis=1)
    if image_mask is not None:
        mask = np.asarray(image_mask, dtype=bool)
        if mask.shape != (camera.height, camera.width):
            raise CalibError(f"image_mask shape {mask.shape} does not match the {camera.width}x{camera.height} camera")
        grid = grid[mask[np.round(grid[:, 1]).astype(int), np.round(grid[:, 0]).astype(int)]]
    b = camera.bearing(grid)
    b = b[np.isfinite(b).all(axis=1)]
    if b.shape[0] < 4:
        raise CalibError(f"the {camera.model} camera has no valid rays to build a panorama from")
    az = np.arctan2(b @ right, b @ fwd)
    el = np.arcsin(np.clip(b @ up, -1.0, 1.0))
    near_horizon = np.abs(el) <= np.deg2rad(45.0)
    if near_horizon.sum() < 4:
        raise CalibError("the camera sees nothing within 45 deg of the panorama horizon; choose another up axis")
    az_h = az[near_horizon]
    # Does the view wrap around behind (azimuth +-pi)?  Then show a full turn.
    if np.any(np.abs(az_h) > np.deg2rad(175.0)):
        az_range = (-np.pi, np.pi)
        in_az = np.ones(az.shape, bool)
    else:
        pad = np.deg2rad(1.0)
        az_range = (float(az_h.min()) - pad, float(az_h.max()) + pad)
        in_az = (az >= az_range[0]) & (az <= az_range[1])
    el_min = max(float(el[in_az].min()) - np.deg2rad(1.0), -max_el)
    el_max = min(float(el[in_az].max()) + np.deg2rad(1.0), max_el)
    return az_range, (el_min, el_max)


def refine_click_to_corner(image_gray: np.ndarray, uv: Any, radius_px: float = 4.0) -> np.ndarray:
    """Snap a click to the strongest corner within ``radius_px`` pixels.

    The corner strength is the Shi-Tomasi score (smaller eigenvalue of the
    gradient structure tensor, ``cv2.cornerMinEigenVal``); the best cell is
    refined to sub-pixel accuracy with ``cv2.cornerSubPix``.  Without a
    distinct corner near the click (flat or edge-only neighbourhood) the click
    is returned unchanged.

    Parameters
    ----------
    image_gray : (H, W) array
        Grey image (uint8 or float).
    uv : (2,) array_like
        Click ``(u, v)``, pixels (top-left pixel centre = 0).
    radius_px : float
        Search radius, pixels.

    Returns
    -------
    (2,) float64 ndarray
        The refined ``(u, v)``.
    """
    img = np.asarray(image_gray)
    if img.ndim != 2:
        raise CalibError(f"corner snapping needs a grey (H, W) image, got shape {img.shape}")
    uv = np.asarray(uv, dtype=np.float64).reshape(-1)
    if uv.shape != (2,) or not np.isfinite(uv).all():
        raise CalibError(f"click must be two finite numbers, got {uv.tolist()}")
    h, w = img.shape
    r = max(1, int(np.ceil(radius_px)))
    margin = r + 3
    u0, v0 = int(round(uv[0])), int(round(uv[1]))
    x0, x1 = max(0, u0 - margin), min(w, u0 + margin + 1)
    y0, y1 = max(0, v0 - margin), min(h, v0 + margin + 1)
    if x1 - x0 < 5 or y1 - y0 < 5:
        return uv.copy()
    patch = np.ascontiguousarray(img[y0:y1, x0:x1], dtype=np.float32)
    score = cv2.cornerMinEigenVal(patch, blockSize=3, ksize=3)
    ys, xs = np.mgrid[y0:y1, x0:x1]
    within = (xs - uv[0]) ** 2 + (ys - uv[1]) ** 2 <= radius_px**2
    if not within.any():
        return uv.copy()
    masked = np.where(within, score, -np.inf)
    k = int(np.argmax(masked))
    best = float(masked.flat[k])
    # A corner must stand out from its surroundings, not just be the least flat spot.
    if not best > max(4.0 * float(np.median(score)), 1e-3 * float(np.max(np.abs(patch)) or 1.0)):
        return uv.copy()
    corner = np.array([[[xs.flat[k], ys.flat[k]]]], dtype=np.float32)
    full = np.ascontiguousarray(img, dtype=np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
    refined = cv2.cornerSubPix(full, corner, (3, 3), (-1, -1), criteria).reshape(2).astype(np.float64)
    if not np.isfinite(refined).all() or np.hypot(*(refined - uv)) > radius_px + 1.0:
        refined = np.array([xs.flat[k], ys.flat[k]], dtype=np.float64)
    return refined
