"""Helpers shared by the app and headless-Chromium tests (not a test module)."""

from __future__ import annotations

import contextlib
import io
import itertools
import math
import os
import socket
import time
from pathlib import Path

import numpy as np
import pytest
from repo_paths import SAMPLE

#: Debian's chromium; browser downloads fail on these machines.
CHROMIUM = Path("/usr/bin/chromium")
#: Flags that let Chromium run headless as root with no network but loopback.
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
TIMEOUT_S = 30.0


#: Under pytest-xdist each worker takes its ports from its own block below Linux's ephemeral range (32768 and
#: up), so that a port found free here cannot be handed to another worker (as ``bind(0)`` could) before the
#: server binds it; viser would then silently serve on the next port.
_WORKER_PORT_BASE, _WORKER_PORT_BLOCK, _WORKER_PORT_BLOCKS = 20000, 400, 30
_worker_ports = itertools.count()


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now (one of this pytest-xdist worker's own, if any)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")  # "gw0", "gw1", ...
    if worker[:2] == "gw" and worker[2:].isdigit() and int(worker[2:]) < _WORKER_PORT_BLOCKS:
        first = _WORKER_PORT_BASE + int(worker[2:]) * _WORKER_PORT_BLOCK
        for _ in range(_WORKER_PORT_BLOCK):
            port = first + next(_worker_ports) % _WORKER_PORT_BLOCK
            with socket.socket() as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:  # in use (or still closing): the next one
                    continue
                return port
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_sample_app(tmp_path: Path, pairs, session_path: Path | None = None):
    """``(app, AppDriver)``: the app on the committed sample, ``pairs`` imported through the pairs upload.

    The import must be acknowledged ("Pairs imported") and solved before this returns; the caller
    stops the app (it is stopped here if the import fails).
    """
    from app.server import CalibrationApp
    from app_driver import AppDriver
    from calib_core.pairs import save_pairs_yaml

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=session_path or tmp_path / "session.yaml", port=free_port())
    try:
        driver = AppDriver(app)
        pairs_file = tmp_path / "pairs.yaml"
        save_pairs_yaml(pairs_file, pairs)
        notes = driver.upload_pairs("pairs.yaml", pairs_file.read_bytes())
        assert [t for t, _ in notes] == ["Pairs imported"], notes
        assert driver.wait_idle() and app.result is not None
    except BaseException:
        app.stop()
        raise
    return app, driver


@contextlib.contextmanager
def open_sample_tab(tmp_path: Path, viewport: dict, n_pairs: int = 6):
    """``(app, driver, tab)``: :func:`start_sample_app` with the sample's first ``n_pairs`` pairs and an
    :class:`AnnotationTab` of size ``viewport`` on it; the browser and the app are stopped on leaving.  Skips the
    test when the playwright package is not installed."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    from calib_core.pairs import load_pairs_yaml

    app, driver = start_sample_app(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml")[:n_pairs])
    try:
        with sync_api.sync_playwright() as p:
            yield app, driver, AnnotationTab(p, app, viewport)
    finally:
        app.stop()


def wait_for(condition, what: str, timeout: float = TIMEOUT_S, interval: float = 0.05):
    """Poll ``condition()`` until it returns something truthy; fail naming ``what``."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(interval)


def save_small_png(png: bytes, path: Path, max_bytes: int = 300_000) -> int:
    """Save a screenshot as a palette PNG (under ``max_bytes`` when 64 colours allow); returns its size in bytes."""
    from PIL import Image

    img = Image.open(io.BytesIO(png)).convert("RGB")
    for colors in (256, 128, 64):
        buf = io.BytesIO()
        img.quantize(colors=colors, method=Image.Quantize.MEDIANCUT).save(buf, format="PNG", optimize=True)
        if buf.tell() < max_bytes:
            break
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(buf.getvalue())
    return len(buf.getvalue())


def page_text(page) -> str:
    """The page's visible text, whitespace collapsed."""
    return " ".join(page.inner_text("body").split())


class WebGLNotice:
    """viser's "Software WebGL rendering detected" notice on ``page`` (headless Chromium renders in software): it
    covers the panel's lower end and swallows clicks.  viser checks WebGL once per load of its page and logs it
    ("WebGL support: ..."); the page closes the notice itself and logs that too (``app.page_builder.ESCAPE_JS``),
    often before the tab's view is set.  Made before ``page.goto``, to hear both."""

    def __init__(self, page) -> None:
        self.page, self.loads, self.closed = page, 0, 0
        page.on("console", self._on_console)

    def _on_console(self, message) -> None:
        if message.text.startswith("WebGL support:"):
            self.loads += 1
        elif message.text.startswith("ba-calib: ") and "Software WebGL" in message.text:
            self.closed += 1

    def wait_closed(self, timeout: float = 5.0) -> None:
        """Wait until the page has closed the notice of every load of viser's page (up to ``timeout`` s: a tab with
        hardware WebGL gets none; a reconnected tab, not loaded again, gets no new one), then until none is shown."""
        deadline = time.monotonic() + timeout
        while not (self.loads and self.closed >= self.loads) and time.monotonic() < deadline:
            self.page.wait_for_timeout(50)  # (playwright delivers console events while it runs)
        notice = self.page.locator(".mantine-Notification-root", has_text="Software WebGL")
        notice.first.wait_for(state="detached", timeout=TIMEOUT_S * 1000)


class AnnotationTab:
    """A headless-Chromium tab on a running app, connected, its annotation view set, the WebGL notice closed.

    ``screen(target, uv)`` is the page position of pixel ``uv`` of a view (``"camera"``, a BA key,
    ``"loupe_ba"``, ``"loupe_camera"``), from the camera the tab reported (:meth:`app_driver.AppDriver.page_position`).
    """

    def __init__(self, playwright, app, viewport: dict, **page_options) -> None:
        from app_driver import AppDriver

        self.app, self.driver = app, AppDriver(app)
        self.browser = playwright.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        self.page = self.browser.new_page(viewport=viewport, **page_options)
        notice = WebGLNotice(self.page)
        self.page.goto(app.url)
        self.cid = wait_for(lambda: self.driver.client_ids(), "the tab to connect")[0]
        wait_for(lambda: app.view.view_settled(self.cid), "the annotation view to be set")
        notice.wait_closed()  # it swallows clicks
        self.box = self.page.locator("canvas").first.bounding_box()
        assert self.box is not None

    def screen(self, target: str, uv) -> tuple[float, float]:
        fx, fy = self.driver.page_position(self.cid, target, uv)
        assert 0.0 < fx < 1.0 and 0.0 < fy < 1.0, f"{target} {uv} is off screen"
        return self.box["x"] + fx * self.box["width"], self.box["y"] + fy * self.box["height"]

    def scale(self, target: str, uv) -> float:
        """Screen px per BA cell (column step) or per image pixel at ``uv`` of ``target``."""
        import numpy as np

        a, b = np.array(self.screen(target, uv)), np.array(self.screen(target, (uv[0] + 1.0, uv[1])))
        return float(np.hypot(*(b - a)))

    def shows_image_at(self, points) -> bool:
        """True once every ``(target, uv)`` of ``points`` shows something other than the light-grey backdrop."""
        import numpy as np
        from PIL import Image

        for target, uv in points:
            x, y = self.screen(target, uv)
            shot = self.page.screenshot(clip={"x": x - 2, "y": y - 2, "width": 4, "height": 4})
            rgb = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB"), dtype=float).reshape(-1, 3)
            if np.abs(rgb.mean(axis=0) - 238.0).max() < 12:
                return False
        return True


def screen_rect(camera, canvas: dict, bounds) -> tuple[float, float, float, float]:
    """Screen rectangle (CSS px) of a world rectangle on the annotation plane, as the tab's camera shows it."""
    import viser.transforms as vtf

    x0, y0, x1, y1 = bounds
    corners = np.array([[x0, y0, 0.0], [x1, y1, 0.0]])
    R = vtf.SO3(np.asarray(camera.wxyz)).as_matrix()  # viser's camera frame: +z forward, +y down (OpenCV)
    local = (corners - np.asarray(camera.position)) @ R
    f = (camera.image_height / 2) / math.tan(camera.fov / 2)
    u = f * local[:, 0] / local[:, 2] + camera.image_width / 2
    v = f * local[:, 1] / local[:, 2] + camera.image_height / 2
    sx, sy = canvas["width"] / camera.image_width, canvas["height"] / camera.image_height
    return (canvas["x"] + u[0] * sx, canvas["y"] + v[0] * sy, canvas["x"] + u[1] * sx, canvas["y"] + v[1] * sy)
