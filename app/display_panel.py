"""The widgets of what the laser panes show: the BA loupe's image (BA as clicked, one BA direction, intensity,
range), the last pane's image (its BA direction, intensity or range), a contrast control for the laser panes and the
loupe, the BA-edge overlay's opacity, and "Hide marks" (every mark off, to see the corner under it).  The images as
shown are the app's ``laser_images`` service (:mod:`app.laser_images`)."""

from __future__ import annotations

from typing import Any, Callable

from .settled_updates import settled


class DisplayPanel:
    """What the laser panes of one :class:`app.server.CalibrationApp` show (``app.display``).

    It owns its widgets, which the loupes place in their folder
    (:meth:`add_loupe_controls`) and the view panel in the View folder
    (:meth:`add_last_pane_control`, :meth:`add_edge_control`); the images they
    choose are the ``laser_images`` service.
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        self._listeners: list[Callable[[str], None]] = []

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
            "BA loupe shows", self.app.laser_images.loupe_sources(), initial_value=self.app.laser_images.loupe_source,
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
            "Last laser pane", self.app.laser_images.last_pane_sources(),
            initial_value=self.app.laser_images.last_pane_source,
            hint="What the bottom laser pane shows: its BA direction, the scan's intensity (if it has one) or "
                 "range; clicks on it pick the same cells")
        self._dd_last_pane.on_update(self.app.guard(self.on_last_pane_source))

    def add_edge_control(self, gui: Any) -> None:
        """The "BA-edge opacity" slider, where ``gui`` adds now."""
        self._sl_edge_opacity = gui.add_slider("BA-edge opacity", 0.0, 1.0, 0.1,
                                               initial_value=self.app.state.view.edge_opacity)
        self._sl_edge_opacity.on_update(settled(self.app.guard(self.on_edge_opacity)))

    @property
    def edge_opacity(self) -> float:
        """Opacity of the BA-edge overlay on the camera view (0 hides it)."""
        return self.app.state.view.edge_opacity

    def on_loupe_source(self, event: Any) -> None:
        """The "BA loupe shows" dropdown."""
        if event.client is None:
            return
        source = str(event.value)
        if source not in self.app.laser_images.loupe_sources():
            return
        self.app.state.set_view(loupe_shows=source)
        self._publish("loupe")

    def on_last_pane_source(self, event: Any) -> None:
        """The "Last laser pane" dropdown: the bottom pane's image (its texture, title and the loupe follow)."""
        if event.client is None:
            return
        source = str(event.value)
        if source not in self.app.laser_images.last_pane_sources():
            return
        self.app.state.set_view(last_pane_shows=source if source in self.app.scene_data.laser_images else "")
        self._publish("last_pane")

    def on_contrast(self, event: Any) -> None:
        """The "Laser contrast" slider: new grey levels for the laser panes and the BA loupe."""
        if event.client is None or event.value != event.target.value:
            return  # our own update, or a newer slider position is queued behind this one
        self.app.state.set_view(contrast=float(event.value))  # clipped to CONTRAST_RANGE
        with self.app.ui_lock:
            self.app.laser_images.recontrast()
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
