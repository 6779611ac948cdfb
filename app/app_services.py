"""What a panel may use of the app: the public services of :class:`app.server.CalibrationApp`.

Panels get the app as their ``app`` argument and use only these names, never its private members nor a sibling
panel (``app.loupes``, ``app.render_pane``, ...): they talk through the state, the panels' events, callables the
composition root passes them, and these services (``tests/test_panel_reaches.py`` enforces it).  A structural
type: the app satisfies it, a test may pass anything else that does.
"""

from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np

from .action_queue import UiLock
from .state import AnnotationState

__all__ = ["AppServices", "UiLock"]  # UiLock: the redraw lock, defined with the action worker (app/action_queue.py)


class AppServices(Protocol):
    """The services of the app that panels use."""

    server: Any  # the running viser.ViserServer (its ``gui`` and ``scene``)
    state: AnnotationState  # the pairs and the view settings (``state.view``); every change goes through it
    ui_lock: UiLock  # held while the scene and the panels are redrawn; hold it to change several widgets at once
    folder_lock: Any  # threading.Lock held while one tab's own widgets are added into a shared folder
    depth: Any  # the scan's depth matrix
    camera: Any  # the camera model
    image: np.ndarray  # the camera image (original pixels)
    ba_keys: tuple[str, ...]  # the BA directions shown, in page order
    slots: dict  # where each image lies on the page (app.layout.ImageSlot), by key
    camera_sizes: dict[str, tuple[int, int]]  # ``(width, height)`` of each camera view (raw, panorama), by key
    wrap_cols: bool  # the scan's last column is next to its first (a 360 degree scan)
    ba_cell_aspect: float  # drawn height / width of one BA cell
    ba_window: Any  # app.ba_view.ColumnWindow: the scan columns the BA images show
    all_points_lidar: np.ndarray  # (N, 3) every valid scan point, lidar frame (metres)
    nodes: Any  # app.scene_nodes.SceneNodes: the scene's diffed nodes (a redraw sends only what changed)
    pairs_folder: Any  # the "Pairs" folder (panels place themselves relative to its ``order``)
    output_path: Any  # Path or None: where "Download extrinsics YAML" also writes
    session_path: Any  # the session file
    solve_bundle: Any  # the last good solve (app.ui_common.SolveBundle), or None
    result: Any  # its calib_core.solve.CalibrationResult, or None
    initial_T_camera_lidar: np.ndarray | None  # (4, 4) the imported rough extrinsic predictions use before a solve
    active_shot: int  # the shot these panes show, 0-based (``state.picks`` its picks, ``state.all_picks`` all)
    shot_scenes: list  # every shot's app.prepared_scene.PreparedScene, in shot order; the live solve uses them all
    scene_data: Any  # this shot's PreparedScene (``depth``, ``camera``, ``image`` ... above are its parts)
    ba_gray: dict  # the BA images' grey levels, by key
    image_gray: np.ndarray  # the camera image's grey levels
    cloud_points_lidar: np.ndarray  # (K, 3) the points the 3-D pane shows, lidar frame (metres)
    camera_view: Any  # the visible app.camera_view.CameraView (raw image or panorama)
    camera_views: dict  # the camera views (``raw``, and ``panorama`` for wide lenses), by key
    title: str  # the page title
    # The pose predictions, the render and the BA columns use (solved, else rough, else the "+x" preset), the
    # predictions both ways under it, and the rough pose (``adopt_rough_pose``; ``subscribe`` to its changes).
    pose_source: Any  # app.pose_source.PoseSource
    actions: Any  # app.action_queue.ActionQueue: the ordered worker of every user action (``busy``)
    laser_images: Any  # app.laser_images.LaserImages: the laser images as shown (contrast applied)

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
