"""Scaramuzza's OCamCalib omnidirectional camera model (fisheye and catadioptric).

Conventions of the toolbox (see ``shared/notes/math.md``):

* ``pol = [a0, a1, ..., a_{N-1}]`` in ascending powers (a0 < 0, a1 = 0);
  ``invpol`` likewise.
* ``xc`` is the ROW and ``yc`` the COLUMN of the distortion centre, 0-based.
* OCam frame: ``x`` along image rows, ``y`` along columns, optical axis ``-z``.

cam2world: pixel ``(row r, column q)`` ->
``xp = ((r - xc) - d (q - yc)) / (c - d e)``,
``yp = (-e (r - xc) + c (q - yc)) / (c - d e)``,
ray ``(xp, yp, pol(hypot(xp, yp)))``.

world2cam: the ray at angle ``alpha`` from the axis lands at the radius
``rho`` solving ``pol(rho) sin(alpha) + rho cos(alpha) = 0`` (i.e.
``pol(rho) - m rho = 0`` with ``m = z / hypot(x, y)``), then
``row = c x + d y + xc``, ``column = e x + y + yc``.  We solve that equation
directly (lookup table of ``alpha(rho)`` + Newton), which is exact at every
angle, and tabulate the solution densely for :meth:`OCamCamera.project`; the
toolbox's ``invpol`` is only a fit, valid out to about the image-corner
radius, and is kept for file export.

Frame change to OpenCV (x right, y down, z forward), a proper rotation::

    X_cv = y_oc,  Y_cv = x_oc,  Z_cv = -z_oc

Rays more than 90 deg from the axis (catadioptric cameras) are handled; the
accepted field of view is the angle reached at the largest radius the image
covers, or where ``alpha(rho)`` stops increasing, whichever comes first
(:attr:`OCamCamera.max_angle_rad`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.polynomial import polynomial as npoly

from ..errors import CalibError
from ..io.atomic import write_bytes_atomic
from ..io.input_files import MAX_CAMERA_BYTES, read_input_text
from .kernels import ocam_bearing, ocam_project, _O_INVSTEP
from .base import as_pixels, as_points_keep_float32, empty_projection, register_camera_model
from .params import param_float, param_image_size, param_vector, require_keys

#: Rotation taking OCam-frame vectors to the OpenCV camera frame (det +1).
R_CV_OCAM = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

_TABLE_SIZE = 4097
_FAST_TABLE_SIZE = 1 << 17
#: Stride of the float32 table (``1 << 14`` entries) over the float64 one.
_COARSE = 8
_INVPOL_MAX_ERR_PX = 0.01  # the toolbox's own stopping criterion
_INVPOL_MAX_DEGREE = 30


def _half_angle_s(alpha: np.ndarray) -> np.ndarray:
    """Monotonic stand-in for the angle from the axis, ``s`` in ``[0, 2]``:
    ``tan(alpha / 2)`` up to 90 deg, ``2 - tan((pi - alpha) / 2)`` beyond.

    A point at distance ``n`` from the axis and ``r`` from the centre has
    ``s = n / (r + |Z|)`` (in front, ``Z >= 0``) or ``2 - n / (r + |Z|)``
    (behind): no arctan per point.  ``alpha(s)`` is smooth on each side of
    ``s = 1`` with a continuous slope, so the table is well interpolated.
    """
    alpha = np.asarray(alpha, dtype=np.float64)
    return np.where(alpha <= np.pi / 2, np.tan(alpha / 2), 2.0 - np.tan((np.pi - alpha) / 2))


def _angle_from_s(s: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_half_angle_s`, radians."""
    return np.where(s <= 1.0, 2 * np.arctan(s), np.pi - 2 * np.arctan(2.0 - s))


@register_camera_model
class OCamCamera:
    """OCamCalib camera (Scaramuzza's polynomial omnidirectional model).

    Parameters
    ----------
    pol : array_like
        ``a0, a1, ...`` of the direct polynomial (cam2world), ascending powers.
    invpol : array_like or None
        Inverse polynomial (world2cam) in ascending powers of
        ``theta = atan(z / hypot(x, y))`` (OCam frame), or None to fit one as
        the toolbox does (max error 0.01 px).
    xc, yc : float
        Centre ROW and COLUMN, 0-based pixels.
    c, d, e : float
        Affine parameters.
    width, height : int
        Image size in pixels.

    Attributes
    ----------
    rho_max : float
        Largest accepted radius (pixels, before the affine map).
    max_angle_rad : float
        Largest accepted angle between a ray and the optical axis, radians;
        may exceed pi/2.
    source_path : Path or None
        The calib_results.txt the camera was read from, if unchanged since.
    """

    model: ClassVar[str] = "ocam"

    def __init__(
        self,
        pol: Any,
        invpol: Any,
        xc: float,
        yc: float,
        c: float,
        d: float,
        e: float,
        width: int,
        height: int,
    ) -> None:
        self.pol = param_vector(pol, "pol")
        if self.pol.size < 1 or not self.pol[0] < 0:
            raise CalibError(f"pol: a0 must be negative (optical axis along -z), got {self.pol.tolist()}")
        self.xc, self.yc = param_float(xc, "xc"), param_float(yc, "yc")
        self.c, self.d, self.e = param_float(c, "c"), param_float(d, "d"), param_float(e, "e")
        det = self.c - self.d * self.e
        if abs(det) < 1e-9:
            raise CalibError(f"affine parameters c={self.c}, d={self.d}, e={self.e} are singular (c - d*e = 0)")
        self._invdet = 1.0 / det
        self.width, self.height = param_image_size(width, height)
        self._dpol = npoly.polyder(self.pol) if self.pol.size > 1 else np.zeros(1)
        self._pol_c = np.ascontiguousarray(self.pol)
        self.source_path: Path | None = None
        self._build_table()
        if invpol is None:
            self.invpol = self.fit_invpol()
        else:
            self.invpol = param_vector(invpol, "invpol")
            if self.invpol.size < 1:
                raise CalibError("invpol: needs at least one coefficient")

    # -- geometry helpers (OCam frame) ----------------------------------------------
    def _image_plane(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel (row, column) -> sensor-plane ``(xp, yp)`` (undo the affine map)."""
        dr, dq = rows - self.xc, cols - self.yc
        return self._invdet * (dr - self.d * dq), self._invdet * (-self.e * dr + self.c * dq)

    def _build_table(self) -> None:
        """Monotonic table of ``alpha(rho)`` over the radii the image covers."""
        rows = np.array([-0.5, -0.5, self.height - 0.5, self.height - 0.5])
        cols = np.array([-0.5, self.width - 0.5, -0.5, self.width - 0.5])
        xp, yp = self._image_plane(rows, cols)
        # rho is convex in the pixel, so its maximum over the image is at a corner.
        rho_image = float(np.max(np.hypot(xp, yp)))
        rho = np.linspace(0.0, rho_image, _TABLE_SIZE)
        z = npoly.polyval(rho, self.pol)
        # d alpha / d rho has the sign of rho pol'(rho) - pol(rho).
        increasing = rho * npoly.polyval(rho, self._dpol) - z > 0
        n = int(np.argmin(increasing)) if not increasing.all() else rho.size
        if n < 2:
            raise CalibError(f"pol={self.pol.tolist()}: the ray angle decreases right from the centre")
        self.rho_max = float(rho[n - 1])
        self._table_rho = rho[:n]
        self._table_alpha = np.arctan2(rho[:n], -z[:n])
        self.max_angle_rad = float(self._table_alpha[-1])
        # rho on a uniform, dense grid of the half-angle variable s (see
        # _half_angle_s): project() then interpolates by index arithmetic, with
        # no arctan, no search and no Newton loop.  Linear interpolation error
        # at this spacing is < 1e-7 px.
        self._s_max = float(_half_angle_s(self.max_angle_rad))
        self._s_step = self._s_max / (_FAST_TABLE_SIZE - 1)
        s = np.linspace(0.0, self._s_max, _FAST_TABLE_SIZE)
        self._fast_rho = self.rho_from_angle(np.clip(_angle_from_s(s), 0.0, self.max_angle_rad))
        # rho and the slope of each interval side by side: an interpolation
        # reads one cache line.  Also in float32, for float32 points (half the
        # cache footprint; rho within 3e-5 px).
        table = np.column_stack([self._fast_rho, np.append(np.diff(self._fast_rho), 0.0)])
        # The compiled kernels' parameter vector (layout: calib_core.cameras.kernels).
        self._prm = np.array([self._s_max, 1.0 / self._s_step, self.c, self.d, self.e, self.xc, self.yc,
                              self.width, self.height, self._invdet, self.rho_max])
        # float32 points (bulk colouring) read a coarser float32 table, _COARSE times the step: 128 kB,
        # which stays in L2 cache under a million random reads (the fine one is 1-2 MB), and its
        # interpolation error (< 1e-7 px x _COARSE^2, about 7e-6 px) is below float32 pixel rounding.
        m = (_FAST_TABLE_SIZE - 1) // _COARSE + 1
        s32 = np.linspace(0.0, self._s_max, m)
        rho32 = self.rho_from_angle(np.clip(_angle_from_s(s32), 0.0, self.max_angle_rad))
        coarse = np.column_stack([rho32, np.append(np.diff(rho32), 0.0)]).astype(np.float32)
        prm32 = self._prm.copy()
        prm32[_O_INVSTEP] = (m - 1) / self._s_max
        self._fast_tables = {np.dtype(np.float64): (self._prm, table), np.dtype(np.float32): (prm32, coarse)}

    def rho_from_angle(self, alpha: np.ndarray) -> np.ndarray:
        """Radius (pixels) at which rays at ``alpha`` rad from the axis land.

        Solves ``pol(rho) sin(alpha) + rho cos(alpha) = 0`` for ``alpha`` in
        ``[0, max_angle_rad]``: table interpolation, then Newton steps.
        """
        alpha = np.asarray(alpha, dtype=np.float64)
        rho = np.interp(alpha, self._table_alpha, self._table_rho)
        s, co = np.sin(alpha), np.cos(alpha)
        with np.errstate(invalid="ignore", divide="ignore"):
            for _ in range(8):
                h = npoly.polyval(rho, self.pol) * s + rho * co
                dh = npoly.polyval(rho, self._dpol) * s + co
                step = np.where(dh > 0, h / np.where(dh > 0, dh, 1.0), 0.0)
                rho = np.clip(rho - step, 0.0, self.rho_max)
                if not np.any(np.abs(step) > 1e-12):
                    break
        return rho

    def fit_invpol(self) -> np.ndarray:
        """The toolbox's inverse polynomial, ``rho(theta)`` with
        ``theta = alpha - pi/2``, of the lowest degree with max error < 0.01 px
        over ``[0, max_angle_rad]``."""
        alpha = np.linspace(0.0, self.max_angle_rad, 1000)
        theta = alpha - np.pi / 2
        rho = self.rho_from_angle(alpha)
        best, best_err = None, np.inf
        for degree in range(2, _INVPOL_MAX_DEGREE + 1):
            coeffs = npoly.polyfit(theta, rho, degree)
            err = float(np.max(np.abs(npoly.polyval(theta, coeffs) - rho)))
            if err < best_err:
                best, best_err = coeffs, err
            if err < _INVPOL_MAX_ERR_PX:
                break
        return best

    # -- F: camera -> image ---------------------------------------------------------
    def project(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of points in the OpenCV camera frame (metres).

        Returns ``(pixels (N, 2), valid (N,))``.  Pixels are NaN for the zero
        vector and for rays beyond :attr:`max_angle_rad`; ``valid`` also
        requires the pixel inside the image.  Rays behind the image plane
        (``Z <= 0``) are fine as long as they are within the field of view.
        float32 points give float32 pixels, computed in float32 (within
        about 2e-4 px of the float64 result, for bulk colouring); anything
        else float64.
        """
        P = as_points_keep_float32(points)
        pixels, valid = empty_projection(P)
        prm, table = self._fast_tables[P.dtype]
        ocam_project(P, prm, table, pixels, valid)
        return pixels, valid

    # -- F^-1: image -> camera ------------------------------------------------------
    def bearing(self, pixels: Any) -> np.ndarray:
        """Unit rays (OpenCV camera frame) for ``(u, v)`` = (column, row) pixels.

        NaN rows where the radius exceeds :attr:`rho_max` (outside the
        calibrated, monotonic part of the model).
        """
        uv = as_pixels(pixels)
        rays = np.empty((uv.shape[0], 3))
        ocam_bearing(uv, self._prm, self._pol_c, rays)
        return rays

    # -- files ----------------------------------------------------------------------
    @classmethod
    def from_calib_results(cls, path: str | os.PathLike) -> "OCamCamera":
        """Read the toolbox's C export ``calib_results.txt``.

        Lines starting with ``#`` are comments; the numbers that remain are, in
        order: ``N a0..a_{N-1}``, ``M p0..p_{M-1}``, ``xc yc``, ``c d e``,
        ``height width``.
        """
        path = Path(path)
        text = read_input_text(path, "calib_results file", MAX_CAMERA_BYTES)  # regular file, bounded
        tokens = [t for line in text.splitlines() if not line.lstrip().startswith("#") for t in line.split()]
        try:
            values = [float(t) for t in tokens]
        except ValueError as exc:
            raise CalibError(f"{path}: not a number in calib_results: {exc}") from None
        pos = 0

        def take(count: int, what: str) -> list[float]:
            nonlocal pos
            if pos + count > len(values):
                raise CalibError(f"{path}: calib_results ends early, missing {what}")
            out = values[pos : pos + count]
            pos += count
            return out

        def take_count(what: str) -> int:
            (n,) = take(1, f"the length of {what}")
            if not (1 <= n <= 100 and n == int(n)):  # NaN fails the range test first
                raise CalibError(f"{path}: bad length {n!r} of {what}")
            return int(n)

        pol = take(take_count("pol"), "pol coefficients")
        invpol = take(take_count("invpol"), "invpol coefficients")
        xc, yc = take(2, "the centre 'xc yc'")
        c, d, e = take(3, "the affine parameters 'c d e'")
        height, width = take(2, "the image size 'height width'")
        if pos != len(values):
            raise CalibError(f"{path}: {len(values) - pos} unexpected numbers after the image size")
        try:
            camera = cls(pol, invpol, xc, yc, c, d, e, width, height)
        except CalibError as exc:
            raise CalibError(f"{path}: {exc}") from None
        camera.source_path = path
        return camera

    def calib_results_text(self) -> str:
        """The C-export text; numbers are written with ``repr`` so they read
        back bit-exactly."""

        def nums(values: Any) -> str:
            return " ".join(repr(float(v)) for v in values)

        return (
            "#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). "
            "These are used by cam2world\n\n"
            f"{self.pol.size} {nums(self.pol)} \n\n"
            "#polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB). "
            "These are used by world2cam\n\n"
            f"{self.invpol.size} {nums(self.invpol)} \n\n"
            '#center: "row" and "column", starting from 0 (C convention)\n\n'
            f"{nums([self.xc, self.yc])}\n\n"
            '#affine parameters "c", "d", "e"\n\n'
            f"{nums([self.c, self.d, self.e])}\n\n"
            '#image size: "height" and "width"\n\n'
            f"{self.height} {self.width}\n\n"
        )

    def write_calib_results(self, path: str | os.PathLike) -> None:
        """Write the toolbox's C export ``calib_results.txt`` (atomically)."""
        write_bytes_atomic(path, self.calib_results_text().encode("utf-8"))

    def to_dict(self, base_dir: Path | None = None) -> dict[str, Any]:
        """``{model: ocam, file: ...}`` when the camera came unchanged from a
        file and ``base_dir`` is given (path relative to it), else all
        parameters inline."""
        if self.source_path is not None and base_dir is not None:
            return {"model": self.model, "file": os.path.relpath(self.source_path.resolve(), Path(base_dir).resolve())}
        return {
            "model": self.model,
            "pol": [float(v) for v in self.pol],
            "invpol": [float(v) for v in self.invpol],
            "xc": self.xc,
            "yc": self.yc,
            "c": self.c,
            "d": self.d,
            "e": self.e,
            "width": self.width,
            "height": self.height,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], base_dir: Path | None = None) -> "OCamCamera":
        """Build from ``{model: ocam, file: calib_results.txt}`` (relative to
        ``base_dir``) or from inline ``pol, [invpol], xc, yc, c, d, e, width,
        height``.  With ``file``, optional ``width``/``height`` replace the
        file's image size."""
        if "file" in data:
            if not isinstance(data["file"], str) or not data["file"]:
                raise CalibError(f"ocam camera: 'file' must be a path, got {data['file']!r}")
            file = Path(data["file"])
            if not file.is_absolute():
                file = Path(base_dir if base_dir is not None else ".") / file
            camera = cls.from_calib_results(file)
            if "width" in data or "height" in data:
                require_keys(data, ("width", "height"), "ocam camera")
                size = param_image_size(data["width"], data["height"])
                if size != (camera.width, camera.height):
                    camera = cls(camera.pol, camera.invpol, camera.xc, camera.yc, camera.c, camera.d, camera.e, *size)
            return camera
        require_keys(data, ("pol", "xc", "yc", "c", "d", "e", "width", "height"), "ocam camera")
        return cls(
            data["pol"], data.get("invpol"), data["xc"], data["yc"], data["c"], data["d"], data["e"],
            data["width"], data["height"],
        )

    def __repr__(self) -> str:
        return (
            f"OCamCamera(pol={self.pol.tolist()}, xc={self.xc:.6g}, yc={self.yc:.6g}, c={self.c:.6g}, "
            f"d={self.d:.6g}, e={self.e:.6g}, {self.width}x{self.height}, "
            f"max_angle={np.degrees(self.max_angle_rad):.1f} deg)"
        )


# -- other tools' files ------------------------------------------------------------------
#: Largest degree tried when a direct polynomial is fitted to a file that only gives the inverse one.
_POL_MAX_DEGREE = 12
#: Smallest angle from the axis sampled for that fit (radians): on the axis ``z = -rho / tan(alpha)`` is 0/0.
_POL_FIT_MIN_ANGLE = np.radians(0.5)


def pjlab_ocam_parameters(K: Any, world2cam: Any, width: Any, height: Any) -> dict[str, Any]:
    """Our ``model: ocam`` parameters for an OCam model in PJLab's intrinsic JSON layout.

    PJLab's SensorsCalibration (``surround-camera/manual_calib``) stores the
    affine part as ``cam_K = [[c, d, u0], [e, 1, v0], [0, 0, 1]]`` and the
    world2cam polynomial (OCamCalib's ``invpol``, ascending powers of
    ``theta``) as ``cam_dist``; it has no cam2world polynomial.  Its
    projection of a point ``(X, Y, Z)`` of the OpenCV camera frame (x
    right, y down, z forward) is, with ``n = hypot(X, Y)``,
    ``theta = atan(-Z / n)`` and ``rho = sum_i D_i theta^i``::

        u = c X rho / n + d Y rho / n + u0     (column)
        v = e X rho / n +   Y rho / n + v0     (row)

    OCamCalib's own frame has x along rows, so the same projection in our
    convention (``row = c' x + d' y + xc``, ``column = e' x + y + yc``,
    ``x = Y rho' / n``, ``y = X rho' / n``) takes ``rho' = c rho``,
    ``c' = 1 / c``, ``d' = e / c``, ``e' = d / c``, ``xc = v0``,
    ``yc = u0``: the same pixels exactly.  The direct polynomial ``pol``
    (``z = pol(rho')``, with ``a1 = 0`` as the toolbox fits it) is fitted to
    the rays ``z = -rho' / tan(alpha)``, ``alpha = theta + pi/2``, out to
    the image corners, of the lowest degree whose angles land within
    0.01 px of ``rho'``.

    Parameters
    ----------
    K : (3, 3) array_like
        ``cam_K``.
    world2cam : array_like
        ``cam_dist``, the world2cam coefficients (pixels per radian^i).
    width, height : int
        Image size in pixels (``img_dist_w``, ``img_dist_h``).

    Returns
    -------
    dict
        ``{model: ocam, pol, invpol, xc, yc, c, d, e, width, height}``.

    Raises
    ------
    CalibError
        A singular affine part, a polynomial that is not increasing from
        the axis out to the image corners, or no direct polynomial that
        reproduces it.
    """
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    coeffs = param_vector(world2cam, "cam_dist (world2cam)")
    c, d, e = float(K[0, 0]), float(K[0, 1]), float(K[1, 0])
    if abs(c) < 1e-9 or abs(K[1, 1] - 1.0) > 1e-9:
        raise CalibError(f"cam_K {K.tolist()} is not an OCam affine part [[c, d, u0], [e, 1, v0], [0, 0, 1]]")
    width, height = param_image_size(width, height)
    invpol = c * coeffs  # rho' = c rho
    ours = {"c": 1.0 / c, "d": e / c, "e": d / c, "xc": float(K[1, 2]), "yc": float(K[0, 2])}
    det = ours["c"] - ours["d"] * ours["e"]
    if abs(det) < 1e-9:
        raise CalibError(f"cam_K {K.tolist()}: the affine part is singular")
    # Sensor-plane radius of the image corners (pixel edges), as OCamCamera measures the image.
    rows = np.array([-0.5, -0.5, height - 0.5, height - 0.5]) - ours["xc"]
    cols = np.array([-0.5, width - 0.5, -0.5, width - 0.5]) - ours["yc"]
    xp, yp = (rows - ours["d"] * cols) / det, (-ours["e"] * rows + ours["c"] * cols) / det
    rho_corner = float(np.max(np.hypot(xp, yp)))
    alpha = np.linspace(0.0, np.pi, 20_001)
    rho = npoly.polyval(alpha - np.pi / 2, invpol)
    increasing = np.diff(rho) > 0
    n_ok = int(np.argmin(increasing)) + 1 if not increasing.all() else rho.size
    reach = np.flatnonzero(rho[:n_ok] >= rho_corner)
    if rho[0] < -0.5 or not reach.size:
        raise CalibError(
            f"cam_dist: the world2cam polynomial does not grow from the centre (rho {rho[0]:.3g} px) out to the image "
            f"corners ({rho_corner:.0f} px)"
        )
    alpha_max = min(alpha[min(int(reach[0] * 1.02) + 1, n_ok - 1)], np.pi - _POL_FIT_MIN_ANGLE)
    samples = np.linspace(_POL_FIT_MIN_ANGLE, alpha_max, 2000)
    rho_s = npoly.polyval(samples - np.pi / 2, invpol)
    z_s = -rho_s / np.tan(samples)
    scale = float(rho_s.max())
    t = rho_s / scale
    best, best_err = None, np.inf
    for degree in range(3, _POL_MAX_DEGREE + 1):
        powers = np.r_[0, np.arange(2, degree + 1)]  # a1 = 0, as the toolbox fits pol
        fit, *_ = np.linalg.lstsq(t[:, None] ** powers[None, :], z_s, rcond=None)
        pol = np.zeros(degree + 1)
        pol[powers] = fit / scale ** powers
        if not pol[0] < 0:
            continue
        # Where each sampled ray lands under the fitted pol: pol(r) sin(alpha) + r cos(alpha) = 0, by Newton.
        r = rho_s.copy()
        dpol = npoly.polyder(pol)
        for _ in range(20):
            h = npoly.polyval(r, pol) * np.sin(samples) + r * np.cos(samples)
            r = r - h / (npoly.polyval(r, dpol) * np.sin(samples) + np.cos(samples))
        err = float(np.max(np.abs(r - rho_s)))
        if np.isfinite(err) and err < best_err:
            best, best_err = pol, err
        if err < _INVPOL_MAX_ERR_PX:
            break
    if best is None or best_err > 0.1:
        raise CalibError(f"cam_dist: no direct polynomial reproduces the world2cam polynomial (best {best_err:.3g} px)")
    return {"model": "ocam", "pol": best.tolist(), "invpol": invpol.tolist(), **ours, "width": width, "height": height}
