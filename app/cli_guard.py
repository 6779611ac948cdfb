"""The CLI's guard rails: the default command, one-line argument errors, option ranges, checks
made before a command runs, and library output folded into the one ``error:`` line."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Sequence

from calib_core.errors import CalibError

EXIT_USAGE = 2


def with_default_command(parser: argparse.ArgumentParser, argv: Sequence[str] | None = None) -> list[str]:
    """``argv`` with ``serve`` inserted when it names no command: ``ba-calib --port 8300`` serves.

    The global options (``--debug``) stay in front; ``-h`` / ``--version`` are left to the main parser.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    commands = set(getattr(parser, "commands", ()))
    i = 0
    while i < len(args) and args[i] == "--debug":
        i += 1
    if i < len(args) and (args[i] in commands or args[i] in ("-h", "--help", "--version")):
        return args
    return args[:i] + ["serve"] + args[i:]


class OneLineParser(argparse.ArgumentParser):
    """argparse with one-line errors: ``error: <problem> (see ba-calib ... --help)``, exit 2."""

    def error(self, message: str):  # type: ignore[override]
        print(f"error: {' '.join(message.split())} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def check_args(args: argparse.Namespace) -> None:
    """Numeric options that argparse's types let through but no command can use."""
    def bad(option: str, value, want: str) -> None:
        raise CalibError(f"{option}: expected {want}, got {value!r}")

    beams = getattr(args, "beams", None)
    if beams is not None and not 1 <= beams <= 4096:
        bad("--beams", beams, "a number of beams from 1 to 4096")
    for key in ("h_res_deg", "v_res_deg"):
        v = getattr(args, key, None)
        if v is not None and not 1e-4 <= v <= 90.0:  # also refuses nan
            bad("--" + key.replace("_", "-"), v, "an angle in degrees from 0.0001 to 90")
    size = getattr(args, "image_size", None)
    if size is not None:
        from calib_core.cameras.params import MAX_IMAGE_SIDE

        if not all(1 <= v <= MAX_IMAGE_SIDE for v in size):
            bad("--image-size", list(size), f"a width and a height from 1 to {MAX_IMAGE_SIDE} pixels")
    port = getattr(args, "port", None)
    if port is not None and not 0 <= port <= 65535:
        bad("--port", port, "a port number from 0 to 65535")
    max_pairs = getattr(args, "max_pairs", None)
    if max_pairs is not None and not 1 <= max_pairs <= 10_000_000:
        bad("--max-pairs", max_pairs, "a number of pairs from 1 to 10,000,000")


def check_serve_files(args: argparse.Namespace) -> None:
    """``serve`` runs until stopped: a session it cannot restore, an output it may not replace, or an image
    the camera file does not fit, is reported now, in one line, rather than after the scene has loaded or at
    the first Export."""
    if args.command != "serve":
        return
    from calib_core.io.atomic import output_target
    from calib_core.io.session_file import check_session_file

    if args.session is not None:
        check_session_file(args.session)
        output_target(args.session)
    if args.output is not None:
        output_target(args.output)
    if getattr(args, "bag", None) is None and args.camera is not None and args.image is not None:
        load_camera_from_args(args)  # also checks the image's size against the camera's


# --- cameras -------------------------------------------------------------------

CAMERA_HELP = ("camera file: our YAML, ROS camera_info YAML, OCamCalib calib_results.txt, a KITTI calib/NNNNNN.txt "
               "(see --kitti-camera), PJLab/OpenCalib intrinsic JSON (pinhole or OCam)")


def add_camera_args(p: argparse.ArgumentParser, required: bool) -> None:
    """``--camera``, ``--image-size`` and ``--kitti-camera``, as every command that reads a camera takes them."""
    p.add_argument("--camera", required=required, type=Path, help=CAMERA_HELP)
    p.add_argument("--image-size", type=int, nargs=2, metavar=("W", "H"), default=None,
                   help="the images' size in pixels, when the camera file states another (or none)")
    p.add_argument("--kitti-camera", type=int, choices=(0, 1, 2, 3), default=None, metavar="N",
                   help="with a KITTI calib file: which rectified camera, 0-3 (P0..P3; default 2, the colour "
                        "image_2); K = P[:, :3], no distortion, the image size from --image (or --image-size)")


def camera_image_size(args: argparse.Namespace) -> tuple[int, int] | None:
    """The image size the camera is loaded with: ``--image-size``, else for a KITTI calib file (which
    states none) the size of ``--image`` (its header), else None (the camera file's own)."""
    size = getattr(args, "image_size", None)
    if size:
        return int(size[0]), int(size[1])
    camera, image = getattr(args, "camera", None), getattr(args, "image", None)
    if camera is not None and image is not None:
        from calib_core.cameras.io import is_kitti_calib

        if is_kitti_calib(camera):
            from calib_core.io.images import image_header_size

            return image_header_size(image)
    return None


def load_camera_from_args(args: argparse.Namespace):
    """The camera of ``--camera`` (with ``--image-size``, ``--kitti-camera``); with ``--image``, also checks
    that the image has the camera's size (one line naming both, and ``--image-size`` when it would help)."""
    from calib_core.cameras import load_camera

    camera = load_camera(args.camera, image_size=camera_image_size(args), kitti_camera=getattr(args, "kitti_camera", None))
    image = getattr(args, "image", None)
    if image is not None:
        check_image_fits_camera(image, camera, args)
    return camera


def check_image_fits_camera(image, camera, args: argparse.Namespace) -> None:
    """Refuse an image whose header size is not the camera model's (before it is decoded)."""
    from calib_core.io.images import image_header_size

    width, height = image_header_size(image)
    if (width, height) == (camera.width, camera.height):
        return
    if getattr(args, "image_size", None):
        fix = f"--image-size says {camera.width} {camera.height}"
    else:
        fix = (f"if the camera's parameters are for this image and only the file's size is wrong, "
               f"give --image-size {width} {height}")
    raise CalibError(f"{image}: the image is {width}x{height} but the camera model {args.camera} is "
                     f"{camera.width}x{camera.height}; {fix}")


def remove_stale_temp_files(args: argparse.Namespace) -> None:
    """Temporary files of interrupted writes, next to this command's outputs, from an earlier run."""
    from calib_core.io.atomic import remove_stale_temp_files

    for key in ("output", "session"):
        path = getattr(args, key, None)
        if path is None:
            continue
        path = Path(path)
        if path.is_dir():
            remove_stale_temp_files(path)
        else:  # also what older versions left: .NAME.XXXXXXXX.tmp
            remove_stale_temp_files(path.parent, legacy_for=[path.name])


class Noise:
    """Collects what libraries say while a command runs: Python warnings and text written to fd 2.

    C libraries (libpng inside OpenCV, for one) write straight to file descriptor 2, past
    ``sys.stderr``; so fd 2 is pointed at a temporary file and read back afterwards.
    """

    def __init__(self) -> None:
        self.lines: list[str] = []
        self._saved_fd: int | None = None

    def say(self, line: str) -> None:
        """Write ``line`` to the real standard error now, also while fd 2 is being collected."""
        fd = self._saved_fd
        if fd is None:
            print(line, file=sys.stderr, flush=True)
            return
        try:
            os.write(fd, (line + "\n").encode("utf-8", "backslashreplace"))
        except OSError:
            pass

    def __enter__(self) -> "Noise":
        import tempfile
        import warnings

        self._warnings = warnings.catch_warnings(record=True)
        self._records = self._warnings.__enter__()
        warnings.simplefilter("default")
        sys.stderr.flush()
        self._saved_fd = os.dup(2)
        self._file = tempfile.TemporaryFile()
        os.dup2(self._file.fileno(), 2)
        return self

    def __exit__(self, *exc) -> None:
        try:
            sys.stderr.flush()
        except (OSError, ValueError):
            pass
        saved, self._saved_fd = self._saved_fd, None
        os.dup2(saved, 2)
        os.close(saved)
        self._file.seek(0)
        text = self._file.read(1 << 20).decode("utf-8", "backslashreplace")
        self._file.close()
        self._warnings.__exit__(*exc)
        seen: set[str] = set()
        for line in [f"{w.category.__name__}: {w.message}" for w in self._records] + text.splitlines():
            line = " ".join(line.split())
            if line and line not in seen:
                seen.add(line)
                self.lines.append(line)

    def folded(self, limit: int = 300) -> str:
        """The collected lines as a suffix of one error line (empty when nothing was said)."""
        if not self.lines:
            return ""
        text = "; ".join(self.lines)
        return f" [libraries said: {text if len(text) <= limit else text[: limit - 3] + '...'}]"


def error_line(exc: BaseException) -> tuple[str, int]:
    """The one ``error:`` line and exit code for an exception a command raised."""
    if isinstance(exc, CalibError):
        return " ".join(str(exc).split()), EXIT_USAGE
    if isinstance(exc, OSError):
        where = exc.filename if exc.filename is not None else ""
        return f"{where}: {exc.strerror or exc}" if where != "" else f"{exc.strerror or exc}", EXIT_USAGE
    if isinstance(exc, RecursionError):
        return "the input is nested too deeply to process", EXIT_USAGE
    if isinstance(exc, MemoryError):
        return "out of memory: the input is too large for this machine", EXIT_USAGE
    return "", 1
