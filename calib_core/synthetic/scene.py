"""The synthetic office room: layout, triangle mesh, labelled corners and the rig.

World frame: x east, y north, z up, metres; the room's inside is
``[0, Lx] x [0, Ly] x [0, H]``.  Every part is a box (``trimesh.creation.box``),
optionally turned about the vertical; all parts are concatenated into one
mesh whose per-face ``face_part`` index says which :class:`Part` (object and
material) a triangle belongs to.

The seed draws the room size, the place and size of every object, the lidar
pose in the room and the perturbation of the ground-truth extrinsics, all from
``numpy.random.default_rng([seed, 0])``; nothing here casts rays, so building
the layout is cheap and :func:`build_room` can rebuild the mesh of a saved
sample from its seed.

Rig: the paper's rotating 2-D scanner (eq. 3) with its rotation axis, the
lidar y axis, vertical (world up).  Lidar x is horizontal ("forward") and
z = x cross y.  The camera pose follows from ``T_world_lidar`` and the ground
truth ``T_camera_lidar``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ..errors import CalibError
from ..transforms import R_from_rpy_deg, invert_T, make_T

#: Ground truth of seed 0: the paper's Table I (roll, pitch, yaw in degrees;
#: translation in metres).
PAPER_RPY_DEG = (0.64, -1.24, 166.95)
PAPER_TRANSLATION_M = (0.207, 0.042, 0.139)

WALL_THICKNESS_M = 0.15

#: Columns of R_world_lidar at zero yaw: lidar x = world x, lidar y = world z
#: (rotation axis vertical), lidar z = x cross y = -world y.
R_WORLD_LIDAR_LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class Part:
    """One box of the scene.

    Attributes
    ----------
    name : str
        Unique, human-readable (``"table_1 top"``).
    material : str
        Shading and laser behaviour, see :mod:`calib_core.synthetic.render`.
    color : (3,) tuple of float
        Base RGB in [0, 1].
    T_world_part : (4, 4) ndarray
        Pose of the box centre: a translation and a turn about world z.
    extents : (3,) ndarray
        Box edge lengths along its own x, y, z, metres.
    has_corners : bool
        Its 8 corners are candidate calibration corners.
    """

    name: str
    material: str
    color: tuple[float, float, float]
    T_world_part: np.ndarray
    extents: np.ndarray
    has_corners: bool = False

    def corners_world(self) -> np.ndarray:
        """(8, 3) corners in the world frame, index ``4*ix + 2*iy + iz`` (0 = minus side)."""
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=np.float64)
        local = signs * (np.asarray(self.extents) / 2.0)
        return local @ self.T_world_part[:3, :3].T + self.T_world_part[:3, 3]


@dataclass(frozen=True)
class Window:
    """Opening of the window in the east wall; its glass returns no laser echo.

    Attributes
    ----------
    x_inner_m, x_glass_m : float
        World x of the room-side face of the window frame and of the glass.
    y_range_m, z_range_m : (2,) tuple of float
        Extent of the opening, metres.
    """

    x_inner_m: float
    x_glass_m: float
    y_range_m: tuple[float, float]
    z_range_m: tuple[float, float]


@dataclass(frozen=True)
class Room:
    """The whole synthetic scene with its sensor rig.

    Attributes
    ----------
    seed : int
    size_m : (3,) ndarray
        Inside size ``(Lx, Ly, H)`` of the room, metres.
    parts : list of Part
    mesh : trimesh.Trimesh
        All parts in the world frame.
    face_part : (F,) int64
        Index into ``parts`` of every mesh face.
    window : Window
    corners_world : (M, 3) ndarray
        Candidate corners (box corners of parts with corners, room corners).
    corner_labels : list of str
    T_world_lidar : (4, 4) ndarray
        Lidar pose in the world.
    T_camera_lidar : (4, 4) ndarray
        Ground-truth extrinsics, ``X_camera = T_camera_lidar @ X_lidar``.
    """

    seed: int
    size_m: np.ndarray
    parts: list[Part]
    mesh: trimesh.Trimesh
    face_part: np.ndarray
    window: Window
    corners_world: np.ndarray
    corner_labels: list[str]
    T_world_lidar: np.ndarray
    T_camera_lidar: np.ndarray

    @property
    def T_world_camera(self) -> np.ndarray:
        """Camera pose in the world (OpenCV camera frame)."""
        return self.T_world_lidar @ invert_T(self.T_camera_lidar)


def ground_truth_T_camera_lidar(rng: np.random.Generator, seed: int) -> np.ndarray:
    """The paper's Table I pose, perturbed by a few degrees and centimetres unless ``seed == 0``."""
    rpy = np.array(PAPER_RPY_DEG)
    t = np.array(PAPER_TRANSLATION_M)
    d_rpy = rng.uniform(-3.0, 3.0, 3)
    d_t = rng.uniform(-0.03, 0.03, 3)
    if seed != 0:
        rpy, t = rpy + d_rpy, t + d_t
    return make_T(R_from_rpy_deg(rpy), t)


def _pose(center, yaw_deg: float = 0.0) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = center
    return T


class _Builder:
    """Collects parts; ``box`` takes world-axis bounds, ``turned`` a centre and a yaw."""

    def __init__(self) -> None:
        self.parts: list[Part] = []

    def box(self, name, material, color, lo, hi, corners=False) -> None:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        self.parts.append(Part(name, material, tuple(color), _pose((lo + hi) / 2), hi - lo, corners))

    def turned(self, name, material, color, center, extents, yaw_deg, corners=True) -> None:
        self.parts.append(Part(name, material, tuple(color), _pose(center, yaw_deg), np.asarray(extents, float), corners))


def _footprint(extents, yaw_deg) -> np.ndarray:
    """Half-size along world x, y of a box turned by ``yaw_deg``."""
    a = np.radians(yaw_deg)
    c, s = abs(np.cos(a)), abs(np.sin(a))
    return np.array([c * extents[0] + s * extents[1], s * extents[0] + c * extents[1]]) / 2


_BOX_COLORS = [
    (0.72, 0.53, 0.33),  # cardboard
    (0.20, 0.42, 0.78),  # blue
    (0.80, 0.22, 0.20),  # red
    (0.25, 0.62, 0.32),  # green
    (0.92, 0.78, 0.22),  # yellow
    (0.55, 0.30, 0.65),  # purple
    (0.95, 0.55, 0.20),  # orange
    (0.30, 0.70, 0.72),  # teal
]


def build_room(seed: int = 0) -> Room:
    """Lay out the office room, its mesh, its corners and the rig for ``seed``.

    Parameters
    ----------
    seed : int
        Draws the layout and the ground truth; seed 0 uses the paper's pose.

    Returns
    -------
    Room
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise CalibError(f"seed must be a non-negative whole number, got {seed!r}")
    rng = np.random.default_rng([int(seed), 0])
    Lx, Ly, H = rng.uniform(6.6, 7.4), rng.uniform(4.7, 5.3), rng.uniform(2.65, 2.95)
    t = WALL_THICKNESS_M
    b = _Builder()

    # Walls: each a colour of its own.  The door (west) and the window (east)
    # cut openings, so those walls are assembled from slabs around the hole.
    wall_s, wall_n = (0.93, 0.87, 0.70), (0.86, 0.78, 0.76)
    wall_w, wall_e = (0.76, 0.85, 0.74), (0.74, 0.81, 0.88)
    b.box("floor", "floor", (0.62, 0.60, 0.57), (-t, -t, -t), (Lx + t, Ly + t, 0))
    b.box("ceiling", "ceiling", (0.94, 0.94, 0.92), (-t, -t, H), (Lx + t, Ly + t, H + t))
    b.box("south wall", "wall", wall_s, (-t, -t, 0), (Lx + t, 0, H))
    b.box("north wall", "wall", wall_n, (-t, Ly, 0), (Lx + t, Ly + t, H))

    door_w, door_h = 0.9, 2.05
    door_y = rng.uniform(2.4, Ly - 1.0)
    y0, y1 = door_y - door_w / 2, door_y + door_w / 2
    b.box("west wall", "wall", wall_w, (-t, 0, 0), (0, y0, H))
    b.box("west wall (north)", "wall", wall_w, (-t, y1, 0), (0, Ly, H))
    b.box("west wall (over door)", "wall", wall_w, (-t, y0, door_h), (0, y1, H))
    recess = 0.05
    b.box("door", "wood", (0.62, 0.40, 0.22), (-recess - 0.04, y0, 0), (-recess, y1, door_h), corners=True)
    b.box("door handle", "metal", (0.75, 0.75, 0.78), (-recess, y1 - 0.17, 1.0), (-recess + 0.05, y1 - 0.05, 1.03))
    casing, depth = 0.07, 0.02
    frame = (0.97, 0.97, 0.95)
    b.box("door frame (south)", "paint", frame, (0, y0 - casing, 0), (depth, y0, door_h + casing), corners=True)
    b.box("door frame (north)", "paint", frame, (0, y1, 0), (depth, y1 + casing, door_h + casing), corners=True)
    b.box("door frame (top)", "paint", frame, (0, y0, door_h), (depth, y1, door_h + casing), corners=True)

    win_w = rng.uniform(1.2, 1.6)
    win_y = rng.uniform(1.3 + win_w / 2, Ly - 1.3 - win_w / 2)
    sill_z, top_z = 1.0, min(2.25, H - 0.35)
    wy0, wy1 = win_y - win_w / 2, win_y + win_w / 2
    b.box("east wall (south)", "wall", wall_e, (Lx, 0, 0), (Lx + t, wy0, H))
    b.box("east wall (north)", "wall", wall_e, (Lx, wy1, 0), (Lx + t, Ly, H))
    b.box("east wall (below window)", "wall", wall_e, (Lx, wy0, 0), (Lx + t, wy1, sill_z))
    b.box("east wall (above window)", "wall", wall_e, (Lx, wy0, top_z), (Lx + t, wy1, H))
    x_glass = Lx + t / 2
    b.box("window glass", "glass", (0.70, 0.85, 1.0), (x_glass - 0.005, wy0, sill_z), (x_glass + 0.005, wy1, top_z))
    wf, wd = 0.06, 0.03
    b.box("window frame (south)", "paint", frame, (Lx - wd, wy0 - wf, sill_z - wf), (Lx, wy0, top_z + wf), corners=True)
    b.box("window frame (north)", "paint", frame, (Lx - wd, wy1, sill_z - wf), (Lx, wy1 + wf, top_z + wf), corners=True)
    b.box("window frame (top)", "paint", frame, (Lx - wd, wy0, top_z), (Lx, wy1, top_z + wf), corners=True)
    b.box("window sill", "paint", frame, (Lx - 0.16, wy0 - wf - 0.04, sill_z - wf), (Lx, wy1 + wf + 0.04, sill_z), corners=True)
    window = Window(Lx - wd, x_glass, (wy0, wy1), (sill_z, top_z))

    # Cabinet in the south-west corner.
    cab_w, cab_d, cab_h = rng.uniform(0.8, 1.0), rng.uniform(0.42, 0.5), rng.uniform(1.75, 2.0)
    cab_x0 = rng.uniform(0.05, 0.3)
    b.box("cabinet", "cabinet", (0.55, 0.62, 0.70), (cab_x0, 0.02, 0), (cab_x0 + cab_w, 0.02 + cab_d, cab_h), corners=True)

    # Table 1 against the south wall, two boxes on it; a picture above it.
    def table(name, x0, y0_, length, width, height, color):
        b.box(f"{name} top", "wood", color, (x0, y0_, height - 0.04), (x0 + length, y0_ + width, height), corners=True)
        leg = 0.05
        for i, (lx, ly) in enumerate([(x0 + 0.04, y0_ + 0.04), (x0 + length - 0.04 - leg, y0_ + 0.04),
                                      (x0 + 0.04, y0_ + width - 0.04 - leg),
                                      (x0 + length - 0.04 - leg, y0_ + width - 0.04 - leg)]):
            b.box(f"{name} leg {i + 1}", "metal", (0.25, 0.25, 0.28), (lx, ly, 0), (lx + leg, ly + leg, height - 0.04))

    colors = list(rng.permutation(len(_BOX_COLORS)))

    def next_color():
        return _BOX_COLORS[colors.pop() if colors else 0]

    def box_on(name, x_range, y_range, z0, max_h):
        ext = np.array([rng.uniform(0.2, 0.45), rng.uniform(0.2, 0.4), rng.uniform(0.15, max_h)])
        yaw = rng.uniform(-20, 20)
        half = _footprint(ext, yaw)
        cx = rng.uniform(x_range[0] + half[0], max(x_range[0] + half[0], x_range[1] - half[0]))
        cy = rng.uniform(y_range[0] + half[1], max(y_range[0] + half[1], y_range[1] - half[1]))
        color = next_color()
        b.turned(name, "cardboard" if color == _BOX_COLORS[0] else "plastic", color, (cx, cy, z0 + ext[2] / 2), ext, yaw)
        return ext

    t1_len, t1_wid, t1_h = rng.uniform(1.4, 1.8), rng.uniform(0.7, 0.8), rng.uniform(0.72, 0.76)
    t1_x0 = rng.uniform(cab_x0 + cab_w + 0.4, cab_x0 + cab_w + 0.9)
    t1_y0 = rng.uniform(0.03, 0.15)
    table("table 1", t1_x0, t1_y0, t1_len, t1_wid, t1_h, (0.80, 0.62, 0.42))
    mid = t1_x0 + t1_len / 2
    box_on("box 1 (on table 1)", (t1_x0 + 0.05, mid - 0.05), (t1_y0 + 0.05, t1_y0 + t1_wid - 0.05), t1_h, 0.42)
    box_on("box 2 (on table 1)", (mid + 0.05, t1_x0 + t1_len - 0.05), (t1_y0 + 0.05, t1_y0 + t1_wid - 0.05), t1_h, 0.3)

    pic_w, pic_h = rng.uniform(0.7, 1.0), rng.uniform(0.5, 0.65)
    pic_x = rng.uniform(t1_x0 + 0.3 + pic_w / 2, t1_x0 + t1_len + 0.6 - pic_w / 2)
    pic_z = rng.uniform(1.55, min(1.8, H - 0.5 - pic_h / 2))
    px0, px1, pz0, pz1 = pic_x - pic_w / 2, pic_x + pic_w / 2, pic_z - pic_h / 2, pic_z + pic_h / 2
    bar, raised = 0.05, 0.04
    dark = (0.22, 0.16, 0.12)
    b.box("picture canvas", "picture", (1, 1, 1), (px0 + bar, 0, pz0 + bar), (px1 - bar, 0.015, pz1 - bar))
    b.box("picture frame (bottom)", "frame", dark, (px0, 0, pz0), (px1, raised, pz0 + bar), corners=True)
    b.box("picture frame (top)", "frame", dark, (px0, 0, pz1 - bar), (px1, raised, pz1), corners=True)
    b.box("picture frame (west)", "frame", dark, (px0, 0, pz0 + bar), (px0 + bar, raised, pz1 - bar))
    b.box("picture frame (east)", "frame", dark, (px1 - bar, 0, pz0 + bar), (px1, raised, pz1 - bar))

    # Open bookshelf at the east end of the south wall, with books.
    sh_w, sh_d, sh_h = rng.uniform(0.9, 1.1), 0.36, rng.uniform(1.2, 1.5)
    sh_x0 = Lx - sh_w - rng.uniform(0.1, 0.35)
    board = 0.025
    white = (0.93, 0.92, 0.88)
    b.box("shelf side (west)", "paint", white, (sh_x0, 0.0, 0), (sh_x0 + board, sh_d, sh_h), corners=True)
    b.box("shelf side (east)", "paint", white, (sh_x0 + sh_w - board, 0.0, 0), (sh_x0 + sh_w, sh_d, sh_h), corners=True)
    b.box("shelf top", "paint", white, (sh_x0 + board, 0.0, sh_h - board), (sh_x0 + sh_w - board, sh_d, sh_h), corners=True)
    b.box("shelf back", "paint", white, (sh_x0 + board, 0.0, 0), (sh_x0 + sh_w - board, 0.01, sh_h - board))
    levels = np.linspace(0.0, sh_h - board, 4)[:-1]
    for i, z in enumerate(levels):
        b.box(f"shelf board {i + 1}", "paint", white, (sh_x0 + board, 0.01, z), (sh_x0 + sh_w - board, sh_d, z + board),
              corners=i > 0)
        x = sh_x0 + board + rng.uniform(0.02, 0.1)
        gap_h = levels[1] - levels[0] - board
        while True:  # a handful of books per board
            thick, tall = rng.uniform(0.03, 0.07), rng.uniform(0.55, 0.85) * gap_h
            if x + thick > sh_x0 + sh_w - board - rng.uniform(0.15, 0.35):
                break
            book = tuple(np.clip(rng.uniform(0.15, 0.9, 3), 0, 1))
            b.box(f"book {i + 1}.{len(b.parts)}", "plastic", book, (x, 0.03, z + board),
                  (x + thick, rng.uniform(0.22, 0.3), z + board + tall))
            x += thick + rng.uniform(0.0, 0.01)

    # Table 2 free-standing in the west half, a box on it.
    t2_len, t2_wid, t2_h = rng.uniform(1.2, 1.5), rng.uniform(0.7, 0.8), rng.uniform(0.72, 0.76)
    t2_x0 = rng.uniform(0.6, 1.0)
    t2_y0 = rng.uniform(cab_d + 0.9, cab_d + 1.2)
    table("table 2", t2_x0, t2_y0, t2_len, t2_wid, t2_h, (0.58, 0.42, 0.30))
    box_on("box 3 (on table 2)", (t2_x0 + 0.1, t2_x0 + t2_len - 0.1), (t2_y0 + 0.05, t2_y0 + t2_wid - 0.05), t2_h, 0.4)

    # Boxes on the floor: a stack in the south-east, one under the window
    # (lower than the sill, so it hides no glass from the scanner), one north.
    ext = box_on("box 4 (floor)", (t1_x0 + t1_len + 0.2, sh_x0 - 0.15), (0.9, 1.5), 0.0, 0.6)
    base = b.parts[-1]
    small = np.minimum(ext * rng.uniform(0.55, 0.8, 3), [ext[0], ext[1], 0.35])
    small[2] = max(small[2], 0.15)
    top_c = base.T_world_part[:3, 3] + [rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), ext[2] / 2 + small[2] / 2]
    col = next_color()
    b.turned("box 5 (on box 4)", "cardboard" if col == _BOX_COLORS[0] else "plastic", col, top_c, small,
             rng.uniform(-25, 25))
    box_on("box 6 (under window)", (Lx - 0.6, Lx - 0.1), (wy0, wy1), 0.0, 0.55)
    box_on("box 7 (north)", (1.5, Lx - 1.5), (Ly - 0.7, Ly - 0.1), 0.0, 0.6)

    # Ceiling lights.
    for i, (cx, cy) in enumerate([(rng.uniform(1.5, 3.0), rng.uniform(1.0, 1.8)),
                                  (rng.uniform(4.0, 5.5), rng.uniform(1.0, 1.8))]):
        b.box(f"ceiling light {i + 1}", "light", (1.0, 0.98, 0.92), (cx - 0.6, cy - 0.3, H - 0.04),
              (cx + 0.6, cy + 0.3, H), corners=True)

    parts = b.parts
    meshes, face_part = [], []
    for i, p in enumerate(parts):
        m = trimesh.creation.box(extents=p.extents, transform=p.T_world_part)
        meshes.append(m)
        face_part.append(np.full(len(m.faces), i, dtype=np.int64))
    mesh = trimesh.util.concatenate(meshes)
    face_part = np.concatenate(face_part)

    corners, labels = [], []
    names = ["bottom", "top"]
    for p in parts:
        if not p.has_corners:
            continue
        pts = p.corners_world()
        for idx in range(8):
            ix, iy, iz = idx // 4, (idx // 2) % 2, idx % 2
            labels.append(f"{p.name}: {names[iz]} {'north' if iy else 'south'}-{'east' if ix else 'west'}")
            corners.append(pts[idx])
    for idx in range(8):
        ix, iy, iz = idx // 4, (idx // 2) % 2, idx % 2
        corners.append([ix * Lx, iy * Ly, iz * H])
        labels.append(f"room: {['floor', 'ceiling'][iz]} {'north' if iy else 'south'}-{'east' if ix else 'west'}")

    # Lidar near the room centre, rotation axis vertical, turned a little.
    yaw = np.radians(rng.uniform(-10, 10))
    Rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    lidar_pos = [Lx / 2 + rng.uniform(-0.3, 0.3), Ly / 2 + rng.uniform(-0.2, 0.3), rng.uniform(1.05, 1.3)]
    T_world_lidar = make_T(Rz @ R_WORLD_LIDAR_LEVEL, lidar_pos)
    T_camera_lidar = ground_truth_T_camera_lidar(np.random.default_rng([int(seed), 1]), int(seed))

    return Room(
        seed=int(seed),
        size_m=np.array([Lx, Ly, H]),
        parts=parts,
        mesh=mesh,
        face_part=face_part,
        window=window,
        corners_world=np.asarray(corners, dtype=np.float64),
        corner_labels=labels,
        T_world_lidar=T_world_lidar,
        T_camera_lidar=T_camera_lidar,
    )
