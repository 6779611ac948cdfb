"""What a panel may use of the app: the public services of :class:`app.server.CalibrationApp`.

Panels (:mod:`app.guide_panel`, :mod:`app.verify_panel`, :mod:`app.export_panel`,
:mod:`app.loupes`, ...) get the app as their ``app`` argument and use only
these names, never its private members, so the app's insides can change
without touching them.  :class:`AppServices` is a structural type: the app
satisfies it, a test may pass anything else that does.
"""

from __future__ import annotations

import threading
from typing import Any, Callable, Protocol

import numpy as np

from .state import AnnotationState


class AppServices(Protocol):
    """The services of the app that panels use.

    Attributes
    ----------
    server : viser.ViserServer
        The running server (its ``gui`` and ``scene``).
    state : AnnotationState
        The pairs and the view settings (``state.view``); every change goes through it.
    ui_lock : threading.RLock
        Held while the scene and the panels are redrawn; hold it to read or change several widgets at once.
    depth, camera, image
        The scan's depth matrix, the camera model and the camera image (original pixels).
    ba_keys : tuple of str
        The BA directions shown, in page order.
    slots : dict
        Where each image lies on the page (:class:`app.layout.ImageSlot`), by key.
    camera_sizes : dict
        ``(width, height)`` of each camera view (``raw``, ``panorama``), by key.
    wrap_cols : bool
        The scan's last column is next to its first (a 360 degree scan).
    """

    server: Any
    state: AnnotationState
    ui_lock: threading.RLock
    depth: Any
    camera: Any
    image: np.ndarray
    ba_keys: tuple[str, ...]
    slots: dict
    camera_sizes: dict[str, tuple[int, int]]
    wrap_cols: bool

    def guard(self, fn: Callable[[Any], None]) -> Callable:
        """A viser callback that queues ``fn(action)`` on the ordered action worker (errors become notifications)."""

    def post(self, fn: Callable[[], Any], client: Any = None, wait: bool = False) -> None:
        """Run ``fn()`` on the action worker, after the actions queued before it."""

    def notify(self, client: Any, title: str, body: str, color: str = "red") -> None:
        """A notification in tab ``client`` (None: every tab)."""

    def camera_slot(self) -> Any:
        """The page slot of the visible camera view."""

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display pixels of original camera pixels in the visible camera view, and which are shown."""

    def make_click_handler(self, key: str) -> Callable:
        """The on-click callback of image slot ``key`` (adds or moves a pair end)."""

    def make_select_handler(self, key: str) -> Callable:
        """The Shift+click callback of image slot ``key`` (selects the nearest pair)."""

    def camera_click_source(self, pick_id: int) -> str | None:
        """Where the last camera click on pick ``pick_id`` landed: ``"loupe"``, ``"full"`` or None."""

    def forget_last_picks(self) -> None:
        """Forget every tab's last click (the next loupe click adds an end)."""
