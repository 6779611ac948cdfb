"""The pose the app predicts and renders with: the last good solve unless its quality is "unreliable", else the rough
pose (imported, aligned, or refitted to the pairs), else the "+x" mounting preset; predictions both ways under it,
the scan projected under it (cached per pose) and the scan columns the camera sees under it (the BA panes' "camera"
window).

A service of the app (``app.pose_source``: state and queries, no widgets).  A new rough pose is published to its
subscribers (:meth:`PoseSource.subscribe`); the composition root redraws what depends on it.  The maths is
:mod:`calib_core.predict`; this only picks the pose and caches per pose.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from calib_core.alignment import preset_T
from calib_core.errors import CalibError
from calib_core.overlays import columns_seen_by_camera, project_lidar_points
from calib_core.predict import ProjectedScan, predict_pixel
from calib_core.transforms import rotation_angle_deg

from .ba_view import ColumnWindow, covering_window

#: The pose the render and the BA columns assume before any pose exists.
DEFAULT_PRESET = "+x"
#: After a rough pose the person did not make (the fit to 2-3 pairs), a click on the render is not placed for this
#: long (seconds) once the new render is shown: it was planned on the old one (run 6: the render rolled 2.2-3 deg
#: after the 2nd pair, and a click then missed).
REFIT_CLICK_GRACE_S = 0.5


@dataclasses.dataclass(frozen=True)
class PoseTurn:
    """One change of the rough pose: ``why`` it changed (e.g. "refitted from 2 pairs"; "" for a step by hand), how
    far it turned (degrees, the angle of the relative rotation), the new ``T_camera_lidar`` (4x4) and when
    (``time.monotonic()`` seconds)."""

    why: str
    degrees: float
    T_camera_lidar: np.ndarray
    at: float

    def note(self) -> str:
        """The notice for the person, e.g. "Pose refitted from 2 pairs: turned 2.6 deg" ("" for a step by hand)."""
        return f"Pose {self.why}: turned {self.degrees:.1f} deg" if self.why else ""


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
        self.last_turn: PoseTurn | None = None  # the last change of the rough pose (adopt_rough_pose)
        self._facing: ColumnWindow | None = None  # from the last good solve it was computed for (else the view pose)
        self._facing_of: Any = None  # the solve ``_facing`` was computed for
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
    def trusted_bundle(self) -> Any:
        """The last good solve if its quality is not "unreliable", else None.  An unreliable solve (e.g. 4 pairs
        close together: translation sigma 229 cm, 0.6 m off in run 7) is not rendered nor predicted from: the
        render would jump away from the photo (run 7)."""
        bundle = self.app.solve_bundle
        quality = getattr(getattr(bundle, "result", None), "quality", None)
        if bundle is None or getattr(quality, "status", None) == "unreliable":
            return None
        return bundle

    @property
    def solve_unreliable(self) -> bool:
        """True while a solve is shown whose quality is "unreliable" (the rough pose is used instead)."""
        return self.app.solve_bundle is not None and self.trusted_bundle() is None

    def pose(self) -> np.ndarray | None:
        """``T_camera_lidar`` predictions use: the last good solve unless unreliable, else the rough pose, else
        None."""
        bundle = self.trusted_bundle()
        return self.initial_T_camera_lidar if bundle is None else bundle.result.T_camera_lidar

    def view_pose(self) -> tuple[np.ndarray, str]:
        """The pose the camera-view render and the BA columns use, and where it comes from: the last good solve
        (``"solve"``), else the rough pose (``"rough"``; ``"unreliable"`` while the solve shown is unreliable), else
        the "+x" mounting preset (``"default"``)."""
        bundle = self.trusted_bundle()
        if bundle is not None:
            return bundle.result.T_camera_lidar, "solve"
        rough = self.initial_T_camera_lidar
        if self.solve_unreliable:
            return (preset_T(DEFAULT_PRESET) if rough is None else rough), "unreliable"
        return (preset_T(DEFAULT_PRESET), "default") if rough is None else (rough, "rough")

    def predict_pixel(self, row: int, col: int) -> tuple[float, float] | None:
        """Original camera pixel where :meth:`pose` expects scan cell ``(row, col)``; None without a pose or unseen."""
        T = self.pose()
        return None if T is None else predict_pixel(T, self.app.camera, self.app.depth, row, col)

    def predict_cell(self, u: float, v: float) -> tuple[int, int] | None:
        """Scan cell ``(row, col)`` the camera sees at original pixel ``(u, v)`` under :meth:`pose`; None if unknown."""
        T = self.pose()
        return None if T is None else self.projection(T).cell_at(float(u), float(v))

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

    # ------------------------------------------------------------------ the columns the camera sees
    @property
    def facing(self) -> ColumnWindow | None:
        """The scan columns whose points the current pose projects into the camera image (None: not known); computed
        by :meth:`ensure_facing` or, after a solve, by the live solve's follow-up work (:meth:`set_facing`)."""
        return self._facing

    def facing_due(self, bundle: Any) -> bool:
        """Is the facing window of solve ``bundle`` still to be computed?"""
        return self._facing_of is not bundle

    def facing_window(self, T_camera_lidar: np.ndarray) -> ColumnWindow | None:
        """The scan columns whose points project into the camera image under ``T_camera_lidar``, or None."""
        seen = columns_seen_by_camera(self.app.depth, self.app.camera, T_camera_lidar)
        n_cols = len(seen)
        # A margin and coarse ends, so that the next solve usually keeps the same window.
        step = max(1, round(n_cols / 225))
        return covering_window(seen, self.app.wrap_cols, margin=step, quantum=step)

    def set_facing(self, bundle: Any, facing: ColumnWindow | None) -> None:
        """The facing window ``facing`` computed for solve ``bundle`` (ignored once a newer solve is shown)."""
        with self.app.ui_lock:
            if bundle is not self.app.solve_bundle:
                return  # a newer solve is shown; its own window comes with it
            self._facing_of = bundle
            if facing is not None:  # the camera sees no column: keep the last window
                self._facing = facing

    def ensure_facing(self) -> None:
        """Compute the camera-facing window of the current pose now, if not done yet (switch to camera mode)."""
        bundle = self.app.solve_bundle
        if bundle is not None and self._facing_of is not bundle:
            self.set_facing(bundle, self.facing_window(self.view_pose()[0]))
        elif bundle is None:
            # Before any solve: the rough pose, else the "+x" preset.
            facing = self.facing_window(self.view_pose()[0])
            if facing is not None:
                self._facing = facing

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

    def adopt_rough_pose(self, T_camera_lidar: np.ndarray | None, why: str = "") -> None:
        """Make ``T_camera_lidar`` the rough pose (None: none), save it in the session and tell the subscribers.

        ``why``: the reason when the person did not make the change (e.g. "refitted from 2 pairs"), shown near
        the render as :meth:`PoseTurn.note` (:attr:`last_turn`); "" for a step by hand."""
        old = self.view_pose()[0]
        self.set_initial_extrinsics(T_camera_lidar)
        new = self.view_pose()[0]
        self.last_turn = PoseTurn(str(why), rotation_angle_deg(old[:3, :3], new[:3, :3]), np.array(new),
                                  time.monotonic())
        saved = () if self.initial_T_camera_lidar is None else tuple(self.initial_T_camera_lidar.reshape(-1))
        self.app.state.set_view(rough_T_camera_lidar=saved)
        for listener in list(self._listeners):
            listener()

    def stale_click_reason(self, shown: Any, now: float | None = None) -> str | None:
        """Why a click on render ``shown`` (:class:`app.shown_render.ShownRender`) must not be placed, or None.

        After a rough pose the person did not make (:attr:`last_turn` with a reason), with no solve to trust: while
        the render shown is still the old pose's (the new one is on its way, and will move under the click), and
        for :data:`REFIT_CLICK_GRACE_S` after the new one was made (the click was planned on the old render)."""
        turn = self.last_turn
        if turn is None or not turn.why or shown is None or self.trusted_bundle() is not None:
            return None
        now = time.monotonic() if now is None else now
        old = not np.array_equal(np.asarray(shown.T_camera_lidar), turn.T_camera_lidar)
        if old or now - float(getattr(shown, "made_at", turn.at)) < REFIT_CLICK_GRACE_S:
            return f"not placed: {turn.note()} just now and the render moved; click again on the new render"
        return None
