"""Stand-ins for a viser client handle (a browser tab) that :class:`app_driver.AppDriver` drives the app with.

They record what the app sends to the tab (notifications, downloads, modal questions) and carry a
camera like the one viser reports, so that tests read what a person would see.
"""

from __future__ import annotations

import contextlib
import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

_CLIENT_IDS = itertools.count(10_000)


class _FakeWidget:
    """A GUI element the app made for one tab: its label, content and click callback."""

    def __init__(self, kind: str, label: str = "", content: str = "") -> None:
        self.kind, self.label, self.content = kind, label, content
        self.callbacks: list[Any] = []
        self.closed = False

    def on_click(self, cb: Any) -> Any:
        self.callbacks.append(cb)
        return cb

    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> "_FakeWidget":
        return self

    def __exit__(self, *exc: Any) -> None:
        return None


class FakeGui:
    """A GUI without a browser: records the modals (questions) the app opens in one tab, with their text and
    buttons; folders and markdown keep their content (enough for the calibration panel)."""

    def __init__(self) -> None:
        self.modals: list[tuple[_FakeWidget, list[_FakeWidget]]] = []

    def add_modal(self, title: str, **kwargs: Any) -> _FakeWidget:
        modal = _FakeWidget("modal", title)
        self.modals.append((modal, []))
        return modal

    def add_folder(self, label: str, **kwargs: Any) -> _FakeWidget:
        return _FakeWidget("folder", label)

    def add_markdown(self, content: str, **kwargs: Any) -> _FakeWidget:
        w = _FakeWidget("markdown", content=content)
        if self.modals:
            self.modals[-1][1].append(w)
        return w

    def add_button(self, label: str, **kwargs: Any) -> _FakeWidget:
        w = _FakeWidget("button", label)
        if self.modals:
            self.modals[-1][1].append(w)
        return w


@dataclass
class FakeCamera:
    """The parts of a viser client camera the app reads and sets (a 1400 x 900 canvas)."""

    position: tuple = (0.0, 0.0, -10.0)
    look_at: tuple = (0.0, 0.0, 0.0)
    up_direction: tuple = (0.0, -1.0, 0.0)
    fov: float = 0.5
    image_width: int = 1400
    image_height: int = 900
    update_callbacks: list = field(default_factory=list)  # what the app registered with on_update (never called)

    def on_update(self, callback: Any) -> Any:
        self.update_callbacks.append(callback)
        return callback

    def screen_of(self, world) -> tuple[float, float]:
        """Canvas pixel of a world point on the annotation plane, for a camera looking along +z (as the app sets)."""
        dist = self.look_at[2] - self.position[2]
        f = (self.image_height / 2) / np.tan(self.fov / 2)
        return (self.image_width / 2 + f * (world[0] - self.position[0]) / dist,
                self.image_height / 2 + f * (world[1] - self.position[1]) / dist)


@dataclass(eq=False)
class FakeTab:
    """Stands in for a viser client handle: records what the app sends to this tab."""

    client_id: int = field(default_factory=lambda: next(_CLIENT_IDS))
    notifications: list[tuple[str, str]] = field(default_factory=list)
    downloads: list[tuple[str, bytes]] = field(default_factory=list)
    gui: FakeGui = field(default_factory=FakeGui)
    camera: FakeCamera = field(default_factory=FakeCamera)

    def add_notification(self, title: str, body: str, **kwargs: Any) -> None:
        self.notifications.append((str(title), str(body)))

    def send_file_download(self, name: str, data: bytes, **kwargs: Any) -> None:
        self.downloads.append((name, bytes(data)))

    def atomic(self):
        return contextlib.nullcontext()
