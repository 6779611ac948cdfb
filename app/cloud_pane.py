"""The 3-D pane: the scan's display cloud (grey, or coloured from the camera by a solve), the lidar frame and the
solved camera's frame, far from the annotation plane (:data:`app.ui_common.CLOUD_ORIGIN`), and the pairs' laser
points, each labelled with its pair number (``S<shot>·<id>`` in a session of several shots, coloured by shot)."""

from __future__ import annotations

from typing import Any

import numpy as np
import viser.transforms as vtf

from calib_core.transforms import invert_T

from .ui_common import CLOUD_ORIGIN

GREY = 150  # the cloud's colour before any solve
#: Colours of the pairs' laser points by shot (cycled): shot 0 orange, 1 blue, 2 green, 3 magenta, 4 yellow, ...
SHOT_COLORS = np.array([[255, 127, 14], [31, 119, 255], [44, 200, 44], [230, 40, 200], [240, 220, 30],
                        [23, 210, 230], [255, 60, 60], [170, 120, 255]], np.uint8)


class CloudPane:
    """The scene nodes of the 3-D pane; it remembers which solve its colours come from (:attr:`shows`).

    Parameters
    ----------
    scene : viser.SceneApi
        Where the nodes go.
    points_lidar : ndarray, shape (K, 3)
        The display cloud, lidar frame (metres).
    """

    def __init__(self, scene: Any, points_lidar: np.ndarray) -> None:
        self._n = len(points_lidar)
        self._root = scene.add_frame("/cloud", show_axes=False, position=CLOUD_ORIGIN, visible=False)
        self._points = scene.add_point_cloud(
            "/cloud/points", points_lidar.astype(np.float32), np.full((self._n, 3), GREY, np.uint8), point_size=0.015,
            precision="float32", point_shape="rounded", point_shading="flat",
        )
        scene.add_frame("/cloud/lidar", axes_length=0.25, axes_radius=0.01)
        scene.add_label("/cloud/lidar/label", "lidar", position=(0.0, 0.0, 0.0), anchor="top-right")
        self._camera_frame = scene.add_frame("/cloud/camera", axes_length=0.2, axes_radius=0.008, visible=False)
        scene.add_label("/cloud/camera/label", "camera", position=(0.0, 0.0, 0.0))
        self.shows: Any = None  # the solve whose colours the cloud shows (None: grey)
        self._scene = scene
        self._pairs: Any = None  # the pairs' point cloud node, made with the first pair
        self._pair_labels: dict[str, Any] = {}  # label text -> handle
        self._pairs_key: tuple | None = None

    @property
    def colors(self) -> np.ndarray:
        """The cloud's colours ``(K, 3)`` uint8 as the page shows them."""
        return np.asarray(self._points.colors)

    @property
    def visible(self) -> bool:
        """Whether the pane is shown (some tab is in the 3-D view)."""
        return bool(self._root.visible)

    @visible.setter
    def visible(self, on: bool) -> None:
        self._root.visible = bool(on)

    def show(self, what: str, value: Any) -> None:
        """Show what the live solve publishes (:meth:`app.live_coordinator.LiveSolveCoordinator.subscribe_cloud`):
        ``"camera"`` (:meth:`show_camera`), ``"pairs"`` (:meth:`show_pairs`) or ``"colors"`` (:meth:`show_colors`)."""
        if what == "camera":
            self.show_camera(value)
        elif what == "pairs":
            self.show_pairs(*value)
        elif what == "colors":
            self.show_colors(*value)
        else:
            raise ValueError(f"unknown 3-D pane update {what!r}")

    def show_colors(self, solve: Any, colors: np.ndarray) -> None:
        """Colour the cloud with ``colors`` ``(K, 3)`` uint8, computed from ``solve``."""
        self._points.colors = colors
        self.shows = solve

    def show_camera(self, T_camera_lidar: np.ndarray | None) -> None:
        """The solved camera's frame at ``T_camera_lidar``; None hides it and greys the cloud."""
        if T_camera_lidar is None:
            self._camera_frame.visible = False
            if self.shows is not None:
                self._points.colors = np.full((self._n, 3), GREY, np.uint8)
                self.shows = None
            return
        T_lidar_camera = invert_T(T_camera_lidar)
        self._camera_frame.wxyz = vtf.SO3.from_matrix(T_lidar_camera[:3, :3]).wxyz
        self._camera_frame.position = T_lidar_camera[:3, 3]
        self._camera_frame.visible = True

    def show_pairs(self, points_lidar: np.ndarray, labels: list[str], shots: np.ndarray) -> None:
        """The pairs' laser points ``(N, 3)`` (lidar frame, metres; NaN rows are not drawn), labelled ``labels``
        and coloured by their ``shots`` (:data:`SHOT_COLORS`).  Unchanged input sends nothing."""
        points = np.asarray(points_lidar, np.float64).reshape(-1, 3)
        ok = np.all(np.isfinite(points), axis=1)
        points, labels = points[ok], [t for t, keep in zip(labels, ok) if keep]
        shots = np.asarray(shots, np.int64).reshape(-1)[ok]
        key = (points.tobytes(), tuple(labels), shots.tobytes())
        if key == self._pairs_key:
            return
        self._pairs_key = key
        colors = SHOT_COLORS[shots % len(SHOT_COLORS)] if len(points) else np.zeros((1, 3), np.uint8)
        drawn = points.astype(np.float32) if len(points) else np.zeros((1, 3), np.float32)
        if self._pairs is None:
            self._pairs = self._scene.add_point_cloud("/cloud/pairs", drawn, colors, point_size=0.06,
                                                      precision="float32", point_shape="circle")
        else:
            self._pairs.points, self._pairs.colors = drawn, colors
        self._pairs.visible = bool(len(points))
        for text in [t for t in self._pair_labels if t not in labels]:
            self._pair_labels.pop(text).remove()
        for text, xyz in zip(labels, points):
            pos = tuple(float(x) for x in xyz)
            handle = self._pair_labels.get(text)
            if handle is None:
                self._pair_labels[text] = self._scene.add_label(f"/cloud/pair_labels/{len(self._pair_labels)}_{text}",
                                                                text, position=pos, anchor="bottom-left")
            elif tuple(float(x) for x in handle.position) != pos:
                handle.position = pos

    @property
    def pair_labels(self) -> dict[str, tuple[float, float, float]]:
        """The pair labels drawn: text -> position (lidar frame, metres)."""
        return {t: tuple(float(x) for x in h.position) for t, h in self._pair_labels.items()}
