"""The laser images as the page shows them: every BA direction and the scan's other laser images (intensity,
range) with the saved contrast applied, which of them the last laser pane and the BA loupe show, and their names.

A service of the app (``app.laser_images``: state and queries, no widgets); :class:`app.display_panel.DisplayPanel`
owns the widgets that change it.  Grey levels come from :mod:`calib_core.display_images`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calib_core.display_images import apply_contrast

from .ui_common import BA_TITLES
from .view_settings import AS_CLICKED


class LaserImages:
    """The laser images of one :class:`app.server.CalibrationApp` as shown (``app.laser_images``)."""

    def __init__(self, app: Any) -> None:
        self.app = app
        self._shown_gray: dict[str, np.ndarray] = {}
        self.recontrast()

    def loupe_sources(self) -> tuple[str, ...]:
        """The choices of what the BA loupe shows."""
        app = self.app
        return (AS_CLICKED, *(BA_TITLES.get(k, k) for k in app.ba_keys), *app.scene_data.laser_images)

    def recontrast(self) -> None:
        """Apply the saved contrast to every laser image again."""
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
