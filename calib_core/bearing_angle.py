"""Bearing Angle (BA) images (paper Sec. III, eq. 4).

The bearing angle of a depth-matrix cell is the angle, at the cell's 3-D
point, between the cell's laser beam and the segment that joins the
*previous* cell's point to it.  Walking along a trace of the depth matrix,
with ``rho_i`` the current range, ``rho_{i-1}`` the previous one and
``dphi`` the angle between the two beams, the law of cosines gives (the
paper prints the denominator as ``sqrt(rho_i^2 - rho_{i-1}^2 - rho_i
rho_{i-1} cos dphi)``, a typo: it can put the arccos argument above 1)::

    BA_i = arccos((rho_i - rho_{i-1} cos dphi)
                  / sqrt(rho_i^2 + rho_{i-1}^2 - 2 rho_i rho_{i-1} cos dphi))

The four traces and the previous neighbour of cell ``(r, c)`` (row 0 at the
top, column 0 at the left, as the image is displayed):

================  ==============  ===========================================
``horizontal``    ``(r, c-1)``    left neighbour
``vertical``      ``(r-1, c)``    upper neighbour
``diag_pos45``    ``(r+1, c-1)``  lower-left: the trace climbs (+45 deg) when
                                  walking left to right
``diag_neg45``    ``(r-1, c-1)``  upper-left: the trace descends (-45 deg)
                                  when walking left to right
================  ==============  ===========================================

A cell whose previous neighbour lies outside the matrix has no BA (NaN),
except that with ``depth.meta["wrap_cols"]`` True (a full 360 deg scan) the
left neighbour of column 0 is column W-1.  A BA pixel is also NaN when the
cell or its neighbour has no return, or the two points coincide.

``dphi`` is the true angle between the two beams (``cos dphi`` is the dot
product of their unit directions), not the row or column step: along a
diagonal it is neither.  It depends only on the beam geometry, so it is
computed once per depth matrix and cached.  Where beams do not share an
origin (the paper's scanner with axis offsets, eq. 3), the ranges are not
measured from a common point and eq. 4 does not apply as such; the BA is then
evaluated from its definition, the angle between the beam direction and the
segment between the two 3-D points, which equals eq. 4 when the origins
coincide.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import cv2
import numpy as np

from .errors import CalibError
from .lidar.depth_matrix import DepthMatrix

#: The four traces, in the order the UI shows them.
BA_DIRECTIONS = ("horizontal", "vertical", "diag_pos45", "diag_neg45")

#: (row, column) offset from a cell to its previous neighbour along each trace.
PREVIOUS_NEIGHBOUR: dict[str, tuple[int, int]] = {
    "horizontal": (0, -1),
    "vertical": (-1, 0),
    "diag_pos45": (1, -1),
    "diag_neg45": (-1, -1),
}

#: Beams whose origins differ by less than this (metres) share an origin.
_COMMON_ORIGIN_TOL_M = 1e-6


def bearing_angle(range_prev, range_cur, cos_dphi) -> np.ndarray:
    """Bearing angle of eq. 4 (law-of-cosines form), elementwise.

    Parameters
    ----------
    range_prev : array_like
        Range rho_{i-1} of the previous beam, metres.
    range_cur : array_like
        Range rho_i of the current beam, metres (same origin as the previous).
    cos_dphi : array_like
        Cosine of the angle between the two beams.  All three broadcast.

    Returns
    -------
    ndarray, float64
        The angle in [0, pi] radians between the current beam and the segment
        from the previous point to the current one.  NaN where a range is not
        finite or <= 0, ``cos_dphi`` is not finite or outside [-1, 1] (beyond
        rounding), or the two points coincide.
    """
    rho_prev, rho_cur, cos_d = np.broadcast_arrays(
        np.asarray(range_prev, dtype=np.float64),
        np.asarray(range_cur, dtype=np.float64),
        np.asarray(cos_dphi, dtype=np.float64),
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = (
            np.isfinite(rho_prev)
            & np.isfinite(rho_cur)
            & (rho_prev > 0.0)
            & (rho_cur > 0.0)
            & np.isfinite(cos_d)
            & (np.abs(cos_d) <= 1.0 + 1e-9)
        )
        cos_d = np.clip(cos_d, -1.0, 1.0)
        segment_sq = rho_cur**2 + rho_prev**2 - 2.0 * rho_cur * rho_prev * cos_d
        segment = np.sqrt(np.maximum(segment_sq, 0.0))
        ok &= segment > 0.0
        # Clipping only absorbs rounding: |argument| <= 1 for any real triangle.
        argument = np.clip((rho_cur - rho_prev * cos_d) / segment, -1.0, 1.0)
        return np.where(ok, np.arccos(argument), np.nan)


def _previous_view(padded: np.ndarray, direction: str) -> np.ndarray:
    """View of a border-padded ``(H+2, W+2, ...)`` array aligned with each cell's previous neighbour."""
    d_row, d_col = PREVIOUS_NEIGHBOUR[direction]
    n_rows, n_cols = padded.shape[0] - 2, padded.shape[1] - 2
    return padded[1 + d_row : 1 + d_row + n_rows, 1 + d_col : 1 + d_col + n_cols]


def _pad(values: np.ndarray, wrap_cols: bool, dtype) -> np.ndarray:
    """``values (H, W, ...)`` inside a one-cell NaN border; with ``wrap_cols`` the side borders wrap around."""
    padded = np.full((values.shape[0] + 2, values.shape[1] + 2) + values.shape[2:], np.nan, dtype=dtype)
    padded[1:-1, 1:-1] = values
    if wrap_cols:
        padded[1:-1, 0] = values[:, -1]
        padded[1:-1, -1] = values[:, 0]
    return padded


@dataclass(frozen=True)
class _TraceGeometry:
    """What the BA needs from the beams of one depth matrix; never the ranges."""

    wrap_cols: bool
    common_origin: bool
    # Common origin: 1 - cos dphi and sin dphi per trace, float32 (H, W), NaN without neighbour.
    versine: dict[str, np.ndarray] | None
    sine: dict[str, np.ndarray] | None
    # Separate origins: the x, y, z planes of the beam directions, float32 (H, W) each.
    direction_planes: tuple[np.ndarray, np.ndarray, np.ndarray] | None


_GEOMETRY_CACHE: dict[int, _TraceGeometry] = {}


def _planes(values: np.ndarray, dtype) -> list[np.ndarray]:
    """The x, y, z planes ``(H, W)`` of an ``(H, W, 3)`` array, contiguous (array code runs faster on them)."""
    return [np.ascontiguousarray(values[..., k], dtype=dtype) for k in range(3)]


def _beams_share_origin(depth: DepthMatrix) -> bool:
    """Whether every valid point is ``range * direction`` (beams start at the origin)."""
    largest = 0.0
    with np.errstate(invalid="ignore"):
        for k in range(3):
            offset = np.abs(depth.points[..., k] - depth.range_m * depth.directions[..., k])
            largest = max(largest, float(np.fmax.reduce(offset, axis=None, initial=0.0)))  # fmax skips NaN
    return largest <= _COMMON_ORIGIN_TOL_M


def _trace_geometry(depth: DepthMatrix, wrap_cols: bool) -> _TraceGeometry:
    """Beam geometry of ``depth``, computed once per depth matrix and cached."""
    key = id(depth)
    cached = _GEOMETRY_CACHE.get(key)
    if cached is not None and cached.wrap_cols == wrap_cols:
        return cached
    if not _beams_share_origin(depth):
        geometry = _TraceGeometry(wrap_cols, False, None, None, tuple(_planes(depth.directions, np.float32)))
    else:
        planes = _planes(depth.directions, np.float64)
        padded = [_pad(plane, wrap_cols, np.float64) for plane in planes]
        versine, sine = {}, {}
        for name in BA_DIRECTIONS:
            # For unit vectors with chord k = |d - e|: 1 - cos = k^2 / 2 and
            # sin = k sqrt(1 - k^2 / 4); both stay accurate for tiny angles.
            chord_sq = sum((plane - _previous_view(pad, name)) ** 2 for plane, pad in zip(planes, padded))
            versine[name] = (0.5 * chord_sq).astype(np.float32)
            sine[name] = np.sqrt(np.clip(chord_sq * (1.0 - 0.25 * chord_sq), 0.0, None)).astype(np.float32)
        geometry = _TraceGeometry(wrap_cols, True, versine, sine, None)
    try:
        weakref.finalize(depth, _GEOMETRY_CACHE.pop, key, None)
    except TypeError:  # not weak-referenceable: do not cache
        return geometry
    _GEOMETRY_CACHE[key] = geometry
    return geometry


def _angle_of(x: np.ndarray, y: np.ndarray, out: np.ndarray, scratch: tuple[np.ndarray, ...]) -> np.ndarray:
    """``atan2(y, x)`` for ``y >= 0``, in [0, pi], float32, into ``out``.

    NaN where ``x`` or ``y`` is NaN or both are 0.  OpenCV's ``phase`` is a
    fast polynomial atan2 (error ~2e-4 rad); one Newton step, the angle
    between ``(x, y)`` and ``(cos a, sin a)``, brings it to float32 accuracy
    (~3e-7 rad) at a fraction of the cost of ``np.arctan2``.  ``scratch`` is
    four float32 buffers of the same shape.
    """
    cos_a, sin_a, along, across = scratch
    cv2.phase(x, y, out)
    cv2.polarToCart(None, out, cos_a, sin_a)
    np.multiply(y, cos_a, out=across)
    across -= np.multiply(x, sin_a, out=along)
    np.multiply(x, cos_a, out=along)
    np.multiply(y, sin_a, out=cos_a)
    along += cos_a
    with np.errstate(invalid="ignore", divide="ignore"):
        # (0, 0) gives 0 / 0 = NaN here: coincident points have no bearing angle.
        across /= along
    out += across
    np.clip(out, 0.0, np.float32(np.pi), out=out)
    return out


def _check_depth(depth) -> tuple[int, int]:
    if not isinstance(depth, DepthMatrix):
        raise CalibError(f"expected a DepthMatrix, got {type(depth).__name__}")
    shape = np.shape(depth.range_m)
    if len(shape) != 2 or np.shape(depth.directions) != shape + (3,) or np.shape(depth.points) != shape + (3,):
        raise CalibError(
            f"inconsistent depth matrix: range {shape}, directions {np.shape(depth.directions)}, points {np.shape(depth.points)}"
        )
    return shape


def bearing_angle_images(depth: DepthMatrix, directions=BA_DIRECTIONS) -> dict[str, np.ndarray]:
    """BA images of a depth matrix along the horizontal, vertical and diagonal traces.

    Parameters
    ----------
    depth : DepthMatrix
        The scan.  ``depth.meta.get("wrap_cols", False)`` says whether its
        columns close a full turn.
    directions : sequence of str
        Which traces to compute, a subset of :data:`BA_DIRECTIONS`
        (the module docstring defines each one's previous neighbour).

    Returns
    -------
    dict[str, ndarray]
        For each trace, an ``(H, W)`` float32 image of bearing angles in
        radians, in [0, pi]; NaN where invalid (no previous neighbour,
        no return at the cell or its neighbour, coincident points).

    Notes
    -----
    Computed as ``atan2(rho_{i-1} sin dphi, rho_i - rho_{i-1} cos dphi)``,
    the same angle as eq. 4 (law of sines and cosines in the triangle
    origin / previous point / current point) but well conditioned near 0 and
    pi, so no clipping is needed.  Arithmetic is float32: the rounding of the
    ranges to float32 alone moves a BA by about ``6e-8 / dphi`` radians.
    """
    n_rows, n_cols = _check_depth(depth)
    unknown = [name for name in directions if name not in PREVIOUS_NEIGHBOUR]
    if unknown:
        raise CalibError(f"unknown BA direction(s) {unknown}; expected some of {', '.join(BA_DIRECTIONS)}")
    wrap_cols = bool(depth.meta.get("wrap_cols", False))
    geometry = _trace_geometry(depth, wrap_cols)
    valid = np.asarray(depth.valid, dtype=bool)

    shape = (n_rows, n_cols)
    x, y = np.empty(shape, np.float32), np.empty(shape, np.float32)
    scratch = tuple(np.empty(shape, np.float32) for _ in range(4))
    images: dict[str, np.ndarray] = {}

    if geometry.common_origin:
        range_pad = _pad(depth.range_m, wrap_cols, np.float32)
        range_cur = range_pad[1:-1, 1:-1]
        range_cur[~valid] = np.nan  # a no-return cell counts as missing whatever its range says
        if wrap_cols:  # refresh the wrapped borders after masking
            range_pad[1:-1, 0] = range_cur[:, -1]
            range_pad[1:-1, -1] = range_cur[:, 0]
        range_cur = np.ascontiguousarray(range_cur)
        for name in directions:
            range_prev = _previous_view(range_pad, name)
            # x = rho_i - rho_{i-1} cos dphi, written with the versine to keep
            # float32 precision for small dphi; y = rho_{i-1} sin dphi.
            np.subtract(range_cur, range_prev, out=x)
            np.multiply(range_prev, geometry.versine[name], out=y)
            x += y
            np.multiply(range_prev, geometry.sine[name], out=y)
            images[name] = _angle_of(x, y, np.empty(shape, np.float32), scratch)
        return images

    # Beams with separate origins: the definition, from the 3-D points.
    # BA = atan2(|d x s|, d . s) with d the beam direction and s the segment.
    beam_x, beam_y, beam_z = geometry.direction_planes
    point_planes = []
    for plane in _planes(depth.points, np.float32):
        plane[~valid] = np.nan
        point_planes.append((plane, _pad(plane, wrap_cols, np.float32)))
    for name in directions:
        seg_x, seg_y, seg_z = (plane - _previous_view(padded, name) for plane, padded in point_planes)
        np.add(beam_x * seg_x + beam_y * seg_y, beam_z * seg_z, out=x)
        cross_sq = (beam_y * seg_z - beam_z * seg_y) ** 2
        cross_sq += (beam_z * seg_x - beam_x * seg_z) ** 2
        cross_sq += (beam_x * seg_y - beam_y * seg_x) ** 2
        np.sqrt(cross_sq, out=y)
        images[name] = _angle_of(x, y, np.empty(shape, np.float32), scratch)
    return images


def ba_to_uint8(ba_rad) -> np.ndarray:
    """Display gray levels ``floor(ba * 255 / pi)``, as PCL's BearingAngleImage.

    Parameters
    ----------
    ba_rad : (H, W) array_like
        Bearing angles in radians, NaN where invalid.

    Returns
    -------
    (H, W) uint8
        0 rad -> 0, pi rad -> 255, invalid -> 0.
    """
    ba = np.asarray(ba_rad, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        gray = np.clip(ba * np.float32(255.0 / np.pi), 0.0, 255.0)
    return np.nan_to_num(gray, nan=0.0).astype(np.uint8)


def ba_to_display(ba_rad, min_gray: int = 32, bins: int = 1024) -> np.ndarray:
    """Gray levels of a BA image for the UI, by histogram equalisation.

    A linear 0..pi mapping wastes the gray range: in a road scene a third of
    the cells (the ground) share one angle and wash out to white or black.
    Ranking the valid cells instead spreads them evenly over
    ``min_gray..255``, so kerbs and fences stand out, while gray 0 stays
    reserved for cells without a return -- holes never look like dark ground.

    Parameters
    ----------
    ba_rad : (H, W) array_like
        Bearing angles in radians, NaN where invalid.
    min_gray : int
        Gray level of the smallest valid angle (1..254).
    bins : int
        Angle bins of the equalisation over 0..pi.

    Returns
    -------
    (H, W) uint8
        Monotone in the angle over valid cells; 0 where invalid.
    """
    if not 1 <= int(min_gray) <= 254:
        raise CalibError(f"min_gray must be within 1..254, got {min_gray}")
    ba = np.asarray(ba_rad, dtype=np.float32)
    finite = np.isfinite(ba)
    gray = np.zeros(ba.shape, dtype=np.uint8)
    if not finite.any():
        return gray
    idx = np.clip((ba[finite] * np.float32(bins / np.pi)).astype(np.int64), 0, bins - 1)
    counts = np.bincount(idx, minlength=bins)
    # Mid-rank of each bin, so a flat image lands in the middle of the range.
    cdf = (np.cumsum(counts) - 0.5 * counts) / idx.size
    lut = np.rint(min_gray + (255 - min_gray) * cdf).astype(np.uint8)
    gray[finite] = lut[idx]
    return gray
