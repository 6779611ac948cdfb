"""The maths of the rough alignment: mounting presets, turning the view about the camera centre (by drag), and the
rotation that 2 or 3 pairs fix before a full solve (:func:`fit_rotation_about_centre`).

Frames: the lidar frame is x forward, y left, z up; the camera frame is OpenCV's, x right, y down,
z forward (the optical axis).  ``T_camera_lidar`` (4, 4) maps lidar points (metres) into the camera
frame: ``p_camera = R @ p_lidar + t``; the camera centre in the lidar frame is ``-R.T @ t``.  Angles are
radians unless a name says degrees.  Pixels are ``(u, v)`` = (column, row), the top-left pixel's centre
at ``(0, 0)``.

Sign convention of the view rotation (:func:`rotate_about_camera`), as seen on the screen:

* positive ``d_yaw`` (about the camera's y axis) moves the projected points to the right (u grows);
* positive ``d_pitch`` (about the camera's x axis) moves them down (v grows);
* positive ``d_roll`` (about the optical axis) turns them clockwise about the principal point.

So dragging the scan overlay by ``(du, dv)`` pixels is :func:`drag_to_rotation` ``(du, dv, f)`` fed
straight into :func:`rotate_about_camera`.
"""

from __future__ import annotations

import numpy as np

from .arrays import as_transform
from .errors import CalibError


def _T_from_camera_axes(x_axis, y_axis, z_axis) -> np.ndarray:
    """``T_camera_lidar`` with the camera at the lidar origin, its x/y/z axes given in the lidar frame."""
    T = np.eye(4)
    T[:3, :3] = np.array([x_axis, y_axis, z_axis], dtype=float)  # rows: camera axes in lidar coordinates
    return T


#: Initial ``T_camera_lidar`` for a camera at the lidar origin looking along one lidar axis, image upright
#: (camera y = -lidar z).  Keys name the lidar axis the optical axis points along.
MOUNTING_PRESETS: dict[str, np.ndarray] = {
    "+x": _T_from_camera_axes((0, -1, 0), (0, 0, -1), (1, 0, 0)),   # forward: image right = lidar -y
    "-y": _T_from_camera_axes((-1, 0, 0), (0, 0, -1), (0, -1, 0)),  # to the right: image right = lidar -x
    "+y": _T_from_camera_axes((1, 0, 0), (0, 0, -1), (0, 1, 0)),    # to the left: image right = lidar +x
    "-x": _T_from_camera_axes((0, 1, 0), (0, 0, -1), (-1, 0, 0)),   # backward: image right = lidar +y
}
#: Plain-word names of the presets.
PRESET_ALIASES = {"forward": "+x", "right": "-y", "left": "+y", "backward": "-x"}


def preset_T(name: str) -> np.ndarray:
    """The mounting preset ``name`` (``"+x"``, ``"-y"``, ``"+y"``, ``"-x"``, or forward/right/left/backward).

    Returns
    -------
    (4, 4) float64
        ``T_camera_lidar``, translation 0 (a copy: safe to modify).
    """
    key = PRESET_ALIASES.get(str(name).strip().lower(), str(name).strip())
    if key not in MOUNTING_PRESETS:
        names = ", ".join(list(MOUNTING_PRESETS) + list(PRESET_ALIASES))
        raise CalibError(f"unknown mounting preset {name!r}; use one of {names}")
    return MOUNTING_PRESETS[key].copy()


def view_rotation(d_yaw_rad: float, d_pitch_rad: float, d_roll_rad: float = 0.0) -> np.ndarray:
    """The rotation ``R_delta`` (3, 3) applied to camera-frame points by :func:`rotate_about_camera`.

    ``R_delta = Rz(d_roll) @ Rx(-d_pitch) @ Ry(d_yaw)`` (right-handed elementary rotations about the
    camera axes; yaw acts first).  A point on the optical axis goes to
    ``(sin(yaw), sin(pitch) cos(yaw), cos(pitch) cos(yaw))`` (before the roll): right for positive yaw,
    down for positive pitch.
    """
    from scipy.spatial.transform import Rotation  # (imported on first use, as in :mod:`.transforms`)

    # Intrinsic "ZXY": the matrix is Rz @ Rx @ Ry.
    return Rotation.from_euler("ZXY", [float(d_roll_rad), -float(d_pitch_rad), float(d_yaw_rad)]).as_matrix()


def rotate_about_camera(T_camera_lidar, d_yaw_rad: float, d_pitch_rad: float, d_roll_rad: float = 0.0) -> np.ndarray:
    """Turn the view about the camera centre: the camera stays where it is, the scene turns in the image.

    Parameters
    ----------
    T_camera_lidar : (4, 4) array_like
        Maps lidar points (metres) into the camera frame.
    d_yaw_rad, d_pitch_rad, d_roll_rad : float
        Radians, about the camera's y (image up/down), x (image left/right) and z (optical) axes, with the
        module's screen convention: positive yaw moves projected points right, positive pitch down,
        positive roll clockwise on the screen.

    Returns
    -------
    (4, 4) float64
        ``[R_delta R | R_delta t]`` with ``R_delta = view_rotation(...)``: camera-frame points are turned by
        ``R_delta``; the camera centre in the lidar frame, ``-R.T t``, is unchanged.
    """
    T = as_transform(T_camera_lidar)
    R_delta = view_rotation(d_yaw_rad, d_pitch_rad, d_roll_rad)
    out = np.eye(4)
    out[:3, :3] = R_delta @ T[:3, :3]
    out[:3, 3] = R_delta @ T[:3, 3]
    return out


def drag_to_rotation(du_px: float, dv_px: float, focal_px) -> tuple[float, float]:
    """The view rotation that makes the point under the cursor follow a drag of ``(du, dv)`` screen pixels.

    For a pinhole camera (focal lengths ``fx``, ``fy``) and a point on the optical axis (it projects to the
    principal point), :func:`rotate_about_camera` with the returned angles moves its projection by exactly
    ``(du, dv)``: after the yaw ``a`` and then the pitch ``b`` of :func:`view_rotation` the point is at
    ``u - cx = fx tan(a) / cos(b)``, ``v - cy = fy tan(b)``, so

    ``d_pitch = atan(dv / fy)``,  ``d_yaw = atan(du / (fx * sqrt(1 + (dv / fy)**2)))``.

    Elsewhere in the image, and for other camera models (with :func:`focal_px_estimate`), the point follows
    the cursor to first order.

    Parameters
    ----------
    du_px, dv_px : float
        Drag in image pixels (right and down positive).
    focal_px : float or (float, float)
        Focal length in pixels, or ``(fx, fy)``.

    Returns
    -------
    (d_yaw_rad, d_pitch_rad) : (float, float)
        Radians, for :func:`rotate_about_camera` (roll 0).
    """
    f = np.broadcast_to(np.asarray(focal_px, dtype=float), (2,))
    fx, fy = float(f[0]), float(f[1])
    if not (np.isfinite(fx) and np.isfinite(fy) and fx > 0 and fy > 0):
        raise CalibError(f"focal length must be positive and finite, got {focal_px}")
    du, dv = float(du_px), float(dv_px)
    if not (np.isfinite(du) and np.isfinite(dv)):
        raise CalibError(f"drag must be finite, got ({du_px}, {dv_px})")
    d_pitch = float(np.arctan2(dv, fy))
    d_yaw = float(np.arctan2(du, fx * np.hypot(1.0, dv / fy)))
    return d_yaw, d_pitch


def translate_in_camera(T_camera_lidar, dx_m: float, dy_m: float, dz_m: float) -> np.ndarray:
    """Move the camera by ``(dx, dy, dz)`` metres along its own axes (x right, y down, z forward).

    The camera centre in the lidar frame moves by ``R.T @ d``; the orientation is unchanged, so
    ``t' = t - d`` (camera-frame points move by ``-d``).

    Returns
    -------
    (4, 4) float64
    """
    T = as_transform(T_camera_lidar).copy()
    d = np.array([dx_m, dy_m, dz_m], dtype=float)
    if not np.isfinite(d).all():
        raise CalibError(f"camera step must be finite, got {tuple(d)}")
    T[:3, 3] -= d
    return T


def focal_px_estimate(camera) -> float:
    """A focal length in pixels (pixels per radian near the image centre), for any camera model.

    From the bearings of the pixels one to each side of the principal point (where the optical axis
    projects; the image centre if it projects outside the image): two pixels ``2 * atan(1 / f)`` apart in
    angle give ``f = 1 / tan(angle / 2)``, horizontally and vertically; the mean of the two is returned.
    Exact ``(fx + fy) / 2`` for an undistorted pinhole; for fisheye and OCam models the local scale of the
    image near its centre.
    """
    width, height = int(camera.width), int(camera.height)
    centre_px, ok = camera.project(np.array([[0.0, 0.0, 1.0]]))
    centre = np.asarray(centre_px, float).reshape(2)
    if not (bool(np.asarray(ok).reshape(-1)[0]) and np.isfinite(centre).all()):
        centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    steps = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
    rays = np.asarray(camera.bearing(centre + steps), float)
    rays = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    focals = []
    for a, b in ((0, 1), (2, 3)):
        angle = np.arctan2(np.linalg.norm(np.cross(rays[a], rays[b])), float(rays[a] @ rays[b]))
        if np.isfinite(angle) and angle > 0:
            focals.append(1.0 / np.tan(angle / 2.0))
    if not focals:
        raise CalibError(f"cannot estimate a focal length: the camera model has no rays at the image centre "
                         f"({camera!r})")
    return float(np.mean(focals))


#: Fewest pairs :func:`fit_rotation_about_centre` needs: two non-parallel directions fix a rotation.
MIN_ROTATION_PAIRS = 2


def fit_rotation_about_centre(T_camera_lidar, points_lidar, bearings_camera, weights=None) -> np.ndarray:
    """The rotation that best turns the pairs' laser points onto their clicked bearings, the camera centre kept.

    Before 4 pairs there is no full solve, but 2 or 3 pairs already fix the rotation well when the rough
    translation is close (lidar and camera a few cm to dm apart, corners metres away).  The camera centre in the
    lidar frame, ``c = -R0^T t0`` of the rough pose, is kept; the directions ``u_i = (X_i - c) / |X_i - c|`` (lidar
    frame) must turn into the unit bearings ``b_i`` (camera frame).  That is Wahba's problem: the rotation
    maximising ``sum w_i b_i . (R u_i)`` is ``R = U diag(1, 1, det(U V^T)) V^T`` from the SVD ``U S V^T`` of
    ``B = sum w_i b_i u_i^T`` (Kabsch).  Closed form: it does not depend on the rough rotation, only on ``c``.

    Parameters
    ----------
    T_camera_lidar : (4, 4) array_like
        The rough pose (maps lidar points, metres, into the camera frame); only its camera centre is used.
    points_lidar : (N, 3) array_like
        Laser points of the pairs, lidar frame (x forward, y left, z up), metres.  N >= 2.
    bearings_camera : (N, 3) array_like
        Bearings of the clicked pixels in the camera frame (OpenCV: x right, y down, z forward); any length.
    weights : (N,) array_like, optional
        Positive weights (e.g. ``1 / pixel_sigma**2``); default all 1.

    Returns
    -------
    (4, 4) float64
        ``[R | -R c]``: the fitted rotation, the same camera centre ``c`` in the lidar frame.

    Raises
    ------
    CalibError
        Fewer than :data:`MIN_ROTATION_PAIRS` pairs, a laser point at the camera centre, non-finite input, or
        directions that do not fix a rotation (all parallel, in the lidar or the camera frame).
    """
    T = as_transform(T_camera_lidar)
    X = np.asarray(points_lidar, dtype=float).reshape(-1, 3)
    b = np.asarray(bearings_camera, dtype=float).reshape(-1, 3)
    n = len(X)
    if len(b) != n:
        raise CalibError(f"{n} laser points but {len(b)} bearings")
    if n < MIN_ROTATION_PAIRS:
        raise CalibError(f"a rotation needs at least {MIN_ROTATION_PAIRS} pairs, got {n}")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float).reshape(n)
    if not (np.isfinite(X).all() and np.isfinite(b).all() and np.isfinite(w).all() and (w > 0).all()):
        raise CalibError("laser points, bearings and weights must be finite (weights positive)")
    centre = -T[:3, :3].T @ T[:3, 3]
    d = X - centre
    dist, blen = np.linalg.norm(d, axis=1), np.linalg.norm(b, axis=1)
    if (dist < 1e-6).any() or (blen < 1e-12).any():
        raise CalibError("a laser point lies at the camera centre (or a bearing is zero): no direction to turn")
    u, b = d / dist[:, None], b / blen[:, None]
    B = (w[:, None] * b).T @ u  # sum w_i b_i u_i^T
    U, S, Vt = np.linalg.svd(B)
    # Parallel directions leave a rotation about them free: B then has rank 1.
    cross_u = np.linalg.norm(np.cross(u[:, None, :], u[None, :, :]), axis=2).max()
    cross_b = np.linalg.norm(np.cross(b[:, None, :], b[None, :, :]), axis=2).max()
    if S[1] < 1e-9 * max(S[0], 1e-300) or cross_u < 1e-6 or cross_b < 1e-6:
        raise CalibError("the pairs' directions are parallel: they do not fix a rotation; pick corners apart")
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    out = np.eye(4)
    out[:3, :3] = R
    out[:3, 3] = -R @ centre
    return out
