"""The pose the app predicts and renders with: the last good solve, else the rough pose (imported or aligned), else
the "+x" mounting preset; predictions both ways under it, and the scan projected under it (cached per pose).

A service of the app (``app.pose_source``: state and queries, no widgets).  A new rough pose is published to its
subscribers (:meth:`PoseSource.subscribe`); the composition root redraws what depends on it.  The maths is
:mod:`calib_core.predict`; this only picks the pose and caches per pose.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np

from calib_core.alignment import preset_T
from calib_core.errors import CalibError
from calib_core.overlays import project_lidar_points
from calib_core.predict import ProjectedScan, predict_pixel

#: The pose the render and the BA columns assume before any pose exists.
DEFAULT_PRESET = "+x"


def read_extrinsics(path: Path, shown: str | None = None) -> np.ndarray:
    """``T_camera_lidar`` (4x4) from any extrinsics file ba-calib reads; errors name ``shown`` instead of ``path``."""
    from calib_core.io.extrinsic_formats import load_extrinsics_any

    try:
        return np.asarray(load_extrinsics_any(path), dtype=np.float64)
    except CalibError as exc:
        if shown is None:
            raise
        raise CalibError(str(exc).replace(str(path), shown)) from None


class PoseSource:
    """The pose predictions use, of one :class:`app.server.CalibrationApp` (``app.pose_source``).

    It owns the rough pose (:attr:`initial_T_camera_lidar`), the extrinsic
    given at start (:attr:`imported_T_camera_lidar`) and the scan projected
    under the current pose (cached per pose).  The solve comes from the app's
    ``solve_bundle`` service.

    Parameters
    ----------
    app : CalibrationApp
        The app (its ``solve_bundle``, ``state``, ``camera``, ``depth``, ``all_points_lidar``, ``scene_data``).
    initial_T_camera_lidar : ndarray, shape (4, 4), optional
        A rough pose to predict with until a solve exists.
    """

    def __init__(self, app: Any, initial_T_camera_lidar: np.ndarray | None = None) -> None:
        self.app = app
        self.initial_T_camera_lidar: np.ndarray | None = None
        self._projected: tuple[bytes, ProjectedScan] | None = None
        self._projected_lock = threading.Lock()
        self._listeners: list[Callable[[], None]] = []
        # The extrinsic given at start (file, bag's /tf_static); a rough pose saved in the session wins over it.
        self.imported_T_camera_lidar: np.ndarray | None = None
        if initial_T_camera_lidar is not None:
            self.set_initial_extrinsics(initial_T_camera_lidar)
            self.imported_T_camera_lidar = self.initial_T_camera_lidar
        saved = app.state.view.rough_T_camera_lidar
        if saved:
            self.set_initial_extrinsics(np.array(saved, np.float64).reshape(4, 4))

    def subscribe(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` after each new rough pose (:meth:`adopt_rough_pose`), on the adopting thread."""
        self._listeners.append(listener)

    # ------------------------------------------------------------------ pose and predictions
    def pose(self) -> np.ndarray | None:
        """``T_camera_lidar`` predictions use: the last good solve, else the imported initial extrinsic, else None."""
        bundle = self.app.solve_bundle
        if bundle is not None:
            return bundle.result.T_camera_lidar
        return self.initial_T_camera_lidar

    def view_pose(self) -> tuple[np.ndarray, str]:
        """The pose the camera-view render and the BA columns use, and where it comes from: the last good solve
        (``"solve"``), else the rough pose (``"rough"``), else the "+x" mounting preset (``"default"``)."""
        bundle = self.app.solve_bundle
        if bundle is not None:
            return bundle.result.T_camera_lidar, "solve"
        if self.initial_T_camera_lidar is not None:
            return self.initial_T_camera_lidar, "rough"
        return preset_T(DEFAULT_PRESET), "default"

    def predict_pixel(self, row: int, col: int) -> tuple[float, float] | None:
        """Original camera pixel where :meth:`pose` expects scan cell ``(row, col)``; None without a pose or unseen."""
        T = self.pose()
        if T is None:
            return None
        return predict_pixel(T, self.app.camera, self.app.depth, row, col)

    def predict_cell(self, u: float, v: float) -> tuple[int, int] | None:
        """Scan cell ``(row, col)`` the camera sees at original pixel ``(u, v)`` under :meth:`pose`; None if unknown."""
        T = self.pose()
        if T is None:
            return None
        return self.projection(T).cell_at(float(u), float(v))

    def predicted_pixels(self, picks: dict) -> tuple[list[int], np.ndarray]:
        """Original camera pixels ``(M, 2)`` where :meth:`pose` expects the picks (by id) that have only a laser
        cell, and their ids (those in view only); none without a pose."""
        T = self.pose()  # the last good solve, else the imported initial extrinsic
        pending = [p for p in picks.values() if p.laser_rc is not None and p.pixel is None]
        if T is None or not pending:
            return [], np.empty((0, 2))
        points = self.app.depth.cell_points(np.array([p.laser_rc for p in pending]))
        uv, ok = project_lidar_points(T, self.app.camera, points)
        return [p.id for p, good in zip(pending, ok) if good], uv[ok]

    def projection(self, T: np.ndarray) -> ProjectedScan:
        """Every scan point projected under ``T`` (cached per pose; built off the click path after a solve)."""
        key = np.asarray(T, np.float64).tobytes()
        with self._projected_lock:
            cached = self._projected
            if cached is not None and cached[0] == key:
                return cached[1]
            app = self.app
            proj = ProjectedScan.build(T, app.camera, app.all_points_lidar, app.scene_data.all_rows_cols)
            self._projected = (key, proj)
            return proj

    def _warm_projection(self) -> None:
        T = self.pose()
        if T is not None:
            self.projection(T)

    # ------------------------------------------------------------------ the rough pose
    def set_initial_extrinsics(self, T_camera_lidar: np.ndarray | None) -> None:
        """Use ``T_camera_lidar`` (4x4) for predictions and "facing the camera" until a solve exists (None: forget it)."""
        if T_camera_lidar is not None:
            T = np.asarray(T_camera_lidar, dtype=np.float64)
            if T.shape != (4, 4) or not np.isfinite(T).all():
                raise CalibError("the initial extrinsic must be a finite 4x4 matrix")
            T_camera_lidar = T
        self.initial_T_camera_lidar = T_camera_lidar
        threading.Thread(target=self._warm_projection, name="ba-calib-projection", daemon=True).start()

    def adopt_rough_pose(self, T_camera_lidar: np.ndarray | None) -> None:
        """Make ``T_camera_lidar`` the rough pose (None: none), save it in the session and tell the subscribers."""
        self.set_initial_extrinsics(T_camera_lidar)
        saved = () if self.initial_T_camera_lidar is None else tuple(self.initial_T_camera_lidar.reshape(-1))
        self.app.state.set_view(rough_T_camera_lidar=saved)
        for listener in list(self._listeners):
            listener()
