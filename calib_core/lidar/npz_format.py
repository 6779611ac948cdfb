"""The native scan file: a laser model and its parameters in one ``.npz``.

A scan file stores the *measurement* (ranges or points) and the *model*
that turns it into a :class:`DepthMatrix`, never the derived arrays, so a
loaded scan is re-derived through exactly the same model function as the
original.  Keys (all plain numpy arrays, no pickles):

============  =================================================================
``model``     0-d string: ``"rotating_2d"``, ``"spherical"`` or ``"organized"``
``wrap_cols`` 0-d bool, optional (default False): columns close 360 deg
rotating_2d   ``range_m`` (H, W) metres, NaN = no return; ``theta_rad`` and
              ``phi_rad`` broadcastable to (H, W), radians; ``dx_m``,
              ``dz_m`` 0-d, metres (paper eq. 3)
spherical     ``range_m`` (H, W) metres, NaN = no return; ``elevation_rad``
              (H,) and ``azimuth_rad`` (W,), radians
organized     ``points`` (H, W, 3) metres in the lidar frame, NaN = no return
============  =================================================================

Other keys are ignored, so files may carry extra data (e.g. intensities).
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix
from .organized import organized_cloud_depth
from .rotating_scanner import rotating_scanner_depth
from .spherical import spherical_depth

#: Model name -> the keys that hold its parameters, in the model function's argument order.
MODEL_KEYS: dict[str, tuple[str, ...]] = {
    "rotating_2d": ("range_m", "theta_rad", "phi_rad", "dx_m", "dz_m"),
    "spherical": ("range_m", "elevation_rad", "azimuth_rad"),
    "organized": ("points",),
}

_MODEL_FUNCTIONS = {
    "rotating_2d": rotating_scanner_depth,
    "spherical": spherical_depth,
    "organized": organized_cloud_depth,
}


def _scan_arrays(depth: DepthMatrix) -> dict[str, np.ndarray]:
    """The arrays that describe ``depth`` in the native format."""
    meta = depth.meta
    model = meta.get("model")
    wrap_cols = np.asarray(bool(meta.get("wrap_cols", False)))
    if model in ("rotating_2d", "spherical") and all(key in meta for key in MODEL_KEYS[model][1:]):
        arrays = {"model": np.asarray(model), "range_m": np.asarray(depth.range_m, dtype=np.float64)}
        for key in MODEL_KEYS[model][1:]:
            arrays[key] = np.asarray(meta[key], dtype=np.float64)
    else:
        # No beam model known: the points themselves describe the scan exactly.
        arrays = {"model": np.asarray("organized"), "points": np.asarray(depth.points, dtype=np.float64)}
    arrays["wrap_cols"] = wrap_cols
    return arrays


def save_depth_npz(path, depth: DepthMatrix) -> None:
    """Write ``depth`` as a native scan file, atomically.

    The model and its parameters are taken from ``depth.meta`` (as set by
    :func:`rotating_scanner_depth` and :func:`spherical_depth`).  A depth
    matrix without a known beam model is stored as an organized cloud of its
    points.  The file is written to a temporary name in the same folder and
    moved into place with :func:`os.replace`, so a reader never sees half a
    file.

    Parameters
    ----------
    path : str or Path
        Destination, written as given (no ``.npz`` suffix is added).
    depth : DepthMatrix
        The scan to store.
    """
    path = Path(path)
    arrays = _scan_arrays(depth)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise CalibError(f"cannot write scan file {path}: {err.strerror or err}") from None


def _read_key(data, path: Path, key: str, model: str) -> np.ndarray:
    if key not in data.files:
        raise CalibError(f"{path}: missing key '{key}' (needed by model '{model}')")
    try:
        value = data[key]
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as err:
        raise CalibError(f"{path}: cannot read key '{key}': {err}") from None
    if value.dtype.kind not in "biuf":
        raise CalibError(f"{path}: key '{key}' must be numeric, got dtype {value.dtype}")
    return value


def load_depth_npz(path) -> DepthMatrix:
    """Read a native scan file and re-derive its :class:`DepthMatrix`.

    Parameters
    ----------
    path : str or Path
        An ``.npz`` written by :func:`save_depth_npz` or by hand with the
        keys listed in this module's docstring.

    Returns
    -------
    DepthMatrix
        Built by the model function named in the file; ``meta`` holds the
        model, its parameters and ``wrap_cols``.

    Raises
    ------
    CalibError
        The file is missing or not an ``.npz``; a key is missing, not numeric
        or has the wrong shape; the model is unknown.  The message names the
        file and the key.
    """
    path = Path(path)
    if not path.is_file():
        raise CalibError(f"scan file not found: {path}")
    try:
        data = np.load(path, allow_pickle=False)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as err:
        raise CalibError(f"{path}: not a readable .npz scan file ({err})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise CalibError(f"{path}: holds a single array, not an .npz scan with a 'model' key")
    with data:
        if "model" not in data.files:
            raise CalibError(f"{path}: missing key 'model' (one of {', '.join(MODEL_KEYS)})")
        try:
            model_array = data["model"]
        except (ValueError, OSError, zipfile.BadZipFile, EOFError) as err:
            raise CalibError(f"{path}: cannot read key 'model': {err}") from None
        if model_array.dtype.kind != "U" or model_array.size != 1:
            raise CalibError(f"{path}: key 'model' must be one string, got {model_array.dtype} of shape {model_array.shape}")
        model = str(model_array.reshape(()))
        if model not in MODEL_KEYS:
            raise CalibError(f"{path}: key 'model' is '{model}', expected one of {', '.join(MODEL_KEYS)}")

        parameters = [_read_key(data, path, key, model) for key in MODEL_KEYS[model]]
        wrap_cols = False
        if "wrap_cols" in data.files:
            wrap_array = _read_key(data, path, "wrap_cols", model)
            if wrap_array.dtype.kind != "b" or wrap_array.size != 1:
                raise CalibError(f"{path}: key 'wrap_cols' must be one bool, got {wrap_array.dtype} of shape {wrap_array.shape}")
            wrap_cols = bool(wrap_array.reshape(()))

    try:
        return _MODEL_FUNCTIONS[model](*parameters, wrap_cols=wrap_cols)
    except CalibError as err:
        # The model functions name their arguments, which are the file's keys.
        raise CalibError(f"{path}: {err}") from None
