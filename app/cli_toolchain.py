"""``ba-calib export`` and ``ba-calib bag``: extrinsics in robotics formats, scenes out of ROS bags."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from calib_core.errors import CalibError


def _check_output_file(path: Path) -> None:
    """Refuse to replace anything but a regular file (a folder, a device, a fifo)."""
    if os.path.lexists(path) and not path.is_file():
        raise CalibError(f"{path}: exists and is not a regular file; not replacing it")


def cmd_export(args: argparse.Namespace) -> int:
    from calib_core.io.atomic import write_bytes_atomic
    from calib_core.io.extrinsic_formats import export_extrinsics, read_extrinsics_any

    T = read_extrinsics_any(args.extrinsics).T_camera_lidar
    text = export_extrinsics(T, args.format, args.parent_frame, args.child_frame, lidar_frame=args.lidar_frame)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    _check_output_file(args.output)
    write_bytes_atomic(args.output, text.encode("utf-8"))
    print(f"wrote {args.output} ({args.format})", file=sys.stderr)
    return 0


def cmd_bag_info(args: argparse.Namespace) -> int:
    import math

    from calib_core.io.bags import bag_info

    info = bag_info(args.bag)
    print(f"{info.path}: {info.kind}, {info.duration_s:.3f} s, {sum(t.count for t in info.topics)} messages")
    width = max([len(t.name) for t in info.topics] + [5])
    print(f"{'topic':{width}}  {'type':34} {'count':>7} {'rate [Hz]':>10}")
    for t in info.topics:
        rate = f"{t.rate_hz:10.2f}" if math.isfinite(t.rate_hz) else f"{'-':>10}"
        print(f"{t.name:{width}}  {t.msgtype:34} {t.count:7d} {rate}")
    return 0


def cmd_bag_extract(args: argparse.Namespace) -> int:
    from calib_core.io.bags import read_bag_scene, write_bag_scene

    scene = read_bag_scene(
        args.bag, args.cloud_topic, args.image_topic, args.camera_info_topic, time_s=args.time, index=args.index
    )
    paths = write_bag_scene(scene, args.output)
    for note in scene.notes:
        print(note)
    print(
        f"cloud {scene.cloud_topic} #{scene.cloud_index} ({len(scene.cloud.xyz)} points, frame {scene.lidar_frame or '?'}) "
        f"at {scene.cloud_time_s:.6f} s"
    )
    print(
        f"image {scene.image_topic} at {scene.image_time_s:.6f} s (frame {scene.camera_frame or '?'}): "
        f"gap {1000 * scene.gap_s:+.3f} ms"
    )
    if scene.camera is None:
        print("no camera info: give the camera file yourself (--camera)")
    for what, path in paths.items():
        print(f"wrote {path} ({what})")
    return 0
