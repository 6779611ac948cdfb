"""The browser annotation app: a viser server around :mod:`calib_core`.

The page shows the four Bearing Angle images beside the camera image (raw, or
unwrapped into a panorama for ``ocam`` / ``fisheye`` cameras).  The user
clicks a BA image and the camera image, in either order, to make a pair; from
4 pairs on the extrinsics are solved live in a worker thread and the page
shows the errors, a per-pair residual table, the reprojected points and BA
edges, and a coloured point cloud in a 3-D view.

Wide lidar scans (e.g. 64 x 1800) are shown with rows stretched to about
square cells in angle and, on request, only a window of columns such as the
part facing the camera (:mod:`app.ba_view`); zoom buttons centre and magnify
the last click.

Every number shown comes from :mod:`calib_core`; this module only routes
clicks, draws, and moves data between the state, the solver and the page.

A click is answered in this order: the changed pick markers at once (only
the scene nodes that changed are sent, mostly as in-place updates), then,
from the solver thread, the errors, the residual table and the 2-D overlays;
the 3-D cloud is recoloured after that in its own thread, and only while a
tab shows the 3-D view.  A change is on disk before any of this
(:mod:`app.session_store`), so what the page shows survives a kill -9.  :meth:`CalibrationApp.last_click_to_update`
reports the time to the second step.

Use :func:`serve` (what ``ba-calib`` runs), or :class:`CalibrationApp` to
start and stop the server from Python (tests).
"""

from __future__ import annotations

import os
import queue
import threading
import time
import traceback
from pathlib import Path
from typing import Any, Callable

import numpy as np
import viser

from calib_core.errors import CalibError

from .ba_view import ColumnWindow
from .live_solver import LiveSolver
from .view_panel import ViewPanel
from .pairs_panel import PairsPanel
from .calibration_panel import CalibrationPanel
from .export_panel import ExportPanel
from .live_coordinator import LiveSolveCoordinator
from .overlay_drawing import OverlayDrawing
from .prepared_scene import MAX_CLOUD_POINTS, PreparedScene
from .scene_nodes import SceneNodes
from .security import TOKEN_QUERY, AccessPolicy, RefusalLog, start_guarded_viser
from .state import AnnotationState
from .warm_up import WarmUp
from .ui_common import CLOUD_ORIGIN, BA_WINDOW_MODES, UP_AXES, md_escape, SolveBundle, _Action


class CalibrationApp(OverlayDrawing, LiveSolveCoordinator, ExportPanel, CalibrationPanel, PairsPanel, ViewPanel):
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
        self.panorama, self.pano_image, self.pano_gray = sd.panorama, sd.pano_image, sd.pano_gray
        self.edge_points_lidar, self.all_points_lidar, self.all_rows_cols = (
            sd.edge_points_lidar, sd.all_points_lidar, sd.all_rows_cols)
        self.ba_cell_aspect, self._wrap_cols, self.cloud_points_lidar = (
            sd.ba_cell_aspect, sd.wrap_cols, sd.cloud_points_lidar)

        # -- state ------------------------------------------------------------------
        # Every change is on disk (an fsync'd journal line) before the UI shows it; the journal is
        # compacted into the session YAML in the background and by stop().
        self.state = AnnotationState(self.depth.valid, (self.camera.width, self.camera.height), self.session_path,
                                     on_save_error=self._on_save_error)
        view = self.state.view_settings()
        self._use_panorama = bool(view.get("panorama", True)) and self.panorama is not None
        self._show_reprojection = bool(view.get("show_reprojection", True))
        self._show_edges = bool(view.get("show_edges", True))
        self._snap = bool(view.get("snap", False))
        self._up_axis = str(view.get("up_axis", "+y" if self.depth.meta.get("model") == "rotating_2d" else "+z"))
        if self._up_axis not in UP_AXES:
            self._up_axis = "+z"

        n_cols = self.depth.shape[1]
        self._ba_mode = str(view.get("ba_window_mode", "all"))
        if self._ba_mode not in BA_WINDOW_MODES:
            self._ba_mode = "all"
        try:
            start, width = int(view.get("ba_window_start", 0)), int(view.get("ba_window_width", n_cols))
        except (TypeError, ValueError):
            start, width = 0, n_cols
        self._ba_custom = ColumnWindow.make(start, width, n_cols, self._wrap_cols)
        self._ba_facing: ColumnWindow | None = None  # from the last good solve it was computed for
        self._facing_of: SolveBundle | None = None  # the solve ``_ba_facing`` was computed for
        self._ba_window = self._wanted_ba_window()
        self._camera_sizes = {"raw": (self.camera.width, self.camera.height)}
        if self.panorama is not None:
            self._camera_sizes["panorama"] = (self.panorama.width, self.panorama.height)
        self.slots = self._layout()

        self._ui_lock = threading.RLock()
        self._upload_lock = threading.Lock()
        self._bundle: SolveBundle | None = None
        self._solve_error: str | None = None
        self._submitted: tuple | None = None
        self._job = 0
        self._result_floor = 0
        self._solving = False
        self._client_mode: dict[int, str] = {}
        self._last_click: dict[int, tuple] = {}  # client id -> ("ba", key, row, col) or ("camera", u, v)
        self._view_target: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        self._marker_cache: dict[str, tuple[tuple, dict]] = {}  # slot key -> (inputs, number labels) last drawn
        self._overlay_inputs: tuple | None = None  # (solve, inputs) the overlays were last drawn from
        self._cloud_shows: SolveBundle | None = None  # the solve whose colours the 3-D cloud shows (None: grey)
        self._change_time: tuple[int, float] = (0, 0.0)  # (job, perf_counter) of the last change of the pairs
        self._last_update: tuple[float, float] | None = None  # (click-to-update seconds, perf_counter published)
        self._stopped = False

        # -- server -------------------------------------------------------------------
        self._actions: queue.Queue = queue.Queue()
        self._action_thread = threading.Thread(target=self._run_actions, name="ba-calib-actions", daemon=True)
        self._action_thread.start()
        # Every request must name this server (Host, Origin) and, off loopback, carry the token.
        self.access = AccessPolicy.for_bind(host, token=token, extra_hosts=tuple(allowed_hosts))
        self._refusals = RefusalLog()
        try:
            self.server = start_guarded_viser(self.access, on_refused=self._refusals, host=host, port=port,
                                              label=self.title, verbose=False)
        except BaseException:
            self._actions.put(None)
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
        try:
            self._build_scene()
            self._build_gui()
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(self._on_disconnect)
            self._solver = LiveSolver(self._solve_job, self._on_solved)
            # Cloud colours and the camera-facing window: after the solve is shown, in their own thread.
            self._cloud_worker = LiveSolver(self._cloud_job, self._on_cloud_done, name="ba-calib-cloud")
            self.state.subscribe(self._on_state_change)
            self._on_state_change(self.state)
        except BaseException:
            self._actions.put(None)
            self.server.stop()
            self.state.close()
            raise

    # ======================================================================= scene
    def _build_scene(self) -> None:
        scene = self.server.scene
        backdrop = scene.add_image(
            "/annot/backdrop", np.full((2, 2, 3), 238, np.uint8), 600.0, 600.0, format="png", position=(0.0, 0.0, 0.5)
        )
        # A no-op drag on the backdrop keeps left-drags from orbiting the flat view.
        backdrop.on_drag(lambda event: None)
        self._image_handles: dict[str, Any] = {}
        raw = scene.add_image(
            "/annot/camera_raw", self.image, self.slots["raw"].render_width, self.slots["raw"].render_height,
            format="jpeg", jpeg_quality=92, position=self.slots["raw"].center, visible=not self._use_panorama,
        )
        self._image_handles["raw"] = raw
        if self.panorama is not None:
            s = self.slots["panorama"]
            self._image_handles["panorama"] = scene.add_image(
                "/annot/camera_pano", self.pano_image, s.render_width, s.render_height,
                format="jpeg", jpeg_quality=92, position=s.center, visible=self._use_panorama,
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
            handle.on_click(self._make_click_handler(key))
            handle.on_click(modifier="shift")(self._make_select_handler(key))
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
    # ========================================================================= GUI
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large", show_share_button=False, dark_mode=False)
        gui.add_markdown(
            f"**{md_escape(self.title)}**  \n"
            "Click a point in any **BA image** and the same point in the **camera image** (either order) "
            "to make a pair. **Shift+click** a marker to select its pair; then clicks move it. "
            "**Drag** a marker to move it. Wheel zooms on the view centre, right-drag pans; "
            "**Zoom: on last click** centres and magnifies the point you last clicked. "
            "**BA columns** shows only part of a wide scan, e.g. the part facing the camera."
        )
        self._pairs_folder = gui.add_folder("Pairs")
        with self._pairs_folder:
            self._md_pairs = gui.add_markdown("")
            self._dd_selected = gui.add_dropdown("Selected pair", ("none",), initial_value="none")
            self._dd_selected.on_update(self._guard(self._on_select_dropdown))
            self._bg_edit = gui.add_button_group("Edit", ("Undo", "Redo", "Deselect", "Delete"))
            self._bg_edit.on_click(self._guard(self._on_edit))
            self._btn_clear = gui.add_button("Clear all pairs (undoable)", color="red", icon=viser.Icon.TRASH)
            self._btn_clear.on_click(self._guard(self._on_clear))
            self._cb_snap = gui.add_checkbox("Snap clicks to corners", initial_value=self._snap,
                                             hint="Refine each click to the strongest corner within 4 pixels")
            self._cb_snap.on_update(self._guard(self._on_view_checkbox))
            # Each tab gets its own upload button (see _on_connect): viser keeps one value per button,
            # which two tabs uploading at once would overwrite.
            self._btn_pairs = gui.add_button("Download pairs YAML", icon=viser.Icon.DOWNLOAD)
            self._btn_pairs.on_click(self._guard(self._on_download_pairs))
        with gui.add_folder("Calibration"):
            self._md_result = gui.add_markdown("")
            self._md_table = gui.add_markdown("")
        with gui.add_folder("View"):
            self._bg_view = gui.add_button_group("Show", ("2D annotation", "3D cloud"))
            self._bg_view.on_click(self._guard(self._on_view_mode))
            self._bg_zoom = gui.add_button_group("Frame", ("All", "Camera", "BA images"))
            self._bg_zoom.on_click(self._guard(self._on_zoom))
            self._bg_magnify = gui.add_button_group("Zoom", ("In", "Out", "On last click"))
            self._bg_magnify.on_click(self._guard(self._on_magnify))
            n_cols = self.depth.shape[1]
            self._dd_ba_window = gui.add_dropdown(
                "BA columns", tuple(BA_WINDOW_MODES.values()), initial_value=BA_WINDOW_MODES[self._ba_mode],
                hint="Show all scan columns, the ones whose points the current calibration projects into the "
                     "camera image, or the range set below",
            )
            self._dd_ba_window.on_update(self._guard(self._on_ba_window_mode))
            self._sl_ba_start = gui.add_slider("BA first column", 0, max(n_cols - 1, 1), 1,
                                               initial_value=self._ba_window.start)
            self._sl_ba_start.on_update(self._guard(self._on_ba_window_slider))
            self._sl_ba_width = gui.add_slider("BA columns shown", min(16, n_cols), n_cols, 1,
                                               initial_value=max(self._ba_window.width, min(16, n_cols)))
            self._sl_ba_width.on_update(self._guard(self._on_ba_window_slider))
            self._cb_pano = gui.add_checkbox(
                "Unwrapped panorama", initial_value=self._use_panorama, disabled=self.panorama is None,
                hint="Show the camera image unwrapped (azimuth x elevation); clicks still give original-image pixels",
            )
            self._cb_pano.on_update(self._guard(self._on_view_checkbox))
            self._cb_reproj = gui.add_checkbox("Reprojected pairs and residuals", initial_value=self._show_reprojection)
            self._cb_reproj.on_update(self._guard(self._on_view_checkbox))
            self._cb_edges = gui.add_checkbox("Reprojected BA-edge points", initial_value=self._show_edges)
            self._cb_edges.on_update(self._guard(self._on_view_checkbox))
            self._dd_up = gui.add_dropdown("3D up axis (lidar)", tuple(UP_AXES), initial_value=self._up_axis)
            self._dd_up.on_update(self._guard(self._on_up_axis))
        with gui.add_folder("Export"):
            self._btn_yaml = gui.add_button("Download extrinsics YAML", icon=viser.Icon.DOWNLOAD, color="green")
            self._btn_yaml.on_click(self._guard(self._on_download_yaml))
            self._btn_ply = gui.add_button("Download coloured PLY", icon=viser.Icon.DOWNLOAD)
            self._btn_ply.on_click(self._guard(self._on_download_ply))
            where = f"Also written to {md_escape(str(self.output_path))}  \n" if self.output_path else ""
            self._md_export = gui.add_markdown(
                f"{where}Session (saved after every change): {md_escape(str(self.session_path))}"
            )
        self._sync_window_widgets()

    # ================================================================== callbacks
    def _guard(self, fn: Callable) -> Callable:
        """Wrap a callback: queue it for the ordered action worker.

        Viser runs plain callbacks on a thread pool, where two quick clicks
        can be handled out of order (a BA, camera, BA sequence would then pair
        the wrong ends).  This async wrapper runs on the event loop, in arrival
        order, and only snapshots the widget value and queues the work.
        """

        async def enqueue(event: Any) -> None:
            target = getattr(event, "target", None)
            value = getattr(target, "value", None) if not isinstance(target, viser.SceneNodeHandle) else None
            self._actions.put((fn, _Action(event, value)))

        return enqueue

    def _run_actions(self) -> None:
        """The action worker: applies queued user actions one by one; errors become notifications."""
        while True:
            item = self._actions.get()
            try:
                if item is None:
                    return
                fn, action = item
                try:
                    fn(action)
                except CalibError as exc:
                    self._notify(action.client, "Not accepted", str(exc))
                except Exception as exc:  # never let a click kill anything
                    traceback.print_exc()
                    self._notify(action.client, "Internal error", f"{type(exc).__name__}: {exc}")
            finally:
                self._actions.task_done()

    def _on_save_error(self, message: str) -> None:
        # On the compactor's thread; the journal holds every change, the compaction is retried.
        if hasattr(self, "server") and not getattr(self, "_stopped", True):
            self._notify(None, "Session file not updated (retrying; no change lost)", message)

    def _notify(self, client: Any, title: str, body: str, color: str = "red") -> None:
        body = " ".join(str(body).split())
        targets = [client] if client is not None else list(self.server.get_clients().values())
        for c in targets:
            try:
                c.add_notification(title, body, color=color, auto_close_seconds=8.0, with_close_button=True)
            except Exception:
                pass

    # ================================================================ live solve
    # ============================================================ 3-D cloud
    # ================================================================== drawing
    # ================================================================== cameras
    # ================================================================ test hooks
    @property
    def ba_window(self) -> ColumnWindow:
        """The scan columns the BA images show."""
        return self._ba_window

    @property
    def result(self):
        """The last good :class:`calib_core.solve.CalibrationResult`, or None."""
        bundle = self._bundle
        return None if bundle is None else bundle.result

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until queued user actions are applied and the live solver and the cloud worker are idle."""
        deadline = time.monotonic() + timeout
        while True:
            while self._actions.unfinished_tasks:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.01)
            for worker in (self._solver, self._cloud_worker):
                if not worker.wait_idle(max(0.0, deadline - time.monotonic())):
                    return False
            # A finished solve queues cloud work, finished cloud work may queue a view update.
            if not self._actions.unfinished_tasks and self._solver.idle and self._cloud_worker.idle:
                return True

    def last_click_to_update(self) -> float | None:
        """Seconds from the last change of the pairs to its solve shown: error display, table, 2-D overlays.

        Measured from the start of the change in the state (before its
        journal write) to the moment the result was handed to viser (sending it to
        the browsers is not counted, nor is the 3-D cloud recolouring that
        follows).  None before the first solve of a change.
        """
        last = self._last_update
        return None if last is None else last[0]

    @property
    def last_update_time(self) -> float | None:
        """``time.perf_counter()`` when the newest change's solve was shown (see :meth:`last_click_to_update`)."""
        last = self._last_update
        return None if last is None else last[1]

    def stop(self) -> None:
        """Stop the solver thread and the server; returns once the session file holds every change.

        Raises
        ------
        CalibError
            The session file cannot be written (the server is stopped anyway).
        """
        self._stopped = True
        self._actions.put(None)
        self._action_thread.join(timeout=5.0)
        self._solver.stop()
        self._cloud_worker.stop()
        try:
            self.state.close()
        finally:
            self.server.stop()
