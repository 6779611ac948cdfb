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
from .base import as_points, in_image, register_camera_model
from .io import param_image_size, param_matrix, param_vector, require_keys

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

    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of points in the OpenCV camera frame (metres).

        Returns ``(pixels (N, 2), valid (N,))``; pixels are NaN for ``Z <= 0``
        or ``theta > theta_max``; ``valid`` also requires the pixel inside the
        image.
        """
        P = as_points(points, "points", 3)
        pixels = np.full((P.shape[0], 2), np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.hypot(P[:, 0], P[:, 1])
            theta = np.arctan2(r, P[:, 2])
            ok = np.isfinite(P).all(axis=1) & (P[:, 2] > 0) & (theta <= self.theta_max)
            td = _theta_d(theta[ok], self.D)
            scale = np.where(r[ok] > 0, td / np.where(r[ok] > 0, r[ok], 1.0), 0.0)
            xp, yp = P[ok, 0] * scale, P[ok, 1] * scale
            pixels[ok, 0] = self.K[0, 0] * xp + self.K[0, 1] * yp + self.K[0, 2]
            pixels[ok, 1] = self.K[1, 1] * yp + self.K[1, 2]
        return pixels, ok & in_image(pixels, self.width, self.height)

    def bearing(self, pixels: Any) -> np.ndarray:
        """Unit rays (OpenCV camera frame) for ``(u, v)`` pixels.

        Inverts ``theta_d(theta)`` with a lookup table and Newton steps; NaN
        rows beyond ``theta_d(theta_max)``.
        """
        uv = as_points(pixels, "pixels", 2)
        yp = (uv[:, 1] - self.K[1, 2]) / self.K[1, 1]
        xp = (uv[:, 0] - self.K[0, 2] - self.K[0, 1] * yp) / self.K[0, 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            td = np.hypot(xp, yp)
            ok = np.isfinite(td) & (td <= self.theta_d_max)
            theta = np.interp(td, self._table_theta_d, self._table_theta)
            for _ in range(8):
                step = (_theta_d(theta, self.D) - td) / _dtheta_d(theta, self.D)
                theta = np.clip(theta - np.where(np.isfinite(step), step, 0.0), 0.0, self.theta_max)
                if not np.any(np.abs(step[ok]) > 1e-15):
                    break
            s = np.where(td > 0, np.sin(theta) / np.where(td > 0, td, 1.0), 0.0)
            rays = np.stack([xp * s, yp * s, np.cos(theta)], axis=1)
        rays[~ok] = np.nan
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
