"""The kernels are compiled in the background: the first page never waits for them (issue 12)."""

from __future__ import annotations

import http.client
import threading

import calib_core.solve
from browser_helpers import free_port
from repo_paths import SAMPLE


def test_first_page_is_served_while_the_warm_up_still_runs(tmp_path, monkeypatch):
    from app.server import CalibrationApp

    release, started, ran_on = threading.Event(), threading.Event(), []

    def slow_warm_up():  # stands in for a long JIT compile
        ran_on.append(threading.current_thread())
        started.set()
        assert release.wait(60)
        return 0.0

    monkeypatch.setattr(calib_core.solve, "warm_up", slow_warm_up)
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", port=free_port())
    try:
        assert started.wait(60), "the solve warm-up was never called"
        assert not app.warm_up.done
        conn = http.client.HTTPConnection("127.0.0.1", app.port, timeout=10)
        conn.request("GET", "/")
        response = conn.getresponse()
        assert response.status == 200 and b"<html" in response.read().lower()
        conn.close()
        assert not app.warm_up.done  # the page came while the compile was still going
        assert ran_on[0] is not threading.main_thread() and ran_on[0].daemon
    finally:
        release.set()
        assert app.warm_up.wait(60) and app.warm_up.error is None
        assert "calib_core.solve" in app.warm_up.seconds
        app.stop()
