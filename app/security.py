"""Who may drive the app: Host, Origin and token checks on every request viser serves.

A page on another site must not be able to talk to the app through the
user's browser (cross-site websocket hijacking), and a hostile DNS name
pointed at 127.0.0.1 must not be served (DNS rebinding).  Like Jupyter, every
HTTP request and every websocket handshake is refused with HTTP 403 unless

* its ``Host`` header names the address the server listens on and the port it
  accepted the connection on (with a loopback bind: ``127.0.0.1``,
  ``localhost`` or ``[::1]``);
* its ``Origin`` header, when present, is that same ``http://host:port``;
* with a non-loopback bind, it carries the server's random token: the
  ``token`` query parameter (the printed URL has it), or the cookie set on
  the first tokened request (the browser sends it with the websocket
  handshake), or ``Authorization: token <token>``.

viser has no public hook for this.  :func:`start_guarded_viser` starts a
:class:`viser.ViserServer` while viser's ``websockets.asyncio.server.serve``
call is redirected to one that wraps viser's ``process_request`` with
:meth:`AccessPolicy.refusal`.  Written against **viser 1.1.1** (its
``viser/infra/_infra.py`` calls ``websockets.asyncio.server.serve(...,
process_request=...)`` from the server thread) and websockets 16; the range
is pinned in ``pyproject.toml``.  If the hook point is gone, or a request
with a foreign Host is not refused right after start, the app refuses to
start (:class:`calib_core.errors.CalibError`), so a viser upgrade can never
silently drop the check.
"""

from __future__ import annotations

import hmac
import http
import ipaddress
import secrets
import socket
import threading
from dataclasses import dataclass, field
from typing import Any, Callable
from urllib.parse import parse_qs, urlsplit

from calib_core.errors import CalibError

#: The viser version the hook was written and tested against.
VISER_TESTED = "1.1.1"
LOOPBACK_NAMES = frozenset({"127.0.0.1", "localhost", "::1"})
WILDCARD_HOSTS = frozenset({"", "0.0.0.0", "::"})
TOKEN_QUERY = "token"

_START_LOCK = threading.Lock()


def is_loopback(host: str) -> bool:
    """True for a bind address that only this machine can reach (``127.0.0.0/8``, ``::1``, ``localhost``)."""
    h = host.strip().strip("[]").lower()
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


def split_host(value: str | None) -> tuple[str, int] | None:
    """``(lower-case host name, port)`` of a ``Host`` header value or a ``scheme://`` origin; None if malformed.

    A missing port is 80 (``http``).  IPv6 literals lose their brackets.
    """
    if value is None:
        return None
    value = value.strip()
    if not value or any(c.isspace() or c in "/?#@\\" for c in value):
        return None
    try:
        parts = urlsplit("//" + value)
        host, port = parts.hostname, parts.port
    except ValueError:
        return None
    if not host:
        return None
    return host.rstrip(".").lower(), 80 if port is None else int(port)


def cookie_name(port: int) -> str:
    """The token cookie of the server on ``port`` (cookies are per host, not per port)."""
    return f"ba-calib-token-{int(port)}"


@dataclass(frozen=True)
class AccessPolicy:
    """What a request must carry to be served."""

    bind_host: str  # the address the server was started on (--host)
    token: str | None = None  # the required secret, or None (loopback binds)
    # More host names the server may be reached by (e.g. a DNS name of a wildcard bind), lower case.
    extra_hosts: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def for_bind(cls, host: str, token: str | None = None, extra_hosts: tuple[str, ...] = ()) -> "AccessPolicy":
        """The policy for a server bound to ``host``: a random token unless it is a loopback address."""
        if token is None and not is_loopback(host):
            token = secrets.token_urlsafe(24)
        if token is not None and (len(token) < 16 or not token.isprintable() or any(c.isspace() for c in token)):
            raise CalibError("the access token must be at least 16 printable characters without spaces")
        return cls(host, token, frozenset(h.strip("[]").rstrip(".").lower() for h in extra_hosts))

    def allowed_hosts(self, local_ip: str | None) -> frozenset[str]:
        """Host names a request may name, given the local address the connection arrived on."""
        bind = self.bind_host.strip("[]").lower()
        names = set(self.extra_hosts)
        if is_loopback(bind):
            names |= LOOPBACK_NAMES
        elif bind in WILDCARD_HOSTS:
            # Any interface: the address this connection came in on, this machine's names, loopback.
            names |= LOOPBACK_NAMES | {socket.gethostname().lower(), socket.getfqdn().lower()}
            if local_ip:
                names.add(local_ip.lower())
        else:
            names.add(bind)
        return frozenset(names)

    def refusal(self, headers: Any, path: str, local_address: tuple | None) -> str | None:
        """Why a request must be refused, or None to serve it.

        Parameters
        ----------
        headers : mapping
            The request headers (``Host``, ``Origin``, ``Cookie``, ``Authorization``).
        path : str
            The request target (path and query string).
        local_address : tuple or None
            ``(ip, port, ...)`` of the server socket that accepted the connection.
        """
        if local_address is None:
            return "unknown local address"
        local_ip, local_port = str(local_address[0]), int(local_address[1])
        host = split_host(headers.get("Host"))
        if host is None:
            return "missing or malformed Host header"
        if host[1] != local_port or host[0] not in self.allowed_hosts(local_ip):
            return f"Host {headers.get('Host')!r} is not this server"
        origin = headers.get("Origin")
        if origin is not None:
            o = urlsplit(origin.strip()) if origin.strip().lower().startswith("http://") else None
            if o is None or o.path or o.query or split_host(o.netloc) != host:
                return f"Origin {origin!r} is not this server"
        if self.token is not None and not self._has_token(headers, path, local_port):
            return "missing or wrong access token (open the URL with ?token=... that ba-calib printed)"
        return None

    def token_in_query(self, path: str) -> bool:
        """True if the request target carries the right ``?token=``."""
        if self.token is None:
            return False
        values = parse_qs(urlsplit(path).query).get(TOKEN_QUERY, [])
        return any(hmac.compare_digest(v.encode(), self.token.encode()) for v in values)

    def _has_token(self, headers: Any, path: str, port: int) -> bool:
        assert self.token is not None
        if self.token_in_query(path):
            return True
        want = self.token.encode()
        auth = headers.get("Authorization") or ""
        if auth.lower().startswith("token ") and hmac.compare_digest(auth[6:].strip().encode(), want):
            return True
        name = cookie_name(port)
        for header in headers.get_all("Cookie") if hasattr(headers, "get_all") else [headers.get("Cookie") or ""]:
            for item in header.split(";"):
                key, _, value = item.strip().partition("=")
                if key == name and hmac.compare_digest(value.encode(), want):
                    return True
        return False


def guard_process_request(policy: AccessPolicy, inner: Callable | None,
                          on_refused: Callable[[str], None] | None = None) -> Callable:
    """A websockets ``process_request`` that applies ``policy`` before ``inner`` (viser's HTTP server)."""

    def process_request(connection: Any, request: Any) -> Any:
        try:
            reason = policy.refusal(request.headers, request.path, getattr(connection, "local_address", None))
        except Exception as exc:  # e.g. two Host headers: refuse, never serve on a header we could not read
            reason = f"malformed request headers ({type(exc).__name__})"
        if reason is not None:
            if on_refused is not None:
                on_refused(reason)
            return connection.respond(http.HTTPStatus.FORBIDDEN, f"403 Forbidden: {reason}\n")
        response = inner(connection, request) if inner is not None else None
        if response is not None and policy.token_in_query(request.path):
            # The page loaded with the token: the browser sends the cookie with the websocket handshake.
            port = int(connection.local_address[1])
            response.headers["Set-Cookie"] = (f"{cookie_name(port)}={policy.token}; Path=/; HttpOnly; "
                                              "SameSite=Strict")
        return response

    return process_request


class _Forward:
    """Attribute access forwarded to ``real``, except the names given (viser's view of ``websockets``)."""

    def __init__(self, real: Any, **overrides: Any) -> None:
        self._real = real
        self.__dict__.update(overrides)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


def start_guarded_viser(policy: AccessPolicy, on_refused: Callable[[str], None] | None = None,
                        **viser_kwargs: Any):
    """Start a :class:`viser.ViserServer` whose every request passes ``policy``; returns it.

    Raises
    ------
    CalibError
        The hook point is missing (a viser version this was not written
        for), or the started server serves a request it should refuse.
    """
    import viser
    from viser.infra import _infra

    real = getattr(_infra, "websockets", None)
    real_serve = getattr(getattr(getattr(real, "asyncio", None), "server", None), "serve", None)
    if real_serve is None:
        raise CalibError(_hook_missing(viser.__version__, "viser.infra._infra no longer uses websockets.asyncio."
                                                          "server.serve"))
    calls: list[bool] = []
    armed: list[bool] = []  # the start-up self-test's refusal is not reported

    def report(reason: str) -> None:
        if armed and on_refused is not None:
            on_refused(reason)

    def serve(*args: Any, process_request: Callable | None = None, **kwargs: Any) -> Any:
        calls.append(process_request is not None)
        return real_serve(*args, process_request=guard_process_request(policy, process_request, report), **kwargs)

    fake = _Forward(real, asyncio=_Forward(real.asyncio, server=_Forward(real.asyncio.server, serve=serve)))
    with _START_LOCK:  # one start at a time: the redirection is process-wide while it lasts
        _infra.websockets = fake
        try:
            server = viser.ViserServer(**viser_kwargs)
        finally:
            _infra.websockets = real
    if not calls or not calls[-1]:
        server.stop()
        raise CalibError(_hook_missing(viser.__version__, "viser did not start its server through the hook"))
    if not refuses_foreign_host(server.get_port(), viser_kwargs.get("host", "127.0.0.1")):
        server.stop()
        raise CalibError(_hook_missing(viser.__version__, "a request with a foreign Host header was served"))
    armed.append(True)
    return server


def _hook_missing(version: str, what: str) -> str:
    return (f"refusing to start: the request check could not be installed on viser {version} ({what}); "
            f"ba-calib's check was written for viser {VISER_TESTED}")


def refuses_foreign_host(port: int, bind_host: str, timeout: float = 5.0) -> bool:
    """True if the server on ``port`` answers a request with ``Host: evil.invalid`` by 403 (start-up self-test)."""
    addr = "127.0.0.1" if bind_host.strip("[]") in WILDCARD_HOSTS else bind_host.strip("[]")
    if addr == "localhost":
        addr = "127.0.0.1"
    try:
        with socket.create_connection((addr, port), timeout=timeout) as sock:
            sock.sendall(f"GET / HTTP/1.1\r\nHost: evil.invalid:{port}\r\nConnection: close\r\n\r\n".encode())
            head = sock.recv(64)
    except OSError:
        return False
    return head.startswith(b"HTTP/1.1 403")


class RefusalLog:
    """``on_refused`` callback: one stderr line per refused request, at most ``limit`` of them.

    Attributes
    ----------
    count : int
        Requests refused so far.
    """

    def __init__(self, limit: int = 20) -> None:
        self.limit = int(limit)
        self.count = 0
        self._lock = threading.Lock()

    def __call__(self, reason: str) -> None:
        import sys

        with self._lock:
            self.count += 1
            n = self.count
        if n <= self.limit:
            more = "; further refusals are not shown" if n == self.limit else ""
            print(f"ba-calib: refused a request: {' '.join(reason.split())}{more}", file=sys.stderr, flush=True)


def upload_display_name(name: Any, limit: int = 80) -> str:
    """A client-sent file name made safe to show: last path part, plain characters only, at most ``limit`` long."""
    text = str(name or "").replace("\\", "/").rsplit("/", 1)[-1].strip()
    text = "".join(ch if ch.isalnum() or ch in "._-+() " else "_" for ch in text)
    if text in ("", ".", ".."):
        text = "upload"
    return text if len(text) <= limit else text[: limit - 3] + "..."
