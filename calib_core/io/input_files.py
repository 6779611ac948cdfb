"""Reading small input files (cameras, pairs, extrinsics, sessions) with bounds.

Every such file is checked before a byte is read: it must be a regular file
(a FIFO would block, ``/dev/zero`` would never end) and no larger than a
limit that fits its kind.  The file is opened non-blocking and checked again
on the open descriptor, so a path swapped in between cannot slip through.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import CalibError
from .atomic import file_kind

#: Size limits in bytes, per kind of file (far above any real file of that kind).
MAX_CAMERA_BYTES = 1 << 20
MAX_EXTRINSICS_BYTES = 16 << 20
MAX_SESSION_BYTES = 8 << 20


def with_article(what: str) -> str:
    """``what`` with its indefinite article ("a camera file", "an extrinsics file")."""
    return f"{'an' if what[:1].lower() in 'aeiou' else 'a'} {what}"


def _size_text(n: int) -> str:
    return f"{n / (1 << 20):.3g} MiB" if n >= 1 << 20 else f"{n} bytes"


def check_input_file(path: str | os.PathLike, what: str, max_bytes: int, hint: str = "") -> int:
    """Check that ``path`` is a readable regular file of at most ``max_bytes``; return its size.

    Parameters
    ----------
    path : path-like
        The file as the user gave it.
    what : str
        What the file should be (``"camera file"``), for the message.
    max_bytes : int
        Largest accepted size.
    hint : str
        Appended to the too-large message (e.g. the option that raises the limit).

    Raises
    ------
    CalibError
        Missing, not a regular file, or too large; the message names ``path``.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise CalibError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise CalibError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    _check_stat(path, st, what, max_bytes, hint)
    return st.st_size


def _check_stat(path: Path, st: os.stat_result, what: str, max_bytes: int, hint: str = "") -> None:
    if stat.S_ISDIR(st.st_mode):
        raise CalibError(f"{path}: is a folder, expected {with_article(what)}")
    if not stat.S_ISREG(st.st_mode):
        raise CalibError(f"{path}: is {file_kind(st.st_mode)}, expected {with_article(what)} (a regular file)")
    if st.st_size > max_bytes:
        raise CalibError(f"{path}: {_size_text(st.st_size)} is too large for {with_article(what)} (at most {_size_text(max_bytes)}){'; ' + hint if hint else ''}")


def read_input_bytes(path: str | os.PathLike, what: str, max_bytes: int, hint: str = "") -> bytes:
    """The bytes of a small regular file, checked as in :func:`check_input_file`.

    The file is opened with ``O_NONBLOCK`` (a FIFO swapped in after the check
    cannot block) and at most ``max_bytes + 1`` bytes are read (a file that
    grows meanwhile is still refused).
    """
    path = Path(path)
    check_input_file(path, what, max_bytes, hint)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise CalibError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    try:
        _check_stat(path, os.fstat(fd), what, max_bytes, hint)
        chunks, total = [], 0
        while total <= max_bytes:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    except OSError as exc:
        raise CalibError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if total > max_bytes:
        raise CalibError(f"{path}: grew beyond {_size_text(max_bytes)} while being read; too large for {with_article(what)}")
    return b"".join(chunks)


def read_input_text(path: str | os.PathLike, what: str, max_bytes: int, hint: str = "") -> str:
    """:func:`read_input_bytes` decoded as UTF-8 (a BOM is allowed); a one-line error otherwise."""
    data = read_input_bytes(path, what, max_bytes, hint)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CalibError(f"{Path(path)}: not UTF-8 text, expected {with_article(what)} (byte {exc.start} is 0x{data[exc.start]:02x})") from None
