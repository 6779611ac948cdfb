"""Camera models: the paper's F (project) and F^-1 (bearing), vectorised.

Models are registered by their YAML ``model:`` name: ``pinhole`` (OpenCV
distortion), ``fisheye`` (Kannala-Brandt, ``cv2.fisheye``) and ``ocam``
(Scaramuzza's OCamCalib).  Pixels are ``(u, v) = (column, row)``; rays are in
the OpenCV camera frame (x right, y down, z forward).
"""

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
]
