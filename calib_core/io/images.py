"""Camera image loading.

An image is checked before it is decoded: a regular file of at most
:data:`MAX_IMAGE_BYTES`, whose header (read with Pillow, which parses headers
lazily) declares at most :data:`MAX_IMAGE_PIXELS`.  OpenCV then decodes it with
its library messages (libpng, libjpeg) captured: a decoder that complains
about corrupt or truncated data makes the image refused, with what it said.
"""

from __future__ import annotations

import os
import struct
import warnings
from pathlib import Path

import cv2
import numpy as np

from ..errors import CalibError
from ..lidar.npz_format import check_regular_file
from .quiet import library_output

#: Largest image accepted, in pixels (a 50 MP camera; 8-bit RGB is 150 MB decoded).
MAX_IMAGE_PIXELS = 50_000_000
#: Largest image file accepted, in bytes.
MAX_IMAGE_BYTES = 256 * 1024 * 1024
#: Decoder messages that mean the pixels are not all there (libjpeg, libpng).
_CORRUPT_WORDS = ("premature end", "corrupt", "truncated", "crc error", "read error")


def image_header_size(path: str | os.PathLike) -> tuple[int, int]:
    """Width and height declared by an image file's header, without decoding the pixels.

    Raises
    ------
    CalibError
        Not a regular file, or not an image format Pillow can identify.
    """
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    check_regular_file(path, "image")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # DecompressionBombWarning: we apply our own cap
            with Image.open(path) as img:
                width, height = img.size
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, EOFError, struct.error):
        raise CalibError(f"{path}: not a readable image (PNG, JPEG, TIFF, BMP ...)") from None
    except Image.DecompressionBombError:
        raise CalibError(
            f"{path}: the image header declares more than {2 * Image.MAX_IMAGE_PIXELS:,} pixels "
            f"(the limit is {MAX_IMAGE_PIXELS:,})"
        ) from None
    return int(width), int(height)


def load_image_rgb(path: str | os.PathLike, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """Read an image file as an (H, W, 3) uint8 RGB array.

    Grey images are expanded to three channels and alpha is dropped, so every
    caller gets one layout.  16-bit images are scaled to 8 bits.

    Parameters
    ----------
    path : str or PathLike
        A PNG, JPEG, TIFF, BMP ... file.
    max_pixels : int
        Refuse images whose header declares more pixels, before decoding.

    Raises
    ------
    CalibError
        Missing or non-regular file, a file over :data:`MAX_IMAGE_BYTES`, an
        unreadable, truncated or corrupt image, more than ``max_pixels``, or
        a sample type other than 8 or 16-bit integers.
    """
    path = Path(path)
    info = check_regular_file(path, "image")
    if info.st_size == 0:
        raise CalibError(f"{path}: not a readable image (the file is empty)")
    if info.st_size > MAX_IMAGE_BYTES:
        raise CalibError(f"{path}: the image file has {info.st_size:,} bytes, more than the {MAX_IMAGE_BYTES:,} allowed")
    width, height = image_header_size(path)
    if width < 1 or height < 1:
        raise CalibError(f"{path}: the image header declares {width} x {height} pixels")
    if width * height > max_pixels:
        raise CalibError(
            f"{path}: the image header declares {width} x {height} = {width * height:,} pixels, "
            f"more than the {max_pixels:,} allowed"
        )
    data = np.fromfile(path, dtype=np.uint8)
    with library_output() as said:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    complaint = said.text()
    if img is None:
        # The header was readable, so the pixel data is what is broken.
        raise CalibError(f"{path}: cannot decode the {width} x {height} image data (truncated or corrupt?){said.suffix()}")
    if any(word in complaint.lower() for word in _CORRUPT_WORDS):
        raise CalibError(f"{path}: corrupt or truncated image data (decoder said: {complaint})")
    if img.shape[:2] != (height, width):
        raise CalibError(f"{path}: the header declares {width} x {height} pixels but {img.shape[1]} x {img.shape[0]} were decoded")
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise CalibError(f"{path}: unsupported image sample type {img.dtype}")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    if img.shape[2] != 3:
        raise CalibError(f"{path}: an image with {img.shape[2]} channels; expected grey, RGB or RGBA")
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
