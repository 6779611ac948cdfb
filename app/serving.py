"""Serve the annotation app until Ctrl+C (what ``ba-calib`` and ``ba-calib serve`` run)."""

from __future__ import annotations

import os
import signal
import socket
import threading
import time
from typing import Any

from .security import TOKEN_QUERY, is_loopback
from .server import CalibrationApp


def serve(
    scan_path: str | os.PathLike,
    image_path: str | os.PathLike,
    camera_path: str | os.PathLike,
    *,
    session_path: str | os.PathLike | None = None,
    output_path: str | os.PathLike | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    title: str | None = None,
    scan_options: dict | None = None,
    image_size: tuple[int, int] | None = None,
    token: str | None = None,
    allowed_hosts: tuple[str, ...] = (),
) -> None:
    """Serve the annotation app until Ctrl+C; prints the URL (with the access token off loopback).

    See :class:`CalibrationApp` for the parameters.  Bad input files raise
    :class:`CalibError` before the server starts.
    """
    app = CalibrationApp(scan_path, image_path, camera_path, session_path=session_path, output_path=output_path,
                         host=host, port=port, title=title, scan_options=scan_options, image_size=image_size,
                         token=token, allowed_hosts=allowed_hosts)
    print(f"ba-calib: open {app.url} in a browser (Ctrl+C to stop)", flush=True)
    print(f"ba-calib: session file {app.session_path}", flush=True)
    if app.access.token is not None and not is_loopback(host):
        if host in ("0.0.0.0", "", "::"):
            print(f"ba-calib: from other machines: http://{socket.getfqdn()}:{app.port}/?{TOKEN_QUERY}="
                  f"{app.access.token}", flush=True)
        print(f"ba-calib: listening on {host}: requests without the token in the URL above are refused", flush=True)
    if threading.current_thread() is threading.main_thread():
        # `kill` (SIGTERM) stops like Ctrl+C: stop() writes the last changes to the session file.
        signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()


def _raise_keyboard_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt
