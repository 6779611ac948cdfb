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

Each image is one compiled pass over the depth matrix (numba, cached on
disk; :func:`warm_up` compiles it ahead of use).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from ._jit import kernel
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

#: Beam direction components below this are set to 0 (see _trace_geometry).
_TINY_COMPONENT = 1e-10


# ------------------------------------------------------------------ kernels
# atan(t) = t P(t^2) on [0, 1]: minimax (absolute error) coefficients of
# degree 15, fitted for this module.  In float32 the polynomial is within
# 1.6e-7 rad of atan; with the float32 rounding of the result the images are
# within 4e-7 rad (2.3e-5 deg) of eq. 4 (3.7e-7 rad measured), which
# tests/test_bearing_angle.py checks over the whole 0..180 deg range.
_ATAN_C0 = np.float32(0.9999994602868411)
_ATAN_C1 = np.float32(-0.3333036165293929)
_ATAN_C2 = np.float32(0.19952026589133437)
_ATAN_C3 = np.float32(-0.13934982034036378)
_ATAN_C4 = np.float32(0.09707729934543516)
_ATAN_C5 = np.float32(-0.05678586807014375)
_ATAN_C6 = np.float32(0.02245502772813752)
_ATAN_C7 = np.float32(-0.00421461362526089)
_HALF_PI32 = np.float32(np.pi / 2)
_PI32 = np.float32(np.pi)
_NAN32 = np.float32(np.nan)


@kernel
def _atan2_upper(y, x):
    """``atan2(y, x)`` in [0, pi] for float32 ``y >= 0``; NaN if ``x`` or ``y`` is NaN or both are 0.

    Branch-free (selects only), so the loops that call it run on SIMD lanes.
    """
    ax = abs(x)
    swap = y > ax
    t = (ax if swap else y) / (y if swap else ax)  # in [0, 1]; 0/0 and NaN give NaN
    z = t * t
    p = _ATAN_C7 * z + _ATAN_C6
    p = p * z + _ATAN_C5
    p = p * z + _ATAN_C4
    p = p * z + _ATAN_C3
    p = p * z + _ATAN_C2
    p = p * z + _ATAN_C1
    p = p * z + _ATAN_C0
    p = p * t
    p = _HALF_PI32 - p if swap else p
    p = _PI32 - p if x < 0 else p
    # Rounding may leave [0, pi] by an ulp; comparisons keep NaN.
    p = np.float32(0.0) if p < 0 else p
    return _PI32 if p > _PI32 else p


@kernel
def _masked_planes(values, valid, out):
    """``values`` (H, W, K) float64 into ``out`` (K, H, W) float32, NaN where not ``valid``."""
    n_rows, n_cols = valid.shape
    for k in range(out.shape[0]):
        for r in range(n_rows):
            for c in range(n_cols):
                out[k, r, c] = np.float32(values[r, c, k]) if valid[r, c] else _NAN32


@kernel
def _ba_row_common_origin(rho_cur, rho_prev, versine, sine, out):
    """One row of a BA image of beams sharing an origin (1-D float32 arrays of one length).

    BA = atan2(y, x) with y = rho_prev sin dphi and
    x = rho_cur - rho_prev cos dphi = (rho_cur - rho_prev) + rho_prev (1 - cos dphi).
    """
    for c in range(out.shape[0]):  # runs on SIMD lanes
        prev = rho_prev[c]
        x = (rho_cur[c] - prev) + prev * versine[c]
        out[c] = _atan2_upper(prev * sine[c], x)


@kernel
def _segment_legs_row(cur_x, cur_y, cur_z, prev_x, prev_y, prev_z, beam_x, beam_y, beam_z, along, across):
    """``d . s`` and ``|d x s|`` for one row (1-D float32 arrays): the legs of the BA's triangle.

    ``cur_*`` and ``prev_*`` are the coordinates of the cells' points and of
    their previous neighbours' points, ``s = cur - prev``; ``beam_*`` the
    cells' unit beam directions ``d``.
    """
    for c in range(along.shape[0]):
        sx, sy, sz = cur_x[c] - prev_x[c], cur_y[c] - prev_y[c], cur_z[c] - prev_z[c]
        dx, dy, dz = beam_x[c], beam_y[c], beam_z[c]
        cx, cy, cz = dy * sz - dz * sy, dz * sx - dx * sz, dx * sy - dy * sx
        along[c] = dx * sx + dy * sy + dz * sz
        across[c] = np.sqrt(cx * cx + cy * cy + cz * cz)


@kernel
def _atan2_row(y, x, out):
    """``out = atan2(y, x)`` for 1-D float32 arrays with ``y >= 0``."""
    for c in range(out.shape[0]):  # runs on SIMD lanes
        out[c] = _atan2_upper(y[c], x[c])


@kernel
def _ba_span(values, geometry, r, pr, start, stop, shift, common_origin, along, across, out):
    """Cells ``start:stop`` of row ``r`` of a BA image, previous neighbours at ``(pr, c + shift)``.

    Slices of one row with integer leading indices stay C-contiguous, which
    is what lets the row loops run on SIMD lanes.  Beams with separate
    origins take two loops: the one over ten arrays is too many for LLVM's
    aliasing checks to vectorise, and the atan2 is what has to be vectorised
    (its selects become mispredicted branches in scalar code).
    """
    if common_origin:
        _ba_row_common_origin(values[0, r, start:stop], values[0, pr, start + shift : stop + shift],
                              geometry[0, r, start:stop], geometry[1, r, start:stop], out[r, start:stop])
        return
    n = stop - start
    _segment_legs_row(
        values[0, r, start:stop], values[1, r, start:stop], values[2, r, start:stop],
        values[0, pr, start + shift : stop + shift], values[1, pr, start + shift : stop + shift],
        values[2, pr, start + shift : stop + shift],
        geometry[0, r, start:stop], geometry[1, r, start:stop], geometry[2, r, start:stop], along[:n], across[:n],
    )
    _atan2_row(across[:n], along[:n], out[r, start:stop])


@kernel
def _ba_image(values, geometry, d_row, d_col, wrap, common_origin, out):
    """One BA image into ``out`` (H, W) float32, a row at a time.

    ``values`` (K, H, W) float32 holds the masked ranges (K = 1) or points
    (K = 3); ``geometry`` (2, H, W) float32 is 1 - cos dphi and sin dphi
    (common origin) or (3, H, W) the beam directions.  The previous
    neighbour of cell (r, c) is (r + d_row, c + d_col), with d_col 0 or -1;
    with ``wrap`` column 0 follows column W-1.
    """
    n_rows, n_cols = out.shape
    along, across = np.empty(n_cols, np.float32), np.empty(n_cols, np.float32)
    first = 1 if d_col != 0 else 0
    for r in range(n_rows):
        pr = r + d_row
        if pr < 0 or pr >= n_rows:
            out[r, :] = _NAN32
            continue
        _ba_span(values, geometry, r, pr, first, n_cols, d_col, common_origin, along, across, out)
        if first:
            out[r, 0] = _NAN32
            if wrap:  # column 0 follows column W-1
                _ba_span(values, geometry, r, pr, 0, 1, n_cols - 1, common_origin, along, across, out)


@kernel
def _dphi_geometry(directions, d_row, d_col, wrap, versine, sine):
    """``1 - cos dphi`` and ``sin dphi`` of every cell to its previous neighbour, float32; NaN without one.

    For unit vectors with chord k = |d - e|: 1 - cos = k^2 / 2 and
    sin = k sqrt(1 - k^2 / 4); both stay accurate for tiny angles.
    """
    n_rows, n_cols = versine.shape
    for r in range(n_rows):
        pr = r + d_row
        for c in range(n_cols):
            pc = c + d_col
            if pc < 0 and wrap:
                pc = n_cols - 1
            if pr < 0 or pr >= n_rows or pc < 0:
                versine[r, c] = _NAN32
                sine[r, c] = _NAN32
                continue
            k2 = 0.0
            for k in range(3):
                diff = directions[r, c, k] - directions[pr, pc, k]
                k2 += diff * diff
            s2 = k2 * (1.0 - 0.25 * k2)
            s2 = 0.0 if s2 < 0.0 else s2  # keeps NaN
            versine[r, c] = np.float32(0.5 * k2)
            sine[r, c] = np.float32(np.sqrt(s2))


@kernel
def _largest_origin_offset(points, rng, directions):
    """Largest ``|point - range * direction|`` coordinate over the cells where it is a number, metres."""
    n_rows, n_cols = rng.shape
    largest = 0.0
    for r in range(n_rows):
        for c in range(n_cols):
            for k in range(3):
                offset = abs(points[r, c, k] - rng[r, c] * directions[r, c, k])
                if offset > largest:  # NaN never is
                    largest = offset
    return largest


# ------------------------------------------------------------ beam geometry
@dataclass(frozen=True)
class _TraceGeometry:
    """What the BA needs from the beams of one depth matrix; never the ranges."""

    wrap_cols: bool
    common_origin: bool
    # Common origin: per trace, (2, H, W) float32 of 1 - cos dphi and sin dphi, NaN without neighbour.
    # Separate origins: for every trace, (3, H, W) float32 planes of the unit beam directions.
    planes: dict[str, np.ndarray]


_GEOMETRY_CACHE: dict[int, _TraceGeometry] = {}


def _c_array(values, dtype) -> np.ndarray:
    """C-contiguous array of ``dtype`` (no copy when it already is): the kernels are compiled for these."""
    return np.ascontiguousarray(values, dtype=dtype)


def _trace_geometry(depth: DepthMatrix, wrap_cols: bool) -> _TraceGeometry:
    """Beam geometry of ``depth``, computed once per depth matrix and cached."""
    key = id(depth)
    cached = _GEOMETRY_CACHE.get(key)
    if cached is not None and cached.wrap_cols == wrap_cols:
        return cached
    directions = _c_array(depth.directions, np.float64)
    offset = _largest_origin_offset(_c_array(depth.points, np.float64), _c_array(depth.range_m, np.float64), directions)
    common_origin = offset <= _COMMON_ORIGIN_TOL_M
    if common_origin:
        planes = {}
        for name in BA_DIRECTIONS:
            planes[name] = np.empty((2,) + depth.shape, np.float32)
            _dphi_geometry(directions, *PREVIOUS_NEIGHBOUR[name], wrap_cols, planes[name][0], planes[name][1])
    else:
        beams = _c_array(np.moveaxis(directions, 2, 0), np.float32)  # (3, H, W)
        # Components like cos(pi/2) = 6e-17 make denormal products in the
        # cross product, which the CPU handles ~6x slower; zeroing them turns
        # a beam by under 1e-10 rad.
        beams[np.abs(beams) < _TINY_COMPONENT] = 0.0
        planes = dict.fromkeys(BA_DIRECTIONS, beams)
    geometry = _TraceGeometry(wrap_cols, common_origin, planes)
    try:
        weakref.finalize(depth, _GEOMETRY_CACHE.pop, key, None)
    except TypeError:  # not weak-referenceable: do not cache
        return geometry
    _GEOMETRY_CACHE[key] = geometry
    return geometry


def _check_depth(depth) -> tuple[int, int]:
    if not isinstance(depth, DepthMatrix):
        raise CalibError(f"expected a DepthMatrix, got {type(depth).__name__}")
    shape = np.shape(depth.range_m)
    if len(shape) != 2 or np.shape(depth.directions) != shape + (3,) or np.shape(depth.points) != shape + (3,):
        raise CalibError(
            f"inconsistent depth matrix: range {shape}, directions {np.shape(depth.directions)}, points {np.shape(depth.points)}"
        )
    if np.shape(depth.valid) != shape:
        raise CalibError(f"inconsistent depth matrix: range {shape}, valid {np.shape(depth.valid)}")
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
    pi, so no clipping is needed.  One compiled pass per image, in
    float32: the angle comes from a polynomial within 4e-7 rad of atan2,
    and the rounding of the ranges to float32 moves a BA by about
    ``6e-8 / dphi`` radians.
    """
    n_rows, n_cols = _check_depth(depth)
    unknown = [name for name in directions if name not in PREVIOUS_NEIGHBOUR]
    if unknown:
        raise CalibError(f"unknown BA direction(s) {unknown}; expected some of {', '.join(BA_DIRECTIONS)}")
    wrap_cols = bool(depth.meta.get("wrap_cols", False))
    geometry = _trace_geometry(depth, wrap_cols)
    valid = _c_array(depth.valid, np.bool_)
    # A no-return cell counts as missing whatever its range or point says.
    source = depth.range_m[..., None] if geometry.common_origin else depth.points
    values = np.empty((source.shape[2], n_rows, n_cols), np.float32)
    _masked_planes(_c_array(source, np.float64), valid, values)
    images: dict[str, np.ndarray] = {}
    for name in directions:
        out = np.empty((n_rows, n_cols), np.float32)
        _ba_image(values, geometry.planes[name], *PREVIOUS_NEIGHBOUR[name], wrap_cols, geometry.common_origin, out)
        images[name] = out
    return images


def warm_up() -> None:
    """Compile (or load from numba's disk cache) this module's kernels on a tiny scan."""
    from .lidar.spherical import spherical_depth

    rho = np.array([[1.0, 2.0, np.nan], [1.5, 1.0, 2.0]])
    common = spherical_depth(rho, [0.1, 0.0], [0.2, 0.0, -0.2], wrap_cols=True)
    bearing_angle_images(common)
    # The separate-origins kernel: move every beam's origin off the centre.
    shifted = DepthMatrix(common.range_m, common.directions, common.points + 1.0, common.valid, dict(common.meta))
    bearing_angle_images(shifted)


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
