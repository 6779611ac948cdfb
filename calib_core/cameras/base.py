"""The camera-model protocol and the registry keyed by the YAML ``model:`` name.

Pixel convention (stated once, used by every model): pixels are
``(u, v) = (column, row)`` and the centre of the top-left pixel is ``(0, 0)``,
as in OpenCV and in OCamCalib's C export.  Camera frame: OpenCV, x right,
y down, z forward.

Every model implements the paper's F and F^-1 (eqs. 1 and 2), vectorised over
N points:

* :meth:`CameraModel.bearing` -- camera-from-image: pixels to unit rays;
* :meth:`CameraModel.project` -- image-from-camera: points to pixels plus a
  validity mask.

Adding a model is a one-place change: write a class with ``model = "name"``
decorated with :func:`register_camera_model`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from ..arrays import as_rows


@runtime_checkable
class CameraModel(Protocol):
    """A calibrated central camera."""

    model: ClassVar[str]
    width: int
    height: int

    def bearing(self, pixels: np.ndarray) -> np.ndarray:
        """Unit rays for pixels.

        Parameters
        ----------
        pixels : (N, 2) array_like
            ``(u, v)`` pixel coordinates (column, row; top-left centre = 0).

        Returns
        -------
        (N, 3) ndarray
            Unit vectors in the OpenCV camera frame.  Rows are NaN where the
            pixel has no ray under the model.
        """
        ...

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of 3-D points.

        Parameters
        ----------
        points : (N, 3) array_like
            Points (or directions) in the OpenCV camera frame, metres.

        Returns
        -------
        pixels : (N, 2) ndarray
            ``(u, v)``; NaN where the model cannot project the point.
        valid : (N,) bool ndarray
            The model can project the point (e.g. it is not behind a pinhole
            or fisheye camera, not outside the calibrated field of view) and
            the pixel lies inside the image, ``-0.5 <= u <= W - 0.5`` and
            ``-0.5 <= v <= H - 0.5``.
        """
        ...

    def to_dict(self, base_dir: Path | None = None) -> dict[str, Any]:
        """The YAML description of this camera (inverse of ``from_dict``)."""
        ...

    @classmethod
    def from_dict(cls, data: dict[str, Any], base_dir: Path) -> "CameraModel":
        """Build from a YAML mapping; relative paths are resolved against ``base_dir``."""
        ...


CAMERA_MODELS: dict[str, type] = {}


def register_camera_model(cls: type) -> type:
    """Class decorator: make ``cls`` loadable by its ``model`` name."""
    CAMERA_MODELS[cls.model] = cls
    return cls


def in_image(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """True where ``(u, v)`` lies inside a ``width`` x ``height`` image."""
    u, v = pixels[:, 0], pixels[:, 1]
    with np.errstate(invalid="ignore"):
        return (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)


def as_points_keep_float32(points: Any) -> np.ndarray:
    """``as_rows(points, "points", 3)``, but float32 input stays float32.

    Bulk colouring passes float32 points and is projected in float32.  The
    result is C-contiguous, or a column-major float32 array as it came (the
    compiled kernels take both without a copy).
    """
    P = np.asarray(points)
    if P.dtype != np.float32:
        return np.ascontiguousarray(as_rows(P, "points", 3))
    if P.ndim != 2 or P.shape[1] != 3:
        return as_rows(P, "points", 3).astype(np.float32)  # (3,) -> (1, 3), or the shape error
    if P.flags.c_contiguous or P.flags.f_contiguous:
        return P
    return np.ascontiguousarray(P)


def as_pixels(pixels: Any) -> np.ndarray:
    """``as_rows(pixels, "pixels", 2)``, C-contiguous (for the compiled kernels)."""
    return np.ascontiguousarray(as_rows(pixels, "pixels", 2))


def empty_projection(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Output arrays of a ``project`` of ``P``: pixels ``(N, 2)`` of ``P``'s dtype and ``valid (N,)``."""
    return np.empty((P.shape[0], 2), P.dtype), np.empty(P.shape[0], np.bool_)
