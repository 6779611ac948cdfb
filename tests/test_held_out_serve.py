"""Issue 23, ``serve``: a SIGTERM during start-up, the "organised by" line, the URL for other machines, --help.

The server runs as a real process on the committed sample, with a session whose journal holds changes the
session YAML does not (a server killed earlier); what a clean stop must do with it is checked on the files.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import pytest
import yaml

from app.security import AccessPolicy
from app.state import AnnotationState
from calib_core.io.scan_readers import load_scan
from browser_helpers import free_port
from repo_paths import SAMPLE

ROOT = Path(__file__).resolve().parents[1]


def killed_session(tmp_path: Path) -> tuple[Path, list]:
    """A session on the sample whose last changes are only in its journal (the server was killed)."""
    depth = load_scan(SAMPLE / "scan.npz")
    rows, cols = depth.valid.nonzero()
    path = tmp_path / "session.yaml"
    state = AnnotationState(depth.valid, (640, 480), session_path=path)
    cells = [(int(rows[k]), int(cols[k])) for k in range(0, len(rows), len(rows) // 5)][:5]
    for k, cell in enumerate(cells):
        state.add_laser(*cell)
        state.add_pixel(100.0 + 10 * k, 200.0 + 5 * k)
        if k == 1:
            state.flush_session()  # the YAML holds the first two pairs, the journal the rest
    journal = path.with_name(path.name + ".journal")
    assert journal.exists() and len(yaml.safe_load(path.read_text())["pairs"]) < len(cells)
    store = state._store  # noqa: SLF001 - "killed": its compactor must never write again
    with store._lock:
        store._closed = True
        store._cond.notify_all()
    if store._thread is not None:
        store._thread.join(10)
    return path, cells


def serve(tmp_path: Path, session: Path, port: int, *extra: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--scan", str(SAMPLE / "scan.npz"), "--image", str(SAMPLE / "image.png"),
         "--camera", str(SAMPLE / "camera.yaml"), "--session", str(session), "--port", str(port), *extra],
        cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def assert_folded(session: Path, cells: list) -> None:
    assert not session.with_name(session.name + ".journal").exists()
    saved = yaml.safe_load(session.read_text())["pairs"]
    assert [tuple(p["laser_rc"]) for p in saved] == cells


def test_sigterm_while_the_app_starts_stops_it_cleanly_and_folds_the_journal(tmp_path):
    session, cells = killed_session(tmp_path)
    port = free_port()
    proc = serve(tmp_path, session, port)
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=0.05) as probe:
                    # A whole request (a bare connect is logged as a failed handshake): the port answers.
                    probe.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
                    break  # the page is not built yet
            except OSError:
                time.sleep(0.002)
        else:
            pytest.fail(f"the server never answered: {proc.stdout.read() if proc.poll() is not None else ''}")
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    output = proc.stdout.read()
    assert code == 0, (code, output[-2000:])
    assert "internal error" not in output
    assert_folded(session, cells)


def test_serve_says_how_the_scan_was_organised_and_a_working_url_for_other_machines(tmp_path):
    session, cells = killed_session(tmp_path)
    port = free_port()
    proc = serve(tmp_path, session, port, "--host", "0.0.0.0")
    lines: list[str] = []
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line.rstrip("\n"))
            if line.startswith("ba-calib: listening on"):
                break
        text = "\n".join(lines)
        assert any(line.startswith("organised by native: 180 x 720") for line in lines), text
        other = [line for line in lines if line.startswith("ba-calib: from other machines: ")]
        assert len(other) == 1, text
        url = other[0].split(": ", 2)[2]
        host = urlsplit(url).hostname
        assert "token=" in url and host not in ("localhost", "127.0.0.1", "::1"), url
        with urllib.request.urlopen(url, timeout=30) as response:  # the printed URL works
            assert response.status == 200
    finally:
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=120)
    assert code == 0
    assert_folded(session, cells)


def test_the_other_machines_url_is_not_localhost_when_the_fqdn_is(monkeypatch, capsys):
    from types import SimpleNamespace

    from app import serving

    monkeypatch.setattr(socket, "getfqdn", lambda name="": "localhost")
    token, port = "t" * 32, 8123
    app = SimpleNamespace(url=f"http://127.0.0.1:{port}/?token={token}", session_path=Path("s.yaml"), port=port,
                          access=SimpleNamespace(token=token), depth=None)
    serving._announce(app, "0.0.0.0")
    lines = capsys.readouterr().out.splitlines()
    other = [line.split(": ", 2)[2] for line in lines if line.startswith("ba-calib: from other machines: ")]
    assert len(other) == 1, lines
    if other[0].startswith("no network address found"):
        pytest.skip(f"this machine has no network address: {other[0]}")
    parts = urlsplit(other[0])
    assert parts.hostname not in ("localhost", "127.0.0.1", "::1") and parts.port == port, other[0]
    assert parts.query == f"token={token}"
    # What a server bound to 0.0.0.0 accepts from a connection arriving on that address.
    policy = AccessPolicy.for_bind("0.0.0.0", token=token)
    assert policy.refusal({"Host": parts.netloc}, f"/?{parts.query}", (parts.hostname, port)) is None
    # And the address is this machine's: a socket bound to every interface accepts a connection to it.
    with socket.socket(socket.AF_INET6 if ":" in parts.hostname else socket.AF_INET) as listener:
        listener.bind(("::" if ":" in parts.hostname else "0.0.0.0", 0))
        listener.listen(1)
        with socket.create_connection((parts.hostname, listener.getsockname()[1]), timeout=5):
            pass


def test_serve_help_describes_every_scene_option():
    run = subprocess.run([sys.executable, "-m", "app.cli", "serve", "--help"], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert run.returncode == 0
    help_text = " ".join(run.stdout.split())
    for option, words in (("--camera CAMERA", "camera file"), ("--scan SCAN", "scan file"),
                          ("--image IMAGE", "camera image"), ("--kitti-camera N", "KITTI calib")):
        start = help_text.index(option, help_text.index("options:"))
        assert words in help_text[start : start + 200], (option, help_text[start : start + 200])
