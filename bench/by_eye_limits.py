"""What limits the by-eye results, from the kept walkthrough pairs: ``python -m bench.by_eye_limits``.

Every by-eye run (``docs/by_eye.md``) kept its pairs in ``tests/by_eye_sessions/`` (clicks chosen by eye from
screenshots only).  This benchmark solves each session as the app does (:func:`calib_core.solve.calibrate`,
check pairs left out) and scores it against the published calibration, then asks four questions:

1. **Does the click weighting matter?**  The same pairs solved with each click's ``precision_px`` as stored (the
   app), without any (unweighted), with a floor of 1, 2 and 3 px on it, and with a laser pick error of one whole
   cell instead of :data:`calib_core.solve.whiten.PICK_CELL_SIGMA`.
2. **Is the stated uncertainty honest?**  The pose error's Mahalanobis distance ``d^2 = e^T C^-1 e`` under the
   result's ``covariance_6x6`` (``e``: the rotation vector of ``R_published R^T`` and the translation difference).
   For an honest covariance ``d^2`` follows chi^2 with 6 degrees of freedom (median 5.35, 95 % below 12.59); the
   factor ``sqrt(median d^2 / 5.35)`` says how much the stated sigma understates the error.  First under the
   independent noise alone (click and laser cell, ``shared_ratio=0``), then under the app's model with the
   error the pairs share (:data:`calib_core.solve.whiten.BY_EYE_SHARED_RATIO`), with the share of sessions
   whose true error lies inside the stated 95 % region.  The fit of that ratio: ``median d^2 / 5.348 - 1`` of
   the independent model over both scenes pooled (printed at the end, with each scene's own fit and the other
   scene's median d^2 under it: one constant, not tuned per scene).
3. **Are the pairs' errors biased?**  Each pair's error under the published pose (click minus the cell's
   projection), its mean ``(du, dv)`` per range band.
4. **KITTI only: does a motion de-skew explain the near pairs' bias?**  The KITTI object frames are not motion
   compensated.  A forward speed ``v`` moves each point along lidar +x by ``v * azimuth / (2 pi * 10 Hz)`` (a 10 Hz
   scan, the camera triggered at azimuth 0); the pairs' errors and the sessions' results are recomputed for a few
   ``v``.  The object dataset gives no speed, so this is a diagnosis, not something the app can apply.

The scenes are read from ``../shared/data`` (skipped with a line when missing).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from calib_core.cameras.io import load_camera
from calib_core.io.extrinsic_formats import load_extrinsics_any
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import load_pairs_yaml, resolve_pairs
from calib_core.solve.calibrate import calibrate
from calib_core.solve.whiten import BY_EYE_SHARED_RATIO
from calib_core.transforms import transform_points

REPO = Path(__file__).resolve().parents[1]
SESSIONS = REPO / "tests" / "by_eye_sessions"
DATA = REPO.parent / "shared" / "data"
KITTI = DATA / "kitti_object_000002"
PJLAB = DATA / "pjlab_opencalib_lidar2camera" / "manual_calib"
SCENES = {
    "kitti": (KITTI / "velodyne" / "000002.bin", REPO / "real_data" / "kitti_000002_camera.yaml", None,
              KITTI / "calib" / "000002.txt"),
    "pjlab_manual": (PJLAB / "0.pcd", PJLAB / "center_camera-intrinsic.json", (1920, 1200),
                     PJLAB / "top_center_lidar-to-center_camera-extrinsic.json"),
}
#: Median of chi^2 with 6 degrees of freedom.
CHI2_6_MEDIAN = 5.348
#: 95 % quantile of chi^2 with 6 degrees of freedom: the stated 95 % region of the pose.
CHI2_6_95 = 12.592
#: Range bands (m) for the pairs' bias.
BANDS_M = ((0, 10), (10, 20), (20, 40), (40, 1000))
#: Pairs further off than this (px) under the published pose are mistakes, left out of the bias means.
MISTAKE_PX = 20.0


def pose_error(T: np.ndarray, T_ref: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Rotation angle (deg), translation distance (cm) and the 6-vector ``(rotvec of R_ref R^T, t_ref - t)``."""
    rotvec = Rotation.from_matrix(T_ref[:3, :3] @ T[:3, :3].T).as_rotvec()
    dt = T_ref[:3, 3] - T[:3, 3]
    return float(np.degrees(np.linalg.norm(rotvec))), float(100 * np.linalg.norm(dt)), np.r_[rotvec, dt]


def deskewed(depth, speed_mps: float):
    """``depth`` with each point moved along lidar +x by ``speed * azimuth / (2 pi * 10 Hz)`` (metres)."""
    pts = np.array(depth.points, dtype=np.float64)
    pts[..., 0] += speed_mps * np.arctan2(pts[..., 1], pts[..., 0]) / (2 * np.pi * 10.0)
    rng = np.linalg.norm(pts, axis=-1)
    valid = np.asarray(depth.valid)
    return dataclasses.replace(
        depth, points=pts, range_m=np.where(valid, rng, np.nan),
        directions=np.where(valid[..., None], pts / np.maximum(rng, 1e-9)[..., None], depth.directions))


def with_precision(pairs, transform):
    return [dataclasses.replace(p, precision_px=transform(p.precision_px)) for p in pairs]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--speeds", type=float, nargs="*", default=[0.0, -4.0, -8.0, -10.0, -12.0],
                    help="KITTI de-skew speeds to try, m/s along lidar +x (question 4)")
    args = ap.parse_args(argv)
    variants = {
        "app": lambda s: s,
        "unweighted": lambda s: None,
        "floor 1 px": lambda s: max(1.0 if s is None else s, 1.0),
        "floor 2 px": lambda s: max(1.0 if s is None else s, 2.0),
        "floor 3 px": lambda s: max(1.0 if s is None else s, 3.0),
    }
    independent_d2: dict[str, np.ndarray] = {}
    for scene, (scan, camera_file, size, ref) in SCENES.items():
        files = sorted(SESSIONS.glob(f"{scene}_run*.yaml"), key=lambda p: int(p.stem.rsplit("run", 1)[1]))
        if not scan.exists():
            print(f"{scene}: {scan} is missing; skipped")
            continue
        depth = load_scan(scan)
        camera = load_camera(camera_file, image_size=size) if size else load_camera(camera_file)
        T_ref = load_extrinsics_any(ref)
        print(f"\n## {scene}: {len(files)} sessions\n")
        table = {name: [] for name in [*variants, "cell sigma 1"]}
        d2s, d2_model, biases = [], [], []
        for f in files:
            pairs = load_pairs_yaml(f)
            fit = [p for p in pairs if not p.check]
            row = []
            for name, transform in variants.items():
                res = calibrate(with_precision(fit, transform), depth, camera)
                deg, cm, e = pose_error(res.T_camera_lidar, T_ref)
                table[name].append((deg, cm))
                if name == "app":
                    d2_model.append(float(e @ np.linalg.solve(res.covariance_6x6, e)))
                    alone = calibrate(fit, depth, camera, shared_ratio=0.0)  # the same pose, independent noise only
                    d2s.append(float(e @ np.linalg.solve(alone.covariance_6x6, e)))
                    row.append(f"{deg:.2f} deg / {cm:.1f} cm, d2 {d2s[-1]:.1f} (independent), {d2_model[-1]:.1f} "
                               f"(with the shared part); quality {alone.quality.status} -> {res.quality.status}")
                    first_reason = res.quality.reasons[0] if res.quality.reasons else ""
            res = calibrate(fit, depth, camera, cell_sigma=1.0)
            table["cell sigma 1"].append(pose_error(res.T_camera_lidar, T_ref)[:2])
            points, _, pixels = resolve_pairs(pairs, depth, camera)
            projected, _ = camera.project(transform_points(T_ref, points))
            err = np.asarray(pixels, dtype=np.float64) - projected
            biases.append(np.c_[err, np.linalg.norm(points, axis=1)])
            print(f"{f.name:26s} {len(fit):2d} pairs in the fit: {row[0]}\n{'':29s}first reason: {first_reason}")
        print("\nsolve variant        median deg  median cm   mean deg   mean cm")
        for name, vals in table.items():
            a = np.array(vals)
            print(f"{name:18s} {np.median(a[:, 0]):10.2f} {np.median(a[:, 1]):10.1f} {a[:, 0].mean():10.2f} "
                  f"{a[:, 1].mean():9.1f}")
        d2, dm = np.array(d2s), np.array(d2_model)
        independent_d2[scene] = d2
        for label, v in (("independent noise only", d2), (f"app, shared ratio {BY_EYE_SHARED_RATIO:g}", dm)):
            print(f"\nMahalanobis d^2 of the pose error ({label}): median {np.median(v):.1f} "
                  f"(honest: {CHI2_6_MEDIAN}): "
                  f"the stated sigma understates the error {np.sqrt(np.median(v) / CHI2_6_MEDIAN):.2f}x; true error "
                  f"inside the stated 95 % region in {int((v <= CHI2_6_95).sum())} of {len(v)} sessions")
        B = np.vstack(biases)
        size_px = np.linalg.norm(B[:, :2], axis=1)
        ok = size_px < MISTAKE_PX
        print(f"\npairs' error under the published pose: {len(B)} pairs, median {np.median(size_px):.2f} px; "
              f"{(~ok).sum()} over {MISTAKE_PX:g} px left out of the means below")
        for lo, hi in BANDS_M:
            s = ok & (B[:, 2] >= lo) & (B[:, 2] < hi)
            if s.any():
                du, dv = B[s, :2].mean(axis=0)
                print(f"  {lo:4g}-{hi:<4g} m: {s.sum():3d} pairs, mean du {du:+.2f} px, dv {dv:+.2f} px, "
                      f"median error {np.median(size_px[s]):.2f} px")
        if scene != "kitti":
            continue
        print("\nKITTI de-skew (question 4): speed, pairs' median error, mean du, sessions' median result")
        for v in args.speeds:
            moved = deskewed(depth, v)
            errs, results = [], []
            for f in files:
                pairs = load_pairs_yaml(f)
                points, _, pixels = resolve_pairs(pairs, moved, camera)
                projected, _ = camera.project(transform_points(T_ref, points))
                errs.append(np.asarray(pixels, dtype=np.float64) - projected)
                res = calibrate([p for p in pairs if not p.check], moved, camera)
                results.append(pose_error(res.T_camera_lidar, T_ref)[:2])
            E = np.vstack(errs)
            m = np.linalg.norm(E, axis=1)
            R = np.array(results)
            print(f"  v = {v:+5.1f} m/s: median {np.median(m):.2f} px, mean du {E[m < MISTAKE_PX, 0].mean():+.2f} px; "
                  f"result median {np.median(R[:, 0]):.2f} deg / {np.median(R[:, 1]):.1f} cm, "
                  f"within 0.5 deg and 10 cm: {int(((R[:, 0] <= 0.5) & (R[:, 1] <= 10)).sum())} of {len(R)}")
    if len(independent_d2) == len(SCENES):
        print("\n## The shared part's ratio (calib_core.solve.whiten.BY_EYE_SHARED_RATIO)\n")
        pooled = np.concatenate(list(independent_d2.values()))
        print(f"fit on both scenes pooled ({len(pooled)} sessions): median d^2 {np.median(pooled):.1f} -> ratio "
              f"{shared_ratio_fit(pooled):.2f} (in use: {BY_EYE_SHARED_RATIO:g})")
        for scene, d2 in independent_d2.items():
            ratio = shared_ratio_fit(d2)
            others = ", ".join(f"{o} median d^2 {np.median(v) / (1 + ratio):.1f}" for o, v in independent_d2.items()
                               if o != scene)
            print(f"fit on {scene} alone: ratio {ratio:.2f}; under it {others}")
    return 0


def shared_ratio_fit(d2_independent: np.ndarray) -> float:
    """The shared part's variance ratio that makes the median ``d^2`` honest: ``median d^2 / 5.348 - 1`` (>= 0).

    ``d2_independent``: the sessions' squared Mahalanobis distances under the independent noise's covariance.
    The median, not the mean (the maximum-likelihood fit of a variance factor): a session with a mistaken pair
    (d^2 near 200) would weigh on the mean as much as ten good ones.
    """
    return max(float(np.median(d2_independent)) / CHI2_6_MEDIAN - 1.0, 0.0)


if __name__ == "__main__":
    raise SystemExit(main())
