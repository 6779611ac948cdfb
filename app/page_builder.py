"""The page of the app: the theme, the intro text, the backdrop and the annotation images' scene nodes (camera
views and BA images with their titles, wired to the pairs panel's click handlers).  What the images show is set by
the view panel (column window, camera view) and the display panel (contrast)."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from .ui_common import md_escape
from .view_settings import BA_WINDOW_MODES, UP_AXES

INTRO = (
    "Click a point in any **BA image** and the same point in the **camera image** (either order) "
    "to make a pair. **Shift+click** a marker to select its pair; then clicks move it. "
    "**Drag** a marker to move it. The two **loupes** on the right magnify the last click and the "
    "predicted other end; click in them for exact cells and sub-pixel points (a loupe click right after a "
    "click on the full image refines it). Wheel zooms on the view centre, right-drag pans. "
    "**BA columns** shows only part of a wide scan, e.g. the part facing the camera."
)


class PageBuilder:
    """The page of one :class:`app.server.CalibrationApp` (``app.page``).

    Construction sets the theme, adds the intro text (first in the control
    panel) and the backdrop; :meth:`add_images` adds the annotation images
    once the panels exist.  Public: :attr:`image_handles` (scene image of each
    camera view and BA key), :attr:`ba_titles`, :attr:`camera_title` (what the
    view and display panels update), :attr:`folder_lock` and :meth:`texture`.
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        # Held while one tab's own widgets are added into a shared folder (one GUI context at a time).
        self.folder_lock = threading.Lock()
        gui, scene = app.server.gui, app.server.scene
        gui.configure_theme(control_width="large", show_share_button=False, dark_mode=False)
        gui.add_markdown(f"**{md_escape(app.title)}**  \n" + INTRO)
        backdrop = scene.add_image(
            "/annot/backdrop", np.full((2, 2, 3), 238, np.uint8), 600.0, 600.0, format="png", position=(0.0, 0.0, 0.5)
        )
        # A no-op drag on the backdrop keeps left-drags from orbiting the flat view.
        backdrop.on_drag(lambda event: None)
        self.image_handles: dict[str, Any] = {}
        self.ba_titles: dict[str, Any] = {}
        self.camera_title: Any = None

    def add_images(self, ba_textures: dict[str, np.ndarray], ba_titles: dict[str, str]) -> None:
        """Add the camera views and the BA images (``ba_textures``, titled ``ba_titles``) at their page slots."""
        app = self.app
        scene = app.server.scene
        shown = app.camera_view.key
        for key, view in app.camera_views.items():
            s = app.slots[key]
            self.image_handles[key] = scene.add_image(
                {"raw": "/annot/camera_raw", "panorama": "/annot/camera_pano"}[key], view.image, s.render_width,
                s.render_height, format="jpeg", jpeg_quality=92, position=s.center, visible=key == shown,
            )
        for key in app.ba_keys:
            s = app.slots[key]
            self.image_handles[key] = scene.add_image(
                f"/annot/ba_{key}", ba_textures[key], s.render_width, s.render_height, format="png",
                position=s.center,
            )
            x0, y0, _, _ = s.bounds()
            self.ba_titles[key] = scene.add_label(f"/annot/titles/{key}", ba_titles[key],
                                                  position=(x0, y0 - 0.03, -0.01), anchor="bottom-left",
                                                  font_screen_scale=0.9)
        pairs = app.pairs_panel
        for key, handle in self.image_handles.items():
            handle.on_click(pairs.make_click_handler(key))
            handle.on_click(modifier="shift")(pairs.make_select_handler(key))
            handle.on_drag(pairs.make_drag_handler(key))
        self.camera_title = scene.add_label("/annot/titles/camera", "", position=(0, 0, -0.01), anchor="bottom-left",
                                            font_screen_scale=0.9)

    def texture(self, key: str) -> np.ndarray:
        """The texture image ``key`` (a BA key or camera view) shows now."""
        return np.asarray(self.image_handles[key].image)


def build_view_folder(app: Any) -> None:
    """The "View" folder's widgets (the view and display panels' handlers)."""
    gui = app.server.gui
    view = app.state.view
    app._view_folder = gui.add_folder("View")
    with app._view_folder:
        app._bg_loupe_zoom = gui.add_button_group("Loupe zoom", ("BA +", "BA -", "Camera +", "Camera -"))
        app._bg_loupe_zoom.on_click(app.guard(app.loupe_support.on_loupe_zoom))
        app._dd_loupe_source = gui.add_dropdown(
            "BA loupe shows", app.loupe_sources(), initial_value=app.loupe_source,
            hint="The BA image last clicked, one BA direction, the scan's intensity (if it has one) or range")
        app._dd_loupe_source.on_update(app.guard(app._on_loupe_source))
        app._dd_last_pane = gui.add_dropdown(
            "Last laser pane", app.last_pane_sources(), initial_value=app.last_pane_source,
            hint="What the bottom laser pane shows: its BA direction, the scan's intensity (if it has one) or "
                 "range; clicks on it pick the same cells")
        app._dd_last_pane.on_update(app.guard(app._on_last_pane_source))
        app._sl_contrast = gui.add_slider("Laser contrast", 0.5, 3.0, 0.25, initial_value=view.contrast,
                                           hint="Contrast of the BA images and the BA loupe")
        app._sl_contrast.on_update(app.guard(app._on_contrast))
        app._bg_view = gui.add_button_group("Show", ("2D annotation", "3D cloud"))
        app._bg_view.on_click(app.guard(app._on_view_mode))
        app._bg_zoom = gui.add_button_group("Frame", ("All", "Camera", "BA images"))
        app._bg_zoom.on_click(app.guard(app._on_zoom))
        app._bg_magnify = gui.add_button_group("Zoom", ("In", "Out", "On last click"))
        app._bg_magnify.on_click(app.guard(app._on_magnify))
        n_cols = app.depth.shape[1]
        app._dd_ba_window = gui.add_dropdown(
            "BA columns", tuple(BA_WINDOW_MODES.values()), initial_value=BA_WINDOW_MODES[view.ba_window_mode],
            hint="Show all scan columns, the ones whose points the current calibration projects into the "
                 "camera image, or the range set below",
        )
        app._dd_ba_window.on_update(app.guard(app._on_ba_window_mode))
        app._sl_ba_start = gui.add_slider("BA first column", 0, max(n_cols - 1, 1), 1,
                                           initial_value=app._ba_window.start)
        app._sl_ba_start.on_update(app.guard(app._on_ba_window_slider))
        app._sl_ba_width = gui.add_slider("BA columns shown", min(16, n_cols), n_cols, 1,
                                           initial_value=max(app._ba_window.width, min(16, n_cols)))
        app._sl_ba_width.on_update(app.guard(app._on_ba_window_slider))
        app._cb_pano = gui.add_checkbox(
            "Unwrapped panorama", initial_value=app.camera_view.key == "panorama", disabled="panorama" not in app.camera_views,
            hint="Show the camera image unwrapped (azimuth x elevation); clicks still give original-image pixels",
        )
        app._cb_pano.on_update(app.guard(app._on_view_checkbox))
        app._cb_reproj = gui.add_checkbox("Reprojected pairs and residuals", initial_value=view.show_reprojection)
        app._cb_reproj.on_update(app.guard(app._on_view_checkbox))
        app._cb_edges = gui.add_checkbox("Reprojected BA-edge points", initial_value=view.show_edges)
        app._cb_edges.on_update(app.guard(app._on_view_checkbox))
        app._sl_edge_opacity = gui.add_slider("BA-edge opacity", 0.0, 1.0, 0.1, initial_value=view.edge_opacity)
        app._sl_edge_opacity.on_update(app.guard(app._on_edge_opacity))
        app._dd_up = gui.add_dropdown("3D up axis (lidar)", tuple(UP_AXES), initial_value=view.up_axis)
        app._dd_up.on_update(app.guard(app._on_up_axis))
