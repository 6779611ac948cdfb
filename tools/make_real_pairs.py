"""Generate the pairs files of the real scenes (``real_data/pairs/``).

Scenes: the two PJLab OpenCalib scenes and KITTI object frame 000002.

Method (b) of ``real_data/README.md``: the *laser cells* are chosen by a fixed
rule at real structure of the scan, and each *camera pixel* is the projection
of the cell's 3-D point with the dataset's published calibration, plus
Gaussian noise of 1 px per axis.  The pairs therefore test the whole pipeline
(reader, organisation into a depth matrix, cell lookup, distorted pinhole
model, solver) against the published extrinsic; they do not test how well a
person can click.

Selection rule (fixed before any calibration was run):

1. Candidate cells are *foreground corners* of the depth matrix: a valid cell
   that has a same-surface neighbour (range within 2 %) and is in front of the
   opposite neighbour (by more than 1 m and 10 %) both along its row and along
   its column.  The opposite neighbour must be a return, except the one above
   the cell, which may be sky (no return); holes in the ground (dark asphalt
   returns nothing) are not edges.  These are the ends of the edges seen in
   the BA images: tops and bases of poles, corners of boxes, signs, fence
   posts and cars.
2. Only cells between 3 m and 40 m (beyond, a pixel is too many centimetres
   to fix the translation) whose point projects at least 20 px inside
   the image are kept.
3. Spread over the view by farthest-point sampling in the image: start with
   the nearest candidate (near points fix the translation), then repeatedly
   add the candidate farthest (in pixels) from those already taken, until
   11 pairs.
4. Pixel = projection with the published T_camera_lidar + N(0, 1 px) per
   axis, from ``numpy.random.default_rng(seed)``; seed 1 for auto_calib, 2
   for manual_calib and 3 for KITTI 000002.

KITTI: the scan is organised with ``load_scan``'s defaults (its scan order,
64 x 2158).  The image is rectified, so the camera is a pinhole with
``K = P2[:, :3]`` and no distortion (written to
``real_data/kitti_000002_camera.yaml``), and the published extrinsic is
``T_camera_lidar = [I | K^-1 P2[:, 3]] @ R0_rect @ Tr_velo_to_cam``: R0_rect
rotates into the rectified frame and P2's fourth column is camera 2's
baseline offset from the reference camera 0.

Run from the repository root (reads ``../shared/data``)::

    python tools/make_real_pairs.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from calib_core.cameras import load_camera  # noqa: E402
from calib_core.cameras.io import save_camera_yaml  # noqa: E402
from calib_core.cameras.pinhole import PinholeCamera  # noqa: E402
from calib_core.io.kitti_calib import read_kitti_camera2  # noqa: E402
from calib_core.io.scan_readers import load_scan  # noqa: E402
from calib_core.lidar.depth_matrix import DepthMatrix  # noqa: E402
from calib_core.transforms import transform_points  # noqa: E402

DATA = REPO.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera"
KITTI = REPO.parent / "shared" / "data" / "kitti_object_000002"
KITTI_SEED = 3
KITTI_IMAGE_SIZE = (1242, 375)

#: scene name -> (scan file, load_scan options, camera image size override, noise seed)
SCENES = {
    "auto_calib": ("calib.pcd", {}, None, 1),
    "manual_calib": ("0.pcd", {"beams": 64}, (1920, 1200), 2),
}

N_PAIRS = 11
SAME_SURFACE_REL = 0.02
JUMP_MIN_M = 1.0
JUMP_MIN_REL = 0.10
RANGE_LIMITS_M = (3.0, 40.0)
IMAGE_MARGIN_PX = 20.0
PIXEL_NOISE_PX = 1.0


def published_T_camera_lidar(scene_dir: Path) -> np.ndarray:
    """The dataset's lidar -> camera 4x4 transform (metres)."""
    data = json.loads((scene_dir / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    return np.array(data["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], dtype=float)


def _shifted(range_m: np.ndarray, d_row: int, d_col: int) -> np.ndarray:
    """``out[r, c] = range_m[r + d_row, c + d_col]``, NaN outside the matrix."""
    out = np.full_like(range_m, np.nan)
    h, w = range_m.shape
    rs = slice(max(0, -d_row), h - max(0, d_row))
    cs = slice(max(0, -d_col), w - max(0, d_col))
    rd = slice(max(0, d_row), h - max(0, -d_row))
    cd = slice(max(0, d_col), w - max(0, -d_col))
    out[rs, cs] = range_m[rd, cd]
    return out


def foreground_corners(depth: DepthMatrix) -> tuple[np.ndarray, np.ndarray]:
    """Cells at the corner of a foreground object, and their range jump.

    Returns
    -------
    corner : (H, W) bool
    jump_m : (H, W) float
        The smaller of the row and column jumps to the background (metres);
        sky above a cell counts as a jump of 100 m.
    """
    rng = np.where(depth.valid, depth.range_m, np.nan)
    along = {}
    with np.errstate(invalid="ignore"):
        # (axis, offsets of the two neighbours, whether a missing neighbour counts as background)
        for axis, offsets, sky_ok in (("row", ((0, -1), (0, 1)), (False, False)), ("col", ((1, 0), (-1, 0)), (False, True))):
            a, b = (_shifted(rng, *o) for o in offsets)
            jumps = []
            # Same surface on one side, background on the other: b is background for (a, b), a for (b, a).
            for same, other, other_sky_ok in ((a, b, sky_ok[1]), (b, a, sky_ok[0])):
                same_ok = np.abs(same - rng) <= SAME_SURFACE_REL * rng
                jump = np.where(np.isnan(other), 100.0 if other_sky_ok else 0.0, other - rng)
                far = (jump > JUMP_MIN_M) & (jump > JUMP_MIN_REL * rng)
                jumps.append(np.where(same_ok & far, jump, 0.0))
            along[axis] = np.maximum(*jumps)
        jump_m = np.minimum(along["row"], along["col"])
    return depth.valid & (jump_m > 0.0), jump_m


def select_pairs(depth: DepthMatrix, camera, T_camera_lidar: np.ndarray, seed: int) -> list[dict]:
    """Apply the selection rule of the module docstring; return pairs-file entries."""
    corner, jump = foreground_corners(depth)
    rows, cols = np.nonzero(corner)
    points = depth.points[rows, cols]
    ranges = depth.range_m[rows, cols]
    points_camera = transform_points(T_camera_lidar, points)
    pixels, ok = camera.project(points_camera)
    ok &= points_camera[:, 2] > 0
    ok &= (ranges >= RANGE_LIMITS_M[0]) & (ranges <= RANGE_LIMITS_M[1])
    with np.errstate(invalid="ignore"):
        ok &= (pixels[:, 0] >= IMAGE_MARGIN_PX) & (pixels[:, 0] <= camera.width - 1 - IMAGE_MARGIN_PX)
        ok &= (pixels[:, 1] >= IMAGE_MARGIN_PX) & (pixels[:, 1] <= camera.height - 1 - IMAGE_MARGIN_PX)
    rows, cols, ranges, pixels, jumps = rows[ok], cols[ok], ranges[ok], pixels[ok], jump[rows[ok], cols[ok]]
    # Farthest-point sampling (a loop over the 11 picks, not over cells).
    chosen = [int(np.argmin(ranges))]
    gap = np.linalg.norm(pixels - pixels[chosen[0]], axis=1)
    while len(chosen) < min(N_PAIRS, len(ranges)):
        chosen.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.linalg.norm(pixels - pixels[chosen[-1]], axis=1))
    first = np.array(chosen)
    noise = np.random.default_rng(seed).normal(0.0, PIXEL_NOISE_PX, size=(len(first), 2))
    entries = []
    for k, i in enumerate(first):
        u, v = pixels[i] + noise[k]
        label = f"foreground corner at {ranges[i]:.1f} m, range jump {min(jumps[i], 100.0):.1f} m"
        entries.append({"laser_rc": [int(rows[i]), int(cols[i])], "pixel": [round(float(u), 2), round(float(v), 2)], "label": label})
    return entries


HEADER = """\
# Pairs for the PJLab OpenCalib {scene} scene (../shared/data/pjlab_opencalib_lidar2camera/{scene}).
# Method (b), see real_data/README.md: laser cells chosen by a fixed rule at
# foreground corners of the depth matrix (load_scan({scan}{opts})), camera pixels =
# projection with the PUBLISHED extrinsic + N(0, 1 px) noise (seed {seed}).
# Generated by tools/make_real_pairs.py; not hand-clicked.
"""


def _write_pairs(path: Path, header: str, entries: list[dict]) -> None:
    path.write_text(header + yaml.safe_dump({"pairs": entries}, sort_keys=False, default_flow_style=None))
    print(f"{path.relative_to(REPO)}: {len(entries)} pairs")
    for e in entries:
        print(f"  {e['laser_rc']} -> {e['pixel']}  ({e['label']})")


KITTI_HEADER = """\
# Pairs for KITTI object frame 000002 (../shared/data/kitti_object_000002).
# Method (b), see real_data/README.md: laser cells chosen by a fixed rule at
# foreground corners of the depth matrix (load_scan(velodyne/000002.bin), default
# options: the scan order, 64 x 2158), camera pixels = projection with the PUBLISHED
# calibration (P2, R0_rect, Tr_velo_to_cam) + N(0, 1 px) noise (seed {seed}).
# Camera: real_data/kitti_000002_camera.yaml (K = P2[:, :3], rectified, no distortion).
# Generated by tools/make_real_pairs.py; not hand-clicked.
"""


def make_kitti(out_dir: Path) -> None:
    K, T = read_kitti_camera2(KITTI / "calib" / "000002.txt")
    camera = PinholeCamera(K, [], *KITTI_IMAGE_SIZE)
    save_camera_yaml(camera, REPO / "real_data" / "kitti_000002_camera.yaml")
    depth = load_scan(KITTI / "velodyne" / "000002.bin")
    entries = select_pairs(depth, camera, T, KITTI_SEED)
    _write_pairs(out_dir / "kitti_000002_pairs.yaml", KITTI_HEADER.format(seed=KITTI_SEED), entries)


def main() -> int:
    out_dir = REPO / "real_data" / "pairs"
    out_dir.mkdir(parents=True, exist_ok=True)
    for scene, (scan_name, options, image_size, seed) in SCENES.items():
        scene_dir = DATA / scene
        depth = load_scan(scene_dir / scan_name, **options)
        camera = load_camera(scene_dir / "center_camera-intrinsic.json", image_size=image_size)
        entries = select_pairs(depth, camera, published_T_camera_lidar(scene_dir), seed)
        opts = "".join(f", {k}={v}" for k, v in options.items())
        path = out_dir / f"{scene.split('_')[0]}_calib_pairs.yaml"
        _write_pairs(path, HEADER.format(scene=scene, scan=scan_name, opts=opts, seed=seed), entries)
    make_kitti(out_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
