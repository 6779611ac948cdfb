"""Camera files: loading, saving and checking the numbers in them.

Accepted inputs (:func:`load_camera`):

* ``.yaml`` / ``.yml`` in our own format::

      model: pinhole            # or fisheye, ocam
      width: 1920
      height: 1200
      K: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
      dist: [k1, k2, p1, p2, k3]  # pinhole: any OpenCV length
      # D: [k1, k2, k3, k4]       # fisheye (Kannala-Brandt, cv2.fisheye)
      # file: calib_results.txt   # ocam, relative to this YAML's folder

* ``.yaml`` / ``.yml`` in ROS ``camera_info`` format (``image_width``,
  ``image_height``, ``camera_matrix``, ``distortion_model``,
  ``distortion_coefficients``); ``plumb_bob`` and ``rational_polynomial`` map
  to ``pinhole``, ``equidistant`` to ``fisheye``.
* ``.txt``: the OCamCalib toolbox's C export ``calib_results.txt``, or a
  KITTI ``calib/NNNNNN.txt``: rectified camera 2 by default (``P2``; 0-3
  with ``kitti_camera``), pinhole ``K = P[:, :3]`` without distortion, and
  the image size given by the caller (KITTI states none).
* ``.json``: the PJLab OpenCalib intrinsic JSON (``cam_K``, ``cam_dist``,
  ``img_dist_w``, ``img_dist_h``): a pinhole with OpenCV distortion, or an
  OCam model as PJLab's surround-view tools store it (``cam_K`` holds the
  affine ``c, d, e`` and the centre, ``cam_dist`` the world2cam polynomial);
  or our own format as JSON.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibError
from ..io.atomic import write_yaml_atomic
from ..io.input_files import MAX_CAMERA_BYTES, check_input_file, read_input_text
from ..io.yaml_files import parse_json_text, read_yaml_mapping
from .base import CAMERA_MODELS, CameraModel
from .params import numeric_array, param_float, param_image_size, param_vector, require_keys

#: ROS ``distortion_model`` names -> our model names.
ROS_DISTORTION_MODELS = {
    "plumb_bob": "pinhole",
    "rational_polynomial": "pinhole",
    "equidistant": "fisheye",
    "fisheye": "fisheye",
}

#: File name of the OCamCalib sidecar written by :func:`save_camera_yaml`.
OCAM_SIDECAR_NAME = "calib_results.txt"


# -- format conversions ---------------------------------------------------------------
def _ros_matrix(block: Any, name: str) -> np.ndarray:
    """The ``data`` of a ROS ``{rows, cols, data}`` block, shape ``(rows, cols)``."""
    require_keys(block, ("data",), name)
    data = param_vector(block["data"] if block["data"] is not None else [], f"{name}.data")
    rows, cols = block.get("rows"), block.get("cols")
    if rows is not None and cols is not None:
        r, c = int(param_float(rows, f"{name}.rows")), int(param_float(cols, f"{name}.cols"))
        if r * c != data.size:
            raise CalibError(f"{name}: rows x cols = {r}x{c} but data has {data.size} numbers")
        return data.reshape(r, c)
    return data.reshape(1, -1)


def ros_camera_info_to_dict(data: dict[str, Any]) -> dict[str, Any]:
    """A ROS ``camera_info`` YAML mapping -> our own camera mapping."""
    require_keys(data, ("image_width", "image_height", "camera_matrix"), "ROS camera_info")
    K = _ros_matrix(data["camera_matrix"], "camera_matrix")
    if K.size != 9:
        raise CalibError(f"camera_matrix must be 3x3, got {K.size} numbers")
    dist_model = data.get("distortion_model", "plumb_bob")
    if dist_model not in ROS_DISTORTION_MODELS:
        known = ", ".join(ROS_DISTORTION_MODELS)
        raise CalibError(f"unknown ROS distortion_model {dist_model!r} (known: {known})")
    D = _ros_matrix(data.get("distortion_coefficients", {"data": []}), "distortion_coefficients")
    out: dict[str, Any] = {
        "model": ROS_DISTORTION_MODELS[dist_model],
        "width": data["image_width"],
        "height": data["image_height"],
        "K": K.reshape(3, 3).tolist(),
    }
    out["D" if out["model"] == "fisheye" else "dist"] = D.ravel().tolist()
    return out


def pjlab_intrinsic_to_dict(data: dict[str, Any]) -> dict[str, Any]:
    """A PJLab OpenCalib ``*-intrinsic.json`` mapping -> our own pinhole mapping, or our ``ocam`` mapping
    for the OCam models PJLab's surround-view tools store in the same layout
    (:func:`calib_core.cameras.ocam.pjlab_ocam_parameters`)."""
    param = data.get("param")
    if param is None:
        blocks = [v for v in data.values() if isinstance(v, dict) and "param" in v]
        if len(blocks) != 1:
            raise CalibError("not a PJLab intrinsic JSON: expected one block with a 'param' mapping")
        param = blocks[0]["param"]
    require_keys(param, ("cam_K", "img_dist_w", "img_dist_h"), "PJLab intrinsic param")
    require_keys(param["cam_K"], ("data",), "cam_K")
    K = numeric_array(param["cam_K"]["data"], "cam_K.data")
    if K.size != 9:
        raise CalibError(f"cam_K.data must be 3x3, got shape {K.shape}")
    dist: list[float] = []
    if "cam_dist" in param:
        require_keys(param["cam_dist"], ("data",), "cam_dist")
        dist = numeric_array(param["cam_dist"]["data"], "cam_dist.data").ravel().tolist()
    K = K.reshape(3, 3)
    if (abs(K[0, 0]) < 10 and abs(K[1, 1]) < 10) or len(dist) > 14:
        # PJLab's surround-view tools store an OCam (Scaramuzza) model in this layout: the affine c, d, e
        # (near 1 and 0) in place of fx, fy and the skew, and the world2cam polynomial (its first term
        # hundreds of px) as the distortion; their run_avm.cpp projects with it.
        from .ocam import pjlab_ocam_parameters

        return pjlab_ocam_parameters(K, dist, param["img_dist_w"], param["img_dist_h"])
    return {
        "model": "pinhole",
        "width": param["img_dist_w"],
        "height": param["img_dist_h"],
        "K": K.tolist(),
        "dist": dist,
    }


def _normalise(data: Any) -> dict[str, Any]:
    """Own format as is; a ROS camera_info converted; anything else an error."""
    if not isinstance(data, dict):
        raise CalibError(f"expected a mapping describing a camera, got {type(data).__name__}")
    if "model" in data:
        return dict(data)
    if "camera_matrix" in data or "image_width" in data:
        return ros_camera_info_to_dict(data)
    raise CalibError("not a camera description: no 'model' key and not a ROS camera_info")


def camera_from_dict(data: dict[str, Any], base_dir: str | os.PathLike | None = None) -> CameraModel:
    """Build a camera from our YAML mapping (or a ROS ``camera_info`` mapping).

    Parameters
    ----------
    data : dict
        ``{model: pinhole | fisheye | ocam, ...}`` as described in this module.
    base_dir : path-like, optional
        Folder against which relative paths (``file:`` of an ``ocam`` camera)
        are resolved; the current folder if omitted.
    """
    data = _normalise(data)
    name = data["model"]
    if not isinstance(name, str) or name not in CAMERA_MODELS:
        known = ", ".join(sorted(CAMERA_MODELS))
        raise CalibError(f"unknown camera model {name!r} (known: {known})")
    return CAMERA_MODELS[name].from_dict(data, Path(base_dir) if base_dir is not None else Path.cwd())


def is_kitti_calib(path: str | os.PathLike) -> bool:
    """True when ``path`` is a ``.txt`` holding KITTI calib lines (``P2: ...``), not an OCamCalib export."""
    from ..io.kitti_calib import looks_like_kitti_calib

    path = Path(path)
    if path.suffix.lower() != ".txt":
        return False
    try:
        return looks_like_kitti_calib(read_input_text(path, "camera file", MAX_CAMERA_BYTES))
    except CalibError:
        return False  # load_camera says what is wrong with the file


def kitti_camera_dict(path: Path, kitti_camera: int | None, image_size: tuple[int, int] | None) -> dict[str, Any]:
    """Our pinhole mapping of rectified camera ``kitti_camera`` (default 2) of a KITTI calib file.

    ``K = Pn[:, :3]``, no distortion (KITTI's images are rectified).  The
    file states no image size: ``image_size`` (the rectified image's, about
    1242 x 375) is required.
    """
    from ..io.kitti_calib import DEFAULT_KITTI_CAMERA, kitti_camera_matrix, read_kitti_calib

    camera = DEFAULT_KITTI_CAMERA if kitti_camera is None else kitti_camera
    K = kitti_camera_matrix(read_kitti_calib(path), camera, str(path))
    if image_size is None:
        raise CalibError(
            f"{path}: a KITTI calib file states no image size: give the rectified image (serve and colorize "
            f"take its size from --image) or --image-size W H"
        )
    return {"model": "pinhole", "width": image_size[0], "height": image_size[1], "K": K.tolist(), "dist": []}


def load_camera(
    path: str | os.PathLike, image_size: tuple[int, int] | None = None, kitti_camera: int | None = None
) -> CameraModel:
    """Load a camera model from a file.

    Parameters
    ----------
    path : path-like
        ``.yaml``/``.yml`` (own format or ROS camera_info), ``.txt`` (OCamCalib
        ``calib_results.txt``, or a KITTI ``calib/NNNNNN.txt``) or ``.json``
        (PJLab intrinsic, or own format).
    image_size : (int, int), optional
        ``(width, height)`` in pixels replacing the size stated in the file
        (e.g. PJLab's manual_calib JSON claims 1920x1080 for a 1920x1200 image);
        required for a KITTI calib file, which states none.
    kitti_camera : int, optional
        For a KITTI calib file: which rectified camera, 0-3 (``P0``..``P3``;
        default 2, the colour images).  Refused for other files.

    Raises
    ------
    CalibError
        Missing or malformed file, missing keys, wrong shapes, unknown model,
        non-finite numbers; the message names the file.
    """
    path = Path(path)
    check_input_file(path, "camera file", MAX_CAMERA_BYTES)
    suffix = path.suffix.lower()
    try:
        if image_size is not None:
            if len(image_size) != 2:
                raise CalibError(f"image_size must be (width, height), got {image_size!r}")
            param_image_size(*image_size)
        if is_kitti_calib(path):
            return camera_from_dict(kitti_camera_dict(path, kitti_camera, image_size), path.parent)
        if kitti_camera is not None:
            raise CalibError("is not a KITTI calib file (no 'P2:' line): the KITTI camera option does not apply")
        if suffix == ".txt":
            camera = CAMERA_MODELS["ocam"].from_calib_results(path)
            if image_size is not None:
                data = camera.to_dict(None)
                data["width"], data["height"] = image_size
                camera = camera_from_dict(data, path.parent)
            return camera
        if suffix in (".yaml", ".yml"):
            data = _normalise(read_yaml_mapping(path, "camera file", max_bytes=MAX_CAMERA_BYTES))
        elif suffix == ".json":
            raw = parse_json_text(read_input_text(path, "camera file", MAX_CAMERA_BYTES), str(path))
            if not isinstance(raw, dict):
                raise CalibError(f"expected a JSON object, got {type(raw).__name__}")
            data = dict(raw) if "model" in raw else pjlab_intrinsic_to_dict(raw)
        else:
            raise CalibError(f"unsupported camera file type '{suffix}' (use .yaml, .yml, .txt or .json)")
        if image_size is not None:
            data["width"], data["height"] = image_size
        return camera_from_dict(data, path.parent)
    except CalibError as exc:
        msg = str(exc)
        if msg.startswith(str(path)):
            raise
        raise CalibError(f"{path}: {msg}") from None


def save_camera_yaml(camera: CameraModel, path: str | os.PathLike) -> None:
    """Write ``camera`` as our YAML format (atomically).

    An ``ocam`` camera is written as ``model: ocam`` + ``file:
    calib_results.txt``, with the OCamCalib C-export file written next to the
    YAML file (overwriting any file of that name there).
    """
    path = Path(path)
    if camera.model == "ocam":
        sidecar = path.parent / OCAM_SIDECAR_NAME
        camera.write_calib_results(sidecar)
        data = {"model": "ocam", "file": OCAM_SIDECAR_NAME}
    else:
        data = camera.to_dict(path.parent)
    write_yaml_atomic(path, data)
