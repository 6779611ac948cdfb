"""The browser annotation app: a viser server around :mod:`calib_core` (the composition root).

The page shows the four Bearing Angle images beside the camera image (raw, or unwrapped into a panorama) and two
loupes.  A BA click and a camera click, in either order, make a pair; from 4 pairs on the extrinsics are solved live
(:mod:`app.live_coordinator`).  A change is on disk (:mod:`app.session_store`) before the page shows it.
:class:`CalibrationApp` constructs one object per concern and wires them; start and stop it from Python or ``ba-calib``.
"""

from __future__ import annotations

import os
import threading
import traceback
from pathlib import Path
from typing import Any, Callable

import numpy as np

from . import blas_threads
from .action_queue import ActionQueue, UiLock, notify_tabs
from .align_panel import AlignPanel
from .calibration_panel import CalibrationPanel
from .camera_view import camera_views
from .cloud_pane import CloudPane
from .display_panel import DisplayPanel
from .export_panel import ExportPanel, FormatExportPanel
from .guide_panel import GuidePanel
from .laser_images import LaserImages
from .layout import RENDER_KEY
from .live_coordinator import LiveSolveCoordinator
from .loupes import Loupes
from .overlay_drawing import OverlayDrawing
from .page_builder import PageBuilder
from .pairs_panel import PairsPanel
from .prepared_scene import MAX_CLOUD_POINTS, PreparedScene
from .render_pane import RenderPane
from .scene_nodes import SceneNodes
from .security import AccessPolicy, RefusalLog, start_guarded_viser
from .state import AnnotationState
from .ui_common import page_url, units_per_screen_px
from .verify_panel import VerifyPanel
from .view_panel import ViewPanel
from .picks import ShotFiles
from .pose_source import PoseSource, read_extrinsics
from .warm_up import WarmUp


# The composition root: one object per concern (a public attribute each, e.g. ``live``, ``loupes``); panels use only
# its services (app/app_services.py).
class CalibrationApp:
    """The annotation app on one scene; the viser server runs from construction.

    Parameters
    ----------
    scan_path, image_path, camera_path : path-like
        The laser scan (any format :func:`calib_core.io.scan_readers.load_scan` reads), the camera image and
        the camera model file.
    session_path : path-like, optional
        Session file (pairs and view settings), saved after every change and restored on start.  Default:
        ``<scan stem>.ba-calib-session.yaml`` in the current directory.
    output_path : path-like, optional
        Where "Download extrinsics YAML" also writes the file.
    host, port : str, int
        Bind address (``127.0.0.1`` by default: local only).  If the port is busy viser takes the next free
        one; see :attr:`port`.
    title : str, optional
        Page title.
    scan_options : dict, optional
        Keyword options of :func:`calib_core.io.scan_readers.load_scan` (``organize``, ``beams``, ...).
    image_size : (width, height), optional
        Overrides the camera file's image size (see :func:`calib_core.cameras.load_camera`).
    kitti_camera : int, optional
        For a KITTI calib file as the camera: which rectified camera (0-3; default 2).
    max_cloud_points : int
        Points shown in the 3-D pane (the PLY export has all of them).
    token : str, optional
        Access token required with a non-loopback ``host`` (default: a random one; :attr:`url` carries it).
        Loopback binds need none unless given.
    allowed_hosts : tuple of str
        More host names the server may be reached by (``Host`` headers); see :mod:`app.security`.
    initial_extrinsics_path : path-like, optional
        A rough extrinsic (any format :func:`calib_core.io.extrinsic_formats.load_extrinsics_any` reads)
        that predictions and "Facing the camera" use until a solve exists.
    scene_data, state, shot_scenes : optional
        A session of several shots (:class:`app.serving.ShotServer`): this shot's loaded scene, the
        state shared by every shot (not closed by :meth:`stop`) and every shot's scene, in shot order.

    Raises
    ------
    CalibError
        Unreadable or inconsistent input files.
    """

    def __init__(self, scan_path: str | os.PathLike, image_path: str | os.PathLike, camera_path: str | os.PathLike,
                 *, session_path: str | os.PathLike | None = None, output_path: str | os.PathLike | None = None,
                 host: str = "127.0.0.1", port: int = 8080, title: str | None = None, scan_options: dict | None = None,
                 image_size: tuple[int, int] | None = None, max_cloud_points: int = MAX_CLOUD_POINTS,
                 token: str | None = None, allowed_hosts: tuple[str, ...] = (),
                 initial_extrinsics_path: str | os.PathLike | None = None, kitti_camera: int | None = None,
                 scene_data: PreparedScene | None = None, state: AnnotationState | None = None,
                 shot_scenes: list[PreparedScene] | None = None) -> None:
        # Kernels compile in the background while the inputs load; nothing waits for it.
        self.warm_up = WarmUp()
        self.scan_path, self.image_path, self.camera_path = Path(scan_path), Path(image_path), Path(camera_path)
        self.output_path = None if output_path is None else Path(output_path)
        self.session_path = (Path.cwd() / f"{self.scan_path.stem}.ba-calib-session.yaml" if session_path is None
                             else Path(session_path))
        self.title = title or f"ba-calib: {self.scan_path.name} + {self.image_path.name}"

        # -- data (all maths from calib_core, no viser) ----------------------------------
        self.scene_data = sd = scene_data or PreparedScene.load(
            self.scan_path, self.image_path, self.camera_path, scan_options=scan_options, image_size=image_size,
            max_cloud_points=max_cloud_points, kitti_camera=kitti_camera)
        self.shot_scenes = list(shot_scenes) if shot_scenes else [sd]  # every shot's scene (the live solve's)
        self.depth, self.camera, self.image = sd.depth, sd.camera, sd.image
        self.ba_keys, self.ba_gray, self.image_gray = sd.ba_keys, sd.ba_gray, sd.image_gray
        self.all_points_lidar, self.cloud_points_lidar = sd.all_points_lidar, sd.cloud_points_lidar
        self.ba_cell_aspect, self.wrap_cols = sd.ba_cell_aspect, sd.wrap_cols
        self.camera_views = camera_views(sd)  # raw, and panorama for ocam / fisheye (app.view.camera_view)
        self.camera_sizes = {k: (v.image.shape[1], v.image.shape[0]) for k, v in self.camera_views.items()}
        initial_T = None if initial_extrinsics_path is None else read_extrinsics(Path(initial_extrinsics_path))

        # -- state ------------------------------------------------------------------
        # Every change is on disk (an fsync'd journal line) before the UI shows it; the journal is compacted into
        # the session YAML in the background and by stop().  The view settings live in ``state.view`` only.
        self._stopped = False
        self._owns_state = state is None
        self.state = state or AnnotationState(self.depth.valid, (self.camera.width, self.camera.height),
                                              self.session_path, on_save_error=self._on_save_error,
                                              default_view=sd.default_view(),
                                              shots=(ShotFiles.of(self.scan_path, self.image_path),))
        self.session_path = self.state.session_path or self.session_path
        self.active_shot = self.state.active_shot  # the shot these panes show
        self.ui_lock = UiLock()  # public: held while the scene and the panels are redrawn
        self.folder_lock = threading.Lock()  # held while one tab's own widgets go into a shared folder
        self.laser_images = LaserImages(self)  # the laser panes' grey levels, with the saved contrast
        self.display = DisplayPanel(self)  # their widgets (loupe source, last pane, contrast, hide marks, edges)
        self.live = LiveSolveCoordinator(self)  # the solve shown; its threads start with the page
        self.pose_source = PoseSource(self, initial_T)  # the pose predictions use (solved, else rough)
        self.pose_source.subscribe(self._on_rough_pose)
        self.pose_source.ensure_facing()  # from the rough pose, else the "+x" preset

        # -- server -------------------------------------------------------------------
        # Every request must name this server (Host, Origin) and, off loopback, carry the token.
        self.access = AccessPolicy.for_bind(host, token=token, extra_hosts=tuple(allowed_hosts))
        self.server = start_guarded_viser(self.access, on_refused=RefusalLog(), host=host, port=port,
                                          label=self.title, verbose=False)
        self.actions = ActionQueue(self.notify)  # the ordered worker every user action runs on
        self.host, self.port = host, self.server.get_port()
        self.url = page_url(host, self.port, self.access.token)
        blas_threads.limit()  # BLAS's spinning threads would take a core from the clicks' solves and redraws
        self._blas_limited = True
        try:
            # Redraws diff against what the scene shows, so a click only sends the nodes it changed.
            self.nodes = SceneNodes(self.server.scene)
            self.nodes.fill_label_pool()
            self.overlays = OverlayDrawing(self)  # markers, labels, selection, reprojection overlays
            self.cloud = CloudPane(self.server.scene, self.cloud_points_lidar)  # the 3-D pane
            self.live.subscribe_cloud(self.cloud.show)  # it shows the live solve's camera, colours and pair points
            # The control panel's folders in page order; each panel builds its own widgets.
            self.page = PageBuilder(self)  # theme, intro text, backdrop
            self.pairs_panel = PairsPanel(  # "Pairs" folder, clicks on the images
                self, top=self.page.intro.order, loupe_marks_after=self.overlays.loupe_marks_after,
                nearest_pick=self.overlays.nearest_pick, aligning=lambda: self.align.drag_enabled)
            self.pairs_folder = self.pairs_panel.folder  # guided picking goes below it
            self.subscribe_solve(lambda shown: self.pairs_panel.refresh())  # after the overlays' (OverlayDrawing)
            self.calibration_panel = CalibrationPanel(self.server.gui)
            self.subscribe_solve(self.calibration_panel.on_solve_shown)
            # "View" folder, the BA column window, the page layout, each tab's camera; holds two display widgets.
            self.view = ViewPanel(self, add_last_pane_control=self.display.add_last_pane_control,
                                  add_edge_control=self.display.add_edge_control)
            self.view.subscribe_window(self.page.show_ba_window)  # the BA images follow the window and layout
            self.view.subscribe_layout(lambda moved: self.overlays.refresh())  # the marks follow the images
            self.view.subscribe_camera_view(self.page.show_camera_view)
            self.view.subscribe_3d(self._on_3d_view)
            self.export_panel = ExportPanel(self)
            self.page.add_images({k: self.view.ba_texture(k) for k in self.ba_keys},
                                 {k: self.view.ba_title(k) for k in self.ba_keys})
            self.view.update_camera_title()
            # The scan seen from the camera, below the camera image; a click on it picks a laser cell.
            self.render_pane = RenderPane(self, laser_key=lambda: self.loupes.ba_crop.key,
                                          click_at=self.pairs_panel.click_at)
            self.view.subscribe_window(lambda shown: self.render_pane.place())
            self.align = AlignPanel(  # rough pose; first folder; it holds the render's widgets, drags on its nodes
                self, order=self.pairs_folder.order - 0.5, add_render_controls=self.render_pane.add_controls,
                drag_nodes=lambda: {**{key: self.page.image_handle(key) for key in self.camera_views},
                                    **self.render_pane.drag_nodes},
                render_drag_callbacks={RENDER_KEY: self.render_pane.plain_drag_callback,
                                       "camera_overlay": self.render_pane.overlay_drag_callback})
            self.render_pane.hand_plain_drags_to(lambda event: self.align.take_drag(RENDER_KEY, event))
            self.render_pane.subscribe(lambda what, shown: self.align.show())  # its pose line names the render's pose
            self.align.subscribe_drag(self.render_pane.show_drag_pose)  # the render follows an alignment drag
            self.align.subscribe_drag_mode(self.render_pane.on_align_drag_mode)
            # The magnified BA and camera panes; their folder holds the display panel's loupe widgets.
            self.loupes = Loupes(self, add_controls=self.display.add_loupe_controls)
            self.pairs_panel.resolve_clicks_with(  # a click in a loupe or on the render picks what it shows there
                loupe=self.loupes.target_at, render=lambda uv, client: (self.render_pane.target_at(
                    uv, screen_units=units_per_screen_px(getattr(client, "camera", None))), self.render_pane.last_pixel))
            self.overlays.place_loupes_by(self.loupes.display_of)  # the marks in the loupes, Shift+click on them
            self.overlays.subscribe(self.loupes.draw_marks)  # the loupes show the marks magnified
            self.pairs_panel.subscribe_clicks(self.loupes.on_pair_click)  # the loupes follow each click
            self.pairs_panel.subscribe_cancel(self.loupes.on_pair_cancelled)
            self.pairs_panel.subscribe_clicks(self.view.on_pair_click)  # "Zoom on last click"
            self.view.subscribe_layout(self.loupes.relayout)  # after the marks' redraw
            self.view.frame_also("loupe_ba", "loupe_camera")  # "All" frames the loupes too
            self.render_pane.subscribe(self.loupes.on_render, replay=True)  # the laser loupe can show its crop
            self.format_export = FormatExportPanel(self)  # verify: its own widgets (formats, reference import)
            self.display.subscribe(self._on_display_change)
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(lambda client: self.view.forget_tab(client.client_id))
            self.subscribe_solved(lambda shown: self.render_pane.request())  # the render follows the solve shown
            # In the action worker, so a click is never mapped through a window that changed under it.
            self.live.subscribe_facing(lambda: self.post(self.view.apply_ba_window))
            self.live.start()
            self.guide = GuidePanel(  # guided picking (app/guide_panel.py); it frames the loupes
                self, loupes=lambda: self.loupes, on_status=self.pairs_panel.show_guide_status)
            self.pairs_panel.set_next_pair_handler(self.guide.callback("Next pair"))  # its button in the pair actions
            self.state.subscribe(self.live.on_state_change)
            self.live.on_state_change(self.state)
            self.state.subscribe(self.align.on_pairs_change)  # 2-3 pairs turn the rough pose to fit them
            self.align.on_pairs_change(self.state)
            self.state.subscribe(self.render_pane.on_state_change)  # after the live solve's: sees its bundle
            self.render_pane.request()
            self.verify_panel = VerifyPanel(self)  # verify: check pairs, leave-one-out, heat map, reference, plots
            self.export_panel.verification = self.verify_panel.report_for  # the YAML carries the Verify report
            self.format_export.reference_listeners.append(self.verify_panel.set_reference)
        except BaseException:
            self.stop()
            raise

    def _on_connect(self, client: Any) -> None:
        try:  # this tab's own upload buttons, then its view of the page
            self.pairs_panel.add_upload_button(client)
            self.align.add_upload_button(client)
            self.view.set_view(client, "all")
        except Exception:
            traceback.print_exc()

    def _on_display_change(self, what: str) -> None:
        """What the laser panes show changed (:meth:`DisplayPanel.subscribe`): redraw the panes, loupe and marks."""
        if what in ("marks", "edges"):
            if what == "edges":
                self.overlays.invalidate()  # redraw the overlays with the new blend
            self.overlays.refresh()  # "Hide marks": the marks' redraws depend on it, only they are sent
            return
        keys = {"contrast": self.ba_keys, "last_pane": self.ba_keys[-1:]}.get(what, ())
        with self.ui_lock, self.server.atomic():
            for key in keys:
                title = {"title": self.view.ba_title(key)} if what == "last_pane" else {}
                self.page.set_ba(key, texture=self.view.ba_texture(key), **title)
        self.loupes.refresh()

    def _on_3d_view(self, shown: bool) -> None:
        """Some tab shows the 3-D view (or none does): the cloud shows, with the current solve's colours."""
        self.cloud.visible = shown
        self.live.show_3d(shown)  # a tab that switches to 3-D gets the current solve's colours

    def _on_rough_pose(self) -> None:
        """A new rough pose (:meth:`PoseSource.subscribe`): redraw predictions, the facing window and the render."""
        if self.state.view.ba_window_mode == "camera" and self.live.bundle is None:
            self.pose_source.ensure_facing()
            self.view.apply_ba_window()
        if getattr(self, "render_pane", None) is not None:
            self.render_pane.request()
            self.align.show()
        self.overlays.invalidate()
        self.overlays.refresh()
        self.live.redraw()
        guide = getattr(self, "guide", None)
        if guide is not None:  # proposals can start from the imported pose
            guide.update()

    def _on_save_error(self, message: str) -> None:
        # On the compactor's thread; the journal holds every change, the compaction is retried.
        if hasattr(self, "server") and not self._stopped:
            self.notify(None, "Session file not updated (retrying; no change lost)", message)

    # ================================================================ services
    # What panels may use of the app; each is documented once, in app/app_services.py (AppServices).
    def guard(self, fn: Callable) -> Callable:
        return self.actions.guard(fn)

    def post(self, fn: Callable[[], Any], client: Any = None, wait: bool = False) -> None:
        self.actions.post(fn, client, wait)

    def notify(self, client: Any, title: str, body: str, color: str = "red") -> None:
        notify_tabs(self.server, client, title, body, color)

    slots = property(lambda self: self.view.slots)
    ba_window = property(lambda self: self.view.ba_window)
    camera_view = property(lambda self: self.view.camera_view)

    def slot_of(self, key: str) -> Any:
        if key.startswith("loupe_"):
            return self.loupes.slot(key[len("loupe_"):])
        return self.view.slots[key]

    def camera_slot(self) -> Any:
        return self.view.camera_slot()

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.view.camera_view.display_from_pixels(pixels)

    def make_click_handler(self, key: str) -> Callable:
        return self.pairs_panel.make_click_handler(key)

    def make_drag_handler(self, key: str) -> Callable:
        return self.pairs_panel.make_drag_handler(key)

    def make_select_handler(self, key: str) -> Callable:
        return self.pairs_panel.make_select_handler(key)

    def camera_click_source(self, pick_id: int) -> str | None:
        return self.pairs_panel.camera_click_source(pick_id)

    def forget_last_picks(self) -> None:
        self.pairs_panel.forget_last_picks()

    def subscribe_solve(self, listener: Callable[[Any], None]) -> None:
        self.live.subscribe(listener)

    def subscribe_solved(self, listener: Callable[[Any], None]) -> None:
        self.live.subscribe_solved(listener)

    def solve_shown(self) -> Any:
        return self.live.shown()

    solve_bundle = property(lambda self: self.live.bundle)
    result = property(lambda self: getattr(self.live.bundle, "result", None))

    def pose(self) -> np.ndarray | None:
        return self.pose_source.pose()

    initial_T_camera_lidar = property(lambda self: self.pose_source.initial_T_camera_lidar)
    last_update_time = property(lambda self: self.live.last_update_time,
                                doc="``perf_counter()`` when the newest change's solve was shown.")

    def wait_idle(self, timeout: float = 30.0) -> bool:
        return self.live.wait_idle(timeout)

    def stop(self) -> None:
        """Stop the threads and the server once the session file holds every change (CalibError if it cannot);
        also what a construction that failed part way had started."""
        self._stopped = True
        self.actions.stop()
        self.live.stop()
        for part in ("render_pane", "guide", "verify_panel"):
            if hasattr(self, part):  # built
                getattr(self, part).stop()
        try:
            self.state.close() if self._owns_state else self.state.clear_listeners()
        finally:
            self.server.stop()
            if self._blas_limited:  # once per app, however often stop() is called
                self._blas_limited = False
                blas_threads.unlimit()
