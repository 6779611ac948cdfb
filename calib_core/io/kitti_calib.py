"""KITTI calibration files (``calib/NNNNNN.txt`` of the object benchmark): the one reader for cameras and extrinsics.

Each line is ``KEY: numbers``: ``P0`` .. ``P3`` (3x4 projections of the
rectified cameras 0-3: grey left/right, colour left/right), ``R0_rect``
(3x3 rectifying rotation of camera 0), ``Tr_velo_to_cam`` (3x4, Velodyne to
the unrectified camera 0) and ``Tr_imu_to_velo``.  Camera ``n``'s image of a
Velodyne point is ``x = Pn @ R0_rect @ Tr_velo_to_cam @ X``.  ``Pn = K @ [I | t_n]``
(the rectified cameras share one ``K`` and differ by a baseline ``t_n``), so
camera ``n`` is a pinhole ``K = Pn[:, :3]`` without distortion (its images
are rectified) and ``T_camera_lidar = [I | K^-1 Pn[:, 3]] @ R0_rect @
Tr_velo_to_cam`` (metres) maps Velodyne points into the rectified camera-n
frame.

A file of ``ba-calib export --format kitti`` holds ``Tr_velo_to_cam`` only:
its extrinsic is that matrix.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import CalibError

#: KITTI's cameras: 0/1 grey left/right, 2/3 colour left/right.
KITTI_CAMERAS = (0, 1, 2, 3)
#: The camera of KITTI's colour images (``image_2``), which the benchmarks use.
DEFAULT_KITTI_CAMERA = 2
#: Values of the keys used here.
KITTI_SHAPES = {**{f"P{n}": (3, 4) for n in KITTI_CAMERAS}, "R0_rect": (3, 3), "Tr_velo_to_cam": (3, 4)}

_KITTI_LINE = re.compile(r"^\s*(P[0-3]|R0_rect|Tr_velo_to_cam)\s*:", re.MULTILINE)


def looks_like_kitti_calib(text: str) -> bool:
    """True when ``text`` has a KITTI calib line (``P0:`` .. ``P3:``, ``R0_rect:`` or ``Tr_velo_to_cam:``)."""
    return _KITTI_LINE.search(text) is not None


def parse_kitti_calib(text: str, where: str = "KITTI calib") -> dict[str, np.ndarray]:
    """The matrices of a KITTI calib text: key -> array of :data:`KITTI_SHAPES` (other numeric keys as flat
    arrays).

    Lines without a colon, comments and other keys whose values are not numbers are skipped.

    Raises
    ------
    CalibError
        A known key whose values are not finite numbers, or not as many as its shape; one line naming
        ``where`` and the key.
    """
    out: dict[str, np.ndarray] = {}
    for line in text.splitlines():
        if ":" not in line or line.lstrip().startswith("#"):
            continue
        key, values = (part.strip() for part in line.split(":", 1))
        shape = KITTI_SHAPES.get(key)
        try:
            numbers = np.array(values.split(), dtype=np.float64)
        except ValueError:
            if shape is None:
                continue  # another key (KITTI raw's calib_time: a date): not used here
            raise CalibError(f"{where}: '{key}:' holds something that is not a number") from None
        if not np.isfinite(numbers).all():
            if shape is None:
                continue
            raise CalibError(f"{where}: '{key}:' holds a value that is not finite")
        if shape is not None:
            if numbers.size != shape[0] * shape[1]:
                raise CalibError(f"{where}: '{key}:' needs {shape[0] * shape[1]} numbers, got {numbers.size}")
            numbers = numbers.reshape(shape)
        out[key] = numbers
    return out


def _need(calib: dict[str, np.ndarray], key: str, where: str) -> np.ndarray:
    if key not in calib:
        raise CalibError(f"{where}: KITTI calib needs a '{key}:' line with {np.prod(KITTI_SHAPES[key])} numbers")
    return calib[key]


def _check_camera(camera: int) -> int:
    if isinstance(camera, bool) or not isinstance(camera, (int, np.integer)) or camera not in KITTI_CAMERAS:
        raise CalibError(f"KITTI camera must be one of 0, 1, 2, 3 (P0..P3), got {camera!r}")
    return int(camera)


def kitti_camera_matrix(calib: dict[str, np.ndarray], camera: int = DEFAULT_KITTI_CAMERA, where: str = "KITTI calib") -> np.ndarray:
    """``K = Pn[:, :3]`` (3x3, pixels) of rectified camera ``n``.

    Raises
    ------
    CalibError
        No ``Pn`` line, or one that is not ``K @ [I | t]`` with a pinhole ``K`` (last row 0 0 1, positive
        focal lengths).
    """
    n = _check_camera(camera)
    K = _need(calib, f"P{n}", where)[:, :3].copy()
    if not (np.allclose(K[2], [0.0, 0.0, 1.0], atol=1e-9) and K[1, 0] == 0.0 and K[0, 0] > 0 and K[1, 1] > 0):
        raise CalibError(f"{where}: P{n}[:, :3] = {K.tolist()} is not a pinhole camera matrix (rows fx s cx, 0 fy cy, 0 0 1)")
    return K


def kitti_T_camera_lidar(calib: dict[str, np.ndarray], camera: int = DEFAULT_KITTI_CAMERA, where: str = "KITTI calib") -> np.ndarray:
    """``T_camera_lidar`` (4x4, metres): Velodyne points into rectified camera ``n``'s frame.

    ``[I | K^-1 Pn[:, 3]] @ R0_rect @ Tr_velo_to_cam``; a text with
    ``Tr_velo_to_cam`` only (no ``Pn``, no ``R0_rect``: a ``ba-calib`` export)
    gives that matrix.
    """
    Tr = np.eye(4)
    Tr[:3, :] = _need(calib, "Tr_velo_to_cam", where)
    n = _check_camera(camera)
    if f"P{n}" not in calib and "R0_rect" not in calib:
        return Tr
    K = kitti_camera_matrix(calib, n, where)
    R0 = np.eye(4)
    R0[:3, :3] = _need(calib, "R0_rect", where)
    offset = np.eye(4)
    offset[:3, 3] = np.linalg.solve(K, calib[f"P{n}"][:, 3])
    return offset @ R0 @ Tr


def read_kitti_calib(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """:func:`parse_kitti_calib` of a file (a regular file of at most the camera-file size)."""
    from .input_files import MAX_CAMERA_BYTES, read_input_text

    path = Path(path)
    return parse_kitti_calib(read_input_text(path, "KITTI calib file", MAX_CAMERA_BYTES), str(path))


def read_kitti_camera2(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """``K`` (3x3, px) of rectified camera 2 and ``T_camera_lidar`` (4x4, metres) from a KITTI calib file.

    Raises
    ------
    CalibError
        A key (``P2``, ``R0_rect``, ``Tr_velo_to_cam``) is missing or has the wrong number of values.
    """
    calib = read_kitti_calib(path)
    for key in ("P2", "R0_rect", "Tr_velo_to_cam"):
        _need(calib, key, str(path))
    return kitti_camera_matrix(calib, 2, str(path)), kitti_T_camera_lidar(calib, 2, str(path))
