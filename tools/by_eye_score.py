"""Score a by-eye walkthrough afterwards (docs/by_eye.md): each pair's own error and the result against a reference.

    python tools/by_eye_score.py --scan S --camera C --reference REF SESSION.yaml [--actions LOG_DIR/actions.jsonl]
        [--image-size W H]

Each complete pair of the session is scored by the distance between its clicked pixel and the projection, under
the reference (published) calibration, of the laser point it names (an edge pair, ``edge_deg``: the distance across
its edge).  The pairs are then solved as the app solves
them (:func:`calib_core.solve.calibrate.calibrate`, each click weighted by its ``precision_px``; before stop 28 the
weights were dropped here, see docs/by_eye.md) and the result is compared with the reference: the rotation
angle after projecting both onto SO(3), and the translation difference.  The reference is used only here, never
while clicking.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from calib_core.cameras.io import load_camera
from calib_core.io.extrinsic_formats import load_extrinsics_any
from calib_core.io.scan_readers import load_scan
from calib_core.io.yaml_files import read_yaml_mapping
from calib_core.pairs import Pair, resolve_pairs
from calib_core.solve.calibrate import calibrate
from calib_core.solve.edges import edge_pixel_errors
from calib_core.transforms import transform_points


def nearest_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation nearest to ``R`` (SVD), so a printed, slightly non-orthonormal matrix scores no false error."""
    U, _, Vt = np.linalg.svd(R)
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def pose_difference(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """Rotation angle (degrees) and translation difference (cm) between two ``T_camera_lidar``."""
    R = nearest_rotation(T_a[:3, :3]).T @ nearest_rotation(T_b[:3, :3])
    skew = np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    angle = np.degrees(np.arctan2(skew, (np.trace(R) - 1) / 2))
    return float(angle), float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]) * 100)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("session")
    ap.add_argument("--scan", required=True)
    ap.add_argument("--camera", required=True)
    ap.add_argument("--reference", required=True, help="the published calibration (any extrinsics format)")
    ap.add_argument("--actions", help="the driver's actions.jsonl, to count UI actions and minutes")
    ap.add_argument("--image-size", type=int, nargs=2, metavar=("W", "H"),
                    help="the image's size when the camera file states another (PJLab manual_calib: 1920 1200)")
    args = ap.parse_args(argv)

    depth = load_scan(args.scan)
    camera = load_camera(args.camera, image_size=tuple(args.image_size)) if args.image_size else load_camera(args.camera)
    T_ref = load_extrinsics_any(args.reference)  # a KITTI calib file: rectified camera 2, the one its image shows
    session = read_yaml_mapping(args.session, "session file")
    entries = [(k, e) for k, e in enumerate(session.get("pairs", [])) if e.get("pixel") is not None
               and (e.get("laser_rc") is not None or e.get("laser_xyz") is not None)]
    pairs = [Pair(laser_rc=tuple(e["laser_rc"]) if e.get("laser_rc") is not None else None,
                  laser_xyz=tuple(e["laser_xyz"]) if e.get("laser_rc") is None else None,
                  pixel=tuple(e["pixel"]), id=int(e.get("id", k + 1)),
                  precision_px=None if e.get("precision_px") is None else float(e["precision_px"]),
                  edge_deg=None if e.get("edge_deg") is None else float(e["edge_deg"]))
             for k, e in entries]
    # Check pairs (left out of the fit in the app) are scored but, as in the app, not solved with.
    is_check = [bool(e.get("check", False)) for _, e in entries]
    print(f"{len(pairs)} complete pairs" + (f" ({sum(is_check)} of them check pairs, left out of the fit)"
                                            if any(is_check) else ""))
    if pairs:
        points, _, pixels = resolve_pairs(pairs, depth, camera)
        projected, ok = camera.project(transform_points(T_ref, points))
        # An edge pair's error is its distance across its edge (its click may lie anywhere along the edge).
        edges = np.array([np.nan if p.edge_deg is None else p.edge_deg for p in pairs], np.float64)
        errors = np.where(ok, edge_pixel_errors(projected, pixels, edges), np.nan)
        for p, e in zip(pairs, errors):
            print(f"  pair {p.id}: laser_rc {p.laser_rc}, pixel ({p.pixel[0]:.1f}, {p.pixel[1]:.1f}): "
                  f"{e:.1f} px from the reference projection" + ("" if p.edge_deg is None else
                                                                 f" across its edge ({p.edge_deg:.0f} deg)"))
        print(f"pair errors: median {np.nanmedian(errors):.1f} px, range {np.nanmin(errors):.1f}-"
              f"{np.nanmax(errors):.1f} px")
    fitted = [p for p, c in zip(pairs, is_check) if not c]
    if len(fitted) >= 4:
        result = calibrate(fitted, depth, camera, robust=True)
        angle, cm = pose_difference(result.T_camera_lidar, T_ref)
        print(f"result vs reference: {angle:.2f} deg, {cm:.1f} cm")
    if any(is_check) and len(pairs) >= 4:
        result = calibrate(pairs, depth, camera, robust=True)
        angle, cm = pose_difference(result.T_camera_lidar, T_ref)
        print(f"with the check pairs in the fit too: {angle:.2f} deg, {cm:.1f} cm")
    if args.actions:
        rows = [json.loads(line) for line in Path(args.actions).read_text().splitlines() if line.strip()]
        acts = [r for r in rows if r["action"]]
        minutes = (rows[-1]["t_s"] - rows[0]["t_s"]) / 60 if rows else 0.0
        print(f"UI actions: {len(acts)}, screenshots: {len(rows) - len(acts)}, minutes: {minutes:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
