"""Pinhole camera with OpenCV's full distortion model.

Forward model (OpenCV ``projectPoints``), for a point ``(X, Y, Z)`` in the
OpenCV camera frame with ``Z > 0``::

    x, y = X / Z, Y / Z,   r2 = x^2 + y^2
    radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2
    yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y + s3 r2 + s4 r2^2
    (xd, yd) <- tilt(tx, ty) applied to (xd, yd, 1), then dehomogenised
    u = fx xd + cx,   v = fy yd + cy

The coefficient vector has any OpenCV length: 0, 4, 5, 8, 12 or 14
(``k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]``).

A polynomial distortion bends back beyond some radius: far off-axis points
then land inside the image again.  The model therefore only accepts
undistorted radii up to the first radius where ``r * radial(r)`` stops
increasing (``r_max``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..errors import CalibError
from .kernels import (
    pinhole_bearing,
    PINHOLE_PARAMS,
    pinhole_project,
    _P_CX,
    _P_CY,
    _P_FX,
    _P_FY,
    _P_H,
    _P_K,
    _P_RMAX,
    _P_T,
    _P_TILT,
    _P_W,
)
from .base import as_pixels, as_points_keep_float32, empty_projection, register_camera_model
from .params import param_image_size, param_matrix, param_vector, require_keys

#: Accepted lengths of an OpenCV distortion vector.
OPENCV_DIST_LENGTHS = (0, 4, 5, 8, 12, 14)

# Undistorted radii searched for the end of monotonicity: fine up to r = 10
# (84 deg off-axis), coarse beyond.
_R_SEARCH = np.concatenate([np.linspace(0.0, 10.0, 50001), np.geomspace(10.0, 1e4, 4001)[1:]])


def tilt_matrix(tau_x: float, tau_y: float) -> np.ndarray:
    """OpenCV's tilted-sensor projection (``computeTiltProjectionMatrix``), radians."""
    cx, sx, cy, sy = np.cos(tau_x), np.sin(tau_x), np.cos(tau_y), np.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    rot_y = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    rot_xy = rot_y @ rot_x
    proj_z = np.array(
        [[rot_xy[2, 2], 0.0, -rot_xy[0, 2]], [0.0, rot_xy[2, 2], -rot_xy[1, 2]], [0.0, 0.0, 1.0]]
    )
    return proj_z @ rot_xy


def _radial_parts(r2: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Numerator, denominator of the radial factor and their r2-derivatives."""
    num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
    den = 1.0 + r2 * (k[5] + r2 * (k[6] + r2 * k[7]))
    dnum = k[0] + r2 * (2.0 * k[1] + 3.0 * r2 * k[4])
    dden = k[5] + r2 * (2.0 * k[6] + 3.0 * r2 * k[7])
    return num, den, dnum, dden


def monotonic_radius(k: np.ndarray) -> float:
    """Largest undistorted radius ``r = hypot(X/Z, Y/Z)`` up to which the radial
    mapping ``r -> r * radial(r^2)`` is strictly increasing (``inf`` if it is
    increasing over the whole search range, up to ``r = 1e4``)."""
    r2 = _R_SEARCH * _R_SEARCH
    num, den, _, _ = _radial_parts(r2, k)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        rd = _R_SEARCH * num / den
        bad = ~(den > 0) | ~np.isfinite(rd)
        bad[1:] |= ~(np.diff(rd) > 0)
    if not bad.any():
        return float("inf")
    first = int(np.argmax(bad))
    # Conservative: the last sample before the first failure.
    return float(_R_SEARCH[max(first - 1, 0)])


@register_camera_model
class PinholeCamera:
    """Pinhole camera with OpenCV distortion (``cv2.projectPoints`` model).

    Parameters
    ----------
    K : (3, 3) array_like
        ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels (zero skew, as in
        OpenCV's model).
    dist : array_like
        OpenCV distortion coefficients, length 0, 4, 5, 8, 12 or 14.
    width, height : int
        Image size in pixels.

    Attributes
    ----------
    r_max : float
        Largest accepted undistorted radius ``hypot(X/Z, Y/Z)`` (``inf`` if the
        distortion never folds back).
    """

    model: ClassVar[str] = "pinhole"

    def __init__(self, K: Any, dist: Any, width: int, height: int) -> None:
        K = param_matrix(K, "K", (3, 3))
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibError(f"K: fx and fy must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise CalibError("K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (OpenCV's pinhole model has no skew)")
        dist = param_vector(dist, "dist", OPENCV_DIST_LENGTHS)
        self.K = K
        self.dist = dist
        self.width, self.height = param_image_size(width, height)
        self._k = np.zeros(14)
        self._k[: dist.size] = dist
        self._tilt = tilt_matrix(self._k[12], self._k[13])
        self._tilt_inv = np.linalg.inv(self._tilt)
        self.r_max = monotonic_radius(self._k)
        # Lookup table of the radial-only mapping, for Newton's initial guess.
        r = _R_SEARCH[_R_SEARCH <= min(self.r_max, 1e4)]
        num, den, _, _ = _radial_parts(r * r, self._k)
        self._table_r, self._table_rd = r, np.ascontiguousarray(r * num / den)
        # The compiled kernels' parameter vectors (layout: calib_core.cameras.kernels).
        prm = np.zeros(PINHOLE_PARAMS)
        prm[[_P_FX, _P_FY, _P_CX, _P_CY]] = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        prm[_P_RMAX], prm[_P_W], prm[_P_H] = self.r_max, self.width, self.height
        prm[_P_TILT] = float(self._k[12] != 0 or self._k[13] != 0)
        prm[_P_K : _P_K + 14] = self._k
        self._prm_project, self._prm_bearing = prm.copy(), prm.copy()
        self._prm_project[_P_T :] = self._tilt.ravel()
        self._prm_bearing[_P_T :] = self._tilt_inv.ravel()

    # -- F: camera -> image ---------------------------------------------------
    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of points in the OpenCV camera frame (metres).

        Returns ``(pixels (N, 2), valid (N,))``.  Pixels are NaN for points with
        ``Z <= 0`` or beyond ``r_max``; ``valid`` also requires the pixel to lie
        inside the image.  float32 points give float32 pixels (for bulk
        colouring), anything else float64; the arithmetic is float64.
        """
        P = as_points_keep_float32(points)
        pixels, valid = empty_projection(P)
        pinhole_project(P, self._prm_project, pixels, valid)
        return pixels, valid

    # -- F^-1: image -> camera ------------------------------------------------
    def bearing(self, pixels: Any) -> np.ndarray:
        """Unit rays (OpenCV camera frame) for ``(u, v)`` pixels.

        Inverts the distortion by Newton's method started from the radial-only
        inverse.  Rows are NaN where no undistorted point within ``r_max`` maps
        to the pixel.
        """
        uv = as_pixels(pixels)
        rays = np.empty((uv.shape[0], 3))
        pinhole_bearing(uv, self._prm_bearing, self._table_r, self._table_rd, rays)
        return rays

    # -- YAML -------------------------------------------------------------------
    def to_dict(self, base_dir: Path | None = None) -> dict[str, Any]:
        """``{model: pinhole, width, height, K, dist}`` with plain floats."""
        return {
            "model": self.model,
            "width": self.width,
            "height": self.height,
            "K": [[float(v) for v in row] for row in self.K],
            "dist": [float(v) for v in self.dist],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], base_dir: Path | None = None) -> "PinholeCamera":
        """Build from ``{model: pinhole, width, height, K, dist}`` (``dist`` optional)."""
        require_keys(data, ("width", "height", "K"), "pinhole camera")
        return cls(data["K"], data.get("dist", []), data["width"], data["height"])

    def __repr__(self) -> str:
        return (
            f"PinholeCamera(fx={self.K[0, 0]:.6g}, fy={self.K[1, 1]:.6g}, cx={self.K[0, 2]:.6g}, "
            f"cy={self.K[1, 2]:.6g}, dist={self.dist.tolist()}, {self.width}x{self.height})"
        )
