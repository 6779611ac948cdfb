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

Every member is checked from the zip central directory and its ``.npy``
header before anything is decompressed, so a small hostile file (a zip
bomb, a header declaring 10^12 cells) is refused without allocating.
"""

from __future__ import annotations

import math
import os
import stat
import zipfile
from pathlib import Path

import numpy as np

from ..errors import CalibError, one_line
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

#: Default cap on the cells of a depth matrix and the points of a cloud read from a file.
DEFAULT_MAX_CELLS = 5_000_000
#: How the cap is raised, for messages.
MAX_CELLS_OPTION = "--max-points"
#: Bytes a member may hold per allowed cell: float64 x, y, z and a few float64 fields.
_BYTES_PER_CELL = 64
#: Fewest valid cells a native scan must have (as a cloud needs 3 finite points).
MIN_VALID_CELLS = 3
#: Coordinates (metres) beyond this are not a sensor's measurement (the Earth is 1.3e7 m across).
MAX_ABS_COORDINATE_M = 1e8

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


def check_regular_file(path: Path, what: str = "scan file") -> os.stat_result:
    """Stat ``path`` and refuse anything but an existing regular file (FIFOs, devices, folders)."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise CalibError(f"{what} not found: {path}") from None
    except OSError as err:
        raise CalibError(f"{path}: cannot read ({err.strerror or err})") from None
    if stat.S_ISDIR(info.st_mode):
        raise CalibError(f"{path}: is a folder, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise CalibError(f"{path}: is not a regular file (a device, FIFO or socket)")
    return info


def npz_members(path, keys=None, max_bytes: int | None = None) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Shapes and dtypes of the arrays in an ``.npz``, read without decompressing them.

    The uncompressed sizes come from the zip central directory and the
    shapes from each member's ``.npy`` header; the two must agree.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file.
    keys : iterable of str, optional
        Only these keys (missing ones are left out); default: every ``.npy`` member.
    max_bytes : int, optional
        Refuse when the inspected members hold more than this many bytes in total.

    Returns
    -------
    dict
        key -> (shape, dtype).

    Raises
    ------
    CalibError
        Not a zip; a member that is a pickle, has a broken header, or whose
        size does not match its header; more than ``max_bytes``.
    """
    path = Path(path)
    wanted = None if keys is None else set(keys)
    members: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
    total = 0
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                key = info.filename[:-4]
                if wanted is not None and key not in wanted:
                    continue
                total += info.file_size
                if max_bytes is not None and total > max_bytes:
                    raise CalibError(
                        f"{path}: the arrays decompress to more than {max_bytes:,} bytes "
                        f"(member '{key}' alone declares {info.file_size:,}); raise the limit with {MAX_CELLS_OPTION}"
                    )
                with archive.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(member)
                    elif version == (2, 0):
                        shape, _, dtype = np.lib.format.read_array_header_2_0(member)
                    else:
                        raise CalibError(f"{path}: array '{key}' uses .npy format {version}, not 1.0 or 2.0")
                    header_bytes = member.tell()
                if dtype.hasobject:
                    raise CalibError(f"{path}: array '{key}' holds Python objects (a pickle), which is not loaded")
                expected = header_bytes + math.prod(shape) * dtype.itemsize
                if expected != info.file_size:
                    raise CalibError(
                        f"{path}: array '{key}' declares shape {shape} of {dtype} ({expected:,} bytes) "
                        f"but holds {info.file_size:,} bytes"
                    )
                members[key] = (tuple(int(n) for n in shape), dtype)
    except CalibError:
        raise
    except Exception as err:  # BadZipFile, ValueError (bad .npy header), OSError, EOFError, NotImplementedError
        text = " ".join(str(err).split())[:120] or type(err).__name__
        raise CalibError(f"{path}: unreadable .npz ({text})") from None
    return members


def _member(data, path: Path, key: str) -> np.ndarray:
    """Array ``key`` of an open ``.npz``; a damaged member is a one-line CalibError naming the file."""
    try:
        return data[key]
    except Exception as err:  # BadZipFile (CRC), zlib.error (a damaged deflate stream), ValueError, OSError, EOFError
        raise CalibError(f"{path}: cannot read key '{key}' (damaged file?): {one_line(err)}") from None


def _read_key(data, path: Path, key: str, model: str) -> np.ndarray:
    if key not in data.files:
        raise CalibError(f"{path}: missing key '{key}' (needed by model '{model}')")
    value = _member(data, path, key)
    if value.dtype.kind not in "biuf":
        raise CalibError(f"{path}: key '{key}' must be numeric, got dtype {value.dtype}")
    return value


def load_depth_npz(path, max_cells: int = DEFAULT_MAX_CELLS) -> DepthMatrix:
    """Read a native scan file and re-derive its :class:`DepthMatrix`.

    Parameters
    ----------
    path : str or Path
        An ``.npz`` written by :func:`save_depth_npz` or by hand with the
        keys listed in this module's docstring.
    max_cells : int
        Refuse depth matrices with more cells (and members holding more
        than 64 bytes per allowed cell) before decompressing them.

    Returns
    -------
    DepthMatrix
        Built by the model function named in the file; ``meta`` holds the
        model, its parameters and ``wrap_cols``.

    Raises
    ------
    CalibError
        The file is missing, not a regular file or not an ``.npz``; a key is
        missing, not numeric or has the wrong shape; the model is unknown;
        the matrix is larger than ``max_cells``, has no valid cell or holds
        absurd coordinates.  The message names the file and the key.
    """
    path = Path(path)
    check_regular_file(path)
    members = npz_members(path, ("model", "wrap_cols", *{k for keys in MODEL_KEYS.values() for k in keys}), max_cells * _BYTES_PER_CELL)
    for key in ("range_m", "points"):
        if key in members:
            shape = members[key][0]
            cells = math.prod(shape[:-1] if key == "points" and len(shape) > 1 else shape)
            if cells > max_cells:
                raise CalibError(
                    f"{path}: key '{key}' has shape {shape}: {cells:,} cells, above the limit of {max_cells:,} "
                    f"(raise it with {MAX_CELLS_OPTION})"
                )
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as err:  # BadZipFile, zlib.error, ValueError, OSError, EOFError
        raise CalibError(f"{path}: not a readable .npz scan file ({one_line(err)})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise CalibError(f"{path}: holds a single array, not an .npz scan with a 'model' key")
    with data:
        if "model" not in data.files:
            raise CalibError(f"{path}: missing key 'model' (one of {', '.join(MODEL_KEYS)})")
        model_array = _member(data, path, "model")
        if model_array.dtype.kind != "U" or model_array.size != 1:
            raise CalibError(f"{path}: key 'model' must be one string, got {model_array.dtype} of shape {model_array.shape}")
        model = str(model_array.reshape(()))
        if model not in MODEL_KEYS:
            raise CalibError(f"{path}: key 'model' is '{model}', expected one of {', '.join(MODEL_KEYS)}")

        parameters = [_read_key(data, path, key, model) for key in MODEL_KEYS[model]]
        for key, value in zip(MODEL_KEYS[model], parameters):
            # NaN marks a missing return; infinities and huge numbers are corruption, not measurements.
            with np.errstate(all="ignore"):
                bad = np.isinf(value) | (np.abs(np.nan_to_num(value)) > MAX_ABS_COORDINATE_M)
            if bad.any():
                worst = value[bad].flat[0]
                raise CalibError(f"{path}: key '{key}' holds {int(bad.sum())} value(s) like {worst:.3g}: not a measurement")
        wrap_cols = False
        if "wrap_cols" in data.files:
            wrap_array = _read_key(data, path, "wrap_cols", model)
            if wrap_array.dtype.kind != "b" or wrap_array.size != 1:
                raise CalibError(f"{path}: key 'wrap_cols' must be one bool, got {wrap_array.dtype} of shape {wrap_array.shape}")
            wrap_cols = bool(wrap_array.reshape(()))

    try:
        with np.errstate(all="ignore"):  # absurd values are refused below, not warned about
            depth = _MODEL_FUNCTIONS[model](*parameters, wrap_cols=wrap_cols)
    except CalibError as err:
        # The model functions name their arguments, which are the file's keys.
        raise CalibError(f"{path}: {err}") from None
    if not depth.valid.any():
        raise CalibError(f"{path}: the scan has no valid cell (all {depth.valid.size} ranges are missing or not positive)")
    n_valid = int(np.count_nonzero(depth.valid))
    if n_valid < MIN_VALID_CELLS:
        raise CalibError(
            f"{path}: only {n_valid} valid cell(s) in the {depth.shape[0]} x {depth.shape[1]} scan; "
            f"a scan needs at least {MIN_VALID_CELLS}"
        )
    with np.errstate(all="ignore"):
        largest = float(np.max(np.abs(depth.points[depth.valid])))
    if not np.isfinite(largest) or largest > MAX_ABS_COORDINATE_M:
        raise CalibError(f"{path}: a valid cell lies {largest:.3g} m away: not a measurement in metres")
    return depth
