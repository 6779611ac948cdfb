"""Do edge pairs on lane lines fix the by-eye translation?  ``python -m bench.edge_pairs``.

On the PJLab road scene (``manual_calib``, 64-beam lidar, 1920x1200 photo) a person finds corners only 20-100 m
away, and the translation comes out tens of centimetres off.  Near the car there are painted lane lines,
crossed by the laser rings: a ring's crossing of a line is a precise laser point, but its place in the photo is
known only ACROSS the line -- an edge pair (:attr:`calib_core.pairs.Pair.edge_deg`).

For every kept PJLab by-eye session (``tests/by_eye_sessions/pjlab_manual_run*.yaml``) this solves its fit pairs
as the app does (:func:`calib_core.solve.calibrate`), then the same pairs plus N simulated lane-line crossings:

* candidates: cells on rings whose point lies ``--near`` metres from the lidar and whose projection under the
  PUBLISHED pose falls on yellow or white paint in the photo (found by colour, HSV thresholds), one cell per run
  of such cells along a ring (its middle: the ring's crossing of the line);
* the photo end: that projection plus ``--across`` px of Gaussian noise across the line and a uniform offset of
  up to ``--along`` px along it (the line's direction from the paint mask around it, for the simulation only),
  kept on the paint;
* ``edge_deg``: :func:`calib_core.image_edges.edge_at` on the photo (grey) at that pixel -- the real direction
  finder, not the mask; a candidate whose edge is not coherent (``.ok`` False) is dropped, as the app would;
* ``precision_px``: ``--across`` (the simulated click noise).

It prints, per session and as medians, the result against the published calibration (rotation deg, translation
cm) without and with the edge pairs.  The scene is read from ``../shared/data`` (a line and exit 0 when missing).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SESSIONS = REPO / "tests" / "by_eye_sessions"
PJLAB = REPO.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "manual_calib"
SCAN, CAMERA, IMAGE = PJLAB / "0.pcd", PJLAB / "center_camera-intrinsic.json", PJLAB / "0.png"
REFERENCE = PJLAB / "top_center_lidar-to-center_camera-extrinsic.json"
IMAGE_SIZE = (1920, 1200)


def paint_masks(bgr: np.ndarray) -> dict[str, np.ndarray]:
    """Yellow and white paint of the photo, by colour (HSV; OpenCV's hue 0-180)."""
    import cv2

    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    return {"yellow": (h > 15) & (h < 40) & (s > 55) & (v > 110), "white": (s < 45) & (v > 160)}


def line_direction(mask: np.ndarray, uv: np.ndarray, half: int = 25) -> np.ndarray:
    """Unit direction ``(du, dv)`` of the paint around ``uv``: main axis of the mask's pixels in a window."""
    u, v = int(round(uv[0])), int(round(uv[1]))
    ys, xs = np.nonzero(mask[max(v - half, 0):v + half, max(u - half, 0):u + half])
    X = np.c_[xs, ys].astype(np.float64)
    X -= X.mean(axis=0)
    return np.linalg.eigh(X.T @ X)[1][:, 1]


def crossings(depth, camera, T_ref, masks, near_m: tuple[float, float]) -> list[tuple[int, int, str, np.ndarray]]:
    """Cells (row, col) at the middle of each run of a ring's cells on paint, with the paint kind and the
    projection under the published pose (px)."""
    from calib_core.transforms import transform_points

    valid = np.asarray(depth.valid)
    rr, cc = np.nonzero(valid)
    P = np.asarray(depth.points)[rr, cc]
    rng = np.linalg.norm(P, axis=1)
    uv, ok = camera.project(transform_points(T_ref, P))
    uv, ok = np.asarray(uv, np.float64), np.asarray(ok, bool)
    W, H = IMAGE_SIZE
    ok &= (rng >= near_m[0]) & (rng <= near_m[1]) & np.isfinite(uv).all(axis=1)
    ok &= (uv[:, 0] > 40) & (uv[:, 0] < W - 41) & (uv[:, 1] > 40) & (uv[:, 1] < H - 41)
    iu, iv = np.round(np.where(ok[:, None], uv, 0)).astype(int).T
    out = []
    for kind, mask in masks.items():
        on = ok & mask[iv, iu]
        for r in np.unique(rr[on]):
            k = np.flatnonzero(on & (rr == r))
            k = k[np.argsort(cc[k])]
            for run in np.split(k, np.flatnonzero(np.diff(cc[k]) > 1) + 1):
                if len(run) >= 2:
                    mid = run[len(run) // 2]
                    out.append((int(rr[mid]), int(cc[mid]), kind, uv[mid]))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=4, help="simulated crossings added per session (default 4)")
    ap.add_argument("--near", type=float, nargs=2, default=(8.0, 11.5), help="range band of the crossings, m")
    ap.add_argument("--across", type=float, default=2.5, help="click noise across the line, px (1-sigma)")
    ap.add_argument("--along", type=float, default=40.0, help="largest offset along the line, px")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mask-direction", action="store_true",
                    help="diagnosis: edge_deg from the paint mask's direction instead of edge_at")
    ap.add_argument("--session-floor-px", type=float, default=None,
                    help="diagnosis: a floor on the session pairs' precision_px (as the lead's pixel solver's 3 px)")
    args = ap.parse_args(argv)
    if not SCAN.exists() or not IMAGE.exists():
        print(f"bench.edge_pairs: {PJLAB} is missing; nothing to measure")
        return 0
    import cv2

    from calib_core.cameras.io import load_camera
    from calib_core.image_edges import edge_at
    from calib_core.io.extrinsic_formats import load_extrinsics_any
    from calib_core.io.scan_readers import load_scan
    from calib_core.pairs import Pair, load_pairs_yaml
    from calib_core.solve.calibrate import calibrate
    from bench.by_eye_limits import pose_error

    t0 = time.perf_counter()
    depth = load_scan(SCAN)
    camera = load_camera(CAMERA, image_size=IMAGE_SIZE)
    T_ref = load_extrinsics_any(REFERENCE)
    bgr = cv2.imread(str(IMAGE))
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    masks = paint_masks(bgr)
    rng = np.random.default_rng(args.seed)
    candidates = crossings(depth, camera, T_ref, masks, tuple(args.near))
    directions = [line_direction(masks[kind], uv0) for _, _, kind, uv0 in candidates]
    tries, dropped, angle_err = 0, 0, []

    def click(k: int, pair_id: int) -> Pair | None:
        """A simulated click on crossing ``k``: on the paint, with a coherent edge there (up to 20 tries)."""
        nonlocal tries, dropped
        r, c, kind, uv0 = candidates[k]
        t = directions[k]
        n = np.array([-t[1], t[0]])
        for _ in range(20):
            tries += 1
            pixel = uv0 + rng.normal(0.0, args.across) * n + rng.uniform(-args.along, args.along) * t
            iu, iv = int(round(pixel[0])), int(round(pixel[1]))
            if not (0 <= iu < IMAGE_SIZE[0] and 0 <= iv < IMAGE_SIZE[1]) or not masks[kind][iv, iu]:
                dropped += 1  # slid off the paint (a dash's end): not a click on the line
                continue
            edge = edge_at(gray, pixel)
            if not edge.ok:
                dropped += 1
                continue
            mask_deg = np.degrees(np.arctan2(t[1], t[0])) % 180.0
            angle_err.append(min(abs(edge.angle_deg - mask_deg), 180 - abs(edge.angle_deg - mask_deg)))
            return Pair((r, c), None, (float(pixel[0]), float(pixel[1])), id=pair_id, precision_px=args.across,
                        edge_deg=mask_deg if args.mask_direction else edge.angle_deg)
        return None

    ranges = [float(np.linalg.norm(depth.points[r, c])) for r, c, _, _ in candidates]
    print(f"bench.edge_pairs: PJLab manual_calib; {len(candidates)} lane-line crossings at {args.near[0]:g}-"
          f"{args.near[1]:g} m ({', '.join(f'{kind} {x:.1f} m' for (_, _, kind, _), x in zip(candidates, ranges))}); "
          f"{args.n} added per session, {args.across:g} px across, up to {args.along:g} px along")
    if len(candidates) < args.n:
        print("too few crossings for the experiment")
        return 0
    files = sorted(SESSIONS.glob("pjlab_manual_run*.yaml"), key=lambda p: int(p.stem.rsplit("run", 1)[1]))
    print(f"\n{'session':22s} {'pairs':>5s}   {'without':>17s}   {'with edge pairs':>17s}")
    rows = []
    for f in files:
        fit = [p for p in load_pairs_yaml(f) if not p.check]
        if args.session_floor_px is not None:
            fit = [dataclasses.replace(p, precision_px=max(p.precision_px or 1.0, args.session_floor_px)) for p in fit]
        base = calibrate(fit, depth, camera)
        next_id = max([p.id for p in fit if p.id is not None] + [0]) + 1
        pick = rng.choice(len(candidates), args.n, replace=False)
        extra = [p for p in (click(int(k), next_id + j) for j, k in enumerate(pick)) if p is not None]
        with_edges = calibrate(fit + extra, depth, camera)
        a = pose_error(base.T_camera_lidar, T_ref)[:2]
        b = pose_error(with_edges.T_camera_lidar, T_ref)[:2]
        rows.append((*a, *b))
        print(f"{f.stem:22s} {len(fit):3d}+{len(extra)}   {a[0]:5.2f} deg {a[1]:5.1f} cm   {b[0]:5.2f} deg {b[1]:5.1f} cm   "
              f"({with_edges.quality.status}, {len(with_edges.outliers)} outliers)")
    print(f"\nsimulated clicks: {tries} drawn, {dropped} redrawn (off the paint or no coherent edge); edge_at against "
          f"the paint mask's direction: median {np.median(angle_err):.1f} deg, largest {np.max(angle_err):.1f} deg")
    m = np.median(np.array(rows), axis=0)
    print(f"\nmedian without edge pairs: {m[0]:.2f} deg, {m[1]:.1f} cm")
    print(f"median with {args.n} edge pairs:  {m[2]:.2f} deg, {m[3]:.1f} cm")
    print(f"({len(rows)} sessions, {time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
