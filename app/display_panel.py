"""What the laser panes show: the BA loupe's image (BA as clicked, one BA direction, intensity, range), the last
pane's image (its BA direction, intensity or range), a contrast control for the laser panes and the loupe, and the
BA-edge overlay's opacity.  Grey levels come from
:mod:`calib_core.display_images` and :func:`calib_core.bearing_angle.ba_to_display`."""

from __future__ import annotations

from typing import Any

import numpy as np

from calib_core.display_images import apply_contrast

from .ba_view import ba_texture, texture_factor
from .ui_common import BA_TITLES
from .view_settings import AS_CLICKED



class DisplayPanel:
    """Part of :class:`app.server.CalibrationApp` (a mixin: it uses the app's attributes)."""

    def _init_display(self) -> None:
        self._shown_gray: dict[str, np.ndarray] = {}
        self._recontrast()

    def loupe_sources(self) -> tuple[str, ...]:
        """The choices of what the BA loupe shows."""
        return (AS_CLICKED, *(BA_TITLES.get(k, k) for k in self.ba_keys), *self.scene_data.laser_images)

    def _recontrast(self) -> None:
        images = {k: self.ba_gray[k] for k in self.ba_keys} | dict(self.scene_data.laser_images)
        contrast = self.state.view.contrast
        self._shown_gray = {k: apply_contrast(g, contrast) for k, g in images.items()}

    def last_pane_sources(self) -> tuple[str, ...]:
        """The choices of what the last laser pane shows: its BA direction, then the scene's other laser images."""
        return (BA_TITLES.get(self.ba_keys[-1], self.ba_keys[-1]), *self.scene_data.laser_images)

    @property
    def last_pane_source(self) -> str:
        """What the last laser pane shows (the saved choice if this scene has that image, else its BA direction)."""
        source = self.state.view.last_pane_shows
        return source if source in self.scene_data.laser_images else self.last_pane_sources()[0]

    def _pane_image_name(self, key: str) -> str:
        """The name of the grey image pane ``key`` shows: ``key`` itself, or a laser image on the last pane."""
        if key == self.ba_keys[-1] and self.last_pane_source in self.scene_data.laser_images:
            return self.last_pane_source
        return key

    def ba_display(self, key: str) -> np.ndarray:
        """The grey image shown in laser pane ``key`` ``(rows, cols)`` uint8 (contrast applied): its BA
        direction, or on the last pane the chosen laser image.  Clicks on it pick the same cells either way."""
        return self._shown_gray[self._pane_image_name(key)]

    def ba_title(self, key: str) -> str:
        """The name of what laser pane ``key`` shows (e.g. ``BA +45 deg``, ``Intensity``)."""
        name = self._pane_image_name(key) if key in self.ba_keys else key
        return BA_TITLES.get(name, name)

    def loupe_image(self, key: str) -> tuple[np.ndarray, str]:
        """The BA loupe's grey image and its name, when the last BA click was on direction ``key``."""
        source = self.loupe_source
        if source == AS_CLICKED:
            return self.ba_display(key), self.ba_title(key)
        for k in self.ba_keys:
            if BA_TITLES.get(k, k) == source:
                return self._shown_gray[k], source
        return self._shown_gray[source], source

    @property
    def loupe_source(self) -> str:
        """What the BA loupe shows (the saved choice if this scene has it, else :data:`AS_CLICKED`)."""
        source = self.state.view.loupe_shows
        return source if source in self.loupe_sources() else AS_CLICKED

    @property
    def edge_opacity(self) -> float:
        """Opacity of the BA-edge overlay on the camera view (0 hides it)."""
        return self.state.view.edge_opacity

    def _on_loupe_source(self, event: Any) -> None:
        if event.client is None:
            return
        source = str(event.value)
        if source not in self.loupe_sources():
            return
        self.state.set_view(loupe_shows=source)
        self.loupes.refresh()

    def _on_last_pane_source(self, event: Any) -> None:
        if event.client is None:
            return
        source = str(event.value)
        if source not in self.last_pane_sources():
            return
        self.state.set_view(last_pane_shows=source if source in self.scene_data.laser_images else "")
        key = self.ba_keys[-1]
        with self.ui_lock:
            self._image_handles[key].image = self._ba_texture(key)
            self._ba_titles[key].text = self._ba_title(key)
        self.loupes.refresh()

    def _on_contrast(self, event: Any) -> None:
        if event.client is None or event.value != event.target.value:
            return  # our own update, or a newer slider position is queued behind this one
        self.state.set_view(contrast=float(event.value))  # clipped to CONTRAST_RANGE
        with self.ui_lock:
            self._recontrast()
            window = self._ba_window
            k = texture_factor(window.width, self.depth.shape[0])
            with self.server.atomic():
                for key in self.ba_keys:
                    self._image_handles[key].image = ba_texture(self.ba_display(key), window, k)
            self.loupes.refresh()

    def _on_edge_opacity(self, event: Any) -> None:
        if event.client is None or event.value != event.target.value:
            return
        self.state.set_view(edge_opacity=float(event.value))  # clipped to EDGE_OPACITY_RANGE
        self._overlay_inputs = None  # redraw the overlays with the new blend
        self._refresh_scene()
