"""``ba-calib serve``: the browser app on a scene, on several shots of one rig, the bundled sample or a ROS bag's frame."""

from __future__ import annotations

import argparse
from pathlib import Path

from calib_core.errors import CalibError


def cmd_serve(args: argparse.Namespace) -> int:
    from app.serving import serve

    from .cli_common import default_sample_dir, scan_options
    from .cli_guard import camera_image_size

    if getattr(args, "shot", None):
        return _serve_shots(args)
    several = [o for o, v in (("--time", args.time), ("--index", args.index)) if v is not None and len(v) > 1]
    if getattr(args, "bag", None) is not None and (args.frames is not None or several):
        return _serve_bag_shots(args)
    if args.frames is not None or several:
        raise CalibError(f"{', '.join(several) or '--frames'} choose(s) frames of a bag: give --bag too")
    if getattr(args, "bag", None) is not None:
        from app.serving import BagSource

        if args.scan is not None or args.image is not None:
            raise CalibError("serve --bag takes the scan and the image from the bag: leave out --scan and --image")
        source = BagSource(args.bag, cloud_topic=args.cloud_topic, image_topic=args.image_topic,
                           camera_info_topic=args.camera_info_topic, index=None if args.index is None else args.index[0],
                           time_s=None if args.time is None else args.time[0],
                           camera=args.camera, frames_dir=args.frames_dir, session=args.session)
        serve(None, None, None, output_path=args.output, host=args.host, port=args.port,
              scan_options=scan_options(args), image_size=tuple(args.image_size) if args.image_size else None,
              initial_extrinsics_path=args.initial_extrinsics, bag=source, kitti_camera=args.kitti_camera)
        return 0
    bag_only = [o for o, v in (("--cloud-topic", args.cloud_topic), ("--image-topic", args.image_topic),
                               ("--camera-info-topic", args.camera_info_topic), ("--index", args.index),
                               ("--time", args.time), ("--frames-dir", args.frames_dir)) if v is not None]
    if bag_only:
        raise CalibError(f"{', '.join(bag_only)} choose(s) what to read from a bag: give --bag too")
    if args.scan is None and args.image is None and args.camera is None:
        sample = default_sample_dir()
        args.scan, args.image, args.camera = sample / "scan.npz", sample / "image.png", sample / "camera.yaml"
        if args.session is None:
            args.session = Path.cwd() / "ba-calib-sample-session.yaml"
    missing = [n for n in ("scan", "image", "camera") if getattr(args, n) is None]
    if missing:
        raise CalibError("serve needs --scan, --image and --camera (or none of them, for the sample); missing: " + ", ".join("--" + m for m in missing))
    serve(
        args.scan,
        args.image,
        args.camera,
        session_path=args.session,
        output_path=args.output,
        host=args.host,
        port=args.port,
        scan_options=scan_options(args),
        image_size=camera_image_size(args),  # a KITTI calib file states none: the image's
        initial_extrinsics_path=args.initial_extrinsics,
        kitti_camera=args.kitti_camera,
    )
    return 0


def _serve_bag_shots(args: argparse.Namespace) -> int:
    """``serve --bag BAG --frames N`` (or several ``--time`` / ``--index``): the frames written as shots
    (:func:`calib_core.io.bag_frames.shots_from_bag`), then served as one session of several shots."""
    from calib_core.io.bag_frames import default_frames_dir, shots_from_bag

    from app.serving import serve

    from .cli_common import scan_options

    if args.scan is not None or args.image is not None or args.shot:
        raise CalibError("serve --bag takes the scans and the images from the bag: leave out --scan, --image and --shot")
    by_hand = None if args.frames is not None else ("times" if args.time is not None else "indices")
    if args.frames is not None and (args.time is not None or args.index is not None):
        raise CalibError("give --frames N, or the frames by hand with --time or --index, not both")
    session = args.session if args.session is not None else (
        Path.cwd() / f"{Path(args.bag).absolute().name}.ba-calib-session.yaml")
    source = dict(bag=args.bag, out_dir=args.frames_dir or default_frames_dir(args.bag, session),
                  cloud_topic=args.cloud_topic, image_topic=args.image_topic, camera_info_topic=args.camera_info_topic)
    shots = shots_from_bag(frames=args.frames, times=args.time if by_hand == "times" else None,
                           indices=args.index if by_hand == "indices" else None, **source)
    for note in shots.notes:
        print(f"ba-calib: {note}", flush=True)
    for k, shot in enumerate(shots):
        print(f"ba-calib: shot {k}: {shot.line()}", flush=True)
    camera = args.camera if args.camera is not None else shots.camera
    if camera is None:
        raise CalibError(f"{args.bag}: no CameraInfo topic; give the camera file with --camera")
    serve(None, None, camera, shots=[(shot.scan, shot.image) for shot in shots], shot_bag=source, session_path=session,
          output_path=args.output, host=args.host, port=args.port, scan_options=scan_options(args),
          image_size=tuple(args.image_size) if args.image_size else None,
          initial_extrinsics_path=args.initial_extrinsics or shots.initial_extrinsics, kitti_camera=args.kitti_camera)
    return 0


def _serve_shots(args: argparse.Namespace) -> int:
    """``serve --camera C --shot SCAN IMAGE [--shot ...]``: the files checked first, one line per problem."""
    from app.serving import serve

    from .cli_common import scan_options
    from .cli_guard import camera_image_size, check_image_fits_camera, load_camera_from_args

    if args.bag is not None or args.scan is not None or args.image is not None:
        raise CalibError("give the shots with --shot SCAN IMAGE only: leave out --scan, --image and --bag")
    if args.camera is None:
        raise CalibError("serve --shot needs --camera: the one camera of every shot")
    first = argparse.Namespace(**{**vars(args), "image": args.shot[0][1]})  # a KITTI calib file takes its size
    camera = load_camera_from_args(argparse.Namespace(**{**vars(first), "image": None}))
    for k, (scan, image) in enumerate(args.shot):
        for what, path in (("scan", scan), ("image", image)):
            if not path.is_file():
                raise CalibError(f"shot {k}: the {what} {path} does not exist")
        try:
            check_image_fits_camera(image, camera, args)
        except CalibError as exc:
            raise CalibError(f"shot {k}: {exc}") from None
    serve(None, None, args.camera, shots=[tuple(s) for s in args.shot], session_path=args.session,
          output_path=args.output, host=args.host, port=args.port, scan_options=scan_options(args),
          image_size=camera_image_size(first), initial_extrinsics_path=args.initial_extrinsics,
          kitti_camera=args.kitti_camera)
    return 0


def add_serve_parser(sub) -> None:
    """The ``serve`` sub-command's options (``sub``: the parser's sub-parsers)."""
    from .cli_common import add_organize_args
    from .cli_guard import add_camera_args

    p = sub.add_parser("serve", help="open the browser app on a scene",
                       description="Open the browser app on a scan, its camera image and the camera model "
                                   "(all three, or none for the bundled sample).")
    p.add_argument("--scan", type=Path,
                   help="scan file: .npz (native), .pcd, .ply, .bin (KITTI, nuScenes, SUN RGB-D), .las/.laz, .npy")
    p.add_argument("--image", type=Path, help="the camera image taken with the scan (PNG, JPEG, ...)")
    p.add_argument("--shot", type=Path, nargs=2, action="append", metavar=("SCAN", "IMAGE"), default=None,
                   help="a scan and the photo taken with it; repeat for several shots of one rig (one camera, one "
                        "T_camera_lidar): every shot's pairs are solved together, the page switches shots")
    add_camera_args(p, required=False)
    add_organize_args(p)
    p.add_argument("--session", type=Path, default=None, help="pairs session file, saved after every change and restored on start")
    p.add_argument("--output", type=Path, default=None, help="where Export also writes the extrinsics YAML")
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8080)
    p.add_argument("--initial-extrinsics", type=Path, default=None,
                   help="start from this extrinsic (any format 'export' writes, or a ba-calib YAML)")
    g = p.add_argument_group("ROS bags (no ROS needed)")
    g.add_argument("--bag", type=Path, default=None,
                   help="serve a frame of this .bag / ROS 2 bag folder (the page can switch frames)")
    g.add_argument("--cloud-topic", default=None, help="sensor_msgs/PointCloud2 topic (default: the only one)")
    g.add_argument("--image-topic", default=None, help="sensor_msgs/Image or CompressedImage topic (default: the only one)")
    g.add_argument("--camera-info-topic", default=None, help="sensor_msgs/CameraInfo topic (default: the only one; --camera overrides)")
    which = g.add_mutually_exclusive_group()
    which.add_argument("--index", type=int, nargs="+", default=None,
                       help="the cloud with this 0-based index (default 0); several: those frames as shots")
    which.add_argument("--time", type=float, nargs="+", default=None,
                       help="the cloud nearest this many seconds after the bag's start; several: those frames as shots")
    g.add_argument("--frames", type=int, default=None,
                   help="serve N frames as shots of one session, spread over the bag and still (ba-calib bag frames)")
    g.add_argument("--frames-dir", type=Path, default=None,
                   help="where frames are extracted (default ./<bag name>.ba-calib-frames)")
    p.set_defaults(func=cmd_serve)
