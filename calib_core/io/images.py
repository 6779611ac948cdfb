"""Camera image loading."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from ..errors import CalibError


def load_image_rgb(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as an (H, W, 3) uint8 RGB array.

    Grey images are expanded to three channels and alpha is dropped, so every
    caller gets one layout.  16-bit images are scaled to 8 bits.
    """
    path = Path(path)
    if not path.is_file():
        raise CalibError(f"{path}: image not found")
    data = np.fromfile(path, dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise CalibError(f"{path}: not a readable image (PNG, JPEG, TIFF, BMP ...)")
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise CalibError(f"{path}: unsupported image sample type {img.dtype}")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def save_image_rgb(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an RGB (or grey) uint8 image; the format follows the suffix."""
    from .atomic import write_bytes_atomic

    path = Path(path)
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(path.suffix or ".png", img)
    if not ok:
        raise CalibError(f"{path}: cannot encode image as {path.suffix}")
    write_bytes_atomic(path, buf.tobytes())
