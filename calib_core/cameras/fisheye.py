"""Kannala-Brandt fisheye camera, as in ``cv2.fisheye``.

Forward model, for a point ``(X, Y, Z)`` in the OpenCV camera frame::

    theta   = atan2(hypot(X, Y), Z)                 # angle from the axis, rad
    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
    (x', y') = theta_d * (X, Y) / hypot(X, Y)
    u = fx x' + s y' + cx,   v = fy y' + cy       # s = K[0, 1] = fx * alpha

``cv2.fisheye.projectPoints`` computes theta from ``hypot(X/Z, Y/Z)`` and so
maps ``P`` and ``-P`` to the same pixel.  This model rejects ``Z <= 0``
(theta >= 90 deg) and angles beyond the first turning point of
``theta_d(theta)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..errors import CalibError
from .kernels import fisheye_bearing, FISHEYE_PARAMS, fisheye_project, _F_D
from .base import as_pixels, as_points_keep_float32, empty_projection, register_camera_model
from .params import param_image_size, param_matrix, param_vector, require_keys

_THETA_SEARCH = np.linspace(0.0, np.pi / 2, 20001)


def _theta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    t2 = theta * theta
    return theta * (1.0 + t2 * (D[0] + t2 * (D[1] + t2 * (D[2] + t2 * D[3]))))


def _dtheta_d(theta: np.ndarray, D: np.ndarray) -> np.ndarray:
    t2 = theta * theta
    return 1.0 + t2 * (3.0 * D[0] + t2 * (5.0 * D[1] + t2 * (7.0 * D[2] + t2 * 9.0 * D[3])))


@register_camera_model
class FisheyeCamera:
    """Kannala-Brandt fisheye camera (``cv2.fisheye`` model).

    Parameters
    ----------
    K : (3, 3) array_like
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, pixels; the skew ``s`` is
        ``fx * alpha`` in ``cv2.fisheye`` terms (usually 0).
    D : (4,) array_like
        ``k1, k2, k3, k4``.
    width, height : int
        Image size in pixels.

    Attributes
    ----------
    theta_max : float
        Largest accepted angle from the optical axis, radians (< pi/2).
    """

    model: ClassVar[str] = "fisheye"

    def __init__(self, K: Any, D: Any, width: int, height: int) -> None:
        K = param_matrix(K, "K", (3, 3))
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibError(f"K: fx and fy must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise CalibError("K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
        self.K = K
        self.D = param_vector(D, "D", (4,))
        self.width, self.height = param_image_size(width, height)
        theta = _THETA_SEARCH
        bad = ~(_dtheta_d(theta, self.D) > 0)
        bad[0] = False
        last = int(np.argmax(bad)) - 1 if bad.any() else theta.size - 2  # keep < pi/2
        if last < 1:
            raise CalibError(f"D={self.D.tolist()}: theta_d(theta) decreases right from the axis")
        self.theta_max = float(theta[last])
        self._table_theta = theta[: last + 1]
        self._table_theta_d = _theta_d(self._table_theta, self.D)
        self.theta_d_max = float(self._table_theta_d[-1])
        # The compiled kernels' parameter vector (layout: calib_core.cameras.kernels).
        self._prm = np.zeros(FISHEYE_PARAMS)
        self._prm[: _F_D] = (K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2], self.theta_max, self.theta_d_max,
                                     self.width, self.height)
        self._prm[_F_D :] = self.D

    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of points in the OpenCV camera frame (metres).

        Returns ``(pixels (N, 2), valid (N,))``; pixels are NaN for ``Z <= 0``
        or ``theta > theta_max``; ``valid`` also requires the pixel inside the
        image.  float32 points give float32 pixels, anything else float64;
        the arithmetic is float64.
        """
        P = as_points_keep_float32(points)
        pixels, valid = empty_projection(P)
        fisheye_project(P, self._prm, pixels, valid)
        return pixels, valid

    def bearing(self, pixels: Any) -> np.ndarray:
        """Unit rays (OpenCV camera frame) for ``(u, v)`` pixels.

        Inverts ``theta_d(theta)`` with a lookup table and Newton steps; NaN
        rows beyond ``theta_d(theta_max)``.
        """
        uv = as_pixels(pixels)
        rays = np.empty((uv.shape[0], 3))
        fisheye_bearing(uv, self._prm, self._table_theta_d, self._table_theta, rays)
        return rays

    def to_dict(self, base_dir: Path | None = None) -> dict[str, Any]:
        """``{model: fisheye, width, height, K, D}`` with plain floats."""
        return {
            "model": self.model,
            "width": self.width,
            "height": self.height,
            "K": [[float(v) for v in row] for row in self.K],
            "D": [float(v) for v in self.D],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], base_dir: Path | None = None) -> "FisheyeCamera":
        """Build from ``{model: fisheye, width, height, K, D}``."""
        require_keys(data, ("width", "height", "K", "D"), "fisheye camera")
        return cls(data["K"], data["D"], data["width"], data["height"])

    def __repr__(self) -> str:
        return (
            f"FisheyeCamera(fx={self.K[0, 0]:.6g}, fy={self.K[1, 1]:.6g}, cx={self.K[0, 2]:.6g}, "
            f"cy={self.K[1, 2]:.6g}, D={self.D.tolist()}, {self.width}x{self.height})"
        )
