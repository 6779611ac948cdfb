"""The camera-view laser pane: the scan rendered from the camera under the current pose, below the camera image
(what it shows and how it is used: docs/app.md, "The scan seen from the camera").

The pose is :meth:`app.pose_source.PoseSource.view_pose`.  A click on the render picks the laser cell drawn there,
through the pairs panel like a BA click.  Rendering runs in one background thread that always renders the newest
pose (:class:`app.live_solver.LiveSolver`); clicks never wait for it.  Display plumbing only: the render and its
shading come from :mod:`calib_core.render`.
"""

from __future__ import annotations

import time
import traceback
from typing import Any, Callable

import numpy as np

from calib_core.display_images import find_intensity
from calib_core.errors import CalibError
from calib_core.render import render_from_camera, shade_render

from .layout import RENDER_KEY, ImageSlot
from .live_solver import LiveSolver
from .shown_render import NEAREST_PX, NO_RETURN_RGB, ShownRender, cell_at_pixel, pane_texture, pixel_of_cells
from .ui_common import PICK_RADII, draw_ring_markers
from .view_settings import RENDER_MODES

#: The render's scene nodes (its page slot and click key: :data:`app.layout.RENDER_KEY`).
NODE = "/annot/render"
OVERLAY_NODE = "/annot/render_over"
#: A click on a pixel without a return takes the nearest rendered pixel (:data:`app.shown_render.NEAREST_PX`) ...
#: ... or this close in screen pixels when the pane is shown small (a click aimed at a thin outline lands a pixel
#: or two beside it), at most :data:`NEAREST_MAX_PX` render pixels.
SNAP_SCREEN_PX = 2.0
NEAREST_MAX_PX = 24
#: A click on the pane (scaled down on the page) takes the nearer surface seen within this many screen pixels
#: (:data:`EDGE_RENDER_PX` render pixels at least; :func:`app.shown_render.cell_at_pixel`): run 8's pole edge.
EDGE_SCREEN_PX = 1.5
EDGE_RENDER_PX = 1.5
#: A new solve is rendered at most this often (seconds): a burst of clicks solves many times, each render costs a
#: core for 0.1-0.3 s.  Drags and the Align buttons render at once.
SOLVE_RENDER_INTERVAL_S = 0.5
#: The render's opacity over the photo that ticking "Align by drag" sets when it was hidden (unticking undoes it).
ALIGN_BLEND = 0.5
#: The render controls' help, in the Align folder's text (no tooltips: run 7).
RENDER_HELP = ("**Render shading**: how the scan seen from the camera is coloured (range, the laser's intensity or "
               "the bearing angle; depth edges white).  **Render over photo**: the render drawn over the camera "
               "image (0: photo only, 1: render wherever the scan has a return).")
#: Where the pose the render uses comes from, as its title says it.
POSE_NAMES = {"solve": "solved pose", "rough": "rough pose", "default": "'+x' preset (no pose yet)",
              "drag": "rough pose (dragging)", "unreliable": "rough pose: the solve is unreliable"}


class RenderPane:
    """The camera-view laser pane of one :class:`app.server.CalibrationApp` (``app.render_pane``).

    It owns its scene nodes (the pane, its title, the copy drawn over the photo, the markers on it), the render
    worker, and the widgets it adds to the Align folder (:meth:`add_controls`).  The composition root passes
    what it uses of its siblings: ``laser_key()`` (the BA image a laser end picked on it names: the laser loupe's)
    and ``click_at(key, uv, client)`` (the pairs panel's).
    """

    def __init__(self, app: Any, *, laser_key: Callable[[], str], click_at: Callable[[str, tuple, Any], Any]) -> None:
        self.app = app
        self._laser_key = laser_key  # the BA image the laser loupe falls back to (the loupes')
        self._click_at = click_at  # a click on a slot at a display pixel (the pairs panel's): a shaky drag is one
        self._drag_taker: Callable[[Any], bool] = lambda event: False  # hand_plain_drags_to
        self.current: ShownRender | None = None
        self.last_pixel: tuple[float, float] | None = None  # the render pixel of the last pick on it
        self.drag_pose: np.ndarray | None = None  # while "Align by drag" turns the view: the pose being dragged
        self._requested: tuple | None = None
        self._wanted: tuple | None = None  # (T, mode, source) the page should show; the worker renders the newest
        self._last_done = 0.0  # time.monotonic() when the last render finished
        self._blink_back = 1.0  # the opacity "Blink" goes back to
        self._shown_for_drag = False  # ticking "Align by drag" raised the opacity from 0 (unticking lowers it back)
        self._job = 0
        self._marks_of: tuple | None = None
        self._stopped = False
        self._placed: tuple | None = None  # (render slot, camera slot, camera view) the nodes were placed for
        self._listeners: list[Callable[[str], None]] = []
        scene = app.server.scene
        self._handle = scene.add_image(NODE, np.full((2, 2, 3), NO_RETURN_RGB, np.uint8), 1.0, 1.0, format="png")
        self._title = scene.add_label("/annot/titles/render", "Camera-view laser: rendering ...",
                                      position=(0.0, 0.0, -0.01), anchor="bottom-left", font_screen_scale=0.9)
        # Over the camera view, a little towards the viewer; hidden while the blend is 0 (clicks reach the photo).
        self._overlay = scene.add_image(OVERLAY_NODE, np.zeros((2, 2, 4), np.uint8), 1.0, 1.0, format="png",
                                        visible=False)
        self.place()
        self._handle.on_click(app.make_click_handler(RENDER_KEY))
        self._handle.on_click(modifier="shift")(app.guard(self._on_shift_click))
        self.plain_drag_callback = app.guard(self._on_plain_drag)
        self._handle.on_drag(self.plain_drag_callback)
        # The copy over the photo answers as the camera view under it does (same place, same pixels).
        self._overlay.on_click(self._as_camera_view(app.make_click_handler))
        self._overlay.on_click(modifier="shift")(self._as_camera_view(app.make_select_handler))
        self.overlay_drag_callback = self._as_camera_view(app.make_drag_handler)
        self._overlay.on_drag(self.overlay_drag_callback)
        self._worker = LiveSolver(self._render_job, self._on_rendered, name="ba-calib-render")

    def subscribe(self, listener: Callable[[str, ShownRender | None], None], replay: bool = False) -> None:
        """Call ``listener(what, shown)`` with the render shown (:attr:`current`): ``what`` is ``"pose"`` when the
        render is asked for a pose from another source (solve, rough pose, preset, drag), on the requesting thread,
        ``"render"`` when a new render is shown, under the UI lock and in its message batch.  ``replay``: call it
        now with the render shown, if any."""
        with self.app.ui_lock:
            self._listeners.append(listener)
            if replay and self.current is not None:
                listener("render", self.current)

    def _publish(self, what: str) -> None:
        for listener in list(self._listeners):
            listener(what, self.current)

    # ------------------------------------------------------------------ nodes the Align panel drags on
    def hand_plain_drags_to(self, take: Callable[[Any], bool]) -> None:
        """Offer each plain drag on the pane to ``take(event)`` first (the Align panel's: True when it turned the
        view with it); a drag it leaves that is a shaky click is a click."""
        self._drag_taker = take

    @property
    def drag_nodes(self) -> dict[str, Any]:
        """The render's scene nodes a drag may turn the view on: the pane and its copy over the camera view."""
        return {RENDER_KEY: self._handle, "camera_overlay": self._overlay}

    def _as_camera_view(self, make_handler: Any) -> Any:
        """A viser callback that hands the event to ``make_handler(key)`` of the camera view shown at that moment."""
        async def handler(event: Any) -> None:
            await make_handler(self.app.camera_view.key)(event)

        return handler

    def place(self) -> None:
        """Put the pane where the layout says, in the camera view's framing, and the copy over the camera view."""
        app = self.app
        slot, cam = app.slots[RENDER_KEY], app.camera_slot()
        placed = (slot, cam, app.camera_view.key)
        if placed == self._placed:
            return
        self._placed = placed
        with app.ui_lock, app.server.atomic():
            self._handle.render_width, self._handle.render_height = slot.render_width, slot.render_height
            self._handle.position = slot.center
            x0, y0, _, _ = slot.bounds()
            self._title.position = (x0, y0 - 0.03, -0.01)
            self._overlay.render_width, self._overlay.render_height = cam.render_width, cam.render_height
            self._overlay.position = (cam.center[0], cam.center[1], cam.center[2] - 0.002)
            if self.current is not None:
                self._handle.image = self._shown_texture(self.current)
            self._show_overlay()
            self._marks_of = None
            self.draw_marks()

    # ------------------------------------------------------------------ widgets
    def add_controls(self, gui: Any) -> None:
        """The render's shading, its opacity over the photo and a blink button, where ``gui`` adds now."""
        app, view = self.app, self.app.state.view
        # Run 7: viser's hint tooltips stayed over the Turn / Move buttons after a click on these two (the server
        # cannot dismiss them), so what they would say is text in the folder.
        gui.add_markdown(RENDER_HELP)
        self._dd_mode = gui.add_dropdown("Render shading", tuple(RENDER_MODES.values()),
                                         initial_value=RENDER_MODES[view.render_mode])
        self._dd_mode.on_update(app.guard(self.on_mode))
        self._sl_blend = gui.add_slider("Render over photo", 0.0, 1.0, 0.05, initial_value=view.render_blend)
        self._sl_blend.on_update(app.guard(self.on_blend))
        self._bt_blink = gui.add_button("Blink render / photo",
                                        hint="Swap between the photo alone and the render over it")
        self._bt_blink.on_click(app.guard(self.on_blink))

    def on_mode(self, event: Any) -> None:
        """The "Render shading" dropdown."""
        if event.client is None:
            return
        mode = {label: k for k, label in RENDER_MODES.items()}.get(str(event.value))
        if mode is None:
            return
        if mode == "intensity" and "Intensity" not in self.app.scene_data.laser_images:
            self.app.notify(event.client, "No intensity", "this scan has no intensity field; shading by range",
                            color="yellow")
        self.app.state.set_view(render_mode=mode)
        self.request()

    def on_blend(self, event: Any) -> None:
        """The "Render over photo" slider."""
        if event.client is None or event.value != event.target.value:
            return  # our own update, or a newer position is queued behind this one
        self.set_blend(float(event.value))

    def on_blink(self, event: Any) -> None:
        """Swap between the photo alone and the render fully over it (back to the last blend on the next press)."""
        blend = self.app.state.view.render_blend
        if blend > 0.0:
            self._blink_back = blend
        self.set_blend(0.0 if blend > 0.0 else self._blink_back)

    def show_drag_pose(self, T_camera_lidar: np.ndarray | None, render: bool) -> None:
        """Render ``T_camera_lidar`` while an alignment drag turns the view (None: the drag ended), if ``render``
        (:meth:`app.align_panel.AlignPanel.subscribe_drag`)."""
        self.drag_pose = T_camera_lidar
        if render:
            self.request()

    def on_align_drag_mode(self, on: bool) -> None:
        """"Align by drag" ticked: show the render over the photo (half opaque) if it was hidden; unticked: hide it
        again if the tick showed it and nobody changed it since (run 8: it stayed over the photo)."""
        if on and self.app.state.view.render_blend == 0.0:
            self.set_blend(ALIGN_BLEND)
            self._shown_for_drag = True
        elif not on and self._shown_for_drag:
            self._shown_for_drag = False
            if self.app.state.view.render_blend == ALIGN_BLEND:
                self.set_blend(0.0)

    def set_blend(self, blend: float) -> None:
        """Draw the render over the photo with opacity ``blend`` (0 hides it), and save it."""
        view = self.app.state.set_view(render_blend=float(blend))  # clipped to RENDER_BLEND_RANGE
        with self.app.ui_lock:
            if abs(float(self._sl_blend.value) - view.render_blend) > 1e-9:
                self._sl_blend.value = view.render_blend
            self._show_overlay()

    # ------------------------------------------------------------------ rendering
    def view_pose(self) -> tuple[np.ndarray, str]:
        """The pose the render shows and where it comes from (a key of :data:`POSE_NAMES`)."""
        if self.drag_pose is not None and self.app.pose_source.trusted_bundle() is None:
            return self.drag_pose, "drag"
        return self.app.pose_source.view_pose()

    def on_state_change(self, state: Any) -> None:
        """After any change of the state: a new render if the pose or the shading changed, the markers redrawn."""
        self.request()
        self.draw_marks()

    def request(self) -> None:
        """Render the current pose in the background if the page does not show it yet (never waits)."""
        if self._stopped:
            return
        T, source = self.view_pose()
        mode = self.app.state.view.render_mode
        key = (np.asarray(T, np.float64).tobytes(), mode, source)
        if key == self._requested:
            return
        if self._requested is None or self._requested[2] != source:
            self._publish("pose")  # e.g. the Align panel's pose line says which pose is used (solve, rough, preset)
        self._requested = key
        self._wanted = (np.array(T, np.float64), mode, source)
        self._job += 1
        self._worker.submit(self._job, None)

    def _shade_inputs(self, mode: str) -> tuple[str, dict]:
        """The shading mode that applies to this scan and the images it needs."""
        app = self.app
        if mode == "intensity":
            found = find_intensity(app.depth.meta.get("field_images"))
            if found is None:
                return "range", {}
            return mode, {"intensity": found[1]}
        if mode == "ba":
            return mode, {"ba_image": app.scene_data.ba_rad[app.ba_keys[0]]}
        return "range", {}

    def _render_job(self, _: Any) -> ShownRender:
        if self._wanted[2] == "solve":  # new solves: one render per interval, of the newest pose then
            time.sleep(max(0.0, self._last_done + SOLVE_RENDER_INTERVAL_S - time.monotonic()))
        T, mode, source = self._wanted
        t0 = time.perf_counter()
        render = render_from_camera(self.app.depth, self.app.camera, T)
        shade_mode, images = self._shade_inputs(mode)
        rgba = np.asarray(shade_render(render, self.app.depth, mode=shade_mode, **images), np.uint8)
        return ShownRender(T, mode, source, render, rgba, time.perf_counter() - t0)

    def _on_rendered(self, job: int, shown: ShownRender | None, error: BaseException | None) -> None:
        app = self.app
        self._last_done = time.monotonic()
        if self._stopped:
            return
        if error is not None:
            if not isinstance(error, CalibError):
                traceback.print_exception(error)
            self._title.text = f"Camera-view laser: not rendered ({' '.join(str(error).split())})"
            return
        with app.ui_lock, app.server.atomic():
            self.current = shown
            self._handle.image = self._shown_texture(shown)
            self._title.text = self.title()
            self._show_overlay()
            self.draw_marks()
            self._publish("render")  # e.g. the laser loupe showing its crop, the Align panel's pose line

    def _shown_texture(self, shown: ShownRender) -> np.ndarray:
        """The pane's texture: the render in the camera view's framing, over :data:`NO_RETURN_RGB`."""
        view = self.app.camera_view
        if view.key == "raw":
            return pane_texture(shown.rgba)
        return pane_texture(view.shown(shown.rgba))  # alpha 0 where the panorama sees past the camera

    def _show_overlay(self) -> None:
        """The render over the photo at the saved opacity (hidden at 0 and without a render)."""
        blend = self.app.state.view.render_blend
        shown = self.current
        visible = blend > 0.0 and shown is not None
        if visible:
            rgba = self.app.camera_view.shown(shown.rgba).copy()
            rgba[..., 3] = np.round(rgba[..., 3] * blend).astype(np.uint8)
            self._overlay.image = rgba
        if self._overlay.visible != visible:
            self._overlay.visible = visible

    def title(self) -> str:
        """The pane's title as the page shows it."""
        shown = self.current
        if shown is None:
            return "Camera-view laser: rendering ..."
        mode = RENDER_MODES[shown.mode]
        return (f"Camera-view laser ({mode}) under the {POSE_NAMES[shown.source]}; click a point to pick its "
                f"laser cell")

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until the newest requested render is shown."""
        return self._worker.wait_idle(timeout)

    def stop(self) -> None:
        self._stopped = True
        self._worker.stop()

    # ------------------------------------------------------------------ clicks
    def cell_at_pixel(self, u: float, v: float, radius_px: float = NEAREST_PX,
                      edge_px: float = 0.0) -> tuple[int, int] | None:
        """Scan cell ``(row, col)`` the render draws at original-size pixel ``(u, v)`` (:func:`cell_at_pixel`)."""
        return cell_at_pixel(self.current, u, v, radius_px, edge_px)

    def target_at(self, uv: tuple[float, float], display: bool = True, screen_units: float | None = None) -> tuple:
        """``("ba", key, row, col)``: the laser cell under pixel ``uv`` of the pane (``display``: in the camera
        view's framing; else an original camera pixel).  ``key``: the BA image the laser loupe falls back to.

        Where the render shows no return, the nearest rendered pixel counts if it lies within :data:`NEAREST_PX`
        render pixels or, with ``screen_units`` (world units per screen pixel in the clicking tab), within
        :data:`SNAP_SCREEN_PX` screen pixels (at most :data:`NEAREST_MAX_PX` render pixels).  CalibError when
        there is none."""
        if self.current is None:
            raise CalibError("the camera-view render is not ready yet; try again in a moment")
        stale = self.app.pose_source.stale_click_reason(self.current)  # planned on the render before a refit
        if stale is not None:
            raise CalibError(stale)
        radius, edge = float(NEAREST_PX), EDGE_RENDER_PX
        if display and screen_units is not None:
            per_px = self.app.slots[RENDER_KEY].units_per_px  # world units per pane pixel
            radius = float(min(max(radius, SNAP_SCREEN_PX * screen_units / per_px), NEAREST_MAX_PX))
            edge = float(min(max(edge, EDGE_SCREEN_PX * screen_units / per_px), NEAREST_PX))
        if display:
            raw, ok = self.app.camera_view.pixels_from_display(np.array([uv], np.float64))
            if not ok[0]:
                raise CalibError("the camera does not see that part of the panorama; click inside the picture")
            uv = (float(raw[0, 0]), float(raw[0, 1]))
        cell = self.cell_at_pixel(float(uv[0]), float(uv[1]), radius, edge if display else 0.0)
        if cell is None:
            raise CalibError("no laser return here: click where the camera-view render shows the scan")
        self.last_pixel = (float(uv[0]), float(uv[1]))
        return ("ba", self._laser_key(), *cell)

    def pixel_of_cells(self, rows_cols: np.ndarray) -> np.ndarray:
        """Original camera pixels of scan cells under the shown render's pose (:func:`pixel_of_cells`)."""
        return pixel_of_cells(self.current, self.app.camera, self.app.depth, rows_cols)

    def _on_shift_click(self, event: Any) -> None:
        """Shift+click on the render: select the pair whose laser end is drawn nearest (as on the BA images)."""
        slot = self.app.slots[RENDER_KEY]
        uv = slot.pixel_from_ray(event.ray_origin, event.ray_direction)
        picks = [p for p in self.app.state.picks if p.laser_rc is not None]
        if uv is None or not picks:
            self.app.state.select(None)
            return
        xy, shown = self.app.display_from_pixels(self.pixel_of_cells(np.array([p.laser_rc for p in picks])))
        d = np.where(shown, np.hypot(xy[:, 0] - uv[0], xy[:, 1] - uv[1]), np.inf)
        d = np.where(np.isfinite(d), d, np.inf)
        k = int(np.argmin(d))
        self.app.state.select(picks[k].id if d[k] * slot.units_per_px <= PICK_RADII * self._ring_radius(slot) else None)

    def _on_plain_drag(self, event: Any) -> None:
        """A left-drag on the render: turns the view while "Align by drag" is on; a shaky click is a click."""
        if self._drag_taker(event):  # "Align by drag" is on: the Align panel turned the view
            return
        if event.phase != "end":
            return
        moved = np.hypot(*(np.asarray(event.end_screen_pos) - np.asarray(event.start_screen_pos)))
        slot = self.app.slots[RENDER_KEY]
        start = slot.pixel_from_world(np.asarray(event.start_position)[None])[0]
        if moved < 0.01 and slot.contains(start):  # display pixels, as a click gives them
            self._click_at(RENDER_KEY, (float(start[0]), float(start[1])), event.client)

    # ------------------------------------------------------------------ markers
    @staticmethod
    def _ring_radius(slot: ImageSlot) -> float:
        return max(6.0 * slot.units_per_px, 0.05)

    def draw_marks(self) -> None:
        """The picked laser ends on the render, as rings in their pair's colour where the render's pose puts them."""
        app = self.app
        shown = self.current
        hidden = app.state.view.hide_marks  # "Hide marks": none on the render either
        picks = tuple((p.id, p.laser_rc, p.color) for p in app.state.picks if p.laser_rc is not None and not hidden)
        slot = app.slots[RENDER_KEY]
        inputs = (id(shown), picks, slot, app.state.selected)
        if inputs == self._marks_of:
            return
        self._marks_of = inputs
        xy, ok = app.display_from_pixels(self.pixel_of_cells(np.array([rc for _, rc, _ in picks]).reshape(-1, 2)))
        ok &= np.isfinite(xy).all(axis=1)
        world = slot.world_from_pixel(xy[ok], z_offset=-0.01)
        colors = np.array([c for _, _, c in picks], np.uint8).reshape(-1, 3)[ok]
        sel = [k for k, (pid, _, _) in enumerate(p for p, good in zip(picks, ok) if good) if pid == app.state.selected]
        draw_ring_markers(app.nodes, RENDER_KEY, world, colors, self._ring_radius(slot), sel)
