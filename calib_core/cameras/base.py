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

from ..errors import CalibError


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


def store_projection(
    pixels: np.ndarray, valid: np.ndarray, u: np.ndarray, v: np.ndarray, ok: np.ndarray, width: int, height: int
) -> None:
    """Write projected ``u, v`` into ``pixels`` and the validity into ``valid``, in place.

    ``valid`` becomes ``ok`` and inside the image; pixels where not ``ok``
    become NaN.  Shared by the models' blockwise ``project``.
    """
    np.copyto(valid, ok)
    valid &= (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)
    # 0 / ok is 0 where ok and NaN elsewhere: adding it blanks the pixels
    # that cannot be projected, cheaper than np.where.
    blank = np.divide(0.0, ok, dtype=pixels.dtype)
    pixels[:, 0] = u + blank
    pixels[:, 1] = v + blank


def as_points(arr: Any, name: str, dim: int) -> np.ndarray:
    """``arr`` as a float64 ``(N, dim)`` array, or a :class:`CalibError`."""
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == dim:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != dim:
        raise CalibError(f"{name} must be an (N, {dim}) array, got shape {a.shape}")
    return a


def as_points_keep_float32(points: Any) -> np.ndarray:
    """``as_points(points, "points", 3)``, but float32 input stays float32.

    Bulk colouring passes float32 points and is projected in float32.
    """
    P = np.asarray(points)
    if P.dtype != np.float32:
        return as_points(P, "points", 3)
    if P.ndim != 2 or P.shape[1] != 3:
        return as_points(P, "points", 3).astype(np.float32)  # (3,) -> (1, 3), or the shape error
    return P
