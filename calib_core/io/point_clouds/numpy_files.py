"""``.npy`` arrays and ``.npz`` archives of points, checked from their headers before loading."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ...errors import CalibError, one_line
from ...lidar.npz_format import MAX_CELLS_OPTION, load_depth_npz, npz_members
from .cloud import PointCloud, too_many_points, xyz_field_names


def _cloud_from_array(array: np.ndarray, path: Path, what: str) -> PointCloud:
    """A PointCloud from an array of the shapes documented for ``.npy``."""
    if array.dtype.names:
        axes = xyz_field_names(path, array.dtype.names, what)
        flat = array.reshape(-1)
        if any(flat[axis].ndim != 1 or flat.dtype[axis].kind not in "iuf" for axis in axes):
            raise CalibError(f"{path}: {what}'s x, y, z fields must be single numbers")
        xyz = np.stack([flat[axis].astype(np.float64) for axis in axes], axis=1)
        fields = {n: flat[n].copy() for n in array.dtype.names if n not in axes and flat[n].ndim == 1}
        organized = tuple(array.shape) if array.ndim == 2 and min(array.shape) > 1 else None
        return PointCloud(xyz=xyz, fields=fields, organized_shape=organized)
    if array.dtype.kind not in "iuf":
        raise CalibError(f"{path}: {what} must hold integer or float coordinates, got dtype {array.dtype}")
    if array.ndim == 2 and array.shape[1] in (3, 4):
        fields = {"intensity": array[:, 3].copy()} if array.shape[1] == 4 else {}
        return PointCloud(xyz=array[:, :3].astype(np.float64), fields=fields)
    if array.ndim == 3 and array.shape[2] in (3, 4):
        height, width = array.shape[:2]
        flat = array.reshape(-1, array.shape[2])
        fields = {"intensity": flat[:, 3].copy()} if array.shape[2] == 4 else {}
        organized = (height, width) if min(height, width) > 1 else None
        return PointCloud(xyz=flat[:, :3].astype(np.float64), fields=fields, organized_shape=organized)
    raise CalibError(f"{path}: {what} has shape {array.shape}; expected (N, 3), (N, 4), (H, W, 3) or (H, W, 4)")


def _check_array_shape(path: Path, shape: tuple[int, ...], dtype: np.dtype, what: str) -> None:
    """The shapes :func:`_cloud_from_array` takes, checked from a header before loading."""
    if dtype.names:
        xyz_field_names(path, dtype.names, what)
        return
    if dtype.kind not in "iuf":
        raise CalibError(f"{path}: {what} must hold integer or float coordinates, got dtype {dtype}")
    if not (len(shape) in (2, 3) and shape[-1] in (3, 4)):
        raise CalibError(f"{path}: {what} has shape {shape}; expected (N, 3), (N, 4), (H, W, 3) or (H, W, 4)")


def _array_points(shape: tuple[int, ...], dtype: np.dtype) -> int:
    """Points an array of this shape would give (its cells without the x/y/z axis)."""
    if dtype.names or len(shape) < 2:
        return math.prod(shape)
    return math.prod(shape[:-1])


def read_npy(path: Path, max_points: int, **_) -> PointCloud:
    """An ``.npy`` array of points, its shape and size checked on a memory map first."""
    try:
        # Memory-mapped first: the header is checked against the file size without reading the data.
        mapped = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as err:  # ValueError (pickles, bad header, short file), OSError, EOFError
        raise CalibError(f"{path}: unreadable .npy ({one_line(err)})") from None
    if not isinstance(mapped, np.ndarray):
        raise CalibError(f"{path}: holds several arrays; name it .npz")
    _check_array_shape(path, mapped.shape, mapped.dtype, "the array")
    count = _array_points(mapped.shape, mapped.dtype)
    if count > max_points:
        raise too_many_points(path, "holds", count, max_points)
    array = np.array(mapped)
    del mapped
    cloud = _cloud_from_array(array, path, "the array")
    return dataclasses.replace(cloud, meta={"format": "npy"})


def read_npz(path: Path, max_points: int, **_) -> PointCloud:
    """An ``.npz`` of points (x/y/z, points/xyz or one array) or a native scan, sized from its headers first."""
    members = npz_members(path)
    if "model" in members:
        depth = load_depth_npz(path, max_cells=max_points)
        return PointCloud(
            xyz=depth.points.reshape(-1, 3).copy(),
            organized_shape=depth.shape,
            meta={"format": "native_npz", "model": depth.meta.get("model")},
        )
    # Which arrays hold the points, decided from the headers alone.
    lower = {k.lower(): k for k in members}
    if all(axis in lower for axis in "xyz"):
        keys = [lower[axis] for axis in "xyz"]
        shapes = [members[k][0] for k in keys]
        if any(len(s) != 1 for s in shapes) or len(set(shapes)) != 1 or any(members[k][1].kind not in "iuf" for k in keys):
            raise CalibError(f"{path}: arrays x, y, z must be numeric and 1-D of one length")
        n = shapes[0][0]
        main_keys = keys
    else:
        main = next((k for k in ("points", "xyz") if k in members), None)
        if main is None:
            if len(members) != 1:
                raise CalibError(
                    f"{path}: .npz has neither 'model' (native scan), x/y/z nor 'points' arrays "
                    f"(keys: {', '.join(members) or 'none'})"
                )
            main = next(iter(members))
        shape, dtype = members[main]
        _check_array_shape(path, shape, dtype, f"array '{main}'")
        n = _array_points(shape, dtype)
        main_keys = [main]
    if n > max_points:
        raise too_many_points(path, "holds", n, max_points)
    extra = [
        k for k, (shape, dtype) in members.items()
        if k not in main_keys and shape == (n,) and dtype.kind in "biuf"
    ]
    budget = max_points * 64
    if sum(math.prod(members[k][0]) * members[k][1].itemsize for k in main_keys + extra) > budget:
        raise CalibError(f"{path}: the arrays hold more than {budget:,} bytes (raise the limit with {MAX_CELLS_OPTION})")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in main_keys + extra}
    except Exception as err:  # BadZipFile, CRC errors, ValueError, OSError, EOFError
        raise CalibError(f"{path}: unreadable .npz ({one_line(err)})") from None
    fields = {k: v for k, v in arrays.items() if k in extra}
    if len(main_keys) == 3:
        xyz = np.stack([arrays[k] for k in main_keys], axis=1).astype(np.float64)
        return PointCloud(xyz=xyz, fields=fields, meta={"format": "npz"})
    cloud = _cloud_from_array(arrays[main_keys[0]], path, f"array '{main_keys[0]}'")
    return dataclasses.replace(cloud, fields={**cloud.fields, **fields}, meta={"format": "npz"})
