"""What a panel may use of the app: the public services of :class:`app.server.CalibrationApp`.

Panels (:mod:`app.guide_panel`, :mod:`app.verify_panel`, :mod:`app.export_panel`,
:mod:`app.loupes`, ...) get the app as their ``app`` argument and use only
these names, never its private members, so the app's insides can change
without touching them.  :class:`AppServices` is a structural type: the app
satisfies it, a test may pass anything else that does.

``tests/test_panel_reaches.py`` enforces it: an ``app/`` module (but the composition roots ``app/server.py`` and
``app/serving.py``) that uses ``app.<name>`` must find ``name`` here, and may not use a sibling panel (``app.loupes``,
``app.render_pane``, ...) at all: panels talk through the state, the panels' events, callables the composition root
passes them, and these services.
"""

from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np

from .action_queue import UiLock
from .state import AnnotationState

__all__ = ["AppServices", "UiLock"]  # UiLock: the redraw lock, defined with the action worker (app/action_queue.py)


class AppServices(Protocol):
    """The services of the app that panels use.

    Attributes
    ----------
    server : viser.ViserServer
        The running server (its ``gui`` and ``scene``).
    state : AnnotationState
        The pairs and the view settings (``state.view``); every change goes through it.
    ui_lock : UiLock
        Held while the scene and the panels are redrawn; hold it to read or change several widgets at once.
    folder_lock : threading.Lock
        Held while one tab's own widgets are added into a shared folder (one GUI context at a time).
    depth, camera, image
        The scan's depth matrix, the camera model and the camera image (original pixels).
    ba_keys : tuple of str
        The BA directions shown, in page order.
    slots : dict
        Where each image lies on the page (:class:`app.layout.ImageSlot`), by key.
    camera_sizes : dict
        ``(width, height)`` of each camera view (``raw``, ``panorama``), by key.
    wrap_cols : bool
        The scan's last column is next to its first (a 360 degree scan).
    ba_cell_aspect : float
        Drawn height / width of one BA cell.
    ba_window : app.ba_view.ColumnWindow
        The scan columns the BA images show.
    all_points_lidar : ndarray, shape (N, 3)
        Every valid scan point, lidar frame (metres).
    nodes : app.scene_nodes.SceneNodes
        The scene's diffed line, point and label nodes (a redraw sends only what changed).
    pairs_folder
        The "Pairs" folder (panels place themselves relative to its ``order``).
    output_path, session_path : Path or None
        Where "Download extrinsics YAML" also writes; the session file.
    solve_bundle, result
        The last good solve (:class:`app.ui_common.SolveBundle`) and its
        :class:`calib_core.solve.CalibrationResult`, or None.
    initial_T_camera_lidar : ndarray, shape (4, 4), or None
        The imported rough extrinsic predictions use before a solve.
    active_shot : int
        The shot these panes show (0-based; ``state.picks`` are its picks, ``state.all_picks`` every shot's).
    shot_scenes : list of app.prepared_scene.PreparedScene
        Every shot's scene, in shot order (one for a one-shot session); the live solve uses them all.
    scene_data : app.prepared_scene.PreparedScene
        This shot's scene (``depth``, ``camera``, ``image`` ... above are its parts).
    ba_gray, image_gray : dict, ndarray
        The BA images' grey levels by key, and the camera image's.
    cloud_points_lidar : ndarray, shape (K, 3)
        The points the 3-D pane shows, lidar frame (metres).
    camera_view : app.camera_view.CameraView
        The visible camera view (raw image or panorama).
    camera_views : dict
        The camera views (:class:`app.camera_view.CameraView`: ``raw``, and ``panorama`` for wide lenses), by key.
    title : str
        The page title.
    laser_images : app.laser_images.LaserImages
        The laser images as the page shows them (contrast applied; ``ba_display``, ``ba_title``, ``loupe_image``).
    pose_source : app.pose_source.PoseSource
        The pose predictions, the render and the BA columns use (solved, else rough, else the "+x" preset), the
        predictions both ways under it, and the rough pose (``adopt_rough_pose``; ``subscribe`` to its changes).
    actions : app.action_queue.ActionQueue
        The ordered worker every user action runs on (``busy``: an action runs or waits).
    """

    server: Any
    state: AnnotationState
    ui_lock: UiLock
    folder_lock: Any
    depth: Any
    camera: Any
    image: np.ndarray
    ba_keys: tuple[str, ...]
    slots: dict
    camera_sizes: dict[str, tuple[int, int]]
    wrap_cols: bool
    ba_cell_aspect: float
    ba_window: Any
    all_points_lidar: np.ndarray
    nodes: Any
    pairs_folder: Any
    output_path: Any
    session_path: Any
    solve_bundle: Any
    result: Any
    initial_T_camera_lidar: np.ndarray | None
    active_shot: int
    shot_scenes: list
    scene_data: Any
    ba_gray: dict
    image_gray: np.ndarray
    cloud_points_lidar: np.ndarray
    camera_view: Any
    camera_views: dict
    title: str
    actions: Any
    pose_source: Any
    laser_images: Any

    def subscribe_solve(self, listener: Callable[[Any], None]) -> None:
        """Call ``listener(shown)`` (:class:`app.ui_common.SolveShown`) on every redraw of what the live solve shows."""

    def subscribe_solved(self, listener: Callable[[Any], None]) -> None:
        """Call ``listener(shown)`` after each finished solve is shown (outside the UI lock)."""

    def solve_shown(self) -> Any:
        """What the live solve shows now (:class:`app.ui_common.SolveShown`: the last good solve, its error, whether a
        newer solve runs, the complete pairs), as its events pass it."""

    def guard(self, fn: Callable[[Any], None]) -> Callable:
        """A viser callback that queues ``fn(action)`` on the ordered action worker (errors become notifications)."""

    def post(self, fn: Callable[[], Any], client: Any = None, wait: bool = False) -> None:
        """Run ``fn()`` on the action worker, after the actions queued before it."""

    def notify(self, client: Any, title: str, body: str, color: str = "red") -> None:
        """A notification in tab ``client`` (None: every tab)."""

    def pose(self) -> np.ndarray | None:
        """``T_camera_lidar`` predictions use: the last good solve, else the imported rough pose, else None."""

    def slot_of(self, key: str) -> Any:
        """The page slot (:class:`app.layout.ImageSlot`) of click key ``key``: a BA key, a camera view, the render
        (:data:`app.layout.RENDER_KEY`), ``loupe_ba`` or ``loupe_camera``."""

    def camera_slot(self) -> Any:
        """The page slot of the visible camera view."""

    def display_from_pixels(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display pixels of original camera pixels in the visible camera view, and which are shown."""

    def make_click_handler(self, key: str) -> Callable:
        """The on-click callback of image slot ``key`` (adds or moves a pair end)."""

    def make_drag_handler(self, key: str) -> Callable:
        """The on-drag callback of image slot ``key`` (drags a pair end; a shaky click is a click)."""

    def make_select_handler(self, key: str) -> Callable:
        """The Shift+click callback of image slot ``key`` (selects the nearest pair)."""

    def camera_click_source(self, pick_id: int) -> str | None:
        """Where the last camera click on pick ``pick_id`` landed: ``"loupe"``, ``"full"`` or None."""

    def forget_last_picks(self) -> None:
        """Forget every tab's last click (the next loupe click adds an end)."""

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until queued user actions are applied and the live solve and its follow-up work are idle."""
