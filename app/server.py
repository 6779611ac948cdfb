"""The browser annotation app: a viser server around :mod:`calib_core` (the composition root).

The page shows the four Bearing Angle images beside the camera image (raw, or unwrapped into a panorama),
with two loupes (:mod:`app.loupes`) that magnify the last click and the predicted other end.  A BA click and
a camera click, in either order, make a pair; from 4 pairs on the extrinsics are solved live in a worker
thread.  Each panel owns one concern (pairs, view, calibration, guide, verify, export); every number shown
comes from :mod:`calib_core`.  A change is on disk (:mod:`app.session_store`) before the page shows it, so it
survives a kill -9; then the changed markers are sent at once, the solve's errors, table and overlays follow
from the solver thread (:meth:`last_click_to_update`), and the 3-D cloud is recoloured last in its own thread.

Start and stop :class:`CalibrationApp` from Python (tests) or through ``ba-calib``.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .ba_view import ColumnWindow
from .camera_view import camera_views
from .cloud_pane import CloudPane
from .loupes import Loupes
from .loupe_support import LoupeSupport, read_extrinsics
from .display_panel import DisplayPanel
from .action_queue import ActionQueue, notify_tabs
from .calibration_panel import CalibrationPanel
from .export_panel import ExportPanel
from .pairs_panel import PairsPanel
from .page_builder import PageBuilder, build_view_folder
from .view_panel import ViewPanel
from .export_panel import FormatExportPanel
from .guide_panel import attach_guide_panel
from .verify_panel import VerifyPanel
from .live_coordinator import LiveSolveCoordinator
from .overlay_drawing import OverlayDrawing
from .prepared_scene import MAX_CLOUD_POINTS, PreparedScene
from .scene_nodes import SceneNodes
from .security import TOKEN_QUERY, AccessPolicy, RefusalLog, start_guarded_viser
from .state import AnnotationState
from .warm_up import WarmUp
from .ui_common import SolveBundle
from .view_settings import ViewSettings


# Panels that are classes own their widgets and use only the app's public services (app/app_services.py):
# CalibrationPanel, ExportPanel, FormatExportPanel, Loupes, GuidePanel, VerifyPanel.  The bases below are
# still mixins (one concern and module each) that share the app's attributes.
class CalibrationApp(ViewPanel, DisplayPanel):
    """The annotation app on one scene; the viser server runs from construction.

    Parameters
    ----------
    scan_path, image_path, camera_path : path-like
        The laser scan (any format :func:`calib_core.io.scan_readers.load_scan`
        reads), the camera image and the camera model file.
    session_path : path-like, optional
        Session file (pairs and view settings), saved after every change and
        restored on start.  Default: ``<scan stem>.ba-calib-session.yaml`` in
        the current directory.
    output_path : path-like, optional
        Where "Download extrinsics YAML" also writes the file.
    host, port : str, int
        Bind address (``127.0.0.1`` by default: local only).  If the port is
        busy viser takes the next free one; see :attr:`port`.
    title : str, optional
        Page title.
    scan_options : dict, optional
        Keyword options of :func:`calib_core.io.scan_readers.load_scan`
        (``organize``, ``beams``, ...).
    image_size : (width, height), optional
        Overrides the camera file's image size (see :func:`calib_core.cameras.load_camera`).
    max_cloud_points : int
        Points shown in the 3-D pane (the PLY export has all of them).
    token : str, optional
        Access token required with a non-loopback ``host`` (default: a random
        one; :attr:`url` carries it).  Loopback binds need none unless given.
    allowed_hosts : tuple of str
        More host names the server may be reached by (``Host`` headers);
        see :mod:`app.security`.

    Raises
    ------
    CalibError
        Unreadable or inconsistent input files.
    """

    def __init__(
        self,
        scan_path: str | os.PathLike,
        image_path: str | os.PathLike,
        camera_path: str | os.PathLike,
        *,
        session_path: str | os.PathLike | None = None,
        output_path: str | os.PathLike | None = None,
        host: str = "127.0.0.1",
        port: int = 8080,
        title: str | None = None,
        scan_options: dict | None = None,
        image_size: tuple[int, int] | None = None,
        max_cloud_points: int = MAX_CLOUD_POINTS,
        token: str | None = None,
        allowed_hosts: tuple[str, ...] = (),
        initial_extrinsics_path: str | os.PathLike | None = None,
    ) -> None:
        # Kernels compile in the background while the inputs load; nothing waits for it.
        self.warm_up = WarmUp()
        self.scan_path, self.image_path, self.camera_path = Path(scan_path), Path(image_path), Path(camera_path)
        self.output_path = None if output_path is None else Path(output_path)
        if session_path is None:
            session_path = Path.cwd() / f"{self.scan_path.stem}.ba-calib-session.yaml"
        self.session_path = Path(session_path)
        self.title = title or f"ba-calib: {self.scan_path.name} + {self.image_path.name}"

        # -- data (all maths from calib_core, no viser) ----------------------------------
        self.scene_data = PreparedScene.load(self.scan_path, self.image_path, self.camera_path,
                                             scan_options=scan_options, image_size=image_size,
                                             max_cloud_points=max_cloud_points)
        sd = self.scene_data
        self.depth, self.camera, self.image = sd.depth, sd.camera, sd.image
        self.ba_rad, self.ba_keys, self.ba_gray, self.image_gray = sd.ba_rad, sd.ba_keys, sd.ba_gray, sd.image_gray
        self.edge_points_lidar, self.all_points_lidar, self.all_rows_cols = (
            sd.edge_points_lidar, sd.all_points_lidar, sd.all_rows_cols)
        self.ba_cell_aspect, self.wrap_cols, self.cloud_points_lidar = (
            sd.ba_cell_aspect, sd.wrap_cols, sd.cloud_points_lidar)
        initial_T = None if initial_extrinsics_path is None else read_extrinsics(Path(initial_extrinsics_path))

        # -- state ------------------------------------------------------------------
        # Every change is on disk (an fsync'd journal line) before the UI shows it; the journal is
        # compacted into the session YAML in the background and by stop().
        # The view settings live in the state only (``state.view``, saved with the session).
        default_view = ViewSettings(up_axis="+y" if self.depth.meta.get("model") == "rotating_2d" else "+z")
        self.state = AnnotationState(self.depth.valid, (self.camera.width, self.camera.height), self.session_path,
                                     on_save_error=self._on_save_error, default_view=default_view)
        self.ui_lock = threading.RLock()  # public: held while the scene and the panels are redrawn
        self._init_display()  # the laser panes' grey levels, with the saved contrast
        self.camera_views = camera_views(sd)  # raw, and panorama for ocam / fisheye (app.camera_view)
        self.live = LiveSolveCoordinator(self)  # the solve shown; its threads start with the page
        self.loupe_support = LoupeSupport(self, initial_T)  # the pose predictions use (solved, else imported)
        self.live.ensure_facing()  # from the imported initial extrinsic, if any
        self._ba_window = self._wanted_ba_window()
        self.camera_sizes = {k: (v.image.shape[1], v.image.shape[0]) for k, v in self.camera_views.items()}
        self.slots = self._layout()

        self._client_mode: dict[int, str] = {}
        self._view_target: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        self._stopped = False

        # -- server -------------------------------------------------------------------
        self.actions = ActionQueue(self.notify)  # the ordered worker every user action runs on
        # Every request must name this server (Host, Origin) and, off loopback, carry the token.
        self.access = AccessPolicy.for_bind(host, token=token, extra_hosts=tuple(allowed_hosts))
        self._refusals = RefusalLog()
        try:
            self.server = start_guarded_viser(self.access, on_refused=self._refusals, host=host, port=port,
                                              label=self.title, verbose=False)
        except BaseException:
            self.actions.stop()
            raise
        self.host = host
        self.port = self.server.get_port()
        shown_host = "127.0.0.1" if host in ("0.0.0.0", "", "::") else host
        if ":" in shown_host:
            shown_host = f"[{shown_host}]"
        query = "" if self.access.token is None else f"/?{TOKEN_QUERY}={self.access.token}"
        self.url = f"http://{shown_host}:{self.port}{query}"
        # Redraws diff against what the scene shows, so a click only sends the nodes it changed.
        self.nodes = SceneNodes(self.server.scene)
        self.nodes.fill_label_pool()
        self.overlays = OverlayDrawing(self)  # markers, labels, selection, reprojection overlays
        self.cloud = CloudPane(self.server.scene, self.cloud_points_lidar)  # the 3-D pane
        try:
            # The control panel's folders in page order; each panel builds its own widgets.
            self.page = PageBuilder(self)  # theme, intro text, backdrop
            self.pairs_panel = PairsPanel(self)  # "Pairs" folder and the clicks on the images
            self.pairs_folder = self.pairs_panel.folder  # guided picking goes below it
            self.calibration_panel = CalibrationPanel(self.server.gui)
            build_view_folder(self)
            self.export_panel = ExportPanel(self)
            self._sync_window_widgets()
            self.page.add_images({k: self._ba_texture(k) for k in self.ba_keys},
                                 {k: self._ba_title(k) for k in self.ba_keys})
            self._update_camera_title()
            self.loupes = Loupes(self)  # the magnified BA and camera panes (public: frame_ba, frame_camera)
            self.format_export = FormatExportPanel(self)  # verify: its own widgets (formats, reference import)
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(self._on_disconnect)
            self.live.start()
            self.guide = attach_guide_panel(self)  # guided picking (app/guide_panel.py)
            self.state.subscribe(self.live.on_state_change)
            self.live.on_state_change(self.state)
            self.verify_panel = VerifyPanel(self)  # verify: check pairs, leave-one-out, heat map, reference, plots
        except BaseException:
            self.actions.stop()
            self.server.stop()
            self.state.close()
            raise

    # ================================================================ test hooks
    @property
    def ba_window(self) -> ColumnWindow:
        """The scan columns the BA images show."""
        return self._ba_window

    # ================================================================ services (app/app_services.py)
    def guard(self, fn: Callable) -> Callable:
        """A viser callback that queues ``fn(action)`` on the ordered action worker (:meth:`ActionQueue.guard`)."""
        return self.actions.guard(fn)

    def post(self, fn: Callable[[], Any], client: Any = None, wait: bool = False) -> None:
        """Run ``fn()`` on the action worker after the actions queued before it (:meth:`ActionQueue.post`)."""
        self.actions.post(fn, client, wait)

    def notify(self, client: Any, title: str, body: str, color: str = "red") -> None:
        """A notification in tab ``client`` (None: every tab); the text is shown as is."""
        notify_tabs(self.server, client, title, body, color)

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display pixels (visible camera view) of original camera pixels, and which are shown."""
        return self.camera_view.display_from_pixels(pixels)

    def _refresh_scene(self) -> None:  # the view and display mixins' name for it, until they are objects
        self.overlays.refresh()

    # Names the view mixin still uses, until it is an object.
    _bundle = property(lambda self: self.live.bundle)
    _ba_facing = property(lambda self: self.live.facing)
    _cloud_root = property(lambda self: self.cloud)

    def make_click_handler(self, key: str) -> Callable:
        """The on-click callback of image slot ``key`` (:meth:`PairsPanel.make_click_handler`)."""
        return self.pairs_panel.make_click_handler(key)

    def make_select_handler(self, key: str) -> Callable:
        """The Shift+click callback of image slot ``key`` (:meth:`PairsPanel.make_select_handler`)."""
        return self.pairs_panel.make_select_handler(key)

    def camera_click_source(self, pick_id: int) -> str | None:
        """Where the last camera click on pick ``pick_id`` landed: ``"loupe"``, ``"full"`` or None."""
        return self.pairs_panel.camera_click_source(pick_id)

    def forget_last_picks(self) -> None:
        """Forget every tab's last click (the next loupe click adds an end)."""
        self.pairs_panel.forget_last_picks()

    # Names the view mixin still uses, until it is an object.
    _last_click = property(lambda self: self.pairs_panel._last_click)
    _cb_snap = property(lambda self: self.pairs_panel.snap_checkbox)
    _image_handles = property(lambda self: self.page.image_handles)
    _ba_titles = property(lambda self: self.page.ba_titles)
    _camera_title = property(lambda self: self.page.camera_title)

    def _add_upload_button(self, client: Any) -> None:
        self.pairs_panel.add_upload_button(client)

    def _add_extrinsics_upload_button(self, client: Any) -> None:
        self.loupe_support.add_upload_button(client)

    def _ensure_facing(self) -> None:
        self.live.ensure_facing()

    def _cloud_shown(self) -> bool:
        return self.live.cloud_shown()

    def _request_cloud(self) -> None:
        self.live.request_cloud()

    @property
    def solve_bundle(self) -> SolveBundle | None:
        """The last good solve with what was solved (pick ids, pairs), or None (:attr:`LiveSolveCoordinator.bundle`)."""
        return self.live.bundle

    @property
    def result(self):
        """The last good :class:`calib_core.solve.CalibrationResult`, or None."""
        bundle = self.live.bundle
        return None if bundle is None else bundle.result

    def pose(self) -> np.ndarray | None:
        """``T_camera_lidar`` predictions use: the last good solve, else the imported initial extrinsic, else None."""
        return self.loupe_support.pose()

    @property
    def initial_T_camera_lidar(self) -> np.ndarray | None:
        """The imported rough ``T_camera_lidar`` predictions use before a solve (None: none imported)."""
        return self.loupe_support.initial_T_camera_lidar

    def last_click_to_update(self) -> float | None:
        """:meth:`LiveSolveCoordinator.last_click_to_update` (seconds from the last change to its solve shown)."""
        return self.live.last_click_to_update()

    @property
    def last_update_time(self) -> float | None:
        """:attr:`LiveSolveCoordinator.last_update_time` (``perf_counter`` when that solve was shown)."""
        return self.live.last_update_time

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until queued user actions are applied and the live solve and its follow-up work are idle."""
        return self.live.wait_idle(timeout)

    def _on_save_error(self, message: str) -> None:
        # On the compactor's thread; the journal holds every change, the compaction is retried.
        if hasattr(self, "server") and not getattr(self, "_stopped", True):
            self.notify(None, "Session file not updated (retrying; no change lost)", message)

    def export_extrinsics(self) -> tuple[bytes, Path | None]:
        """:meth:`app.export_panel.ExportPanel.export_extrinsics`."""
        return self.export_panel.export_extrinsics()

    def stop(self) -> None:
        """Stop the solver thread and the server; returns once the session file holds every change.

        Raises
        ------
        CalibError
            The session file cannot be written (the server is stopped anyway).
        """
        self._stopped = True
        self.actions.stop()
        self.live.stop()
        self.guide.stop()
        self.verify_panel.stop()
        try:
            self.state.close()
        finally:
            self.server.stop()
