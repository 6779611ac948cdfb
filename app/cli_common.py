"""What the ``ba-calib`` sub-commands share: the sample scene, the scan options, the solve summary.

Below :mod:`app.cli` and its command modules (:mod:`app.cli_serve`,
:mod:`app.cli_shots`), which import it; it imports none of them.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Sequence


def default_sample_dir() -> Path:
    """The bundled sample scene; generated into the user cache when absent.

    An editable install finds ``sample_data/`` in the checkout.  A plain
    install has no checkout, so the sample is generated once (seed 0, the
    same scene) into ``~/.cache/ba-calib/sample``.
    """
    repo_sample = Path(__file__).resolve().parents[1] / "sample_data"
    if (repo_sample / "scan.npz").is_file():
        return repo_sample
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "ba-calib" / "sample"
    if not (cache / "scan.npz").is_file():
        from calib_core.synthetic import write_sample

        print(f"Generating the sample scene into {cache} (one time, about a minute) ...", flush=True)
        write_sample(cache, seed=0)
    return cache


# --- scan options shared by every command that reads a scan -----------------


def add_scan_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument("--scan", required=required, type=Path, help="scan file: .npz (native), .pcd, .ply, .bin (KITTI), .las/.laz, .npy")
    add_organize_args(p)
    p.add_argument(
        "--sensor-origin", type=float, nargs=3, metavar=("X", "Y", "Z"), default=None,
        help="scanner position in the file's frame (metres), for scans stored in a world frame",
    )
    p.add_argument("--bin-columns", type=int, default=None, metavar="N", help="float32 values per point of a .bin scan (KITTI 4, nuScenes 5; default: detected)")
    p.add_argument("--max-points", type=int, default=None, metavar="N", help="largest cloud (points or grid cells) a scan file may hold (default 5,000,000)")


def add_organize_args(p: argparse.ArgumentParser) -> None:
    """How an unorganized cloud becomes a depth matrix (``solve`` and ``serve`` take these without the other scan options)."""
    p.add_argument(
        "--organize",
        choices=["auto", "ring", "elevation", "firing", "spherical"],
        default="auto",
        help="how an unorganized cloud becomes a depth matrix (default: ring field if present, else the scan order "
        "if points are stored laser after laser, else --beams, else spherical)",
    )
    p.add_argument("--beams", type=int, default=None, help="number of beams, for clouds without a ring field")
    p.add_argument("--h-res-deg", type=float, default=None,
                   help="azimuth resolution in degrees: the spherical fallback's cells, the columns of the other layouts")
    p.add_argument("--v-res-deg", type=float, default=None, help="elevation resolution of the spherical fallback")


def add_bag_topic_args(p: argparse.ArgumentParser) -> None:
    """The topic choices of every command that reads frames of a bag (default: the bag's only topic of a type)."""
    p.add_argument("--cloud-topic", default=None, help="sensor_msgs/PointCloud2 topic")
    p.add_argument("--image-topic", default=None, help="sensor_msgs/Image or CompressedImage topic")
    p.add_argument("--camera-info-topic", default=None, help="sensor_msgs/CameraInfo topic")


def scan_options(args: argparse.Namespace) -> dict:
    opts: dict = {"organize": args.organize}
    for key in ("beams", "h_res_deg", "v_res_deg", "sensor_origin", "bin_columns", "max_points"):
        if getattr(args, key, None) is not None:
            opts[key] = getattr(args, key)
    return opts


def load_scan_from_args(args: argparse.Namespace):
    """The scan as a depth matrix; prints the one-line organisation report."""
    from calib_core.io.scan_readers import load_scan

    depth = load_scan(args.scan, **scan_options(args))
    report = depth.organize_report
    if report is not None:
        print(report.line(), flush=True)
    return depth


def format_summary(result, pairs_count: int, pair_ids: Sequence[int] | None = None) -> str:
    """The solve summary table (paper Table I layout) with the quality verdict, as text."""
    import numpy as np

    from calib_core.solve.quality import NO_ERROR_ESTIMATE, error_estimate_reason, pairs_in_fit
    from calib_core.transforms import rpy_deg_from_R, viewing_direction

    T = result.T_camera_lidar
    rpy = rpy_deg_from_R(T[:3, :3])
    n_out = len(result.outliers)
    quality = getattr(result, "quality", None)
    status = quality.status if quality is not None else "ok"
    n_check = len(getattr(result, "check_positions", []))
    extra = [f"{n_out} left out as outliers"] * bool(n_out) + [f"{n_check} check pairs not fitted"] * bool(n_check)
    lines = [
        f"Calibrated from {result.n_pairs - n_out} of {pairs_count} pairs ({', '.join(extra)}; cost: {result.cost_name})"
        if extra
        else f"Calibrated from {pairs_count} pairs (cost: {result.cost_name})",
        f"quality: {status.upper()}",
    ]
    if quality is not None:
        lines.extend(f"  - {r}" for r in quality.reasons)
    reasons = set(quality.reasons) if quality is not None else set()
    lines.extend(f"note: {w}" for w in result.warnings if w not in reasons)
    lines += ["", f"{'':14}{'value':>12}{'sigma':>10}"]
    for name, v, s in zip(("tx [m]", "ty [m]", "tz [m]"), T[:3, 3], result.sigma_translation_m):
        lines.append(f"{name:14}{v:12.4f}{s:10.4f}")
    for name, v, s in zip(("roll [deg]", "pitch [deg]", "yaw [deg]"), rpy, result.sigma_rpy_deg):
        lines.append(f"{name:14}{v:12.3f}{s:10.3f}")
    view = viewing_direction(T[:3, :3], np.asarray(result.covariance_6x6)[:3, :3])  # optical axis, lidar frame
    for name, v, s in zip(("view az [deg]", "view el [deg]", "view roll[deg]"), (view.azimuth_deg, view.elevation_deg,
                                                                           view.roll_deg), view.sigma_deg):
        lines.append(f"{name:14}{v:12.3f}{s:10.3f}")
    lines.append("")
    fit = "" if not n_out else " (pairs in the fit)"
    no_error = error_estimate_reason(pairs_in_fit(result))
    if no_error is not None:  # a near-exact fit is the likeliest outcome: its residuals are no error figure
        lines.append(f"reprojection error{fit}: {NO_ERROR_ESTIMATE} ({no_error})")
    elif np.isfinite(result.mean_px):
        lines.append(f"reprojection error{fit}: {result.mean_px:.3f} +/- {result.std_px:.3f} px, {result.mean_deg:.4f} +/- {result.std_deg:.4f} deg")
    else:
        lines.append(f"reprojection error{fit}: {result.mean_deg:.4f} +/- {result.std_deg:.4f} deg")
    lines.append("")
    lines.append(f"{'pair':>4}{'error [px]':>12}{'error [deg]':>13}")
    outliers = set(result.outliers)
    ids = list(pair_ids) if pair_ids is not None else list(range(len(result.residual_deg)))
    rows = getattr(result, "pair_positions", None) or list(range(len(result.residual_deg)))
    for i, (px, deg) in enumerate(zip(result.residual_px, result.residual_deg)):
        flag = "  <- outlier, left out of the fit" if i in outliers else ""
        px_s = f"{px:12.3f}" if np.isfinite(px) else f"{'-':>12}"
        lines.append(f"{ids[rows[i]]:4d}{px_s}{deg:13.4f}{flag}")
    for pos, px, deg in zip(getattr(result, "check_positions", []), getattr(result, "check_residual_px", []),
                            getattr(result, "check_residual_deg", [])):
        px_s = f"{px:12.3f}" if np.isfinite(px) else f"{'-':>12}"
        lines.append(f"{ids[pos]:4d}{px_s}{deg:13.4f}  <- check pair (not in the fit)")
    lines.append("")
    lines.append("T_camera_lidar (X_camera = T @ X_lidar):")
    lines.extend("  " + " ".join(f"{x:12.6f}" for x in row) for row in T)
    return "\n".join(lines)
