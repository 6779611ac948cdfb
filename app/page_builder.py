"""Builds the page once: the annotation scene (backdrop, camera and BA images, 3-D cloud, camera frame) and the
control panel's folders and widgets, each wired to its panel's handler."""

from __future__ import annotations

from typing import Any

import numpy as np
import viser


from .calibration_panel import CalibrationPanel
from .export_panel import ExportPanel
from .ui_common import CLOUD_ORIGIN, md_escape
from .view_settings import BA_WINDOW_MODES, UP_AXES


class PageBuilder:
    """Part of :class:`app.server.CalibrationApp` (a mixin: it uses the app's attributes)."""

    def _build_scene(self) -> None:
        scene = self.server.scene
        backdrop = scene.add_image(
            "/annot/backdrop", np.full((2, 2, 3), 238, np.uint8), 600.0, 600.0, format="png", position=(0.0, 0.0, 0.5)
        )
        # A no-op drag on the backdrop keeps left-drags from orbiting the flat view.
        backdrop.on_drag(lambda event: None)
        self._image_handles: dict[str, Any] = {}
        for key, view in self.camera_views.items():
            s = self.slots[key]
            self._image_handles[key] = scene.add_image(
                {"raw": "/annot/camera_raw", "panorama": "/annot/camera_pano"}[key], view.image, s.render_width,
                s.render_height, format="jpeg", jpeg_quality=92, position=s.center, visible=key == self.camera_view.key,
            )
        self._ba_titles: dict[str, Any] = {}
        for key in self.ba_keys:
            s = self.slots[key]
            self._image_handles[key] = scene.add_image(
                f"/annot/ba_{key}", self._ba_texture(key), s.render_width, s.render_height, format="png",
                position=s.center,
            )
            x0, y0, _, _ = s.bounds()
            self._ba_titles[key] = scene.add_label(f"/annot/titles/{key}", self._ba_title(key),
                                                   position=(x0, y0 - 0.03, -0.01), anchor="bottom-left",
                                                   font_screen_scale=0.9)
        for key, handle in self._image_handles.items():
            handle.on_click(self.make_click_handler(key))
            handle.on_click(modifier="shift")(self.make_select_handler(key))
            handle.on_drag(self._make_drag_handler(key))
        self._camera_title = scene.add_label("/annot/titles/camera", "", position=(0, 0, -0.01), anchor="bottom-left",
                                             font_screen_scale=0.9)
        self._update_camera_title()

        # 3-D pane: cloud and frames, far from the annotation plane.
        self._cloud_root = scene.add_frame("/cloud", show_axes=False, position=CLOUD_ORIGIN, visible=False)
        grey = np.full((len(self.cloud_points_lidar), 3), 150, np.uint8)
        self._cloud = scene.add_point_cloud(
            "/cloud/points", self.cloud_points_lidar.astype(np.float32), grey, point_size=0.015,
            precision="float32", point_shape="rounded", point_shading="flat",
        )
        scene.add_frame("/cloud/lidar", axes_length=0.25, axes_radius=0.01)
        scene.add_label("/cloud/lidar/label", "lidar", position=(0.0, 0.0, 0.0), anchor="top-right")
        self._camera_frame = scene.add_frame("/cloud/camera", axes_length=0.2, axes_radius=0.008, visible=False)
        scene.add_label("/cloud/camera/label", "camera", position=(0.0, 0.0, 0.0))

    # ------------------------------------------------------------ BA display
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large", show_share_button=False, dark_mode=False)
        gui.add_markdown(
            f"**{md_escape(self.title)}**  \n"
            "Click a point in any **BA image** and the same point in the **camera image** (either order) "
            "to make a pair. **Shift+click** a marker to select its pair; then clicks move it. "
            "**Drag** a marker to move it. The two **loupes** on the right magnify the last click and the "
            "predicted other end; click in them for exact cells and sub-pixel points (a loupe click right after a "
            "click on the full image refines it). Wheel zooms on the view centre, right-drag pans. "
            "**BA columns** shows only part of a wide scan, e.g. the part facing the camera."
        )
        view = self.state.view
        self.pairs_folder = gui.add_folder("Pairs")
        with self.pairs_folder:
            self._md_pairs = gui.add_markdown("")
            self._dd_selected = gui.add_dropdown("Selected pair", ("none",), initial_value="none")
            self._dd_selected.on_update(self.guard(self._on_select_dropdown))
            self._bg_edit = gui.add_button_group("Edit", ("Undo", "Redo", "Deselect", "Delete"))
            self._bg_edit.on_click(self.guard(self._on_edit))
            self._btn_clear = gui.add_button("Clear all pairs (undoable)", color="red", icon=viser.Icon.TRASH)
            self._btn_clear.on_click(self.guard(self._on_clear))
            self._cb_snap = gui.add_checkbox("Snap clicks to corners", initial_value=view.snap,
                                             hint="Refine each click to the strongest corner within 4 pixels")
            self._cb_snap.on_update(self.guard(self._on_view_checkbox))
            # Each tab gets its own upload button (see _on_connect): viser keeps one value per button,
            # which two tabs uploading at once would overwrite.
            self._btn_pairs = gui.add_button("Download pairs YAML", icon=viser.Icon.DOWNLOAD)
            self._btn_pairs.on_click(self.guard(self._on_download_pairs))
        self.calibration_panel = CalibrationPanel(gui)
        self._view_folder = gui.add_folder("View")
        with self._view_folder:
            self._bg_loupe_zoom = gui.add_button_group("Loupe zoom", ("BA +", "BA -", "Camera +", "Camera -"))
            self._bg_loupe_zoom.on_click(self.guard(self._on_loupe_zoom))
            self._dd_loupe_source = gui.add_dropdown(
                "BA loupe shows", self.loupe_sources(), initial_value=self.loupe_source,
                hint="The BA image last clicked, one BA direction, the scan's intensity (if it has one) or range")
            self._dd_loupe_source.on_update(self.guard(self._on_loupe_source))
            self._dd_last_pane = gui.add_dropdown(
                "Last laser pane", self.last_pane_sources(), initial_value=self.last_pane_source,
                hint="What the bottom laser pane shows: its BA direction, the scan's intensity (if it has one) or "
                     "range; clicks on it pick the same cells")
            self._dd_last_pane.on_update(self.guard(self._on_last_pane_source))
            self._sl_contrast = gui.add_slider("Laser contrast", 0.5, 3.0, 0.25, initial_value=view.contrast,
                                               hint="Contrast of the BA images and the BA loupe")
            self._sl_contrast.on_update(self.guard(self._on_contrast))
            self._bg_view = gui.add_button_group("Show", ("2D annotation", "3D cloud"))
            self._bg_view.on_click(self.guard(self._on_view_mode))
            self._bg_zoom = gui.add_button_group("Frame", ("All", "Camera", "BA images"))
            self._bg_zoom.on_click(self.guard(self._on_zoom))
            self._bg_magnify = gui.add_button_group("Zoom", ("In", "Out", "On last click"))
            self._bg_magnify.on_click(self.guard(self._on_magnify))
            n_cols = self.depth.shape[1]
            self._dd_ba_window = gui.add_dropdown(
                "BA columns", tuple(BA_WINDOW_MODES.values()), initial_value=BA_WINDOW_MODES[view.ba_window_mode],
                hint="Show all scan columns, the ones whose points the current calibration projects into the "
                     "camera image, or the range set below",
            )
            self._dd_ba_window.on_update(self.guard(self._on_ba_window_mode))
            self._sl_ba_start = gui.add_slider("BA first column", 0, max(n_cols - 1, 1), 1,
                                               initial_value=self._ba_window.start)
            self._sl_ba_start.on_update(self.guard(self._on_ba_window_slider))
            self._sl_ba_width = gui.add_slider("BA columns shown", min(16, n_cols), n_cols, 1,
                                               initial_value=max(self._ba_window.width, min(16, n_cols)))
            self._sl_ba_width.on_update(self.guard(self._on_ba_window_slider))
            self._cb_pano = gui.add_checkbox(
                "Unwrapped panorama", initial_value=self.camera_view.key == "panorama", disabled="panorama" not in self.camera_views,
                hint="Show the camera image unwrapped (azimuth x elevation); clicks still give original-image pixels",
            )
            self._cb_pano.on_update(self.guard(self._on_view_checkbox))
            self._cb_reproj = gui.add_checkbox("Reprojected pairs and residuals", initial_value=view.show_reprojection)
            self._cb_reproj.on_update(self.guard(self._on_view_checkbox))
            self._cb_edges = gui.add_checkbox("Reprojected BA-edge points", initial_value=view.show_edges)
            self._cb_edges.on_update(self.guard(self._on_view_checkbox))
            self._sl_edge_opacity = gui.add_slider("BA-edge opacity", 0.0, 1.0, 0.1, initial_value=view.edge_opacity)
            self._sl_edge_opacity.on_update(self.guard(self._on_edge_opacity))
            self._dd_up = gui.add_dropdown("3D up axis (lidar)", tuple(UP_AXES), initial_value=view.up_axis)
            self._dd_up.on_update(self.guard(self._on_up_axis))
        self.export_panel = ExportPanel(self)
        self._sync_window_widgets()
