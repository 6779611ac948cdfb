"""The app's public services for panels (app/app_services.py): present on the app, and doing what they say."""

from __future__ import annotations

import inspect

import pytest

from app.app_services import AppServices
from app_driver import AppDriver, FakeTab
from calib_core.errors import CalibError
from browser_helpers import free_port
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    from app.server import CalibrationApp

    tmp = tmp_path_factory.mktemp("services")
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp / "session.yaml", port=free_port())
    try:
        yield app
    finally:
        app.stop()


def test_the_app_has_every_service_the_panels_are_promised(app):
    names = set(AppServices.__annotations__) | {n for n, v in vars(AppServices).items() if inspect.isfunction(v)}
    assert {"guard", "post", "notify", "ui_lock", "wrap_cols", "camera_sizes"} <= names
    missing = sorted(n for n in names if not hasattr(app, n))
    assert missing == []
    assert set(app.camera_sizes) == set(app.camera_views) and app.camera_slot().key in app.camera_sizes


def test_post_runs_in_order_and_turns_a_refusal_into_a_notification_for_its_tab(app):
    tab, other = FakeTab(), FakeTab()
    seen: list[int] = []

    def refuse() -> None:
        raise CalibError("that is not allowed here")

    app.post(lambda: seen.append(1), client=tab)
    app.post(refuse, client=tab)
    app.post(lambda: seen.append(2), client=tab, wait=True)
    assert seen == [1, 2]  # the refusal in between stopped nothing
    assert tab.notifications == [("Not accepted", "that is not allowed here")] and other.notifications == []
    app.notify(other, "Hello", "a  message\non two lines", color="blue")
    assert other.notifications == [("Hello", "a message on two lines")]


def test_the_last_camera_click_source_is_reported_and_can_be_forgotten(app):
    driver = AppDriver(app)
    app.state.clear()
    driver.click_cell(app.ba_keys[0], 20, 60)
    assert driver.click_camera(300.0, 200.0) == []
    pick = app.state.picks[-1]
    assert pick.complete and app.camera_click_source(pick.id) == "full"
    app.forget_last_picks()
    assert app.camera_click_source(pick.id) is None


def test_the_ui_lock_knows_which_thread_holds_it():
    """app.ui_lock is re-entrant and tells its holder from other threads (a holder must not wait for a redraw)."""
    import threading

    from app.app_services import UiLock

    lock = UiLock()
    seen = {}

    def other():
        seen["held_here"] = lock.held_here()
        seen["acquired"] = lock.acquire(timeout=0.05)
        try:
            lock.release()
        except RuntimeError as exc:
            seen["release"] = str(exc)

    assert not lock.held_here()
    with lock:
        with lock:  # re-entrant
            assert lock.held_here()
        assert lock.held_here()  # still held after the inner exit
        t = threading.Thread(target=other)
        t.start()
        t.join()
    assert not lock.held_here()
    assert seen == {"held_here": False, "acquired": False, "release": "UiLock released by a thread that does not hold it"}
    assert lock.acquire(blocking=False)  # free again
    lock.release()
