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
from .base import as_points, as_points_keep_float32, register_camera_model, store_projection
from .io import param_image_size, param_matrix, param_vector, require_keys

#: Accepted lengths of an OpenCV distortion vector.
OPENCV_DIST_LENGTHS = (0, 4, 5, 8, 12, 14)

_PROJECT_BLOCK = 1 << 15  # points per block in project()

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


def distort_normalized(
    x: np.ndarray, y: np.ndarray, k: np.ndarray, jacobian: bool = False
) -> tuple[np.ndarray, ...]:
    """Apply radial, tangential and thin-prism distortion (no tilt).

    Parameters
    ----------
    x, y : ndarray
        Undistorted normalised coordinates ``X/Z``, ``Y/Z``.
    k : (14,) ndarray
        ``k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty`` (tilt ignored here).
    jacobian : bool
        Also return ``d(xd, yd)/d(x, y)`` as four arrays.

    Returns
    -------
    xd, yd[, j_xx, j_xy, j_yx, j_yy] : ndarray
    """
    p1, p2, s1, s2, s3, s4 = k[2], k[3], k[8], k[9], k[10], k[11]
    r2 = x * x + y * y
    num, den, dnum, dden = _radial_parts(r2, k)
    radial = num / den
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + s1 * r2 + s2 * r2 * r2
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + s3 * r2 + s4 * r2 * r2
    if not jacobian:
        return xd, yd
    d_radial = (dnum * den - num * dden) / (den * den)  # d radial / d r2
    # d r2 / dx = 2x, d r2 / dy = 2y
    gx = 2.0 * x
    gy = 2.0 * y
    j_xx = radial + x * d_radial * gx + 2.0 * p1 * y + 6.0 * p2 * x + (s1 + 2.0 * s2 * r2) * gx
    j_xy = x * d_radial * gy + 2.0 * p1 * x + 2.0 * p2 * y + (s1 + 2.0 * s2 * r2) * gy
    j_yx = y * d_radial * gx + 2.0 * p1 * x + 2.0 * p2 * y + (s3 + 2.0 * s4 * r2) * gx
    j_yy = radial + y * d_radial * gy + 6.0 * p1 * y + 2.0 * p2 * x + (s3 + 2.0 * s4 * r2) * gy
    return xd, yd, j_xx, j_xy, j_yx, j_yy


def _distort_nonzero(x: np.ndarray, y: np.ndarray, r2: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`distort_normalized` (no Jacobian) with the terms of zero coefficients
    left out (most models use 4 or 5 of the 12), given ``r2 = x^2 + y^2``."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = (float(c) for c in k[:12])
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if k4 or k5 or k6:
        radial /= 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    xd = x * radial
    yd = y * radial
    if p1 or p2:
        xy2 = 2.0 * x * y
        xd += p1 * xy2 + p2 * (r2 + 2.0 * x * x)
        yd += p1 * (r2 + 2.0 * y * y) + p2 * xy2
    if s1 or s2 or s3 or s4:
        r4 = r2 * r2
        xd += s1 * r2 + s2 * r4
        yd += s3 * r2 + s4 * r4
    return xd, yd


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
        self._table_r, self._table_rd = r, r * num / den

    # -- F: camera -> image ---------------------------------------------------
    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of points in the OpenCV camera frame (metres).

        Returns ``(pixels (N, 2), valid (N,))``.  Pixels are NaN for points with
        ``Z <= 0`` or beyond ``r_max``; ``valid`` also requires the pixel to lie
        inside the image.  float32 points are projected in float32 (for bulk
        colouring); anything else in float64.
        """
        P = as_points_keep_float32(points)
        pixels = np.empty((P.shape[0], 2), P.dtype)
        valid = np.empty(P.shape[0], bool)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            # Blocks of points: full-size temporaries would cost more in
            # allocation and cache misses than the arithmetic.
            for start in range(0, P.shape[0], _PROJECT_BLOCK):
                block = slice(start, start + _PROJECT_BLOCK)
                self._project_block(P[block], pixels[block], valid[block])
        return pixels, valid

    def _project_block(self, P: np.ndarray, pixels: np.ndarray, valid: np.ndarray) -> None:
        """:meth:`project` of one block, in the dtype of ``P``, into ``pixels`` and ``valid``."""
        X, Y, Z = P[:, 0], P[:, 1], P[:, 2]
        ok = (Z > 0) & (Z < np.inf) & np.isfinite(X) & np.isfinite(Y)
        x = X / Z
        y = Y / Z
        r2 = x * x
        r2 += y * y
        ok &= np.sqrt(r2) <= self.r_max
        xd, yd = self._apply_tilt(*_distort_nonzero(x, y, r2, self._k))
        u = self.K[0, 0] * xd
        u += self.K[0, 2]
        v = self.K[1, 1] * yd
        v += self.K[1, 2]
        store_projection(pixels, valid, u, v, ok, self.width, self.height)

    # -- F^-1: image -> camera ------------------------------------------------
    def bearing(self, pixels: Any) -> np.ndarray:
        """Unit rays (OpenCV camera frame) for ``(u, v)`` pixels.

        Inverts the distortion by Newton's method started from the radial-only
        inverse.  Rows are NaN where no undistorted point within ``r_max`` maps
        to the pixel.
        """
        uv = as_points(pixels, "pixels", 2)
        xd = (uv[:, 0] - self.K[0, 2]) / self.K[0, 0]
        yd = (uv[:, 1] - self.K[1, 2]) / self.K[1, 1]
        xd, yd = self._remove_tilt(xd, yd)
        x, y, ok = self._undistort(xd, yd)
        rays = np.stack([x, y, np.ones_like(x)], axis=1)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        rays[~ok] = np.nan
        return rays

    def _apply_tilt(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._homography(self._tilt, xd, yd)

    def _remove_tilt(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._homography(self._tilt_inv, xd, yd)

    def _homography(self, t: np.ndarray, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Apply the 3x3 sensor-tilt matrix ``t`` (or skip it when there is no tilt)."""
        if self._k[12] == 0 and self._k[13] == 0:
            return xd, yd
        w = t[2, 0] * xd + t[2, 1] * yd + t[2, 2]
        return (t[0, 0] * xd + t[0, 1] * yd + t[0, 2]) / w, (t[1, 0] * xd + t[1, 1] * yd + t[1, 2]) / w

    def _undistort(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Solve ``distort(x, y) = (xd, yd)``; returns ``x, y, converged``."""
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            rd = np.hypot(xd, yd)
            r0 = np.interp(rd, self._table_rd, self._table_r)
            scale = np.where(rd > 0, r0 / np.where(rd > 0, rd, 1.0), 1.0)
            x, y = xd * scale, yd * scale
            for _ in range(30):
                fx, fy, jxx, jxy, jyx, jyy = distort_normalized(x, y, self._k, jacobian=True)
                ex, ey = fx - xd, fy - yd
                det = jxx * jyy - jxy * jyx
                dx = (jyy * ex - jxy * ey) / det
                dy = (-jyx * ex + jxx * ey) / det
                step = np.hypot(dx, dy)
                # Damp steps that would leave the monotonic zone.
                x_new, y_new = x - dx, y - dy
                r_new = np.hypot(x_new, y_new)
                shrink = np.where(r_new > self.r_max, 0.5, 1.0)
                x = np.where(np.isfinite(step), x - shrink * dx, x)
                y = np.where(np.isfinite(step), y - shrink * dy, y)
                if not np.any(step > 1e-15 * (1.0 + np.hypot(x, y))):
                    break
            fx, fy = distort_normalized(x, y, self._k)
            residual = np.hypot(fx - xd, fy - yd)
            ok = (
                np.isfinite(x)
                & np.isfinite(y)
                & (residual <= 1e-10 * (1.0 + rd))
                & (np.hypot(x, y) <= self.r_max)
            )
        return x, y, ok

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
