"""Atomic file writes that never destroy what an output path points at.

* Only a regular file is ever replaced: a device node (``/dev/full``), a FIFO,
  a socket or a folder given as the output is refused with a one-line
  :class:`~calib_core.errors.CalibError` naming the path the user gave.
* A symlink is followed: its final target is replaced atomically and the link
  stays a link.
* The data goes to a temporary file next to the target, named
  ``.ba-calib-tmp-<pid>-<random>``, is fsync'd and renamed over the target, so a
  crash or a full disk never leaves a half-written file.  A temporary file
  left by a killed process is removed by :func:`remove_stale_temp_files`.
* Errors name the user's path, never the temporary name.
"""

from __future__ import annotations

import os
import re
import stat
import tempfile
import time
from pathlib import Path
from typing import Any, Iterable

import yaml

from ..errors import CalibError

#: Prefix of every temporary file this module creates (next to its target).
TEMP_PREFIX = ".ba-calib-tmp-"


def file_kind(mode: int) -> str:
    """What a non-regular file is, from its ``st_mode`` ("a folder", "a device", ...), for messages."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def output_target(path: str | os.PathLike) -> Path:
    """The regular file a write to ``path`` replaces (symlinks followed).

    Parameters
    ----------
    path : path-like
        The output path as the user gave it.

    Returns
    -------
    Path
        ``path`` itself, or the final target of the symlink chain at ``path``
        (which may not exist yet: a dangling link is written through).

    Raises
    ------
    CalibError
        ``path`` (or what it links to) exists and is not a regular file, or
        the link chain loops.
    """
    user = Path(path)
    target = Path(os.path.realpath(user)) if user.is_symlink() else user
    try:
        st = os.stat(target)
    except FileNotFoundError:
        return target
    except OSError as exc:
        raise CalibError(f"{user}: cannot write here: {_reason(exc)}") from None
    if not stat.S_ISREG(st.st_mode):
        via = f" (via the link to {target})" if target != user else ""
        raise CalibError(f"{user}: is {file_kind(st.st_mode)}{via}; refusing to write over anything but a regular file")
    return target


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file next to it, fsync and a rename.

    ``path`` may be a symlink (its target is replaced, the link stays) and its
    parent folders are created.  An existing target keeps its permission bits;
    a new file gets those of a plain ``open()`` (0666 minus the umask).

    Raises
    ------
    CalibError
        The output is not a regular file, or cannot be written (the message
        names ``path`` as given).
    """
    user = Path(path)
    target = output_target(user)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}{os.getpid()}-", dir=target.parent)
    except OSError as exc:
        raise CalibError(f"{user}: cannot write: {_reason(exc)}") from None
    try:
        try:
            mode = stat.S_IMODE(os.stat(target).st_mode)
        except FileNotFoundError:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask
        os.fchmod(fd, mode)  # mkstemp makes the file private (0600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
        fsync_folder(target.parent)
    except OSError as exc:
        _unlink_quietly(tmp)
        raise CalibError(f"{user}: cannot write: {_reason(exc)}") from None
    except BaseException:
        _unlink_quietly(tmp)
        raise


def yaml_bytes(data: Any) -> bytes:
    """``data`` as the UTF-8 YAML :func:`write_yaml_atomic` writes (``yaml.safe_dump``, block style, key order kept)."""
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100).encode("utf-8")


def write_yaml_atomic(path: str | os.PathLike, data: Any) -> None:
    """:func:`yaml_bytes` of ``data`` written to ``path`` atomically."""
    write_bytes_atomic(path, yaml_bytes(data))


def fsync_folder(folder: Path) -> None:
    """Make the rename itself durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _unlink_quietly(path: str | os.PathLike) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _process_start_time() -> float:
    """Wall-clock start of this process (Linux ``/proc``), else the import time of this module."""
    try:
        with open("/proc/self/stat", "rb") as f:
            # Field 22, after the ")" that ends the command name: start time in clock ticks since boot.
            ticks = int(f.read().rsplit(b")", 1)[1].split()[19])
        with open("/proc/stat", "rb") as f:
            boot = next(int(line.split()[1]) for line in f if line.startswith(b"btime "))
        return boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return _IMPORT_TIME


_IMPORT_TIME = time.time()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temp_files(folder: str | os.PathLike, legacy_for: Iterable[str] = ()) -> list[Path]:
    """Remove temporary files of interrupted writes from ``folder``.

    A file is stale when its name has :data:`TEMP_PREFIX`, it is a regular
    file (not a link), it is older than the current process and the process
    that wrote it (its pid is in the name) no longer runs.  Files of writes in
    flight in other processes are left alone.

    ``legacy_for`` names output files (e.g. ``session.yaml``) whose temporary
    files from versions before this prefix, ``.session.yaml.XXXXXXXX.tmp``
    (``tempfile.mkstemp``'s pattern), are removed too when older than the
    current process.

    Returns
    -------
    list of Path
        The files removed.  A missing or unreadable folder removes nothing.
    """
    start = _process_start_time()
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    legacy = [re.compile(rf"\.{re.escape(name)}\.[a-z0-9_]{{8}}\.tmp") for name in legacy_for]
    for entry in entries:
        is_legacy = any(p.fullmatch(entry.name) for p in legacy)
        if not (entry.name.startswith(TEMP_PREFIX) or is_legacy):
            continue
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode) or st.st_mtime >= start:
            continue
        pid_text = "" if is_legacy else entry.name[len(TEMP_PREFIX):].split("-", 1)[0]
        if pid_text.isdigit() and int(pid_text) != os.getpid() and _pid_alive(int(pid_text)):
            continue
        try:
            os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed
