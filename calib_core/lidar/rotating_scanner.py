"""The paper's 3-D scanner: a 2-D scanner on a rotating support (paper eq. 3).

Lidar frame (paper Fig. 2b): origin at the centre of the external rotation
axis, x forward, z up, metres.  A beam is described by

* ``theta`` -- the in-plane angle of the 2-D scanner's mirror, measured in the
  scan plane from the x axis towards +y (radians);
* ``phi`` -- the rotation of the scan plane about the lidar y axis (radians);
  at ``phi = 0`` the scan plane is the x-y plane, and positive ``phi`` turns
  +x towards -z;
* ``dx``, ``dz`` -- the offset of the mirror centre from the rotation axis,
  expressed in the scanner's own (rotating) frame, metres.

Eq. 3 of the paper reads, with ``c_i = cos(phi)``, ``s_i = sin(phi)``,
``c_j = cos(theta)``, ``s_j = sin(theta)``::

    [x]   [ c_i c_j  -c_i s_j  s_i   c_i dx + s_i dz ] [rho]
    [y] = [ s_j       c_j      0     0               ] [ 0 ]
    [z]   [-s_i c_j   s_i s_j  c_i  -s_i dx + c_i dz ] [ 0 ]
                                                       [ 1 ]

which factors as ``p = Ry(phi) @ (Rz(theta) @ [rho, 0, 0] + [dx, 0, dz])``
with the usual right-handed rotations ``Ry`` and ``Rz``.  A beam therefore
starts at ``Ry(phi) @ [dx, 0, dz]`` (not at the origin) and runs along
``Ry(phi) @ Rz(theta) @ [1, 0, 0] = (c_i c_j, s_j, -s_i c_j)``.

``theta = +-90 deg`` points along +-y, the rotation axis: a depth matrix with
one row per ``theta`` in (-90, 90) deg and one column per ``phi`` over 360 deg
covers the whole sphere, with the poles on the y axis.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError
from .depth_matrix import DepthMatrix


def _float_array(value, name: str) -> np.ndarray:
    """``value`` as a float64 array, or CalibError naming ``name``."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibError(f"{name} must be numeric") from None
    return array


def _range_image(range_m) -> np.ndarray:
    """Checked (H, W) float64 range image; non-finite entries are kept for masking."""
    rho = _float_array(range_m, "range_m")
    if rho.ndim != 2 or rho.shape[0] < 1 or rho.shape[1] < 1:
        raise CalibError(f"range_m must be a 2-D (H, W) array, got shape {rho.shape}")
    return rho


def _check_wrap_cols(wrap_cols) -> bool:
    if not isinstance(wrap_cols, (bool, np.bool_)):
        raise CalibError(f"wrap_cols must be True or False, got {wrap_cols!r}")
    return bool(wrap_cols)


def _broadcast_angle(angle, name: str, shape: tuple[int, int]) -> np.ndarray:
    """A finite angle array that broadcasts to ``shape`` (returned unbroadcast)."""
    values = _float_array(angle, name)
    try:
        broadcast = np.broadcast_shapes(values.shape, shape)
    except ValueError:
        broadcast = None
    if broadcast != shape:
        raise CalibError(f"{name} with shape {values.shape} does not broadcast to range_m's shape {shape}")
    if not np.isfinite(values).all():
        raise CalibError(f"{name} contains NaN or inf")
    return values


def _finite_scalar(value, name: str) -> float:
    values = _float_array(value, name)
    if values.ndim != 0 or not np.isfinite(values):
        raise CalibError(f"{name} must be one finite number (metres), got {value!r}")
    return float(values)


def rotating_scanner_beams(theta_rad, phi_rad, dx_m, dz_m) -> tuple[np.ndarray, np.ndarray]:
    """Beam origins and unit directions of the rotating 2-D scanner (eq. 3).

    The measured point of a beam with range ``rho`` is
    ``origins + rho * directions``; this is what a ray caster needs to
    simulate the scanner.

    Parameters
    ----------
    theta_rad : array_like
        In-plane mirror angle theta_j, radians.
    phi_rad : array_like
        Rotation phi_i of the scan plane about the lidar y axis, radians.
    dx_m, dz_m : array_like
        Offset of the mirror centre from the rotation axis, metres.
        All four inputs broadcast together to a shape ``S``.

    Returns
    -------
    origins : (*S, 3) float64
        Beam start points ``Ry(phi) @ [dx, 0, dz]`` in the lidar frame, metres.
    directions : (*S, 3) float64
        Unit beam directions ``Ry(phi) @ Rz(theta) @ [1, 0, 0]`` in the lidar frame.
    """
    theta = _float_array(theta_rad, "theta_rad")
    phi = _float_array(phi_rad, "phi_rad")
    dx = _float_array(dx_m, "dx_m")
    dz = _float_array(dz_m, "dz_m")
    try:
        theta, phi, dx, dz = np.broadcast_arrays(theta, phi, dx, dz)
    except ValueError:
        raise CalibError(
            f"theta_rad {theta.shape}, phi_rad {phi.shape}, dx_m {dx.shape} and dz_m {dz.shape} do not broadcast together"
        ) from None
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    cos_theta, sin_theta = np.cos(theta), np.sin(theta)
    # Eq. 3: rho multiplies the first column (the direction); the fourth is the origin.
    directions = np.stack([cos_phi * cos_theta, sin_theta, -sin_phi * cos_theta], axis=-1)
    origins = np.stack([cos_phi * dx + sin_phi * dz, np.zeros_like(dx), -sin_phi * dx + cos_phi * dz], axis=-1)
    return origins, directions


def rotating_scanner_depth(range_m, theta_rad, phi_rad, dx_m, dz_m, wrap_cols: bool = False) -> DepthMatrix:
    """Depth matrix of the rotating 2-D scanner (paper eq. 3).

    Parameters
    ----------
    range_m : (H, W) array_like
        Measured range rho along each beam, metres, from the mirror centre.
        NaN, inf and values <= 0 mean "no return".
    theta_rad, phi_rad : array_like
        Beam angles (radians, finite) that broadcast against ``(H, W)``:
        e.g. theta per row as ``(H, 1)`` and phi per column as ``(W,)``.
    dx_m, dz_m : float
        Offset of the mirror centre from the rotation axis, metres.
    wrap_cols : bool
        True when the columns close a full 360 deg turn, so that column 0's
        left neighbour is column W-1.

    Returns
    -------
    DepthMatrix
        Points ``origin + rho * direction`` (NaN where invalid);
        ``meta = {"model": "rotating_2d", "theta_rad", "phi_rad", "dx_m",
        "dz_m", "wrap_cols"}`` holding the parameters as given.
    """
    rho = _range_image(range_m)
    shape = rho.shape
    theta = _broadcast_angle(theta_rad, "theta_rad", shape)
    phi = _broadcast_angle(phi_rad, "phi_rad", shape)
    dx = _finite_scalar(dx_m, "dx_m")
    dz = _finite_scalar(dz_m, "dz_m")
    wrap = _check_wrap_cols(wrap_cols)

    origins, directions = rotating_scanner_beams(
        np.broadcast_to(theta, shape), np.broadcast_to(phi, shape), dx, dz
    )
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(rho) & (rho > 0.0)
    range_clean = np.where(valid, rho, np.nan)
    points = origins + range_clean[..., None] * directions
    meta = {
        "model": "rotating_2d",
        "theta_rad": theta.copy(),
        "phi_rad": phi.copy(),
        "dx_m": dx,
        "dz_m": dz,
        "wrap_cols": wrap,
    }
    return DepthMatrix(range_m=range_clean, directions=directions, points=points, valid=valid, meta=meta)
