"""The sample scene: generate it, write it to a folder, read it back.

``write_sample(out_dir, seed)`` is what ``ba-calib sample -o DIR --seed N``
runs; the committed ``sample_data/`` is ``write_sample("sample_data", 0)``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cameras import OCamCamera, load_camera, save_camera_yaml
from ..errors import CalibError
from ..io.atomic import write_bytes_atomic, write_yaml_atomic
from ..io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml
from ..io.images import load_image_rgb, save_image_rgb
from ..io.yaml_files import read_yaml_mapping
from ..lidar import DepthMatrix, load_depth_npz, save_depth_npz
from ..pairs import save_pairs_yaml
from ..transforms import invert_T, rpy_deg_from_R, transform_points
from .picks import simulate_pairs, visible_corners
from .render import cast, render_image, render_scan
from .scene import Room, build_room

# --- the rig -------------------------------------------------------------------------
#: Scanner (paper Sec. V): rows = in-plane angle theta, +89.5 .. -89.5 deg in
#: 1 deg steps; columns = rotation phi over 360 deg in 0.5 deg steps.  Column 0
#: is phi = 90 deg, where the beam points along lidar -z (world north at zero
#: yaw), and phi decreases along the row: the camera looks along lidar +z, so
#: its view sits mid-panorama, the seam of the scan lies behind it, and left
#: and right in the depth matrix are left and right in the camera image.
THETA_STEP_DEG = 1.0
PHI_STEP_DEG = 0.5
PHI_START_DEG = 90.0
SCANNER_DX_M = 0.05
SCANNER_DZ_M = 0.03
RANGE_NOISE_M = 0.01
MAX_RANGE_M = 30.0

#: Camera: OCamCalib polynomial fitted to an equidistant mapping reaching
#: 120 deg from the optical axis at the image-circle radius of 230 px; the
#: angle keeps growing (to ~165 deg at the image corners), so the mapping is
#: one-to-one over the whole image.
CAMERA_WIDTH, CAMERA_HEIGHT = 640, 480
CAMERA_POL = (-111.29, 0.0, 4.1857e-3, -1.54014e-5, 7.42759e-8)
CAMERA_XC, CAMERA_YC = 242.3, 318.6  # centre row, column (0-based), off the image centre
CAMERA_AFFINE = (1.0008, 1.1e-3, -0.9e-3)  # c, d, e
IMAGE_CIRCLE_RADIUS_PX = 230.0

PAIRS_IN_SAMPLE = 10

FILES = ("scan.npz", "image.png", "camera.yaml", "calib_results.txt", "ground_truth.yaml", "corners.yaml",
         "pairs.yaml", "README.md")


@dataclass
class SampleScene:
    """A generated (or loaded) sample: scan, image, camera and the ground truth.

    Attributes
    ----------
    depth : DepthMatrix
        The rotating scanner's depth matrix, lidar frame.
    image : (H, W, 3) uint8
        The omnidirectional camera image, RGB.
    camera : OCamCamera
    T_camera_lidar : (4, 4)
        Ground truth, ``X_camera = T_camera_lidar @ X_lidar``, metres.
    T_world_lidar : (4, 4)
        Lidar pose in the room (world: z up, metres).
    corners_lidar : (M, 3)
        Scene corners seen by both sensors, lidar frame, metres.
    corner_labels : list of str
    seed : int
    room : Room
        Layout and mesh (world frame), rebuilt from the seed when loaded.
    """

    depth: DepthMatrix
    image: np.ndarray
    camera: OCamCamera
    T_camera_lidar: np.ndarray
    T_world_lidar: np.ndarray
    corners_lidar: np.ndarray
    corner_labels: list[str]
    seed: int
    room: Room

    @property
    def mesh(self):
        """The scene mesh in the world frame (``trimesh.Trimesh``)."""
        return self.room.mesh


def sample_camera(image_scale: int = 1) -> OCamCamera:
    """The sample's OCam camera, optionally ``image_scale`` times smaller (for quick tests).

    Shrinking pixel coordinates by ``k`` maps radius ``r`` to ``r / k``; the
    rays stay the same when ``a_i`` becomes ``a_i k^(i-1)``.
    """
    k = int(image_scale)
    if k < 1 or CAMERA_WIDTH % k or CAMERA_HEIGHT % k:
        raise CalibError(f"image_scale must divide {CAMERA_WIDTH} and {CAMERA_HEIGHT}, got {image_scale}")
    pol = [a * float(k) ** (i - 1) for i, a in enumerate(CAMERA_POL)]
    xc, yc = (CAMERA_XC + 0.5) / k - 0.5, (CAMERA_YC + 0.5) / k - 0.5
    return OCamCamera(pol, None, xc, yc, *CAMERA_AFFINE, CAMERA_WIDTH // k, CAMERA_HEIGHT // k)


def scanner_angles_grid(scan_step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Row angles theta (H,) and column angles phi (W,) in radians; ``scan_step`` thins both."""
    k = int(scan_step)
    if k < 1:
        raise CalibError(f"scan_step must be a positive integer, got {scan_step}")
    theta_deg = np.arange(90.0 - THETA_STEP_DEG / 2, -90.0, -THETA_STEP_DEG * k)
    phi_deg = PHI_START_DEG - np.arange(0.0, 360.0, PHI_STEP_DEG * k)
    return np.radians(theta_deg), np.radians(phi_deg)


def _corners(room: Room, camera: OCamCamera, depth: DepthMatrix, image_scale: int) -> tuple[np.ndarray, list[str]]:
    ok = visible_corners(room, camera, depth, IMAGE_CIRCLE_RADIUS_PX / image_scale,
                         lambda o, d: cast(room, o, d))
    corners_l = transform_points(invert_T(room.T_world_lidar), room.corners_world[ok])
    labels = [label for label, keep in zip(room.corner_labels, ok) if keep]
    return corners_l, labels


def make_sample_scene(seed: int = 0, *, image_scale: int = 1, scan_step: int = 1) -> SampleScene:
    """Generate the synthetic sample by ray casting.

    Parameters
    ----------
    seed : int
        Layout of the room and ground truth (seed 0: the paper's Table I pose).
    image_scale : int
        Render a camera this many times smaller (tests only; 1 = 640 x 480).
    scan_step : int
        Keep every ``scan_step``-th scanner row and column (tests only).

    Returns
    -------
    SampleScene
    """
    room = build_room(seed)
    seed = room.seed
    camera = sample_camera(image_scale)
    theta, phi = scanner_angles_grid(scan_step)
    depth = render_scan(room, theta, phi, SCANNER_DX_M, SCANNER_DZ_M, np.random.default_rng([seed, 2]),
                        RANGE_NOISE_M, MAX_RANGE_M)
    image = render_image(room, camera, IMAGE_CIRCLE_RADIUS_PX / image_scale, np.random.default_rng([seed, 3]))
    corners_l, labels = _corners(room, camera, depth, image_scale)
    return SampleScene(depth, image, camera, room.T_camera_lidar.copy(), room.T_world_lidar.copy(),
                       corners_l, labels, seed, room)


def write_sample(out_dir: str | os.PathLike, seed: int = 0, *, image_scale: int = 1,
                 scan_step: int = 1) -> SampleScene:
    """Generate the sample scene and write every file of it into ``out_dir``.

    Writes ``scan.npz``, ``image.png``, ``camera.yaml`` + ``calib_results.txt``,
    ``ground_truth.yaml``, ``corners.yaml``, ``pairs.yaml`` (10 simulated
    clicks) and ``README.md``.

    Returns
    -------
    SampleScene
        What was written.
    """
    out = Path(out_dir)
    scene = make_sample_scene(seed, image_scale=image_scale, scan_step=scan_step)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise CalibError(f"cannot create output folder {out}: {err.strerror or err}") from None
    save_depth_npz(out / "scan.npz", scene.depth)
    save_image_rgb(out / "image.png", scene.image)
    save_camera_yaml(scene.camera, out / "camera.yaml")
    camera_from_file = load_camera(out / "camera.yaml")  # so ground_truth.yaml refers to the file
    save_extrinsics_yaml(out / "ground_truth.yaml", scene.T_camera_lidar, camera=camera_from_file)
    pix, _ = scene.camera.project(transform_points(scene.T_camera_lidar, scene.corners_lidar))
    write_yaml_atomic(out / "corners.yaml", {
        "description": "scene corners seen by both the camera and the scanner (ground truth)",
        "seed": scene.seed,
        "frame": "lidar",
        "units": "m",
        "T_world_lidar": scene.T_world_lidar.tolist(),
        "corners": [
            {"label": label, "xyz": [float(v) for v in xyz], "pixel": [float(v) for v in uv]}
            for label, xyz, uv in zip(scene.corner_labels, scene.corners_lidar, pix)
        ],
    })
    pairs = simulate_pairs(scene, PAIRS_IN_SAMPLE, np.random.default_rng([scene.seed, 4]), pixel_noise_px=1.0)
    save_pairs_yaml(out / "pairs.yaml", pairs)
    write_bytes_atomic(out / "README.md", _readme(scene).encode("utf-8"))
    return scene


def load_sample(sample_dir: str | os.PathLike) -> SampleScene:
    """Read a folder written by :func:`write_sample` (the mesh is rebuilt from the seed).

    Raises
    ------
    CalibError
        A file is missing or malformed (the message names it).
    """
    d = Path(sample_dir)
    if not d.is_dir():
        raise CalibError(f"sample folder not found: {d}")
    depth = load_depth_npz(d / "scan.npz")
    image = load_image_rgb(d / "image.png")
    camera = load_camera(d / "camera.yaml")
    T_camera_lidar = load_extrinsics_yaml(d / "ground_truth.yaml")["T_camera_lidar"]
    path = d / "corners.yaml"
    doc = read_yaml_mapping(path, "corners file")
    try:
        seed = int(doc["seed"])
        T_world_lidar = np.asarray(doc["T_world_lidar"], dtype=np.float64).reshape(4, 4)
        entries = doc["corners"]
        labels = [str(c["label"]) for c in entries]
        corners = np.asarray([c["xyz"] for c in entries], dtype=np.float64).reshape(-1, 3)
    except (KeyError, TypeError, ValueError) as err:
        raise CalibError(f"{path}: malformed corners file ({err})") from None
    return SampleScene(depth, image, camera, T_camera_lidar, T_world_lidar, corners, labels, seed,
                       build_room(seed))


def _readme(scene: SampleScene) -> str:
    H, W = scene.depth.shape
    invalid = 1.0 - scene.depth.valid.mean()
    rpy = rpy_deg_from_R(scene.T_camera_lidar[:3, :3])
    t = scene.T_camera_lidar[:3, 3]
    Lx, Ly, Hr = scene.room.size_m
    return f"""# Sample scene (synthetic, seed {scene.seed})

A synthetic office room seen by the paper's sensor pair: a rotating 2-D laser
scanner and an omnidirectional camera.  Everything here was made by ray
casting a triangle mesh, so the true extrinsics are known exactly.
Regenerate it (the same data) with

    ba-calib sample -o sample_data --seed {scene.seed}

(`calib_core.synthetic.write_sample`).  Another seed gives another room
layout and another ground truth.

## Files

| file | what |
| --- | --- |
| `scan.npz` | the scan in the native format (`model: rotating_2d`): ranges `range_m` ({H} x {W}, metres, NaN = no return) plus `theta_rad`, `phi_rad`, `dx_m`, `dz_m` of paper eq. 3 and `wrap_cols` |
| `image.png` | the camera image, {scene.camera.width} x {scene.camera.height} RGB |
| `camera.yaml` | camera description: `model: ocam`, `file: calib_results.txt` |
| `calib_results.txt` | the OCamCalib model in the toolbox's C-export format |
| `ground_truth.yaml` | the true `T_camera_lidar` in the extrinsics format |
| `corners.yaml` | {len(scene.corner_labels)} scene corners seen by both sensors: label, `xyz` in the lidar frame (metres) and the true `pixel` (u, v); also the seed and `T_world_lidar` |
| `pairs.yaml` | {PAIRS_IN_SAMPLE} simulated clicks at corners spread over the view: `laser_rc` (a whole depth-matrix cell) and `pixel` (true projection + 1 px Gaussian noise per axis) |
| `README.md` | this file |

## Rig

* World (for the layout only): x east, y north, z up, metres.  The room is
  {Lx:.2f} x {Ly:.2f} x {Hr:.2f} m: walls, floor, ceiling, two tables, seven
  boxes, a cabinet, a bookshelf, a framed picture, a recessed door, two
  ceiling lights and a window whose glass gives no laser echo.
* Scanner: paper eq. 3 with its rotation axis (lidar y) vertical; lidar x is
  horizontal, z = x cross y.  Rows: in-plane angle theta from +89.5 deg
  (up) to -89.5 deg in 1 deg steps; columns: rotation phi from 90 deg down to
  -269.5 deg in 0.5 deg steps (column 0 faces away from the camera, so the
  camera's view is mid-scan and not mirrored); offsets dx = {SCANNER_DX_M} m, dz = {SCANNER_DZ_M} m; range
  noise sigma = {RANGE_NOISE_M} m; no return beyond {MAX_RANGE_M:.0f} m or on glass
  ({100 * invalid:.1f} % of the cells have no return).
* Camera: OCam polynomial model, {CAMERA_WIDTH} x {CAMERA_HEIGHT}, image circle of
  radius {IMAGE_CIRCLE_RADIUS_PX:.0f} px, {np.degrees(scene.camera.max_angle_rad):.0f} deg from the optical
  axis at the image corners (120 deg at the circle: a field of view over
  180 deg).  Pixels outside the circle are black; 2 x 2 samples per pixel.
* Ground truth `T_camera_lidar` (X_camera = T @ X_lidar, OpenCV camera frame):
  translation ({t[0]:.4f}, {t[1]:.4f}, {t[2]:.4f}) m, roll/pitch/yaw
  ({rpy[0]:.2f}, {rpy[1]:.2f}, {rpy[2]:.2f}) deg (R = Rz(yaw) Ry(pitch) Rx(roll));
  seed 0 is the paper's Table I result.

## Conventions

Pixels are (u, v) = (column, row) with the centre of the top-left pixel at
(0, 0).  Depth-matrix cells are (row, col), 0-based.
"""
