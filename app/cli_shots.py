"""``solve`` and ``propose`` over several shots (``--shot SCAN PAIRS``, repeated): the CLI side of
:mod:`calib_core.shots`.  No maths here."""

from __future__ import annotations

import argparse
from pathlib import Path

from calib_core.errors import CalibError

from .cli_common import add_bag_topic_args


def add_shot_args(p: argparse.ArgumentParser, *, images: bool = False) -> None:
    """``--shot SCAN PAIRS`` (repeatable) and, for ``propose``, ``--image-for-shot K IMAGE``."""
    p.add_argument(
        "--shot", nargs=2, action="append", type=Path, metavar=("SCAN", "PAIRS"), default=None,
        help="a shot: a scan and the pairs picked in it (repeat for several shots of one rig; "
        "replaces --scan/--pairs; shots are numbered from 0 in this order)",
    )
    if images:
        p.add_argument(
            "--image-for-shot", nargs=2, action="append", metavar=("K", "IMAGE"), default=None,
            help="the photo of shot K (0-based): its proposals need an image corner near their pixel",
        )


def check_shot_form(args: argparse.Namespace, command: str) -> bool:
    """True for the ``--shot`` form; one clear error when the two forms are mixed or neither is given."""
    shots = getattr(args, "shot", None)
    if shots:
        mixed = [opt for opt, key in (("--scan", "scan"), ("--pairs", "pairs"), ("--image", "image"))
                 if getattr(args, key, None) is not None]
        if mixed:
            raise CalibError(f"{command}: give either --shot SCAN PAIRS (repeatable) or {mixed[0]}, not both")
        return True
    if getattr(args, "pairs", None) is None:
        raise CalibError(f"{command}: give --pairs P (with --scan S), or one --shot SCAN PAIRS per shot")
    if command == "propose" and args.scan is None:
        raise CalibError("propose: give --scan S with --pairs P, or one --shot SCAN PAIRS per shot")
    if getattr(args, "image_for_shot", None):
        raise CalibError(f"{command}: --image-for-shot goes with --shot; use --image for one scan")
    return False


def load_shots(args: argparse.Namespace, camera):
    """Each ``--shot``'s scan and pairs, resolved (the organisation report of each scan is printed)."""
    from calib_core.io.scan_readers import load_scan
    from calib_core.pairs import load_pairs_yaml
    from calib_core.shots import Shot

    from .cli_common import scan_options

    shots = []
    for k, (scan_path, pairs_path) in enumerate(args.shot):
        pairs = load_pairs_yaml(pairs_path, max_pairs=getattr(args, "max_pairs", None) or 1_000)
        depth = load_scan(scan_path, **scan_options(args))
        report = depth.organize_report
        if report is not None:
            print(f"shot {k}: {report.line()}", flush=True)
        try:
            shots.append(Shot.from_pairs(pairs, depth, camera, name=f"{scan_path} + {pairs_path}"))
        except CalibError as exc:  # name the shot: the same pair number exists in every shot
            raise CalibError(f"shot {k} ({pairs_path}): {exc}") from None
    return shots


def cmd_solve_shots(args: argparse.Namespace):
    """``solve --shot SCAN PAIRS ...``: the joint solve, its per-shot report and the extrinsics YAML.

    Returns the result's :class:`calib_core.solve.Quality` (the caller turns ``unreliable`` into exit code 3).
    """
    from calib_core.io.atomic import write_yaml_atomic
    from calib_core.shots import format_shots, shots_extrinsics_document, solve_shots

    from .cli_common import format_summary
    from .cli_guard import load_camera_from_args

    camera = load_camera_from_args(args)
    shots = load_shots(args, camera)
    options = {}
    if args.initial_extrinsics is not None:
        from calib_core.io.extrinsic_formats import load_extrinsics_any

        options["initial_T_camera_lidar"] = load_extrinsics_any(args.initial_extrinsics)
    solved = solve_shots(shots, camera, cost=args.cost, **options)
    doc, notes = shots_extrinsics_document(solved, shots, camera, base_dir=args.output.parent)
    write_yaml_atomic(args.output, doc)  # before printing: a closed pipe must not lose the result
    flat_ids = [i for ids in solved.pair_ids for i in ids]
    print(f"{len(shots)} shot{'s' if len(shots) > 1 else ''}, one T_camera_lidar")
    print(format_summary(solved.result, len(flat_ids), flat_ids))
    print("")
    print(format_shots(solved))
    for note in notes:
        print(f"note: {note}")
    print(f"\nwrote {args.output}")
    return solved.result.quality


def cmd_propose_shots(args: argparse.Namespace) -> int:
    """``propose --shot SCAN PAIRS ...``: proposals over all shots, each with its ``shot``."""
    from calib_core.io.atomic import write_yaml_atomic
    from calib_core.io.extrinsics import load_extrinsics_yaml
    from calib_core.io.images import load_image_rgb
    from calib_core.shots import propose_shots, shot_proposals_to_dict

    from .cli_guard import load_camera_from_args

    camera = load_camera_from_args(args)
    shots = load_shots(args, camera)
    images = {}
    for k_text, image_path in args.image_for_shot or []:
        try:
            k = int(k_text)
        except ValueError:
            raise CalibError(f"--image-for-shot: expected a shot number, got {k_text!r}") from None
        if not 0 <= k < len(shots):
            raise CalibError(f"--image-for-shot {k}: there are {len(shots)} shots, numbered 0 to {len(shots) - 1}")
        images[k] = load_image_rgb(image_path)
    T0 = load_extrinsics_yaml(args.extrinsics)["T_camera_lidar"] if args.extrinsics is not None else None
    proposals, state = propose_shots(shots, camera, args.n, T_initial=T0, images=images,
                                     click_sigma_px=args.click_sigma)
    write_yaml_atomic(args.output, shot_proposals_to_dict(proposals, state, [s.name for s in shots]))
    print(f"pose from {state.source} ({state.n_pairs} pairs in {len(shots)} shots); {len(proposals)} proposals")
    for i, sp in enumerate(proposals):
        p = sp.proposal
        major, minor = p.ellipse_sigma_px()
        print(f"{i:3d}  shot {sp.shot}  cell {p.laser_rc}  pixel ({p.pixel[0]:7.1f}, {p.pixel[1]:7.1f})  "
              f"1-sigma {major:5.2f} x {minor:5.2f} px  gain {p.gain:6.3f}  {p.kind}")
    print(f"wrote {args.output}")
    return 0


def add_bag_frames_parser(bag_sub) -> None:
    """``bag frames BAG (--frames N | --time T ... | --index I ...) -o DIR``: several frames of a bag as shots."""
    q = bag_sub.add_parser(
        "frames",
        help="write several frames as shots (scan + image each), chosen spread over the bag and still, or by hand",
        description="Chooses frames (a cloud and the image nearest it in time) and writes each into "
        "DIR/frame_NNNNN/ (scan.pcd, image.png, camera.yaml, initial_extrinsics.yaml as `bag extract` does). "
        "--frames N spreads N frames over the bag, each the stillest of its part: the least motion of the rig "
        "between the cloud's and the image's stamps when the bag has /tf or odometry of the rig, else the "
        "smallest stamp gap. Prints one line per shot: 'shot K: SCAN IMAGE STAMP ...'.",
    )
    q.add_argument("bag", type=Path, help="a .bag file, or a ROS 2 bag folder (or a file in it)")
    add_bag_topic_args(q)
    which = q.add_mutually_exclusive_group(required=True)
    which.add_argument("--frames", type=int, default=None, help="this many frames, spread over the bag and still")
    which.add_argument("--time", type=float, nargs="+", default=None,
                       help="the clouds nearest these times (seconds after the bag's start)")
    which.add_argument("--index", type=int, nargs="+", default=None, help="the clouds with these 0-based indices")
    q.add_argument("-o", "--output", required=True, type=Path, help="output folder (one sub-folder per frame)")
    q.set_defaults(func=cmd_bag_frames)


def cmd_bag_frames(args: argparse.Namespace) -> int:
    """Write the chosen frames; print the notes, then one line per shot (scan, image, stamp, quality of the frame)."""
    from calib_core.io.bag_frames import shots_from_bag

    shots = shots_from_bag(args.bag, frames=args.frames, times=args.time, indices=args.index, out_dir=args.output,
                           cloud_topic=args.cloud_topic, image_topic=args.image_topic,
                           camera_info_topic=args.camera_info_topic)
    for note in shots.notes:
        print(note)
    for k, shot in enumerate(shots):
        print(f"shot {k}: {shot.scan} {shot.image} {shot.stamp_s:.6f}  {shot.line()}")
        for note in shot.notes:
            print(f"  {note}")
    print(f"camera: {shots.camera}" if shots.camera is not None else "no camera info: give the camera file yourself (--camera)")
    if shots.initial_extrinsics is not None:
        print(f"initial extrinsics (/tf_static): {shots.initial_extrinsics}")
    return 0
