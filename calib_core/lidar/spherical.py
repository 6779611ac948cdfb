"""Spherical laser model: one elevation per row, one azimuth per column.

This is the usual model of a spinning multi-beam lidar (rows = beams,
columns = firing azimuths) and of any scanner whose beams all start at the
origin.  Lidar frame: x forward, y left, z up, metres.  A beam with
elevation ``el`` and azimuth ``az`` (radians) has the unit direction
``(cos el cos az, cos el sin az, sin el)``: azimuth is measured from +x
towards +y, elevation from the x-y plane towards +z.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix
from .rotating_scanner import _check_wrap_cols, _float_array, _range_image


def _per_axis_angles(angle, name: str, length: int, axis_name: str) -> np.ndarray:
    values = _float_array(angle, name)
    if values.shape != (length,):
        raise CalibError(f"{name} must have shape ({length},), one angle per {axis_name} of range_m, got {values.shape}")
    if not np.isfinite(values).all():
        raise CalibError(f"{name} contains NaN or inf")
    return values


def spherical_directions(elevation_rad, azimuth_rad) -> np.ndarray:
    """Unit directions ``(cos el cos az, cos el sin az, sin el)``, broadcast, shape ``(..., 3)``."""
    el = np.asarray(elevation_rad, dtype=np.float64)
    az = np.asarray(azimuth_rad, dtype=np.float64)
    cos_el = np.cos(el)
    x, y, z = np.broadcast_arrays(cos_el * np.cos(az), cos_el * np.sin(az), np.sin(el))
    return np.stack([x, y, z], axis=-1)


def spherical_depth(range_m, elevation_rad, azimuth_rad, wrap_cols: bool = False) -> DepthMatrix:
    """Depth matrix with per-row elevations and per-column azimuths.

    Parameters
    ----------
    range_m : (H, W) array_like
        Measured range along each beam from the lidar origin, metres.
        NaN, inf and values <= 0 mean "no return".
    elevation_rad : (H,) array_like
        Elevation of each row's beams, radians (finite).
    azimuth_rad : (W,) array_like
        Azimuth of each column's beams, radians (finite).
    wrap_cols : bool
        True when the columns close a full 360 deg turn, so that column 0's
        left neighbour is column W-1.

    Returns
    -------
    DepthMatrix
        Points ``rho * direction`` in the lidar frame (NaN where invalid);
        ``meta = {"model": "spherical", "elevation_rad", "azimuth_rad",
        "wrap_cols"}``.
    """
    rho = _range_image(range_m)
    n_rows, n_cols = rho.shape
    elevation = _per_axis_angles(elevation_rad, "elevation_rad", n_rows, "row")
    azimuth = _per_axis_angles(azimuth_rad, "azimuth_rad", n_cols, "column")
    wrap = _check_wrap_cols(wrap_cols)

    directions = spherical_directions(elevation[:, None], azimuth[None, :])
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(rho) & (rho > 0.0)
    range_clean = np.where(valid, rho, np.nan)
    points = range_clean[..., None] * directions
    meta = {
        "model": "spherical",
        "elevation_rad": elevation.copy(),
        "azimuth_rad": azimuth.copy(),
        "wrap_cols": wrap,
    }
    return DepthMatrix(range_m=range_clean, directions=directions, points=points, valid=valid, meta=meta)
