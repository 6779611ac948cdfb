"""The view panel and the per-tab cameras: camera image raw or unwrapped, overlays on/off, the BA column window and
the page layout that follows from it, the 2-D / 3-D views and zoom.  The View folder also holds two of the display
panel's widgets."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from calib_core.errors import CalibError
from calib_core.viewpoint import viewpoint_behind_camera

from .ba_view import ColumnWindow, ba_texture, steady_window, texture_factor
from .camera_view import CameraView
from .layout import RENDER_KEY, ImageSlot, bounds_of, layout_with_render
from .loupe_wheel import LOUPE_WHEEL_JS, canvas_rects, send_loupe_rects
from .page_builder import install_page_script
from .settled_updates import settled
from .ui_common import (
    MIN_PAIRS, CLOUD_ORIGIN, PANEL_PX, ZOOM_PX_PER_CELL, ZOOM_PX_PER_IMAGE_PX, ZOOM_STEP,
)
from .view_events import BaWindowShown, ViewEvents
from .view_settings import BA_WINDOW_MODES, UP_AXES


#: How far the BA window's width may drift from the width the page was laid out for (a factor) before the page is
#: laid out again (:meth:`ViewPanel._layout`).
LAYOUT_WIDTH_SLACK = 1.5


def geometry(slot: ImageSlot) -> tuple:
    """Where ``slot`` lies on the page (centre and size, world units), whatever its pixel count."""
    return slot.center, slot.render_width, slot.render_height


class ViewPanel(ViewEvents):
    """The "View" folder of one :class:`app.server.CalibrationApp` and the per-tab cameras (``app.view``).

    It owns the BA column window and the page layout that follows from it
    (:attr:`ba_window`, :attr:`slots`), which camera view is shown
    (:attr:`camera_view`), what each tab looks at, and the View folder (the
    display panel's last-pane and edge widgets, ``add_last_pane_control(gui)`` and ``add_edge_control(gui)``,
    are placed in it).  Built where the folder goes on the page.
    """

    def __init__(self, app: Any, add_last_pane_control: Callable[[Any], None] = lambda gui: None,
                 add_edge_control: Callable[[Any], None] = lambda gui: None) -> None:
        self.app = app
        self._framed_also: tuple[str, ...] = ()  # more slot keys "All" frames (frame_also: the loupes)
        self._client_mode: dict[int, str] = {}  # client id -> "all" | "camera" | "ba" | "3d"
        self._view_target: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        self._framed: dict[int, bool] = {}  # client id -> its view is the app's framing (not zoomed since)
        self._canvas_size: dict[int, tuple[int, int] | None] = {}  # client id -> canvas size last reported
        self._loupe_rects: dict[int, dict] = {}  # client id -> where the loupes lie on its canvas, as last sent
        ViewEvents.__init__(self)
        install_page_script(app.server, LOUPE_WHEEL_JS)  # the wheel over a loupe zooms the loupe
        self._ba_window = self._wanted_ba_window()
        self._laid_out_width: int | None = None  # the BA width the page was laid out for (_layout)
        self.slots: dict[str, ImageSlot] = self._layout()
        self._build_folder(app.server.gui, add_last_pane_control, add_edge_control)
        self.sync_window_widgets()

    def frame_also(self, *keys: str) -> None:
        """Frame the slots of click keys ``keys`` too (e.g. the loupes, once built) when a tab shows "All"."""
        self._framed_also = tuple(keys)

    def _build_folder(self, gui: Any, add_last_pane_control: Callable, add_edge_control: Callable) -> None:
        app, guard, view = self.app, self.app.guard, self.app.state.view
        self.folder = gui.add_folder("View")
        with self.folder:
            add_last_pane_control(gui)
            gui.add_button_group("Show", ("2D annotation", "3D cloud")).on_click(guard(self.on_view_mode))
            gui.add_button_group("Frame", ("All", "Camera", "BA images")).on_click(guard(self.on_zoom))
            gui.add_button_group("Zoom", ("In", "Out", "On last click")).on_click(guard(self.on_magnify))
            n_cols = app.depth.shape[1]
            self.ba_columns_dropdown = gui.add_dropdown(
                "BA columns", tuple(BA_WINDOW_MODES.values()), initial_value=BA_WINDOW_MODES[view.ba_window_mode],
                hint="Show all scan columns, the ones whose points the current calibration projects into the "
                     "camera image, or the range set below",
            )
            self.ba_columns_dropdown.on_update(guard(self.on_ba_window_mode))
            self.ba_start_slider = gui.add_slider("BA first column", 0, max(n_cols - 1, 1), 1,
                                                  initial_value=self._ba_window.start)
            self.ba_start_slider.on_update(settled(guard(self.on_ba_window_slider)))  # applied once typed
            self.ba_width_slider = gui.add_slider("BA columns shown", min(16, n_cols), n_cols, 1,
                                                  initial_value=max(self._ba_window.width, min(16, n_cols)))
            self.ba_width_slider.on_update(settled(guard(self.on_ba_window_slider)))
            self._cb_pano = gui.add_checkbox(
                "Unwrapped panorama", initial_value=self.camera_view.key == "panorama",
                disabled="panorama" not in app.camera_views,
                hint="Show the camera image unwrapped (azimuth x elevation); clicks still give original-image pixels",
            )
            self._cb_pano.on_update(guard(self.on_view_checkbox))
            self._cb_reproj = gui.add_checkbox("Reprojected pairs and residuals", initial_value=view.show_reprojection)
            self._cb_reproj.on_update(guard(self.on_view_checkbox))
            self._cb_edges = gui.add_checkbox("Reprojected BA-edge points", initial_value=view.show_edges)
            self._cb_edges.on_update(guard(self.on_view_checkbox))
            add_edge_control(gui)
            up = gui.add_dropdown("3D up axis (lidar)", tuple(UP_AXES), initial_value=view.up_axis)
            up.on_update(guard(self.on_up_axis))

    @property
    def ba_window(self) -> ColumnWindow:
        """The scan columns the BA images show."""
        return self._ba_window

    def _layout(self) -> dict[str, ImageSlot]:
        """The page's slots for the window shown: the BA panes keep the size they were laid out for while the
        window's width stays within :data:`LAYOUT_WIDTH_SLACK` of it (their cells drawn that much narrower or
        wider).  By-eye run 11: the 4th pair's solve widened the camera-facing window from 272 to 352 columns and
        the 5th narrowed it to 280; each time the whole page moved about 7 screen px under the person's pointer."""
        app = self.app  # the camera-view render goes below the camera view, as large and in its framing
        shown = self._ba_window.width
        laid = self._laid_out_width
        width = laid if laid is not None and laid / LAYOUT_WIDTH_SLACK <= shown <= laid * LAYOUT_WIDTH_SLACK else shown
        self._laid_out_width = width
        slots = layout_with_render(app.camera_sizes, self.camera_view.key, (width, app.depth.shape[0]), app.ba_keys,
                                   app.ba_cell_aspect)
        return {k: replace(s, width_px=shown) if k in app.ba_keys else s for k, s in slots.items()}

    def _wanted_ba_window(self) -> ColumnWindow:
        """The column window the current mode asks for (custom until a solve says what the camera sees)."""
        mode = self.app.state.view.ba_window_mode
        if mode == "all":
            return ColumnWindow.full(self.app.depth.shape[1], self.app.wrap_cols)
        facing = self.app.pose_source.facing
        if mode == "camera" and facing is not None:
            shown = getattr(self, "_ba_window", None)  # None while the panel is being built
            return facing if shown is None else steady_window(shown, facing)
        return self._ba_custom

    @property
    def _ba_custom(self) -> ColumnWindow:
        """The saved custom column window, fitted to the scan (width 0: every column)."""
        view, n_cols = self.app.state.view, self.app.depth.shape[1]
        return ColumnWindow.make(view.ba_window_start, view.ba_window_width or n_cols, n_cols, self.app.wrap_cols)

    def ba_texture(self, key: str) -> np.ndarray:
        """The texture of BA image ``key``: its shown grey image, cut to the column window and enlarged."""
        window = self._ba_window
        return ba_texture(self.app.laser_images.ba_display(key), window, texture_factor(window.width, self.app.depth.shape[0]))

    def ba_title(self, key: str) -> str:
        """The title of BA image ``key`` (with the shown columns when they are not all)."""
        w = self._ba_window
        title = self.app.laser_images.ba_title(key)
        side_by_side = len({round(self.slots[k].center[1], 6) for k in self.app.ba_keys}) == 1
        if w.is_full or side_by_side:  # four narrow panes in a row: a longer title would run into the next one
            return title
        last = (w.start + w.width - 1) % w.n_cols
        return f"{title} (columns {w.start}-{last} of {w.n_cols})"

    def apply_ba_window(self, typed: tuple[int, int] | None = None, relayout: bool = False) -> None:
        """Show the window the mode asks for: new textures, slots, markers, loupes; re-frame 2-D tabs
        (``typed``: see :meth:`sync_window_widgets`; ``relayout``: lay the page out again even if the window is
        the same, e.g. the camera view changed)."""
        with self.app.ui_lock:
            window = self._wanted_ba_window()
            if window == self._ba_window and not relayout:
                return
            self._ba_window = window
            old_slots, self.slots = self.slots, self._layout()
            with self.app.server.atomic():
                keys = self.app.ba_keys
                shown = BaWindowShown({k: self.ba_texture(k) for k in keys}, {k: self.ba_title(k) for k in keys},
                                      {k: self.slots[k] for k in keys})
                for listener in list(self._window_listeners):
                    listener(shown)
            self.sync_window_widgets(typed)
        moved = {k: geometry(s) for k, s in self.slots.items()} != {k: geometry(s) for k, s in old_slots.items()}
        self._publish_layout(moved)
        if not moved:
            return  # same size (only the first column moved): keep every tab's zoom and pan
        clients = self.app.server.get_clients()
        for cid, mode in list(self._client_mode.items()):
            if mode != "3d" and cid in clients:
                self.set_view(clients[cid], mode)

    def sync_window_widgets(self, typed: tuple[int, int] | None = None) -> None:
        """Show the current window in the GUI (server-side updates; their callbacks ignore them).

        ``typed``: the (first column, width) the sliders held when this change was asked for.  If the person
        has changed either since (typing on), nothing is written back: their newer value is applied next.
        """
        if typed is not None and (self.ba_start_slider.value, self.ba_width_slider.value) != typed:
            return
        w = self._ba_window
        want = BA_WINDOW_MODES[self.app.state.view.ba_window_mode]
        if self.ba_columns_dropdown.value != want:
            self.ba_columns_dropdown.value = want
        if self.ba_start_slider.value != w.start:
            self.ba_start_slider.value = w.start
        if self.ba_width_slider.value != w.width:
            self.ba_width_slider.value = max(w.width, self.ba_width_slider.min)

    @property
    def camera_view(self) -> CameraView:
        """The camera view the page shows (raw image or panorama)."""
        panorama = self.app.state.view.panorama and "panorama" in self.app.camera_views  # saved choice, if this camera has one
        return self.app.camera_views["panorama" if panorama else "raw"]

    def camera_slot(self) -> ImageSlot:
        """Where the visible camera view (raw or panorama) lies on the page."""
        return self.slots[self.camera_view.key]

    def update_camera_title(self) -> None:
        """Show the visible camera view and its title on the page."""
        for listener in list(self._camera_view_listeners):
            listener(self.camera_view.key, self.camera_slot(), self.camera_view.title())

    def on_view_checkbox(self, event: Any) -> None:
        with self.app.ui_lock:  # a drawing on another thread sees the old or the new camera view, never a mix
            was = self.camera_view.key
            self.app.state.set_view(panorama=bool(self._cb_pano.value), show_reprojection=bool(self._cb_reproj.value),
                                    show_edges=bool(self._cb_edges.value))
            self.update_camera_title()
        if was != self.camera_view.key:
            # The camera view changed size: the render follows its framing, the page is laid out and re-framed.
            self.apply_ba_window(relayout=True)
        self._publish_layout(False)  # the overlays shown changed

    def on_up_axis(self, event: Any) -> None:
        self.app.state.set_view(up_axis=str(event.value))
        for cid, mode in list(self._client_mode.items()):
            if mode == "3d":
                client = self.app.server.get_clients().get(cid)
                if client is not None:
                    self.set_view(client, "3d")

    def on_view_mode(self, event: Any) -> None:
        if event.client is not None:
            self.set_view(event.client, "3d" if event.value == "3D cloud" else "all")

    def on_zoom(self, event: Any) -> None:
        if event.client is not None:
            self.set_view(event.client, {"All": "all", "Camera": "camera", "BA images": "ba"}[event.value])

    def on_magnify(self, event: Any) -> None:
        if event.client is None:
            return
        if self._client_mode.get(event.client.client_id) == "3d":
            raise CalibError("the zoom buttons work in the 2-D annotation view (the wheel zooms the 3-D view)")
        if event.value == "In":
            self._zoom(event.client, factor=ZOOM_STEP)
        elif event.value == "Out":
            self._zoom(event.client, factor=1.0 / ZOOM_STEP)
        else:
            self._zoom_on_last(event.client)

    def on_ba_window_mode(self, event: Any) -> None:
        if event.client is None:  # our own update of the widget
            return
        mode = {label: m for m, label in BA_WINDOW_MODES.items()}.get(str(event.value), "all")
        self._set_ba_mode(mode)
        if mode == "camera" and self.app.pose_source.facing is None:
            self.app.notify(event.client, "No calibration yet",
                            f"Showing the columns set by the sliders; once {MIN_PAIRS} pairs are solved the BA images "
                            "show the columns the camera sees.", color="yellow")

    def on_ba_window_slider(self, event: Any) -> None:
        if event.client is None:
            return
        if event.value != event.target.value:
            return  # a newer slider position is queued behind this one
        typed = (self.ba_start_slider.value, self.ba_width_slider.value)
        self._set_ba_mode("custom", ColumnWindow.make(int(typed[0]), int(typed[1]), self.app.depth.shape[1],
                                                      self.app.wrap_cols), typed)

    def _set_ba_mode(self, mode: str, custom: ColumnWindow | None = None, typed: tuple | None = None) -> None:
        """Save the BA column mode (and the custom window, if given), then show it (``typed``: the sliders' values
        it came from, see :meth:`sync_window_widgets`)."""
        w = self._ba_custom if custom is None else custom
        self.app.state.set_view(ba_window_mode=mode, ba_window_start=int(w.start), ba_window_width=int(w.width))
        if mode == "camera":
            self.app.pose_source.ensure_facing()
        self.apply_ba_window(typed)
        self.sync_window_widgets(typed)

    def forget_tab(self, client_id: int) -> None:
        """Forget a closed tab (the 3-D pane hides when no tab shows it)."""
        self._client_mode.pop(client_id, None)
        self._last_click.pop(client_id, None)
        self._view_target.pop(client_id, None)
        self._framed.pop(client_id, None)
        self._canvas_size.pop(client_id, None)
        self._loupe_rects.pop(client_id, None)
        self._update_cloud_visibility()

    def _update_cloud_visibility(self) -> None:
        shown = any(m == "3d" for m in list(self._client_mode.values()))  # some tab shows the 3-D view
        for listener in list(self._3d_listeners):
            listener(shown)

    def set_view(self, client: Any, mode: str) -> None:
        """Point one client's camera at the annotation images (``all``, ``camera``, ``ba``) or the 3-D cloud."""
        fov = math.radians(30.0)
        self._watch_canvas(client)
        self._framed[client.client_id] = mode != "3d"
        if mode == "3d":
            self._client_mode[client.client_id] = "3d"
            self._update_cloud_visibility()
            up = self._up_vector()
            bundle = self.app.solve_bundle
            # Stand a little behind and above the solved camera, look where it looks (paper Fig. 9).
            eye, look = viewpoint_behind_camera(None if bundle is None else bundle.result.T_camera_lidar, up)
            pos, look = CLOUD_ORIGIN + eye, CLOUD_ORIGIN + look
            self._apply_camera(client, pos, look, up, math.radians(70.0))
            return
        self._client_mode[client.client_id] = mode
        self._update_cloud_visibility()
        if mode == "camera":
            slots = [self.camera_slot(), self.slots[RENDER_KEY]]
        elif mode == "ba":
            slots = [self.slots[k] for k in self.app.ba_keys]
        else:
            slots = [self.camera_slot(), self.slots[RENDER_KEY]] + [self.slots[k] for k in self.app.ba_keys]
            slots += [self.app.slot_of(key) for key in self._framed_also]  # the loupes are part of the page
        x0, y0, x1, y1 = bounds_of(slots)
        y0 -= 0.3  # room for the titles
        w_px, h_px = self._canvas_px(client)
        usable_px = w_px - PANEL_PX if w_px > 2 * PANEL_PX else w_px
        tan = math.tan(fov / 2)
        margin = 1.06
        dist = max((y1 - y0) * margin / (2 * tan), (x1 - x0) * margin * h_px / (usable_px * 2 * tan))
        units_per_px = 2 * dist * tan / h_px
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        look = np.array([cx + (w_px - usable_px) / 2 * units_per_px, cy, 0.0])
        self._apply_camera(client, look + np.array([0.0, 0.0, -dist]), look, np.array([0.0, -1.0, 0.0]), fov)

    def _zoom(self, client: Any, factor: float = 1.0, centre: np.ndarray | None = None,
              units_per_screen_px: float | None = None, min_units: float = 0.0) -> None:
        """Magnify one tab's flat 2-D view by ``factor`` (or to ``units_per_screen_px``).

        The point shown at the middle of the free canvas area (left of the
        control panel) stays put, or ``centre`` (world) moves there.  The view
        is squared up to face the image plane again.  ``min_units`` (world
        units per screen pixel) caps the magnification; a view beyond it keeps its own.
        """
        cam = client.camera
        try:
            position, look = np.asarray(cam.position, float), np.asarray(cam.look_at, float)
            fov, (w_px, h_px) = float(cam.fov), self._canvas_px(client)
        except AssertionError:  # the tab has not reported its camera yet
            return
        tan = math.tan(fov / 2)
        dist = max(abs(look[2] - position[2]), 1e-6)
        units = 2 * dist * tan / h_px  # world units per screen pixel on the image plane
        shift_px = (w_px - (w_px - PANEL_PX if w_px > 2 * PANEL_PX else w_px)) / 2
        if centre is None:
            centre = look - np.array([shift_px * units, 0.0, 0.0])
        new_units = units / factor if units_per_screen_px is None else units_per_screen_px
        new_units = max(new_units, min(units, min_units))  # at the cap already: only re-centre
        new_units = float(np.clip(new_units, 1e-6, 0.2))  # 0.2 units/px: the whole layout is tiny
        new_look = np.array([centre[0] + shift_px * new_units, centre[1], 0.0])
        new_dist = new_units * h_px / (2 * tan)
        self._framed[client.client_id] = False  # zoomed: a resize keeps this view
        self._apply_camera(client, new_look + np.array([0.0, 0.0, -new_dist]), new_look, np.array([0.0, -1.0, 0.0]),
                           fov)

    def _zoom_on_last(self, client: Any) -> None:
        """Centre the last click and magnify one step (``ZOOM_STEP``), up to ``ZOOM_PX_PER_CELL`` per BA cell
        or ``ZOOM_PX_PER_IMAGE_PX`` per camera pixel: each press keeps the surroundings in view."""
        last = self.last_click(client.client_id)
        if last is None:
            raise CalibError("nothing clicked yet in this tab: click a BA or camera image first")
        with self.app.ui_lock:
            if last[0] == "ba":
                _, key, row, col = last
                slot = self.slots[key]
                u, shown = self._ba_window.display_cols(np.array([col]))
                if not shown[0]:
                    raise CalibError(f"the last clicked cell (column {col}) is outside the shown BA columns")
                centre = slot.world_from_pixel(np.array([[u[0], row]]))[0]
                units = min(slot.units_per_px, slot.units_per_px_y) / ZOOM_PX_PER_CELL
            else:
                slot = self.camera_slot()
                uv, ok = self.app.display_from_pixels(np.array([[last[1], last[2]]]))
                if not ok[0]:
                    raise CalibError("the last clicked camera pixel is not shown in this camera view")
                centre = slot.world_from_pixel(uv)[0]
                units = slot.units_per_px / ZOOM_PX_PER_IMAGE_PX
        self._zoom(client, factor=ZOOM_STEP, centre=centre, min_units=units)

    def _watch_canvas(self, client: Any) -> None:
        """Re-frame tab ``client`` when its canvas changes shape (a resized window), once registered.

        The reported size is in device pixels, which viser also scales down and up by itself when the page
        renders slowly (its adaptive pixel ratio): that keeps the shape and shows the same view, so only a
        change of the width / height ratio counts as a resize.
        """
        if client.client_id in self._canvas_size:
            return
        self._canvas_size[client.client_id] = None

        async def on_camera(camera: Any) -> None:  # every camera message, on viser's event loop: cheap
            cid = camera.client.client_id
            self._publish_loupes(camera.client, camera)
            size = (int(camera.image_width), int(camera.image_height))
            old = self._canvas_size.get(cid)
            if old is not None and min(old + size) > 0 and not _resized(old, size):
                self._canvas_size[cid] = max(old, size)  # the full-resolution size, whatever the pixel ratio
                return
            self._canvas_size[cid] = size
            if old is not None and min(old + size) > 0:
                self.app.post(lambda: self._refit(camera.client), camera.client)

        client.camera.on_update(on_camera)

    def _publish_loupes(self, client: Any, camera: Any) -> None:
        """Tell tab ``client`` where the loupes lie on its canvas under ``camera``, when that changed: a wheel over
        a loupe zooms that loupe (:mod:`app.loupe_wheel`)."""
        rects: dict = {}
        if self._client_mode.get(client.client_id) not in (None, "3d"):
            try:
                bounds = {k: self.app.slot_of(f"loupe_{k}").bounds() for k in ("ba", "camera")}
            except (AttributeError, KeyError):  # no loupes (yet)
                bounds = {}
            rects = canvas_rects(camera, bounds) or {}
        if self._loupe_rects.get(client.client_id) != rects:
            self._loupe_rects[client.client_id] = rects
            send_loupe_rects(client, rects)

    def _canvas_px(self, client: Any) -> tuple[int, int]:
        """Tab ``client``'s canvas size in pixels at full resolution: viser reports it scaled down while the page
        renders slowly; framing with that size (less :data:`PANEL_PX`) drew the page small at the top left
        (by-eye run 4, after a pair)."""
        cam = client.camera
        size = (max(int(cam.image_width), 1), max(int(cam.image_height), 1))
        full = self._canvas_size.get(client.client_id)
        return full if full is not None and min(full) > 0 and not _resized(full, size) else size

    def _refit(self, client: Any) -> None:
        """Frame a resized tab again (the part of the canvas left of the control panel changed), unless its view
        is not the app's framing any more (zoomed, panned or wheeled since)."""
        cid = client.client_id
        mode, target = self._client_mode.get(cid), self._view_target.get(cid)
        if mode in (None, "3d") or target is None or not self._framed.get(cid):
            return
        try:
            cam = client.camera
            framed = np.allclose(cam.position, target[0], atol=1e-4) and np.allclose(cam.look_at, target[1], atol=1e-4)
        except AssertionError:
            return
        if framed:
            self.set_view(client, mode)

    def _apply_camera(self, client: Any, position: np.ndarray, look_at: np.ndarray, up: np.ndarray, fov: float) -> None:
        cam = client.camera
        with client.atomic():
            cam.fov = fov
            cam.up_direction = tuple(up)
            cam.position = tuple(position)
            cam.look_at = tuple(look_at)
            cam.up_direction = tuple(up)
        self._view_target[client.client_id] = (np.asarray(position, float), np.asarray(look_at, float), time.time())

    def _up_vector(self) -> np.ndarray:
        axis = UP_AXES.get(self.app.state.view.up_axis)
        if axis is None:
            bundle = self.app.solve_bundle
            if bundle is None:
                return np.array([0.0, 0.0, 1.0])
            R_lidar_camera = bundle.result.T_camera_lidar[:3, :3].T
            return R_lidar_camera @ np.array([0.0, -1.0, 0.0])
        return np.array(axis, dtype=np.float64)

    # The two below are read only by tests (waiting for a real tab's view); they read this panel's own record.
    def view_set_time(self, client_id: int) -> float:
        """``time.time()`` when this app last set the tab's camera (0.0: never)."""
        target = self._view_target.get(client_id)
        return 0.0 if target is None else float(target[2])

    def view_settled(self, client_id: int) -> bool:
        """True once the tab reported a camera at the pose this app last set."""
        client = self.app.server.get_clients().get(client_id)
        target = self._view_target.get(client_id)
        if client is None or target is None:
            return False
        try:
            cam = client.camera
            fresh = cam.update_timestamp > target[2]
            return bool(fresh and np.allclose(cam.position, target[0], atol=1e-4)
                        and np.allclose(cam.look_at, target[1], atol=1e-4))
        except AssertionError:
            return False


def _resized(old: tuple[int, int], new: tuple[int, int]) -> bool:
    """Did a canvas go from size ``old`` to ``new`` by a resize (its shape changed by more than 2 %), rather than by
    viser's adaptive pixel ratio (same shape, up to rounding of small sizes)?"""
    return abs(new[0] * old[1] / (new[1] * old[0]) - 1.0) > 0.02
