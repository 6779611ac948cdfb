"""The ``ba-calib`` command.

``ba-calib`` alone serves the bundled sample scene in the browser app; the
sub-commands run the same calibration headless.  Every user error prints one
line, ``error: <what is wrong>``, and exits with code 2.  ``solve`` exits with
code 3 when the calibration's quality status is ``unreliable`` (the file is
still written, and the reasons are printed).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from calib_core import __version__, compile_events
from calib_core.errors import CalibError

from .cli_guard import (  # noqa: F401  (with_default_command, load_camera_from_args: public, used elsewhere)
    EXIT_USAGE,
    Noise,
    OneLineParser,
    add_camera_args,
    check_args,
    check_serve_files,
    error_line,
    load_camera_from_args,
    remove_stale_temp_files,
    with_default_command,
)
from .cli_common import (  # noqa: F401  (format_summary: public here too)
    add_bag_topic_args,
    add_organize_args,
    add_scan_args,
    format_summary,
    load_scan_from_args,
)
from .cli_serve import add_serve_parser
from .cli_shots import add_bag_frames_parser, add_shot_args, check_shot_form, cmd_propose_shots, cmd_solve_shots
from .cli_toolchain import cmd_bag_extract, cmd_bag_info, cmd_export

#: ``solve`` wrote the file but the calibration's quality status is ``unreliable``.
EXIT_UNRELIABLE = 3
#: Said once when a command has to compile a kernel (numba's disk cache is empty after an install).
COMPILE_NOTICE = ("ba-calib: compiling the numba kernels on first use (once after an install or an update: seconds "
                  "each, up to about half a minute of CPU for all; later runs load them from the cache) ...")


@dataclass(frozen=True)
class Outcome:
    """A command's exit code with one line for stderr, printed after any library warnings were collected."""

    code: int
    stderr_line: str


# --- commands ----------------------------------------------------------------


def _exit_for(quality) -> int | Outcome:
    """0, or :data:`EXIT_UNRELIABLE` with its reason when the solve's quality is unreliable."""
    if quality.status == "unreliable":
        return Outcome(EXIT_UNRELIABLE, f"unreliable: {quality.reasons[0]} (exit code {EXIT_UNRELIABLE})")
    return 0


def cmd_solve(args: argparse.Namespace) -> int | Outcome:
    if check_shot_form(args, "solve"):
        return _exit_for(cmd_solve_shots(args))
    from calib_core.io.atomic import write_yaml_atomic
    from calib_core.verify import extrinsics_document
    from calib_core.pairs import load_pairs_yaml
    from calib_core.solve.calibrate import calibrate, pair_ids_and_sigmas

    pairs = load_pairs_yaml(args.pairs, max_pairs=args.max_pairs)
    camera = load_camera_from_args(args)
    needs_scan = any(p.laser_rc is not None for p in pairs)
    if needs_scan and args.scan is None:
        raise CalibError(f"{args.pairs}: pairs name depth-matrix cells (laser_rc); give the scan with --scan")
    depth = load_scan_from_args(args) if args.scan is not None else None
    initial = None
    if args.initial_extrinsics is not None:
        from calib_core.io.extrinsic_formats import load_extrinsics_any

        initial = load_extrinsics_any(args.initial_extrinsics, kitti_camera=args.kitti_camera)
    result = calibrate(pairs, depth, camera, cost=args.cost, initial_T_camera_lidar=initial)
    ids, _ = pair_ids_and_sigmas(pairs)
    doc, notes = extrinsics_document(result, pairs, depth, camera, base_dir=args.output.parent)
    # Save before printing: a closed pipe (| head) must not lose the result.  Outliers stay in the pairs block.
    write_yaml_atomic(args.output, doc)
    print(format_summary(result, len(pairs), ids))
    for note in notes:
        print(f"note: {note}")
    print(f"\nwrote {args.output}")
    return _exit_for(result.quality)


def cmd_propose(args: argparse.Namespace) -> int:
    if check_shot_form(args, "propose"):
        return cmd_propose_shots(args)
    from calib_core.guide.evidence import ProposalScreen
    from calib_core.guide.session import GuidedSession
    from calib_core.guide.propose import save_proposals_yaml
    from calib_core.io.extrinsics import load_extrinsics_yaml
    from calib_core.io.images import load_image_rgb
    from calib_core.pairs import load_pairs_yaml

    depth = load_scan_from_args(args)
    camera = load_camera_from_args(args)
    pairs = load_pairs_yaml(args.pairs)
    T0 = load_extrinsics_yaml(args.extrinsics)["T_camera_lidar"] if args.extrinsics is not None else None
    image = load_image_rgb(args.image) if args.image is not None else None
    screen = ProposalScreen(max_ellipse_px=args.max_ellipse_px)
    session = GuidedSession(depth, camera, pairs, T_initial=T0, image=image, click_sigma_px=args.click_sigma,
                            screen=screen)
    proposals = session.proposals(args.n)
    save_proposals_yaml(args.output, proposals, session.state)
    print(f"pose from {session.state.source} ({session.state.n_pairs} pairs); "
          f"{len(session.candidates)} candidate cells, {len(proposals)} proposals")
    for i, p in enumerate(proposals):
        major, minor = p.ellipse_sigma_px()
        print(f"{i:3d}  cell {p.laser_rc}  pixel ({p.pixel[0]:7.1f}, {p.pixel[1]:7.1f})  "
              f"1-sigma {major:5.2f} x {minor:5.2f} px  gain {p.gain:6.3f}  {p.kind}")
    if not proposals:
        print(f"no proposal: {proposals.reason}")
    print(f"wrote {args.output}")
    return 0


def cmd_ba_images(args: argparse.Namespace) -> int:
    from calib_core.bearing_angle import BA_DIRECTIONS, ba_to_display, bearing_angle_images
    from calib_core.io.images import save_image_rgb

    depth = load_scan_from_args(args)
    images = bearing_angle_images(depth)
    if args.output.exists() and not args.output.is_dir():
        raise CalibError(f"{args.output}: exists and is not a folder; -o names the folder for the four PNGs")
    args.output.mkdir(parents=True, exist_ok=True)
    for name in BA_DIRECTIONS:
        out = args.output / f"ba_{name}.png"
        save_image_rgb(out, ba_to_display(images[name]))
        print(f"wrote {out}")
    h, w = depth.shape
    print(f"depth matrix {h} x {w}, {int(depth.valid.sum())} valid cells ({100.0 * depth.valid.mean():.1f} %)")
    return 0


def cmd_colorize(args: argparse.Namespace) -> int:
    from calib_core.io.extrinsics import load_extrinsics_yaml
    from calib_core.io.images import load_image_rgb
    from calib_core.overlays import export_colored_scan

    # Small files first: a mistake in one of them is reported before the scan is loaded.
    T = load_extrinsics_yaml(args.extrinsics)["T_camera_lidar"]
    camera = load_camera_from_args(args)
    image = load_image_rgb(args.image)
    depth = load_scan_from_args(args)
    coloured, n = export_colored_scan(args.output, depth, image, camera, T, occlusion=not args.no_occlusion)
    print(f"coloured {coloured} of {n} points; wrote {args.output}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from calib_core.io.extrinsic_formats import load_extrinsics_any
    from calib_core.render import check_render_path, render_from_camera, shade_render, write_render

    check_render_path(args.output)
    T = load_extrinsics_any(args.extrinsics)
    camera = load_camera_from_args(args)
    depth = load_scan_from_args(args)
    ba = None
    if args.mode == "ba":
        from calib_core.bearing_angle import bearing_angle_images

        ba = bearing_angle_images(depth, directions=(args.ba_direction,))[args.ba_direction]
    render = render_from_camera(depth, camera, T)
    rgba = shade_render(render, depth, args.mode, ba_image=ba) if args.output.suffix.lower() == ".png" else None
    write_render(args.output, render, rgba)
    shown = int(render.has_return.sum())
    print(f"{shown} of {render.range_m.size} pixels show a return; wrote {args.output}")
    return 0


def cmd_sample(args: argparse.Namespace) -> int:
    import time

    from calib_core.synthetic import write_sample

    if args.output.exists() and not args.output.is_dir():
        raise CalibError(f"{args.output}: exists and is not a folder; -o names the folder for the sample scene")
    t0 = time.perf_counter()
    print(f"Generating the synthetic scene (seed {args.seed}) into {args.output} ...", flush=True)
    write_sample(args.output, seed=args.seed)
    print(f"done in {time.perf_counter() - t0:.1f} s")
    for f in sorted(args.output.iterdir()):
        print(f"  {f.name:20} {f.stat().st_size / 1024:8.1f} KiB")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="ba-calib",
        description="Targetless camera / 3D-lidar extrinsic calibration with Bearing Angle images. "
        "With no command, runs 'serve' (the bundled sample scene at http://127.0.0.1:8080 unless "
        "--scan/--image/--camera are given; --host and --port work as for serve).",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    parser.add_argument("--version", action="version", version=f"ba-calib {__version__}")
    sub = parser.add_subparsers(dest="command")

    add_serve_parser(sub)

    p = sub.add_parser(
        "solve",
        help="calibrate from a pairs file and print the summary",
        description="Calibrate from a pairs file.  Exit codes: 0 solved (quality ok or warning), 2 bad input "
        "(one 'error:' line), 3 solved but the quality status is unreliable (the file is still written).",
    )
    p.add_argument("--scan", type=Path, default=None, help="scan file (needed when pairs use laser_rc)")
    add_organize_args(p)
    add_camera_args(p, required=True)
    p.add_argument("--pairs", type=Path, default=None, help="pairs YAML (one shot; or give --shot)")
    add_shot_args(p)
    p.add_argument("--max-pairs", type=int, default=1_000, help="refuse pairs files with more pairs than this (default 1000)")
    p.add_argument(
        "--cost",
        choices=["angular", "geodesic", "pixel"],
        default="angular",
        help="angular = paper eq. 7 whitened by the camera (default), geodesic = eq. 7 as printed, pixel = eq. 6",
    )
    p.add_argument(
        "--initial-extrinsics", type=Path, default=None,
        help="start from this extrinsic (ba-calib YAML, TF, URDF, Autoware, OpenCalib, dvlc, KITTI or a 4x4 with its direction)",
    )  # fmt: skip
    p.add_argument("-o", "--output", required=True, type=Path, help="extrinsics YAML to write")
    p.set_defaults(func=cmd_solve)

    p = sub.add_parser("propose", help="propose the next pairs to click (guided picking), best first")
    add_scan_args(p, required=False)
    add_camera_args(p, required=True)
    p.add_argument("--pairs", type=Path, default=None, help="pairs so far (>= 4, or give --extrinsics; or give --shot)")
    add_shot_args(p, images=True)
    p.add_argument("--extrinsics", type=Path, default=None, help="initial extrinsics YAML (imported calibration)")
    p.add_argument("--image", type=Path, default=None, help="camera image: propose only cells with an image corner near their pixel")
    p.add_argument("-n", type=int, default=20, help="number of proposals (default 20)")
    p.add_argument("--click-sigma", type=float, default=0.3, help="click noise of a guided pair, px (default 0.3)")
    p.add_argument("--max-ellipse-px", type=float, default=40.0,
                   help="largest 3-sigma radius of a proposal, px (the loupe's half side; default 40)")
    p.add_argument("-o", "--output", required=True, type=Path, help="proposals YAML to write")
    p.set_defaults(func=cmd_propose)

    p = sub.add_parser("ba-images", help="write the four Bearing Angle images as PNG")
    add_scan_args(p)
    p.add_argument("-o", "--output", required=True, type=Path, help="output folder")
    p.set_defaults(func=cmd_ba_images)

    p = sub.add_parser("colorize", help="colour the scan from the image and write a PLY")
    add_scan_args(p)
    p.add_argument("--image", required=True, type=Path)
    add_camera_args(p, required=True)
    p.add_argument("--extrinsics", required=True, type=Path)
    p.add_argument("--no-occlusion", action="store_true", help="skip the depth test (colours occluded points too)")
    p.add_argument("-o", "--output", required=True, type=Path)
    p.set_defaults(func=cmd_colorize)

    p = sub.add_parser("render", help="render the scan from the camera's viewpoint (PNG picture or NPZ arrays)")
    add_scan_args(p)
    add_camera_args(p, required=True)
    p.add_argument("--extrinsics", required=True, type=Path, help="T_camera_lidar: ba-calib YAML, KITTI calib txt or any 'export' format")
    p.add_argument("--mode", choices=["range", "intensity", "ba"], default="range", help="shading of the PNG (default range)")
    p.add_argument("--ba-direction", choices=["horizontal", "vertical", "diag_pos45", "diag_neg45"], default="horizontal",
                   help="BA image of --mode ba (default horizontal)")
    p.add_argument("-o", "--output", required=True, type=Path, help="view.png (shaded RGBA) or view.npz (range_m, cell_rc, camera_depth_m)")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("sample", help="generate a synthetic scene with ground truth")
    p.add_argument("-o", "--output", required=True, type=Path)
    p.add_argument("--seed", type=int, default=0, help="changes the layout and the ground truth")
    p.set_defaults(func=cmd_sample)

    from calib_core.io.extrinsic_formats import FORMATS

    p = sub.add_parser(
        "export",
        help="write the extrinsics for ROS/URDF/Autoware/OpenCalib/KITTI/... (direction stated in the file)",
        description="Convert an extrinsics file (ba-calib YAML or any supported format) to FORMAT. "
        "--parent-frame and --child-frame name the two sensors' frames, in either order: TF, URDF, Autoware "
        "and matrix hold T_parent_child, which maps child points into the parent frame (the default, "
        "parent lidar / child camera, gives the inverse of T_camera_lidar). KITTI's Tr_velo_to_cam and "
        "OpenCalib's matrix are T_camera_lidar; dvlc's T_lidar_camera its inverse. Formats: "
        + "; ".join(f"{f.name}: {f.description}" for f in FORMATS.values()),
    )
    p.add_argument("extrinsics", type=Path, help="extrinsics file (ba-calib YAML, or any --format below)")
    p.add_argument("--format", required=True, choices=list(FORMATS), help="output format")
    p.add_argument("--parent-frame", default="lidar", help="parent frame name (default: lidar)")
    p.add_argument("--child-frame", default="camera", help="child frame name (default: camera)")
    p.add_argument("--lidar-frame", default=None, help="which of the two frames is the lidar, when their names do not tell")
    p.add_argument("-o", "--output", type=Path, default=None, help="output file (default: standard output)")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("bag", help="read ROS 1 .bag / ROS 2 .db3 or .mcap bags (no ROS needed)")
    bag_sub = p.add_subparsers(dest="bag_command", required=True)
    q = bag_sub.add_parser("info", help="topics, types, counts and rates")
    q.add_argument("bag", type=Path, help="a .bag file, or a ROS 2 bag folder (or a file in it)")
    q.set_defaults(func=cmd_bag_info)
    q = bag_sub.add_parser(
        "extract",
        help="write one scan (scan.pcd), the image nearest in time (image.png) and camera.yaml",
        description="Writes scan.pcd, image.png, camera.yaml (from CameraInfo) and initial_extrinsics.yaml "
        "(when /tf_static links the cloud's and the image's frames). A topic may be left out when the bag "
        "has only one of its type.",
    )
    q.add_argument("bag", type=Path, help="a .bag file, or a ROS 2 bag folder (or a file in it)")
    add_bag_topic_args(q)
    which = q.add_mutually_exclusive_group()
    which.add_argument("--time", type=float, default=None, help="the cloud nearest to this many seconds after the bag's start")
    which.add_argument("--index", type=int, default=None, help="the cloud with this 0-based index on its topic (default 0)")
    q.add_argument("-o", "--output", required=True, type=Path, help="output folder")
    q.set_defaults(func=cmd_bag_extract)
    add_bag_frames_parser(bag_sub)
    parser.commands = tuple(sub.choices)  # type: ignore[attr-defined]  (for with_default_command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    for stream in (sys.stdout, sys.stderr):
        try:  # paths with undecodable bytes must not crash a print
            stream.reconfigure(errors="backslashreplace")  # type: ignore[union-attr]
        except (AttributeError, ValueError):
            pass
    parser = build_parser()
    try:
        args = parser.parse_args(with_default_command(parser, argv))
    except SystemExit as exc:
        return int(exc.code or 0) if isinstance(exc.code, int) else EXIT_USAGE
    noise = Noise()
    # A first run after an install compiles what it needs (small solves run interpreted): say so, not go quiet.
    compile_events.on_first_compile(lambda _name: noise.say(COMPILE_NOTICE))
    try:
        check_args(args)
        check_serve_files(args)
        remove_stale_temp_files(args)
        if args.command == "serve":  # long-running: its warnings and logs go out live
            return int(args.func(args) or 0)
        with noise:
            outcome = args.func(args)
        for line in noise.lines:
            print(f"warning: {line}", file=sys.stderr)
        if isinstance(outcome, Outcome):
            print(outcome.stderr_line, file=sys.stderr)
            return outcome.code
        return int(outcome or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output went away (e.g. `| head`): not an error of ours.
        # Point stdout at /dev/null so the interpreter's final flush stays quiet.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001 - one line unless --debug (lazrs panics are BaseExceptions)
        message, code = error_line(exc)
        if code == EXIT_USAGE:
            print(f"error: {message}{noise.folded()}", file=sys.stderr)
            return code
        if args.debug:
            raise
        text = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
        print(f"internal error: {text} (run with --debug for the traceback){noise.folded()}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
