"""What the laser panes show: the BA loupe's image (BA as clicked, one BA direction, intensity, range), the last
pane's image (its BA direction, intensity or range), a contrast control for the laser panes and the loupe, the
BA-edge overlay's opacity, and "Hide marks" (every mark off, to see the corner under it).  Grey levels come from
:mod:`calib_core.display_images` and :func:`calib_core.bearing_angle.ba_to_display`."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from calib_core.display_images import apply_contrast

from .settled_updates import settled
from .ui_common import BA_TITLES
from .view_settings import AS_CLICKED


class DisplayPanel:
    """What the laser panes of one :class:`app.server.CalibrationApp` show (``app.display``).

    It owns the grey images as shown (contrast applied) and its widgets, which
    the loupes place in their folder (:meth:`add_loupe_controls`) and the view panel in
    the View folder (:meth:`add_last_pane_control`, :meth:`add_edge_control`).
    Public: :meth:`ba_display`, :meth:`ba_title`,
    :meth:`loupe_image`, :meth:`loupe_sources`, :attr:`loupe_source`,
    :meth:`last_pane_sources`, :attr:`last_pane_source`, :attr:`edge_opacity`,
    :meth:`subscribe` (what shows the laser panes redraws on its changes)
    and the widgets' handlers (``on_*``).
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        self._shown_gray: dict[str, np.ndarray] = {}
        self._listeners: list[Callable[[str], None]] = []
        self._recontrast()

    def subscribe(self, listener: Callable[[str], None]) -> None:
        """Call ``listener(what)`` after each change of what the laser panes show, on the changing thread:
        ``"loupe"`` (the BA loupe's image), ``"last_pane"`` (the last laser pane's image and title),
        ``"contrast"`` (every laser pane's grey levels; called under the UI lock), ``"marks"`` ("Hide marks")
        or ``"edges"`` (the BA-edge overlay's opacity)."""
        self._listeners.append(listener)

    def _publish(self, what: str) -> None:
        for listener in list(self._listeners):
            listener(what)

    def add_loupe_controls(self, gui: Any) -> None:
        """The "BA loupe shows", "Laser contrast" and "Hide marks" widgets, where ``gui`` adds now."""
        guard, view = self.app.guard, self.app.state.view
        self._dd_loupe_source = gui.add_dropdown(
            "BA loupe shows", self.loupe_sources(), initial_value=self.loupe_source,
            hint="The BA image last clicked, one BA direction, the scan's intensity (if it has one) or range")
        self._dd_loupe_source.on_update(guard(self.on_loupe_source))
        self._sl_contrast = gui.add_slider("Laser contrast", 0.5, 3.0, 0.25, initial_value=view.contrast,
                                           hint="Contrast of the BA images and the BA loupe")
        self._sl_contrast.on_update(settled(guard(self.on_contrast)))  # a typed number applies once typed
        self._cb_hide_marks = gui.add_checkbox(
            "Hide marks", initial_value=view.hide_marks,
            hint="Hide the pair markers, their numbers and the overlays on the images and in the loupes, "
                 "to see the corner under them")
        self._cb_hide_marks.on_update(guard(self.on_hide_marks))

    def add_last_pane_control(self, gui: Any) -> None:
        """The "Last laser pane" dropdown, where ``gui`` adds now."""
        self._dd_last_pane = gui.add_dropdown(
            "Last laser pane", self.last_pane_sources(), initial_value=self.last_pane_source,
            hint="What the bottom laser pane shows: its BA direction, the scan's intensity (if it has one) or "
                 "range; clicks on it pick the same cells")
        self._dd_last_pane.on_update(self.app.guard(self.on_last_pane_source))

    def add_edge_control(self, gui: Any) -> None:
        """The "BA-edge opacity" slider, where ``gui`` adds now."""
        self._sl_edge_opacity = gui.add_slider("BA-edge opacity", 0.0, 1.0, 0.1,
                                               initial_value=self.app.state.view.edge_opacity)
        self._sl_edge_opacity.on_update(settled(self.app.guard(self.on_edge_opacity)))

    def loupe_sources(self) -> tuple[str, ...]:
        """The choices of what the BA loupe shows."""
        app = self.app
        return (AS_CLICKED, *(BA_TITLES.get(k, k) for k in app.ba_keys), *app.scene_data.laser_images)

    def _recontrast(self) -> None:
        app = self.app
        images = {k: app.ba_gray[k] for k in app.ba_keys} | dict(app.scene_data.laser_images)
        contrast = app.state.view.contrast
        self._shown_gray = {k: apply_contrast(g, contrast) for k, g in images.items()}

    def last_pane_sources(self) -> tuple[str, ...]:
        """The choices of what the last laser pane shows: its BA direction, then the scene's other laser images."""
        return (BA_TITLES.get(self.app.ba_keys[-1], self.app.ba_keys[-1]), *self.app.scene_data.laser_images)

    @property
    def last_pane_source(self) -> str:
        """What the last laser pane shows (the saved choice if this scene has that image, else its BA direction)."""
        source = self.app.state.view.last_pane_shows
        return source if source in self.app.scene_data.laser_images else self.last_pane_sources()[0]

    def _pane_image_name(self, key: str) -> str:
        """The name of the grey image pane ``key`` shows: ``key`` itself, or a laser image on the last pane."""
        if key == self.app.ba_keys[-1] and self.last_pane_source in self.app.scene_data.laser_images:
            return self.last_pane_source
        return key

    def ba_display(self, key: str) -> np.ndarray:
        """The grey image shown in laser pane ``key`` ``(rows, cols)`` uint8 (contrast applied): its BA
        direction, or on the last pane the chosen laser image.  Clicks on it pick the same cells either way."""
        return self._shown_gray[self._pane_image_name(key)]

    def ba_title(self, key: str) -> str:
        """The name of what laser pane ``key`` shows (e.g. ``BA +45 deg``, ``Intensity``)."""
        name = self._pane_image_name(key) if key in self.app.ba_keys else key
        return BA_TITLES.get(name, name)

    def loupe_image(self, key: str) -> tuple[np.ndarray, str]:
        """The BA loupe's grey image and its name, when the last BA click was on direction ``key``."""
        source = self.loupe_source
        if source == AS_CLICKED:
            return self.ba_display(key), self.ba_title(key)
        for k in self.app.ba_keys:
            if BA_TITLES.get(k, k) == source:
                return self._shown_gray[k], source
        return self._shown_gray[source], source

    @property
    def loupe_source(self) -> str:
        """What the BA loupe shows (the saved choice if this scene has it, else :data:`AS_CLICKED`)."""
        source = self.app.state.view.loupe_shows
        return source if source in self.loupe_sources() else AS_CLICKED

    @property
    def edge_opacity(self) -> float:
        """Opacity of the BA-edge overlay on the camera view (0 hides it)."""
        return self.app.state.view.edge_opacity

    def on_loupe_source(self, event: Any) -> None:
        """The "BA loupe shows" dropdown."""
        if event.client is None:
            return
        source = str(event.value)
        if source not in self.loupe_sources():
            return
        self.app.state.set_view(loupe_shows=source)
        self._publish("loupe")

    def on_last_pane_source(self, event: Any) -> None:
        """The "Last laser pane" dropdown: the bottom pane's image (its texture, title and the loupe follow)."""
        if event.client is None:
            return
        source = str(event.value)
        if source not in self.last_pane_sources():
            return
        self.app.state.set_view(last_pane_shows=source if source in self.app.scene_data.laser_images else "")
        self._publish("last_pane")

    def on_contrast(self, event: Any) -> None:
        """The "Laser contrast" slider: new grey levels for the laser panes and the BA loupe."""
        if event.client is None or event.value != event.target.value:
            return  # our own update, or a newer slider position is queued behind this one
        self.app.state.set_view(contrast=float(event.value))  # clipped to CONTRAST_RANGE
        with self.app.ui_lock:
            self._recontrast()
            self._publish("contrast")

    def on_hide_marks(self, event: Any) -> None:
        """The "Hide marks" checkbox: every mark on the images and in the loupes off (or back)."""
        if event.client is None:
            return
        self.app.state.set_view(hide_marks=bool(event.value))
        self._publish("marks")

    def on_edge_opacity(self, event: Any) -> None:
        """The "BA-edge opacity" slider."""
        if event.client is None or event.value != event.target.value:
            return
        self.app.state.set_view(edge_opacity=float(event.value))  # clipped to EDGE_OPACITY_RANGE
        self._publish("edges")
