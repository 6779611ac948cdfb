"""Camera models: the paper's F (project) and F^-1 (bearing), vectorised.

Models are registered by their YAML ``model:`` name: ``pinhole`` (OpenCV
distortion), ``fisheye`` (Kannala-Brandt, ``cv2.fisheye``) and ``ocam``
(Scaramuzza's OCamCalib).  Pixels are ``(u, v) = (column, row)``; rays are in
the OpenCV camera frame (x right, y down, z forward).
"""

import numpy as _np

from .base import CAMERA_MODELS, CameraModel, register_camera_model
from .fisheye import FisheyeCamera
from .io import camera_from_dict, load_camera, save_camera_yaml
from .ocam import OCamCamera
from .pinhole import PinholeCamera

__all__ = [
    "CAMERA_MODELS",
    "CameraModel",
    "FisheyeCamera",
    "OCamCamera",
    "PinholeCamera",
    "camera_from_dict",
    "load_camera",
    "register_camera_model",
    "save_camera_yaml",
    "warm_up",
]


def warm_up() -> None:
    """Compile (or load from numba's disk cache) the camera kernels for the inputs the package gives them.

    Points come as float64 C arrays (the solve) and as column-major float32
    arrays (colouring: ``xyz.T`` of a (3, N) array); pixels as float64 C
    arrays.  Other layouts compile (or load) on first use.  Here rather than
    in :mod:`.kernels`, which the models import: the kernels stay below the models.
    """
    cams = (
        PinholeCamera(_np.array([[4.0, 0, 2], [0, 4.0, 2], [0, 0, 1]]), _np.zeros(5), 4, 4),
        FisheyeCamera(_np.array([[4.0, 0, 2], [0, 4.0, 2], [0, 0, 1]]), _np.zeros(4), 4, 4),
        OCamCamera([-4.0, 0.0, 0.01], [2.0], 1.5, 1.5, 1.0, 0.0, 0.0, 4, 4),
    )
    points = _np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 2.0], [_np.nan, 0.0, 1.0]])
    for cam in cams:
        cam.project(points)
        cam.project(_np.asfortranarray(points, dtype=_np.float32))
        cam.bearing(_np.array([[1.5, 1.5], [0.0, 2.0]]))
