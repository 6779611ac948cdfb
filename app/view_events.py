"""What the view panel (:class:`app.view_panel.ViewPanel`) publishes: the BA column window and the page layout
shown, the camera view shown, whether some tab shows the 3-D view; and each tab's last click, which it learns from
the pairs panel's click events (for "Zoom on last click").  The composition root wires the subscribers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable


@dataclass(frozen=True)
class BaWindowShown:
    """What the BA images show after the column window or the page layout changed (the page places them): by BA
    key, the texture (cut to the window, enlarged), the title and the page slot."""

    textures: dict
    titles: dict
    slots: dict


class ViewEvents:
    """The view panel's events and per-tab click memory (its base class)."""

    def __init__(self) -> None:
        self._last_click: dict[int, tuple] = {}  # client id -> ("ba", key, row, col) or ("camera", u, v)
        self._window_listeners: list[Callable[[BaWindowShown], None]] = []
        self._layout_listeners: list[Callable[[bool], None]] = []
        self._camera_view_listeners: list[Callable[[str, Any, str], None]] = []
        self._3d_listeners: list[Callable[[bool], None]] = []

    def subscribe_window(self, listener: Callable[[BaWindowShown], None]) -> None:
        """Call ``listener(shown)`` when the BA column window or the page layout changed, under the UI lock and in
        the change's message batch (the page's images and the render follow the new slots)."""
        self._window_listeners.append(listener)

    def subscribe_layout(self, listener: Callable[[bool], None]) -> None:
        """Call ``listener(moved)`` after that, outside the message batch, and after the overlays shown on the camera
        view changed: ``moved`` when the slots changed size or place (not only the first column shown), e.g. the
        marks are redrawn, the loupes placed beside the images."""
        self._layout_listeners.append(listener)

    def _publish_layout(self, moved: bool) -> None:
        for listener in list(self._layout_listeners):
            listener(moved)

    def subscribe_camera_view(self, listener: Callable[[str, Any, str], None]) -> None:
        """Call ``listener(key, slot, title)`` to show camera view ``key`` (hiding the other) at ``slot``."""
        self._camera_view_listeners.append(listener)

    def subscribe_3d(self, listener: Callable[[bool], None]) -> None:
        """Call ``listener(shown)`` whenever a tab changes view or closes: ``shown``, some tab shows the 3-D view."""
        self._3d_listeners.append(listener)

    def on_pair_click(self, click: Any) -> None:
        """Remember each tab's last applied click (:meth:`app.pairs_panel.PairsPanel.subscribe_clicks`)."""
        if click.pick_id is not None and click.client_id is not None:
            self._last_click[click.client_id] = click.target

    def last_click(self, client_id: int) -> tuple | None:
        """Tab ``client_id``'s last click: ``("ba", key, row, col)`` or ``("camera", u, v)``, or None."""
        return self._last_click.get(client_id)
