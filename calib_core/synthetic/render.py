"""Ray-cast renderings of the room: the rotating scanner's depth matrix and the
omnidirectional camera image.

Materials (``Part.material``) decide the laser echo and the look:

=========  ==========================================================
glass      no laser return; the camera sees sky and lawn through it
light      emissive ceiling panel (no shading)
floor      tiles with grout lines
ceiling    panels with grid lines
wood       grain along the part's longest side (door, table tops)
picture    a painted landscape (sky, sun, mountains, hills)
cardboard  brown with a tape strip
cabinet    two doors: a seam and two handles on the front
others     plain colour (wall, paint, metal, plastic, frame)
=========  ==========================================================

Every surface is shaded Lambertian by its face normal under two directional
lights, so the faces of a box differ in brightness.
"""

from __future__ import annotations

import numpy as np

from ..lidar import DepthMatrix, rotating_scanner_beams, rotating_scanner_depth
from ..transforms import transform_points
from .raycast import first_hits
from .scene import Room

# Key light from above and slightly south-east, fill light from the north-west,
# light bounced off the floor.
_LIGHTS = (
    (np.array([0.35, -0.55, 0.76]) / np.linalg.norm([0.35, -0.55, 0.76]), 0.34),
    (np.array([-0.8, 0.45, 0.40]) / np.linalg.norm([-0.8, 0.45, 0.40]), 0.16),
    (np.array([0.1, 0.2, -1.0]) / np.linalg.norm([0.1, 0.2, -1.0]), 0.30),  # bounce light onto the ceiling
)
_AMBIENT = 0.50


def cast(room: Room, origins_world: np.ndarray, directions_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays ``(N, 3)`` (world frame) in the room's mesh.

    Returns
    -------
    t : (N,) float64
        Distance to the hit in units of the direction length (metres for
        unit directions); inf on a miss.
    face : (N,) int64
        Hit mesh face, -1 on a miss.
    """
    triangles = room.mesh.triangles
    return first_hits(triangles, room.face_part, origins_world, directions_world)


def render_scan(
    room: Room,
    theta_rad: np.ndarray,
    phi_rad: np.ndarray,
    dx_m: float,
    dz_m: float,
    rng: np.random.Generator,
    range_noise_m: float = 0.01,
    max_range_m: float = 30.0,
) -> DepthMatrix:
    """Simulate the rotating 2-D scanner (paper eq. 3) standing in the room.

    Parameters
    ----------
    room : Room
    theta_rad : (H,) float
        In-plane angle of every row, radians.
    phi_rad : (W,) float
        Rotation of every column's scan plane, radians (360 deg, wrapping).
    dx_m, dz_m : float
        Axis offsets of eq. 3, metres.
    rng : numpy.random.Generator
        Draws the Gaussian range noise.
    range_noise_m : float
        Standard deviation of the range noise, metres.
    max_range_m : float
        Ranges beyond this give no return.

    Returns
    -------
    DepthMatrix
        In the lidar frame; beams that hit glass, nothing, or something beyond
        ``max_range_m`` are invalid.
    """
    theta = np.asarray(theta_rad, dtype=np.float64).reshape(-1, 1)
    phi = np.asarray(phi_rad, dtype=np.float64).reshape(1, -1)
    origins, directions = rotating_scanner_beams(theta, phi, dx_m, dz_m)
    shape = origins.shape[:2]
    T = room.T_world_lidar
    o_w = transform_points(T, origins.reshape(-1, 3))
    d_w = directions.reshape(-1, 3) @ T[:3, :3].T
    t, face = cast(room, o_w, d_w)
    hit = face >= 0
    material = np.array([p.material for p in room.parts])
    glass = np.zeros_like(hit)
    glass[hit] = material[room.face_part[face[hit]]] == "glass"
    rho = t + rng.normal(0.0, range_noise_m, t.shape)
    valid = hit & ~glass & (t <= max_range_m)
    rho = np.where(valid, rho, np.nan).reshape(shape)
    return rotating_scanner_depth(rho, theta, phi.ravel(), dx_m, dz_m, wrap_cols=True)


def image_circle_mask(camera, pixels: np.ndarray, radius_px: float) -> np.ndarray:
    """Pixels ``(N, 2)`` whose OCam sensor-plane radius is at most ``radius_px``.

    Inverts the affine map ``row = c x + d y + xc``, ``col = e x + y + yc`` of
    the OCamCalib model (``camera`` needs ``xc, yc, c, d, e``).
    """
    r = pixels[:, 1] - camera.xc
    q = pixels[:, 0] - camera.yc
    inv_det = 1.0 / (camera.c - camera.d * camera.e)
    xp = inv_det * (r - camera.d * q)
    yp = inv_det * (-camera.e * r + camera.c * q)
    return np.hypot(xp, yp) <= radius_px


def render_image(
    room: Room,
    camera,
    circle_radius_px: float,
    rng: np.random.Generator,
    supersampling: int = 2,
    noise_gray: float = 1.5,
) -> np.ndarray:
    """Render the camera image by casting one ray per sub-pixel sample.

    Parameters
    ----------
    room : Room
        The camera pose is ``room.T_world_camera``.
    camera : OCamCamera
        Gives the rays (``camera.bearing``) and the image size.
    circle_radius_px : float
        Sensor-plane radius of the image circle; samples outside stay black.
    rng : numpy.random.Generator
        Draws the image noise.
    supersampling : int
        ``s x s`` samples per pixel, averaged (anti-aliased edges).
    noise_gray : float
        Standard deviation of the Gaussian image noise in grey levels.

    Returns
    -------
    (H, W, 3) uint8
        RGB image.
    """
    W, H, s = camera.width, camera.height, int(supersampling)
    offsets = (np.arange(s) + 0.5) / s - 0.5
    u = (np.arange(W)[None, :, None, None] + offsets[None, None, None, :]) + np.zeros((H, 1, s, 1))
    v = (np.arange(H)[:, None, None, None] + offsets[None, None, :, None]) + np.zeros((1, W, 1, s))
    samples = np.stack(np.broadcast_arrays(u, v), axis=-1).reshape(-1, 2)
    inside = image_circle_mask(camera, samples, circle_radius_px)
    rgb = np.zeros((len(samples), 3))
    idx = np.flatnonzero(inside)
    bearings = camera.bearing(samples[idx])
    ok = np.all(np.isfinite(bearings), axis=1)
    idx, bearings = idx[ok], bearings[ok]
    T = room.T_world_camera
    d_w = bearings @ T[:3, :3].T
    o_w = np.broadcast_to(T[:3, 3], d_w.shape)
    t, face = cast(room, o_w, d_w)
    rgb[idx] = shade(room, face, o_w + t[:, None] * d_w, d_w)
    rgb = rgb.reshape(H, W, s * s, 3).mean(axis=2)
    img = rgb * 255.0 + rng.normal(0.0, noise_gray, rgb.shape) * (rgb > 0).any(axis=2, keepdims=True)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _hash_noise(points: np.ndarray, cell_m: float) -> np.ndarray:
    """Deterministic white noise in [0, 1) per ``cell_m`` cube of space."""
    q = np.floor(points / cell_m)
    h = np.sin(q @ np.array([12.9898, 78.233, 37.719])) * 43758.5453
    return h - np.floor(h)


def shade(room: Room, face: np.ndarray, points_world: np.ndarray, view_dirs_world: np.ndarray) -> np.ndarray:
    """Colour of each ray hit, RGB in [0, 1].

    Parameters
    ----------
    room : Room
    face : (N,) int
        Hit mesh faces, -1 for a miss (black).
    points_world : (N, 3)
        Hit points, world frame, metres.
    view_dirs_world : (N, 3)
        Ray directions (from the camera to the hit), world frame.

    Returns
    -------
    (N, 3) float64
    """
    n = len(face)
    out = np.zeros((n, 3))
    hit = face >= 0
    f = face[hit]
    p = points_world[hit]
    d = view_dirs_world[hit]
    part = room.face_part[f]
    normal = room.mesh.face_normals[f]
    normal = np.where((np.einsum("ij,ij->i", normal, d) > 0)[:, None], -normal, normal)

    parts = room.parts
    material = np.array([q.material for q in parts])[part]
    base = np.array([q.color for q in parts])[part]
    R = np.stack([q.T_world_part[:3, :3] for q in parts])[part]
    centre = np.stack([q.T_world_part[:3, 3] for q in parts])[part]
    ext = np.stack([q.extents for q in parts])[part]
    local = np.einsum("nji,nj->ni", R, p - centre)  # R^T (p - c)
    n_local = np.einsum("nji,nj->ni", R, normal)
    face_axis = np.argmax(np.abs(n_local), axis=1)

    light = np.full(len(p), _AMBIENT)
    for direction, strength in _LIGHTS:
        light += strength * np.clip(normal @ direction, 0.0, None)
    grain = _hash_noise(p, 0.01)
    color = base * (0.97 + 0.06 * grain)[:, None]

    m = material == "floor"
    if m.any():
        tile = 0.5
        x, y = p[m, 0] / tile, p[m, 1] / tile
        checker = (np.floor(x) + np.floor(y)) % 2
        c = np.where(checker[:, None] > 0, [0.70, 0.68, 0.64], [0.50, 0.48, 0.46])
        fx, fy = x - np.floor(x), y - np.floor(y)
        grout = (np.minimum(fx, 1 - fx) < 0.012) | (np.minimum(fy, 1 - fy) < 0.012)
        c[grout] = [0.33, 0.32, 0.31]
        color[m] = c * (0.95 + 0.1 * grain[m])[:, None]

    m = material == "ceiling"
    if m.any():
        x, y = p[m, 0] / 0.6, p[m, 1] / 0.6
        fx, fy = x - np.floor(x), y - np.floor(y)
        line = (np.minimum(fx, 1 - fx) < 0.012) | (np.minimum(fy, 1 - fy) < 0.012)
        color[m[:]] = np.where(line[:, None], [0.72, 0.72, 0.72], color[m])

    m = material == "wood"
    if m.any():
        # Grain runs along the part's longest in-face side.
        loc, ax, e = local[m], face_axis[m], ext[m]
        other = np.array([[1, 2], [0, 2], [0, 1]])[ax]
        e_other = np.take_along_axis(e, other, axis=1)
        along_first = e_other[:, 0] >= e_other[:, 1]
        a_idx = np.where(along_first, other[:, 0], other[:, 1])
        c_idx = np.where(along_first, other[:, 1], other[:, 0])
        along = np.take_along_axis(loc, a_idx[:, None], axis=1)[:, 0]
        across = np.take_along_axis(loc, c_idx[:, None], axis=1)[:, 0]
        w = np.sin(2 * np.pi * (across * 14.0 + 0.35 * np.sin(along * 2.3 + across * 9.0)))
        color[m] = base[m] * (0.86 + 0.10 * w + 0.06 * grain[m])[:, None]

    m = material == "picture"
    if m.any():
        s = local[m, 0] / ext[m, 0] + 0.5  # left to right
        t = local[m, 2] / ext[m, 2] + 0.5  # bottom to top
        sky = np.stack([0.30 + 0.55 * (1 - t), 0.55 + 0.30 * (1 - t), 0.95 - 0.25 * (1 - t)], axis=1)
        c = sky
        sun = (s - 0.72) ** 2 + ((t - 0.72) * 0.75) ** 2 < 0.012
        c[sun] = [1.0, 0.86, 0.25]
        mountain = t < 0.50 + 0.14 * np.abs(np.sin(6.0 * s + 0.4)) - 0.1 * s
        c[mountain] = [0.45, 0.40, 0.58]
        hill = t < 0.28 + 0.07 * np.sin(11.0 * s + 1.0)
        c[hill] = [0.22, 0.62, 0.25]
        house = (np.abs(s - 0.3) < 0.07) & (t < 0.30) & (t > 0.12)
        c[house] = [0.85, 0.20, 0.15]
        color[m] = c

    m = material == "cardboard"
    if m.any():
        loc, ax, e = local[m], face_axis[m], ext[m]
        tape = (np.abs(loc[:, 1]) < 0.03) & ((ax == 2) | ((ax == 0) & (loc[:, 2] > e[:, 2] / 2 - 0.07)))
        color[np.flatnonzero(m)[tape]] = [0.86, 0.76, 0.55]

    m = material == "cabinet"
    if m.any():
        loc, ax, e = local[m], face_axis[m], ext[m]
        front = ax == 1
        seam = front & (np.abs(loc[:, 0]) < 0.004)
        handle = front & (np.abs(np.abs(loc[:, 0]) - 0.045) < 0.012) & (np.abs(loc[:, 2]) < 0.12)
        plinth = front & (loc[:, 2] < -e[:, 2] / 2 + 0.08)
        c = color[m]
        c[plinth] *= 0.55
        c[seam] = [0.15, 0.15, 0.18]
        c[handle] = [0.85, 0.85, 0.88]
        color[m] = c

    out_hit = color * light[:, None]

    m = material == "light"
    out_hit[m] = base[m]

    m = material == "glass"
    if m.any():
        up = d[m, 2] / np.linalg.norm(d[m], axis=1)
        sky = np.stack([0.62 - 0.3 * up, 0.80 - 0.15 * up, np.full_like(up, 0.98)], axis=1)
        lawn = np.array([0.36, 0.58, 0.30]) * (0.9 + 0.15 * grain[m])[:, None]
        out_hit[m] = np.where((up < -0.05)[:, None], lawn, np.clip(sky, 0, 1))

    out[hit] = np.clip(out_hit, 0.0, 1.0)
    return out
