"""Keep third-party readers quiet: what they print becomes part of our one-line error.

libpng and libjpeg (through OpenCV) and Rust's lazrs write straight to file
descriptor 2; numpy and pypcd4 emit Python warnings; trimesh and laspy log.
:func:`library_output` collects all three while a file is decoded, so that a
reader can either drop the noise (the file was fine) or fold it into the
:class:`~calib_core.errors.CalibError` it raises.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator

#: Loggers of the libraries the readers call.
LIBRARY_LOGGERS = ("trimesh", "laspy", "PIL", "pypcd4", "lazrs")


class LibraryOutput:
    """What libraries printed, warned or logged inside :func:`library_output`."""

    def __init__(self) -> None:
        self.warnings: list[warnings.WarningMessage] = []
        self.records: list[logging.LogRecord] = []
        self._stderr_file = None
        self._stderr_done = ""

    def stderr_text(self) -> str:
        """What was written to file descriptor 2 (so far, inside the block)."""
        if self._stderr_file is None:
            return self._stderr_done
        self._stderr_file.seek(0)
        return self._stderr_file.read(65536).decode("utf-8", "replace")

    def text(self, limit: int = 120) -> str:
        """Everything captured, as one short line ('' when nothing was)."""
        parts = [str(w.message) for w in self.warnings]
        parts += [record.getMessage() for record in self.records]
        for line in self.stderr_text().splitlines():
            if _is_rust_panic(line):
                break  # the panic's text reaches Python in the exception; the rest is a backtrace
            parts.append(line)
        seen: list[str] = []
        for part in parts:
            part = " ".join(part.split())
            if part and part not in seen:
                seen.append(part)
        text = "; ".join(seen)
        return text if len(text) <= limit else text[: limit - 3] + "..."

    def suffix(self) -> str:
        """`` (library said: ...)`` for an error message, or ''."""
        text = self.text()
        return f" (library said: {text})" if text else ""


def _is_rust_panic(line: str) -> bool:
    """Rust's panic banner, ``thread '...' panicked at ...``."""
    line = line.strip()
    return line.startswith("thread '") and "panicked at" in line


class _Collect(logging.Handler):
    def __init__(self, sink: list[logging.LogRecord]) -> None:
        super().__init__(logging.DEBUG)
        self.sink = sink

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= logging.WARNING:
            self.sink.append(record)


@contextlib.contextmanager
def _fd2_to(sink: LibraryOutput) -> Iterator[None]:
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing to keep quiet
        yield
        return
    handle = tempfile.TemporaryFile()
    try:
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        os.dup2(handle.fileno(), 2)
        sink._stderr_file = handle
        yield
    finally:
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
        sink._stderr_done = sink.stderr_text()
        sink._stderr_file = None
        handle.close()


@contextlib.contextmanager
def library_output() -> Iterator[LibraryOutput]:
    """Collect warnings, library log records and fd-2 output while decoding a file.

    Yields
    ------
    LibraryOutput
        Read it (``.text()``, ``.suffix()``) inside or after the block.
    """
    out = LibraryOutput()
    handler = _Collect(out.records)
    loggers = [logging.getLogger(name) for name in LIBRARY_LOGGERS]
    saved = [(lg.propagate, lg.level) for lg in loggers]
    for lg in loggers:
        lg.addHandler(handler)
        lg.propagate = False
        if lg.level == logging.NOTSET or lg.level > logging.WARNING:
            lg.setLevel(logging.WARNING)
    try:
        with warnings.catch_warnings(record=True) as caught, _fd2_to(out):
            warnings.simplefilter("always")
            try:
                yield out
            finally:
                out.warnings.extend(caught)
    finally:
        for lg, (propagate, level) in zip(loggers, saved):
            lg.removeHandler(handler)
            lg.propagate = propagate
            lg.setLevel(level)
