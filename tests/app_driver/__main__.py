"""The kill -9 durability test's app processes (``tests/test_app_durability.py``).

``python -m app_driver child --session PATH`` (with ``tests/`` on ``PYTHONPATH``) runs the app on the
committed sample and applies one action per line read from stdin (``ba ROW COL``, ``cam U V``, ``undo``),
printing ``ack <json of the pairs>`` when the page would show it: the kill -9 durability test drives such
children.

``python -m app_driver zygote FD`` starts them faster: it imports the app and
compiles (or loads) every numba kernel once, then for each message ``fork
SESSION`` that arrives on the Unix socket FD with a socket attached, forks a
child that runs the same loop with that socket as its stdin and stdout, and
answers ``pid N``.  A child pays only for building the app (about 1.4 s,
against about 3 s for a new process).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from app_driver import AppDriver


def _picks_json(app: Any) -> str:
    return json.dumps([p.to_dict() for p in app.state.picks], separators=(",", ":"))


def _child(session: Path) -> int:
    from app.server import CalibrationApp

    sample = Path(__file__).resolve().parents[2] / "sample_data"
    app = CalibrationApp(sample / "scan.npz", sample / "image.png", sample / "camera.yaml", session_path=session,
                         port=0)
    driver = AppDriver(app)
    print("ready " + _picks_json(app), flush=True)
    for line in sys.stdin:
        cmd = line.split()
        if not cmd:
            continue
        try:
            if cmd[0] == "ba":
                notes = driver.click_cell("horizontal", int(cmd[1]), int(cmd[2]))
            elif cmd[0] == "cam":
                notes = driver.click_camera(float(cmd[1]), float(cmd[2]))
            elif cmd[0] == "undo":
                notes = driver.press_edit("Undo")
            else:
                break
        except ValueError as exc:  # not shown on the page: nothing to click
            notes = [("Not shown", str(exc))]
        if notes:  # refused: say why (one line), the pairs are unchanged
            print("nack " + json.dumps(notes), flush=True)
        else:
            print(f"ack {_picks_json(app)}", flush=True)
    app.stop()
    return 0


def _zygote(control_fd: int) -> int:
    """Fork children that run :func:`_child` (see the module docstring); no thread runs when it forks."""
    import os
    import signal
    import socket

    from app import server  # noqa: F401 - imported once, inherited by every child
    from app.warm_up import WarmUp

    # Compiled code is inherited too: a child's own warm-up finds every kernel ready.  wait() returns
    # once the warm-up's thread has ended, so no thread runs at the forks.
    WarmUp().wait()
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # the kernel reaps the children
    control = socket.socket(fileno=control_fd)
    control.sendall(b"ready\n")
    while True:
        msg, fds, _, _ = socket.recv_fds(control, 4096, 1)
        if not msg:
            return 0  # the test closed its end
        cmd = msg.decode().split()
        if len(cmd) != 2 or cmd[0] != "fork" or len(fds) != 1:
            for fd in fds:
                os.close(fd)
            control.sendall(f"error expected 'fork SESSION' and one socket, got {msg!r}\n".encode())
            continue
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                control.close()
                conn = socket.socket(fileno=fds[0])
                sys.stdin = conn.makefile("r", encoding="utf-8")
                sys.stdout = conn.makefile("w", encoding="utf-8", buffering=1)
                code = _child(Path(cmd[1]))
            except BaseException:
                import traceback

                traceback.print_exc()
            finally:
                os._exit(code)
        os.close(fds[0])  # the child's end: once the child is gone, the test reads EOF
        control.sendall(f"pid {pid}\n".encode())


if __name__ == "__main__":  # pragma: no cover - run by the durability test as a child process
    if len(sys.argv) == 4 and sys.argv[1] == "child" and sys.argv[2] == "--session":
        sys.exit(_child(Path(sys.argv[3])))
    if len(sys.argv) == 3 and sys.argv[1] == "zygote":
        sys.exit(_zygote(int(sys.argv[2])))
    print("usage: python -m app_driver child --session PATH | python -m app_driver zygote FD", file=sys.stderr)
    sys.exit(2)
