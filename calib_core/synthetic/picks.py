"""Which scene corners both sensors see, and simulated user clicks on them.

A user of the tool clicks a corner in the camera image (with about a pixel
of error) and the same corner in a Bearing Angle image, where a click lands
on a whole depth-matrix cell.  :func:`simulate_pairs` reproduces both.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError
from ..lidar import rotating_scanner_beams
from ..pairs import Pair
from ..transforms import invert_T, transform_points

#: A corner is hidden when something is hit this much (metres) before it.
VISIBILITY_TOLERANCE_M = 0.01
#: Corners must project at least this far (pixels) inside the image circle.
CIRCLE_MARGIN_PX = 6.0
#: A corner is pickable in the scan when a cell near it measured a point this close (metres).
MAX_LASER_PICK_ERROR_M = 0.05


def scanner_angles(points_lidar: np.ndarray, dx_m: float, dz_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact inverse of paper eq. 3: the beam angles that pass through points.

    The scan plane at rotation ``phi`` holds the points ``p`` with
    ``p . Ry(phi) e_z = dz``; in that plane the beam leaves the mirror at
    ``Ry(phi) [dx, 0, dz]`` with in-plane angle ``theta``.

    Parameters
    ----------
    points_lidar : (N, 3)
        Points in the lidar frame, metres (farther than ``dz`` from the axis).
    dx_m, dz_m : float
        Axis offsets, metres.

    Returns
    -------
    theta_rad : (N,) in [-pi/2, pi/2]
    phi_rad : (N,) in [0, 2 pi)
    """
    p = np.asarray(points_lidar, dtype=np.float64).reshape(-1, 3)
    rho_h = np.hypot(p[:, 0], p[:, 2])
    alpha = np.arctan2(p[:, 0], p[:, 2])
    phi = np.mod(alpha - np.arccos(np.clip(dz_m / rho_h, -1.0, 1.0)), 2 * np.pi)
    in_plane = np.sqrt(np.maximum(rho_h**2 - dz_m**2, 0.0)) - dx_m
    theta = np.arctan2(p[:, 1], in_plane)
    return theta, phi


def _scan_grid(depth) -> tuple[np.ndarray, np.ndarray, float, float]:
    meta = depth.meta
    if meta.get("model") != "rotating_2d":
        raise CalibError(f"the sample scene needs a rotating_2d scan, got model {meta.get('model')!r}")
    H, W = depth.shape
    theta = np.broadcast_to(np.asarray(meta["theta_rad"], dtype=np.float64), (H, W))[:, 0]
    phi = np.broadcast_to(np.asarray(meta["phi_rad"], dtype=np.float64), (H, W))[0, :]
    return theta, phi, float(meta["dx_m"]), float(meta["dz_m"])


def nearest_cells(depth, points_lidar: np.ndarray) -> np.ndarray:
    """The depth-matrix cell whose beam passes nearest each point: ``(N, 2)`` (row, col)."""
    theta_grid, phi_grid, dx, dz = _scan_grid(depth)
    theta, phi = scanner_angles(points_lidar, dx, dz)
    rows = np.argmin(np.abs(theta[:, None] - theta_grid[None, :]), axis=1)
    dphi = np.angle(np.exp(1j * (phi[:, None] - phi_grid[None, :])))
    cols = np.argmin(np.abs(dphi), axis=1)
    return np.stack([rows, cols], axis=1)


def laser_picks(depth, points_lidar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cells a user would click for each 3-D corner, and their distance to it.

    Start at the cell whose beam passes nearest the corner; among it and its
    8 neighbours (columns wrap when the scan closes 360 deg) take the valid
    cell whose measured point is nearest the corner: the user clicks the
    corner of the object, not the background behind it.

    Returns
    -------
    rows_cols : (N, 2) int64
    error_m : (N,) float64
        Distance from the chosen cell's point to the corner; inf when no
        neighbour is valid.
    """
    p = np.asarray(points_lidar, dtype=np.float64).reshape(-1, 3)
    H, W = depth.shape
    wrap = bool(depth.meta.get("wrap_cols", False))
    rc = nearest_cells(depth, p)
    dr, dc = np.meshgrid([-1, 0, 1], [-1, 0, 1], indexing="ij")
    rows = rc[:, 0, None] + dr.ravel()[None, :]
    cols = rc[:, 1, None] + dc.ravel()[None, :]
    cols = np.mod(cols, W) if wrap else cols
    inside = (rows >= 0) & (rows < H) & (cols >= 0) & (cols < W)
    rows_c, cols_c = np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)
    pts = depth.points[rows_c, cols_c]  # (N, 9, 3)
    err = np.linalg.norm(pts - p[:, None, :], axis=2)
    err = np.where(inside & depth.valid[rows_c, cols_c], err, np.inf)
    best = np.argmin(err, axis=1)
    k = np.arange(len(p))
    return np.stack([rows_c[k, best], cols_c[k, best]], axis=1), err[k, best]


def visible_from(cast, origins_world: np.ndarray, targets_world: np.ndarray) -> np.ndarray:
    """True where nothing blocks the segment from each origin to its target.

    ``cast(origins, directions) -> (t, face)`` is a first-hit ray caster.
    """
    d = targets_world - origins_world
    dist = np.linalg.norm(d, axis=1)
    t, face = cast(origins_world, d)
    return (face < 0) | (t * dist >= dist - VISIBILITY_TOLERANCE_M)


def visible_corners(room, camera, depth, circle_radius_px: float, cast) -> np.ndarray:
    """Mask of ``room.corners_world`` seen by the camera and the scanner.

    A corner counts when (a) the segment from the camera centre and the one
    from the scanner's beam origin are unobstructed (ray cast), (b) it
    projects inside the image and at least :data:`CIRCLE_MARGIN_PX` inside
    the image circle, and (c) a scan cell near it measured a point within
    :data:`MAX_LASER_PICK_ERROR_M`.
    """
    from .render import image_circle_mask

    corners_w = room.corners_world
    T_lidar_world = invert_T(room.T_world_lidar)
    corners_l = transform_points(T_lidar_world, corners_w)
    # Camera side.
    cam_w = np.broadcast_to(room.T_world_camera[:3, 3], corners_w.shape)
    ok = visible_from(cast, np.ascontiguousarray(cam_w), corners_w)
    pix, valid = camera.project(transform_points(room.T_camera_lidar, corners_l))
    ok &= valid
    ok[ok] &= image_circle_mask(camera, pix[ok], circle_radius_px - CIRCLE_MARGIN_PX)
    # Scanner side: from the mirror centre at the rotation that sees the corner.
    _, _, dx, dz = _scan_grid(depth)
    theta, phi = scanner_angles(corners_l, dx, dz)
    origins_l, _ = rotating_scanner_beams(theta, phi, dx, dz)
    ok &= visible_from(cast, transform_points(room.T_world_lidar, origins_l), corners_w)
    _, err = laser_picks(depth, corners_l)
    ok &= err <= MAX_LASER_PICK_ERROR_M
    return ok


def simulate_pairs(scene, n: int, rng: np.random.Generator, pixel_noise_px: float = 1.0) -> list[Pair]:
    """Simulate a user who clicks ``n`` corners spread over the scene.

    Corners are chosen by farthest-point sampling of their camera bearings
    from a random start, so they cover the view (the paper: pairs must be
    spread over the whole scene).  Camera side: the true corner projected
    with the ground truth plus Gaussian noise of ``pixel_noise_px`` per axis,
    kept inside the image.  Laser side: a whole depth-matrix cell, see
    :func:`laser_picks`.

    Parameters
    ----------
    scene : SampleScene
    n : int
        Number of pairs, at most the number of pickable corners.
    rng : numpy.random.Generator
    pixel_noise_px : float
        Standard deviation of the click error per image axis, pixels.

    Returns
    -------
    list of Pair
        ``laser_rc`` and ``pixel`` set, ``laser_xyz`` None.
    """
    corners = np.asarray(scene.corners_lidar, dtype=np.float64).reshape(-1, 3)
    rc, err = laser_picks(scene.depth, corners)
    usable = np.flatnonzero(err <= MAX_LASER_PICK_ERROR_M)
    n = int(n)
    if n < 1 or n > len(usable):
        raise CalibError(f"can simulate between 1 and {len(usable)} pairs on this scene, asked for {n}")
    points_cam = transform_points(scene.T_camera_lidar, corners[usable])
    bearings = points_cam / np.linalg.norm(points_cam, axis=1, keepdims=True)

    chosen = [int(rng.integers(len(usable)))]
    min_cos = bearings @ bearings[chosen[0]]
    for _ in range(n - 1):  # n is a handful
        nxt = int(np.argmin(min_cos))
        chosen.append(nxt)
        min_cos = np.maximum(min_cos, bearings @ bearings[nxt])

    pix_true, _ = scene.camera.project(points_cam[chosen])
    W, H = scene.camera.width, scene.camera.height
    pix = pix_true + rng.normal(0.0, pixel_noise_px, pix_true.shape)
    for _ in range(20):  # redraw the few clicks that fell off the image
        out = (pix[:, 0] < -0.5) | (pix[:, 0] > W - 0.5) | (pix[:, 1] < -0.5) | (pix[:, 1] > H - 0.5)
        if not out.any():
            break
        pix[out] = pix_true[out] + rng.normal(0.0, pixel_noise_px, (int(out.sum()), 2))
    pix = np.clip(pix, [-0.5, -0.5], [W - 0.5, H - 0.5])

    return [
        Pair(laser_rc=(int(rc[usable[i], 0]), int(rc[usable[i], 1])), laser_xyz=None, pixel=(float(u), float(v)))
        for i, (u, v) in zip(chosen, pix)
    ]
