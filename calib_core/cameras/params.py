"""Checking the numbers of camera files: every model's parameters and image size pass through here.

Apart from :mod:`.io` (which reads the files and imports the models) so that
the models can check their parameters without importing the file reader.
"""

from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from ..errors import CalibError, short_repr

#: Largest magnitude of any camera parameter (pixels, coefficients); beyond it a value is absurd.
MAX_PARAM = 1e8
#: Largest image width or height in pixels.
MAX_IMAGE_SIDE = 65_536


def numeric_array(value: Any, name: str, max_abs: float = MAX_PARAM) -> np.ndarray:
    """``value`` as a finite float64 array of magnitudes at most ``max_abs``, or a :class:`CalibError` naming ``name``."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError, OverflowError, RecursionError):
        raise CalibError(f"{name}: expected numbers, got {short_repr(value)}") from None
    if arr.dtype == object or arr.dtype.kind not in "iuf":
        raise CalibError(f"{name}: expected numbers, got {short_repr(value)}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise CalibError(f"{name}: numbers must be finite, got {short_repr(arr.tolist())}")
    if np.any(np.abs(arr) > max_abs):
        raise CalibError(f"{name}: numbers must be at most {max_abs:g} in size, got {short_repr(arr.tolist())}")
    return arr


def param_matrix(value: Any, name: str, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a finite float matrix of exactly ``shape``, or a :class:`CalibError`."""
    arr = numeric_array(value, name)
    if arr.shape != shape:
        raise CalibError(f"{name} must be a {shape[0]}x{shape[1]} matrix, got shape {arr.shape}")
    return arr


def param_vector(value: Any, name: str, lengths: Iterable[int] | None = None) -> np.ndarray:
    """``value`` as a finite 1-D float vector (optionally of an allowed length)."""
    arr = numeric_array(value, name)
    if arr.ndim != 1:
        raise CalibError(f"{name} must be a list of numbers, got shape {arr.shape}")
    if lengths is not None:
        lengths = tuple(lengths)
        if arr.size not in lengths:
            allowed = ", ".join(map(str, lengths))
            raise CalibError(f"{name} must have {allowed} coefficients, got {arr.size}")
    return arr


def param_float(value: Any, name: str) -> float:
    """``value`` as one finite float."""
    arr = numeric_array(value, name)
    if arr.ndim != 0:
        raise CalibError(f"{name} must be one number, got {value!r}")
    return float(arr)


def param_image_size(width: Any, height: Any) -> tuple[int, int]:
    """Positive integer ``(width, height)`` in pixels."""
    out = []
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool):
            raise CalibError(f"{name} must be a positive integer, got {value!r}")
        arr = numeric_array(value, name, max_abs=float("inf"))
        if arr.ndim != 0:
            raise CalibError(f"{name} must be a positive integer, got {short_repr(value)}")
        v = float(arr)
        if v <= 0 or v != int(v):
            raise CalibError(f"{name} must be a positive integer, got {short_repr(value)}")
        if v > MAX_IMAGE_SIDE:
            raise CalibError(f"{name} must be at most {MAX_IMAGE_SIDE} pixels, got {int(v)}")
        out.append(int(v))
    return out[0], out[1]


def require_keys(data: Any, keys: Iterable[str], what: str) -> None:
    """Raise a :class:`CalibError` naming the first key of ``keys`` missing from ``data``."""
    if not isinstance(data, dict):
        raise CalibError(f"{what}: expected a mapping, got {type(data).__name__}")
    for key in keys:
        if key not in data:
            raise CalibError(f"{what}: missing key '{key}'")
