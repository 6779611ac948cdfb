"""Input arrays checked once, in one place: shapes and finiteness, with one-line :class:`CalibError` messages.

Every public function of the package that takes points, pixels or a pose
validates it through these, so the messages read alike everywhere.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import CalibError

__all__ = ["as_rows", "finite_array", "as_transform", "angle_between_rad"]


def as_rows(value: Any, name: str, dim: int, *, single_row: bool = True) -> np.ndarray:
    """``value`` as a float64 ``(N, dim)`` array (points, pixels, bearings), or a :class:`CalibError`.

    Parameters
    ----------
    value : array_like
    name : str
        Named in the message.
    dim : int
        Columns (3 for points and bearings, 2 for pixels).
    single_row : bool
        Accept one ``(dim,)`` vector as a ``(1, dim)`` array.
    """
    a = np.asarray(value, dtype=np.float64)
    if single_row and a.ndim == 1 and a.shape[0] == dim:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != dim:
        raise CalibError(f"{name} must be an (N, {dim}) array, got shape {a.shape}")
    return a


def finite_array(value: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    """``value`` as a float64 array of exactly ``shape`` with finite entries, or a :class:`CalibError`."""
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape:
        raise CalibError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CalibError(f"{name} contains NaN or infinite values")
    return a


def as_transform(value: Any, name: str = "T_camera_lidar") -> np.ndarray:
    """A finite float64 4x4 homogeneous transform, or a :class:`CalibError` ("... must be a 4x4 matrix")."""
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (4, 4):
        raise CalibError(f"{name} must be a 4x4 matrix, got shape {a.shape}")
    return finite_array(a, (4, 4), name)


def angle_between_rad(a: Any, b: Any) -> np.ndarray:
    """Angle (radians, in [0, pi]) between the vectors ``a`` and ``b`` (..., 3), any lengths.

    ``atan2(|a x b|, a . b)``: exact near 0 and pi, where ``arccos`` of the
    dot product loses half the digits.  NaN where either vector is NaN.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c0 = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    c1 = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    c2 = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    dot = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    return np.arctan2(np.sqrt(c0 * c0 + c1 * c1 + c2 * c2), dot)
