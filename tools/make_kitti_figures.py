"""Write the KITTI 000002 figures of docs/real_data.md into docs/real/.

The four BA images exactly as ``ba-calib ba-images`` writes them
(``bearing_angle.ba_to_display``), cropped to the columns the published
calibration projects into the camera image (plus 4 columns each side) and
enlarged with nearest-neighbour sampling, x3 in width and x4 in height; and
the photo scaled to 480 px wide with a 64-colour palette.

Run from the repository root (reads ``../shared/data``)::

    python tools/make_kitti_figures.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

from make_real_pairs import KITTI, KITTI_IMAGE_SIZE  # noqa: E402

from calib_core.io.kitti_calib import read_kitti_camera2  # noqa: E402

from calib_core.bearing_angle import BA_DIRECTIONS, ba_to_display, bearing_angle_images  # noqa: E402
from calib_core.io.scan_readers import load_scan  # noqa: E402
from calib_core.transforms import transform_points  # noqa: E402


def camera_columns(depth, K: np.ndarray, T: np.ndarray) -> tuple[int, int]:
    """First and last depth-matrix column with a valid cell projecting into the image."""
    rows, cols = np.nonzero(depth.valid)
    p = transform_points(T, depth.points[rows, cols])
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K[0, 0] * p[:, 0] / p[:, 2] + K[0, 2]
        v = K[1, 1] * p[:, 1] / p[:, 2] + K[1, 2]
    inside = (p[:, 2] > 0) & (u >= 0) & (u < KITTI_IMAGE_SIZE[0]) & (v >= 0) & (v < KITTI_IMAGE_SIZE[1])
    return int(cols[inside].min()), int(cols[inside].max())


def main() -> int:
    out = REPO / "docs" / "real"
    out.mkdir(parents=True, exist_ok=True)
    K, T = read_kitti_camera2(KITTI / "calib" / "000002.txt")
    depth = load_scan(KITTI / "velodyne" / "000002.bin")
    first, last = camera_columns(depth, K, T)
    lo, hi = max(first - 4, 0), min(last + 5, depth.shape[1])
    print(f"{depth.meta['organize_report'].line()}\ncamera sees columns {first}-{last}; crop {lo}-{hi - 1}")
    images = bearing_angle_images(depth)
    for name in BA_DIRECTIONS:
        crop = np.asarray(ba_to_display(images[name]))[:, lo:hi]
        image = Image.fromarray(crop)
        image.resize((image.width * 3, image.height * 4), Image.NEAREST).save(out / f"kitti_000002_ba_{name}.png", optimize=True)
    photo = Image.open(KITTI / "image_2" / "000002.png").convert("RGB")
    photo = photo.resize((480, round(480 * photo.height / photo.width)), Image.LANCZOS)
    photo.quantize(64).save(out / "kitti_000002_photo.png", optimize=True)
    print(f"wrote {out}/kitti_000002_*.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
