"""Only the app's own page may drive it: Host, Origin and token checks (issue 8).

The served app is started for real on 127.0.0.1 and probed with plain HTTP
requests and a real websocket client (the ``websockets`` package) that
speaks viser's subprotocol, as a hostile page in the user's browser would.
"""

from __future__ import annotations

import asyncio
import http.client

import pytest
import viser
import websockets.asyncio.client as ws_client
from websockets.exceptions import InvalidStatus

from app.security import AccessPolicy, cookie_name, is_loopback, split_host
from calib_core.errors import CalibError
from browser_helpers import free_port
from repo_paths import SAMPLE

SUBPROTOCOL = f"viser-v{viser.__version__}"


class Headers(dict):
    def get_all(self, name):
        return [v for k, v in self.items() if k.lower() == name.lower()]


def refusal(policy, port=8080, local_ip="127.0.0.1", path="/", **headers):
    return policy.refusal(Headers({k.replace("_", "-"): v for k, v in headers.items()}), path, (local_ip, port))


def test_loopback_policy_accepts_only_this_origin_and_port():
    p = AccessPolicy.for_bind("127.0.0.1")
    assert p.token is None  # loopback: no token needed
    for host in ("127.0.0.1:8080", "localhost:8080", "[::1]:8080", "LOCALHOST:8080", "localhost.:8080"):
        assert refusal(p, Host=host) is None, host
        assert refusal(p, Host=host, Origin=f"http://{host}") is None, host
    refused = [
        dict(Host="evil.example:8080"),  # DNS rebinding
        dict(Host="127.0.0.1:8081"),  # another port
        dict(Host="127.0.0.1"),  # port 80 implied
        dict(Host="192.168.1.5:8080"),
        dict(),  # no Host at all
        dict(Host="127.0.0.1:8080@evil.example"),
        dict(Host="127.0.0.1:8080", Origin="http://evil.example"),  # cross-site websocket hijacking
        dict(Host="127.0.0.1:8080", Origin="http://evil.example:8080"),
        dict(Host="127.0.0.1:8080", Origin="http://127.0.0.1:9999"),
        dict(Host="127.0.0.1:8080", Origin="https://127.0.0.1:8080"),
        dict(Host="127.0.0.1:8080", Origin="null"),  # sandboxed iframe, file:// page
        dict(Host="127.0.0.1:8080", Origin="http://localhost:8080"),  # not the origin the page was loaded from
        dict(Host="127.0.0.1:8080", Origin="http://127.0.0.1:8080/x"),
    ]
    for headers in refused:
        assert refusal(p, **headers) is not None, headers


def test_non_loopback_bind_requires_the_token():
    assert not is_loopback("0.0.0.0") and is_loopback("127.0.0.2") and is_loopback("[::1]")
    p = AccessPolicy.for_bind("0.0.0.0")
    assert p.token is not None and len(p.token) >= 24
    assert AccessPolicy.for_bind("0.0.0.0").token != p.token  # random each start
    host = "10.1.2.3:8080"
    # The connection arrived on 10.1.2.3: that address is a valid Host, but only with the token.
    assert "token" in refusal(p, local_ip="10.1.2.3", Host=host)
    assert refusal(p, local_ip="10.1.2.3", Host=host, path=f"/?token={p.token}") is None
    wrong = p.token[:-1] + ("y" if p.token.endswith("x") else "x")  # (a fixed "x" matched 1 token in 64)
    assert refusal(p, local_ip="10.1.2.3", Host=host, path=f"/?token={wrong}") is not None
    assert refusal(p, local_ip="10.1.2.3", Host=host, Cookie=f"a=b; {cookie_name(8080)}={p.token}") is None
    assert refusal(p, local_ip="10.1.2.3", Host=host, Cookie=f"{cookie_name(9090)}={p.token}") is not None
    assert refusal(p, local_ip="10.1.2.3", Host=host, Authorization=f"token {p.token}") is None
    # A rebound name is still refused, token or not.
    assert refusal(p, local_ip="10.1.2.3", Host="evil.example:8080", path=f"/?token={p.token}") is not None
    # A specific address: only that one (and names given on purpose).
    q = AccessPolicy.for_bind("10.1.2.3", extra_hosts=("calib.lan",))
    assert refusal(q, local_ip="10.1.2.3", Host="calib.lan:8080", path=f"/?token={q.token}") is None
    assert refusal(q, local_ip="10.1.2.3", Host="10.9.9.9:8080", path=f"/?token={q.token}") is not None
    with pytest.raises(CalibError, match="at least 16"):
        AccessPolicy.for_bind("0.0.0.0", token="short")
    assert split_host("[::1]:80") == ("::1", 80) and split_host("a b:1") is None and split_host("x:99999") is None


# ------------------------------------------------------------------ the served app

@pytest.fixture(scope="module")
def app(tmp_path_factory):
    from app.server import CalibrationApp

    tmp = tmp_path_factory.mktemp("security")
    a = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                       session_path=tmp / "session.yaml", port=free_port())
    yield a
    a.stop()


def http_get(port, host, origin=None, path="/", cookie=None):
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    headers = {"Host": host}
    if origin is not None:
        headers["Origin"] = origin
    if cookie is not None:
        headers["Cookie"] = cookie
    conn.request("GET", path, headers=headers)
    resp = conn.getresponse()
    body = resp.read()
    conn.close()
    return resp.status, body, resp.getheader("Set-Cookie")


async def ws_first_message(url, origin=None, headers=None):
    """Open a viser websocket and return the size of the first message the server sends."""
    async with ws_client.connect(url, origin=origin, subprotocols=[SUBPROTOCOL], additional_headers=headers,
                                 max_size=None, open_timeout=10) as conn:
        return len(await asyncio.wait_for(conn.recv(), 20))


def raw_handshake(port, host):
    """Status of a websocket opening handshake with the given Host header (101: switching protocols)."""
    import base64
    import os

    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    conn.request("GET", "/", headers={"Host": host, "Upgrade": "websocket", "Connection": "Upgrade",
                                      "Sec-WebSocket-Key": base64.b64encode(os.urandom(16)).decode(),
                                      "Sec-WebSocket-Version": "13", "Sec-WebSocket-Protocol": SUBPROTOCOL})
    status = conn.getresponse().status
    conn.close()
    return status


def ws_status(url, **kwargs):
    try:
        return "open", asyncio.run(ws_first_message(url, **kwargs))
    except InvalidStatus as exc:
        return "refused", exc.response.status_code


def test_served_app_refuses_foreign_host_and_origin(app):
    port = app.port
    assert app.url == f"http://127.0.0.1:{port}" and app.access.token is None
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}"):
        status, body, _ = http_get(port, host)
        assert status == 200 and b"<html" in body[:200].lower(), host
    assert http_get(port, f"127.0.0.1:{port}", origin=f"http://127.0.0.1:{port}")[0] == 200
    for host, origin in ((f"evil.example:{port}", None), (f"127.0.0.1:{port + 1}", None),
                         (f"127.0.0.1:{port}", "http://evil.example")):
        status, body, _ = http_get(port, host, origin)
        assert status == 403 and b"<html" not in body.lower(), (host, origin)

    # Two Host headers (one ours, one foreign): refused, not guessed.
    import socket

    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nHost: evil.example:{port}\r\n"
                     "Connection: close\r\n\r\n".encode())
        assert sock.recv(64).startswith(b"HTTP/1.1 403")

    url = f"ws://127.0.0.1:{port}"
    # A hostile page's websocket: its browser sends its own Origin.
    assert ws_status(url, origin="http://evil.example") == ("refused", 403)
    assert ws_status(url, origin=f"http://evil.example:{port}") == ("refused", 403)
    # A rebound DNS name: the handshake names a foreign Host.
    assert raw_handshake(port, f"evil.example:{port}") == 403
    assert raw_handshake(port, f"127.0.0.1:{port}") == 101
    # The app's own page: accepted, and the server starts sending the scene.
    state, size = ws_status(url, origin=f"http://127.0.0.1:{port}")
    assert state == "open" and size > 0
    state, size = ws_status(f"ws://localhost:{port}", origin=f"http://localhost:{port}")
    assert state == "open" and size > 0


def test_served_app_with_a_token(tmp_path):
    from app.server import CalibrationApp

    token = "t0ken-for-the-test-0123456789"
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=free_port(), token=token)
    try:
        port, host = app.port, f"127.0.0.1:{app.port}"
        assert app.url == f"http://127.0.0.1:{port}/?token={token}"
        assert http_get(port, host)[0] == 403  # the page without the token
        assert http_get(port, host, path="/?token=wrong-token-0123456789")[0] == 403
        status, body, set_cookie = http_get(port, host, path=f"/?token={token}")
        assert status == 200 and b"<html" in body[:200].lower()
        cookie = set_cookie.split(";")[0]
        assert cookie == f"{cookie_name(port)}={token}" and "HttpOnly" in set_cookie
        assert http_get(port, host, cookie=cookie)[0] == 200  # later requests of that browser
        url, origin = f"ws://{host}", f"http://{host}"
        assert ws_status(url, origin=origin) == ("refused", 403)  # no token: no websocket
        assert ws_status(url, origin=origin, headers={"Cookie": cookie})[0] == "open"
        assert ws_status(f"{url}/?token={token}", origin=origin)[0] == "open"
        # The token does not lift the Origin check.
        assert ws_status(url, origin="http://evil.example", headers={"Cookie": cookie}) == ("refused", 403)
    finally:
        app.stop()


def test_the_app_refuses_to_start_without_its_hook(monkeypatch, tmp_path):
    from viser.infra import _infra

    from app.security import AccessPolicy, start_guarded_viser

    # A viser that no longer starts through websockets.asyncio.server.serve: no silent start without the check.
    monkeypatch.delattr(_infra, "websockets")
    with pytest.raises(CalibError, match="refusing to start.*viser 1.1.1"):
        start_guarded_viser(AccessPolicy.for_bind("127.0.0.1"), host="127.0.0.1", port=free_port(), verbose=False)


@pytest.mark.browser
def test_the_real_page_connects_with_the_token_and_not_without(tmp_path):
    """Chromium opens the printed URL: the page loads and its websocket (carrying the cookie) connects."""
    from browser_helpers import CHROMIUM, CHROMIUM_ARGS, wait_for

    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is missing (apt-get install chromium); CI installs it")
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from app.server import CalibrationApp

    token = "browser-test-token-0123456789"
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=free_port(), token=token)
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
            page = browser.new_page()
            response = page.goto(f"http://127.0.0.1:{app.port}/")  # no token: refused
            assert response.status == 403 and not app.server.get_clients()
            response = page.goto(app.url)
            assert response.status == 200
            wait_for(lambda: app.server.get_clients(), "the tokened page's websocket to connect")
            page.get_by_text("Import pairs YAML").first.wait_for(timeout=30_000)  # this tab's own button
            browser.close()
    finally:
        app.stop()


def test_client_file_names_are_only_shown_and_made_plain():
    from app.security import upload_display_name

    assert upload_display_name("..") == "upload" and upload_display_name("") == "upload"
    assert upload_display_name("../../etc/passwd") == "passwd"
    assert upload_display_name("C:\\Users\\me\\pairs.yaml") == "pairs.yaml"
    assert upload_display_name("<img src=x onerror=alert(1)>.yaml") == "_img src_x onerror_alert(1)_.yaml"
    assert upload_display_name("a\nb\x00.yaml") == "a_b_.yaml"
    assert len(upload_display_name("x" * 500)) == 80
