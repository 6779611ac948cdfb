"""The Align folder: a rough pose before any pair, in under a minute (how it is used: docs/app.md, "The scan seen
from the camera, and a rough pose by drag").

The result is an ordinary initial extrinsic (``app.pose_source``).  The render follows every drag at once; the rest
of the page takes the new pose when the drag ends.  After the 2nd and 3rd pair, and after each unreliable solve
(:meth:`AlignPanel.fit_to_pairs`), the rough pose is turned about the camera centre to fit the pairs: one align
step.  The maths is :mod:`calib_core.alignment`; this panel only maps widgets and drags to it.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
import viser

from calib_core.alignment import (
    MIN_ROTATION_PAIRS, MOUNTING_PRESETS, drag_to_rotation, fit_rotation_about_centre, focal_px_estimate, preset_T,
    rotate_about_camera, translate_in_camera,
)
from calib_core.errors import CalibError
from calib_core.pairs import resolve_pairs
from calib_core.transforms import invert_T, rotation_angle_deg

from .layout import RENDER_KEY
from .pose_source import read_extrinsics
from .security import upload_display_name
from .ui_common import MIN_PAIRS

#: One press of a turn button turns the view this much (degrees); a move button moves the camera this far (metres).
TURN_STEP_DEG = 0.5
MOVE_STEP_M = 0.05
#: Rough poses the "Undo align step" button can go back through.
MAX_HISTORY = 100
#: Labels of the buttons (what the render does on the page): turn left / right / up / down, roll.
TURN_LABELS = ("◀", "▶", "▲", "▼", "⟲", "⟳")
MOVE_LABELS = ("x-", "x+", "y-", "y+", "z-", "z+")
HELP = (
    "Before any pair: pick the nearest preset, tick **Align by drag** and drag the **camera-view laser** render "
    "(or the photo) so that its corners land on the photo's; **Shift**+drag rolls. The buttons nudge the render "
    "by 0.5° and move the camera 5 cm along its x (right), y (down), z (forward)."
)


class AlignPanel:
    """The "Align" folder of one :class:`app.server.CalibrationApp` (``app.align``) and the alignment drags.

    It owns its widgets, the undo history of the rough pose and the drag in progress.  The composition root
    passes what it uses of the render pane and the page: ``add_render_controls(gui)`` (the render's widgets, in
    this folder), ``drag_nodes()`` (the scene nodes a drag turns the view on, by slot key) and
    ``render_drag_callbacks`` (the render's own drag callbacks on its nodes, by slot key).
    """

    def __init__(self, app: Any, order: float | None = None, *, add_render_controls: Callable[[Any], None],
                 drag_nodes: Callable[[], dict[str, Any]], render_drag_callbacks: dict[str, Callable]) -> None:
        self.app = app
        self.drag_nodes = drag_nodes  # () -> the scene nodes a drag turns the view on, by slot key
        self._history: list[np.ndarray | None] = []
        self._drag: dict | None = None  # the drag in progress: its start pose and pixel, and its slot
        self._fitted_to: tuple | None = None  # the pair ids the rough pose was last turned to fit (shown)
        self._pairs_seen: tuple | None = None  # every shot's complete pairs at the last change (on_pairs_change)
        self._drag_listeners: list[Callable[[np.ndarray | None, bool], None]] = []
        self._drag_mode_listeners: list[Callable[[bool], None]] = []
        gui, guard = app.server.gui, app.guard
        self.folder = gui.add_folder("Align (rough pose)", order=order)
        with self.folder:
            gui.add_markdown(HELP)
            self._md_pose = gui.add_markdown("")
            self._bg_preset = gui.add_button_group("Camera looks along lidar", tuple(MOUNTING_PRESETS))
            self._bg_preset.on_click(guard(self.on_preset))
            self._bt_imported = gui.add_button("Back to the imported extrinsic",
                                               disabled=app.pose_source.imported_T_camera_lidar is None,
                                               hint="The extrinsic given at start (file or the bag's /tf_static)")
            self._bt_imported.on_click(guard(self.on_imported))
            self._cb_drag = gui.add_checkbox("Align by drag", initial_value=False,
                                             hint="A left-drag on the camera image or the render turns the view "
                                                  "about the camera centre; Shift+drag rolls it")
            self._cb_drag.on_update(guard(self.on_drag_checkbox))
            self._bg_turn = gui.add_button_group(f"Turn render {TURN_STEP_DEG:g}°", TURN_LABELS)
            self._bg_turn.on_click(guard(self.on_turn))
            self._bg_move = gui.add_button_group(f"Move camera {MOVE_STEP_M * 100:g} cm", MOVE_LABELS)
            self._bg_move.on_click(guard(self.on_move))
            self._bt_undo = gui.add_button("Undo align step", disabled=True)
            self._bt_undo.on_click(guard(self.on_undo))
            add_render_controls(gui)  # the render's shading, blend and blink (the render pane's widgets)
        # Every drag callback on the nodes a drag may turn the view on, by (slot key, modifier), as registered.
        self._callbacks: dict[tuple[str, str | None], list] = {}
        for key, node in self.drag_nodes().items():
            shift = guard(self._on_shift_drag)
            node.on_drag(modifier="shift")(shift)
            self._callbacks[(key, "shift")] = [shift]
            if key == RENDER_KEY:  # the render's own drag handler hands plain drags over (a click stays a click)
                self._callbacks[(key, None)] = [render_drag_callbacks[RENDER_KEY]]
                continue
            plain = guard(lambda event, key=key: self.on_drag(key, event) if self.drag_enabled else None)
            node.on_drag(plain)
            # The pairs panel's marker drag (registered with the node) stands aside while aligning.
            marker = (render_drag_callbacks[key] if key == "camera_overlay" else app.make_drag_handler(key))
            self._callbacks[(key, None)] = [marker, plain]
        app.subscribe_solved(self.on_solved)  # an unreliable solve: the rough pose is refitted to its pairs
        self.show()

    # ------------------------------------------------------------------ events
    def subscribe_drag(self, listener: Callable[[np.ndarray | None, bool], None]) -> None:
        """Call ``listener(T_camera_lidar, render)`` on the action worker during an alignment drag: the pose being
        dragged (None once dropped) and whether to render it now (a dropped pose that changed is adopted instead,
        which renders it)."""
        self._drag_listeners.append(listener)

    def subscribe_drag_mode(self, listener: Callable[[bool], None]) -> None:
        """Call ``listener(on)`` when a tab ticks or unticks "Align by drag"."""
        self._drag_mode_listeners.append(listener)

    def _publish_drag(self, T_camera_lidar: np.ndarray | None, render: bool) -> None:
        for listener in list(self._drag_listeners):
            listener(T_camera_lidar, render)

    # ------------------------------------------------------------------ what the panel shows
    @property
    def drag_enabled(self) -> bool:
        """True while "Align by drag" is ticked: left-drags on the camera image and the render turn the view."""
        return bool(self._cb_drag.value)

    @property
    def text(self) -> str:
        """The pose line as shown (markdown)."""
        return str(self._md_pose.content)

    def show(self) -> None:
        """Show the rough pose and what the render uses."""
        app = self.app
        T, source = app.pose_source.view_pose()
        if source == "solve":
            line = (f"A calibration from {MIN_PAIRS}+ pairs is shown; the rough pose is used only with fewer pairs "
                    "or while the solve is unreliable.")
        elif source == "unreliable":
            line = ("**The solve is unreliable**: the render and the predictions use the rough pose (turned to fit "
                    "the pairs) until the solve's quality is warning or ok.")
        elif source == "default":
            line = "No pose yet: the render and the BA panes assume the camera looks along lidar +x."
        else:
            # In words a person can check: the nearest mounting preset, how far the pose is turned from it,
            # and where the camera centre sits in the lidar frame.
            turned = {name: rotation_angle_deg(T[:3, :3], preset_T(name)[:3, :3]) for name in MOUNTING_PRESETS}
            nearest = min(turned, key=turned.get)
            centre = invert_T(T)[:3, 3]
            line = (f"Rough pose: {turned[nearest]:.1f}° from '{nearest}'; camera centre at "
                    f"({centre[0]:.2f}, {centre[1]:.2f}, {centre[2]:.2f}) m in the lidar frame.")
            if self._fitted_to:
                line += (f" Turned to fit pairs {', '.join(str(i) for i in self._fitted_to)} (the camera centre kept): "
                         "drag or **Undo align step** to change it.")
        self._md_pose.content = line
        self._bt_undo.disabled = not self._history
        # Once solved the rough pose is not used: tabs opened from then on find the folder folded.
        if self.folder.expand_by_default != (source != "solve"):
            self.folder.expand_by_default = source != "solve"

    # ------------------------------------------------------------------ changes of the rough pose
    def on_pairs_change(self, state: Any) -> None:
        """When the complete pairs (of every shot) changed and are 2 or 3, queue :meth:`fit_to_pairs` on the action
        worker (subscribed to the state, after the live solve)."""
        picks = [p for p in state.all_picks if p.complete]
        seen = tuple((p.id, p.shot, p.to_pair()) for p in picks)
        if seen == self._pairs_seen:
            return
        self._pairs_seen = seen
        if MIN_ROTATION_PAIRS <= len(picks) < MIN_PAIRS:  # 2-3 pairs fix the rotation: line the render up (issue 20)
            self.app.post(lambda pairs=[p.to_pair() for p in picks]: self.fit_to_pairs(pairs))

    def on_solved(self, shown: Any) -> None:
        """After each finished solve (:meth:`app.server.CalibrationApp.subscribe_solved`): when it is unreliable,
        queue :meth:`fit_to_pairs` with every complete pair on the action worker (the rough pose is used then)."""
        if self.app.pose_source.solve_unreliable:
            pairs = [p.to_pair() for p in self.app.state.all_picks if p.complete]
            self.app.post(lambda: self.fit_to_pairs(pairs))

    def _check_unsolved(self) -> None:
        if self.app.pose_source.trusted_bundle() is not None:
            raise CalibError(f"{MIN_PAIRS}+ pairs are solved: the page shows that calibration, not the rough pose "
                             f"(the rough pose is for starting; delete pairs to go back to it)")

    def _start_pose(self) -> np.ndarray:
        """The pose a step starts from: the rough pose, else the assumed '+x' view."""
        return np.array(self.app.pose_source.view_pose()[0], np.float64)

    def adopt(self, T_camera_lidar: np.ndarray | None, fitted_to: tuple | None = None) -> None:
        """Make ``T_camera_lidar`` the rough pose (None: none), remembering the old one for "Undo align step";
        ``fitted_to``: the ids of the pairs it was turned to fit (None: a step by hand)."""
        self._fitted_to = fitted_to
        old = self.app.initial_T_camera_lidar
        self._history.append(None if old is None else np.array(old))
        del self._history[:-MAX_HISTORY]
        self.app.pose_source.adopt_rough_pose(T_camera_lidar, why=f"refitted from {len(fitted_to)} pairs"
                                              if fitted_to else "")  # shown near the render (run 6)
        self.show()

    def fit_to_pairs(self, pairs: list) -> bool:
        """Before the first solve, or while the solve is unreliable, turn the rough pose so that the complete
        ``pairs`` line up (the camera centre kept; :func:`calib_core.alignment.fit_rotation_about_centre`), as one
        align step.

        Called on the action worker after the complete pairs changed (:meth:`on_pairs_change`: 2 or 3 pairs) or
        an unreliable solve was shown (:meth:`on_solved`: 4+).  Does nothing (returns False) with fewer than 2
        pairs, with 4+ pairs unless the solve shown is unreliable, when the pairs changed again
        meanwhile, when a pair is guided (guided picking proposes from the rough pose it was started on: turning
        it would reshuffle the proposals under the person), or when their directions are parallel (no rotation
        fixed).  Clicks weigh ``1 / precision_px^2``.
        """
        app = self.app
        current = [p.to_pair() for p in app.state.picks if p.complete]
        if (app.pose_source.trusted_bundle() is not None or current != list(pairs)
                or len(pairs) < MIN_ROTATION_PAIRS
                or (len(pairs) >= MIN_PAIRS and not app.pose_source.solve_unreliable)  # 4+: only while unreliable
                or any(getattr(p, "source", None) == "guided" for p in pairs)):
            return False
        points, bearings, _ = resolve_pairs(pairs, app.depth, app.camera)
        sigma = np.array([p.precision_px or 1.0 for p in pairs], np.float64)
        T0 = self._start_pose()
        try:
            T = fit_rotation_about_centre(T0, points, bearings, 1.0 / sigma**2)
        except CalibError:
            return False  # e.g. both corners in one direction from the camera: keep the pose
        if np.allclose(T, T0, atol=1e-12):
            return False
        self.adopt(T, fitted_to=tuple(int(p.id) for p in pairs))
        return True

    def apply_preset(self, name: str) -> None:
        """Start from mounting preset ``name`` (a key of :data:`calib_core.alignment.MOUNTING_PRESETS`)."""
        self._check_unsolved()
        self.adopt(preset_T(name))

    def turn(self, label: str) -> None:
        """One press of a turn button (:data:`TURN_LABELS`): the render moves or rolls by :data:`TURN_STEP_DEG`."""
        self._check_unsolved()
        f = focal_px_estimate(self.app.camera)
        step_px = f * math.tan(math.radians(TURN_STEP_DEG))
        T0 = self._start_pose()
        if label in ("⟲", "⟳"):
            T = rotate_about_camera(T0, 0.0, 0.0, math.radians(TURN_STEP_DEG) * (1.0 if label == "⟳" else -1.0))
        else:
            du, dv = {"◀": (-step_px, 0.0), "▶": (step_px, 0.0), "▲": (0.0, -step_px), "▼": (0.0, step_px)}[label]
            T = rotate_about_camera(T0, *drag_to_rotation(du, dv, f), 0.0)
        self.adopt(T)

    def move(self, label: str) -> None:
        """One press of a move button (:data:`MOVE_LABELS`): the camera moves :data:`MOVE_STEP_M` along its axis."""
        self._check_unsolved()
        axis, sign = "xyz".index(label[0]), (1.0 if label[1] == "+" else -1.0)
        d = [0.0, 0.0, 0.0]
        d[axis] = sign * MOVE_STEP_M
        self.adopt(translate_in_camera(self._start_pose(), *d))

    def undo(self) -> None:
        """Go back to the rough pose before the last align step."""
        if not self._history:
            raise CalibError("no align step to undo")
        self._check_unsolved()
        self._fitted_to = None
        self.app.pose_source.adopt_rough_pose(self._history.pop())
        self.show()

    # ------------------------------------------------------------------ widget handlers
    def add_upload_button(self, client: Any) -> None:
        """This tab's "Import initial extrinsics" button, in the Align folder (each tab gets its own)."""
        app = self.app
        with app.folder_lock:
            with self.folder:
                button = client.gui.add_upload_button(
                    "Import initial extrinsics", icon=viser.Icon.UPLOAD, mime_type="*/*",
                    hint="A rough pose (any extrinsics format ba-calib reads): predictions and 'Facing the camera' "
                         "work before 4 pairs")
        button.on_upload(app.guard(lambda event: self.receive_initial_extrinsics(
            event.client, getattr(event.value, "name", ""), getattr(event.value, "content", b""))))

    def receive_initial_extrinsics(self, client: Any, name: str, content: bytes) -> None:
        """Import an uploaded extrinsics file as the rough pose (the upload button's handler)."""
        shown = upload_display_name(name)
        if not content:
            raise CalibError(f"{shown}: the file is empty")
        suffix = Path(str(name)).suffix.lower()
        suffix = suffix if suffix in (".yaml", ".yml", ".json", ".txt", ".urdf", ".xml", ".launch", ".py") else ".txt"
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"upload{suffix}"
            path.write_bytes(content)
            T = read_extrinsics(path, shown)
        self.adopt(T)
        self.app.notify(client, "Initial extrinsics imported",
                        f"{shown}: predictions use it until {4} pairs are solved", color="green")

    def on_preset(self, event: Any) -> None:
        self.apply_preset(str(event.value))

    def on_imported(self, event: Any) -> None:
        T = self.app.pose_source.imported_T_camera_lidar
        if T is None:
            raise CalibError("no extrinsic was imported at start")
        self._check_unsolved()
        self.adopt(T)

    def on_turn(self, event: Any) -> None:
        self.turn(str(event.value))

    def on_move(self, event: Any) -> None:
        self.move(str(event.value))

    def on_undo(self, event: Any) -> None:
        self.undo()

    def on_drag_checkbox(self, event: Any) -> None:
        """"Align by drag" (e.g. the render shows over the photo while it is on)."""
        if event.client is None:
            return
        for listener in list(self._drag_mode_listeners):
            listener(bool(event.value))

    # ------------------------------------------------------------------ drags
    def drag_callbacks(self, key: str, modifier: str | None) -> list:
        """The drag callbacks node ``key`` (a camera view, ``"render"``, ``"camera_overlay"``) has for ``modifier``."""
        return list(self._callbacks[(key, modifier)])

    def take_drag(self, key: str, event: Any) -> bool:
        """While "Align by drag" is on, turn the view with this drag phase on slot ``key`` (:meth:`on_drag`) and
        return True; else False (e.g. the render pane's own drag handler then treats a shaky click as a click)."""
        if not self.drag_enabled:
            return False
        self.on_drag(key, event)
        return True

    def _on_shift_drag(self, event: Any) -> None:
        if not self.drag_enabled:
            return
        key = next((k for k, node in self.drag_nodes().items() if node is event.target), self.app.camera_view.key)
        self.on_drag(key, event)

    def on_drag(self, key: str, event: Any) -> None:
        """One phase of a left-drag (``event.phase``: start, update, end) on slot ``key`` while "Align by drag" is
        on (called on the action worker, in order).  Plain drags turn the view, Shift+drags roll it."""
        if event.phase == "start":
            self._drag = None
            self._check_unsolved()  # refused once, at the start; the rest of that drag is ignored
            start = self._pixel(key, event.start_position)
            if start is None:
                raise CalibError("start the drag inside the picture")
            self._drag = {"T0": self._start_pose(), "start": start, "key": key, "last": self._start_pose()}
        drag = self._drag
        if drag is None:
            return
        pixel = self._pixel(drag["key"], event.end_position)
        T = drag["last"] if pixel is None else self._dragged(drag, pixel, event.modifier)  # off the picture: hold
        drag["last"] = T
        if event.phase != "end":
            self._publish_drag(T, True)  # only the render follows each move; the rest waits for the drop
            return
        self._drag = None
        unchanged = bool(np.allclose(T, drag["T0"]))
        self._publish_drag(None, unchanged)
        if not unchanged:
            self.adopt(T)

    def _pixel(self, key: str, world: Any) -> np.ndarray | None:
        """Original camera pixel of a world point on the render or the camera view (None: the camera does not
        see there, e.g. the edge of a panorama)."""
        slot = self.app.slots[RENDER_KEY] if key == RENDER_KEY else self.app.camera_slot()
        display = slot.pixel_from_world(np.asarray(world, np.float64)[None])
        raw, ok = self.app.camera_view.pixels_from_display(display)
        return raw[0] if ok[0] else None

    def _dragged(self, drag: dict, pixel: np.ndarray, modifier: Any) -> np.ndarray:
        """The pose after dragging from the drag's start pixel to ``pixel``: turned so that the laser content
        follows the mouse, or with Shift rolled by the angle swept about the principal point."""
        T0, start = drag["T0"], drag["start"]
        camera = self.app.camera
        if modifier == "shift":  # the image turns about the principal point (where the optical axis projects)
            axis_px, ok = camera.project(np.array([[0.0, 0.0, 1.0]]))
            centre = np.asarray(axis_px, np.float64).reshape(2)
            if not (bool(np.asarray(ok).reshape(-1)[0]) and np.isfinite(centre).all()):
                centre = np.array([(camera.width - 1) / 2.0, (camera.height - 1) / 2.0])
            a0 = math.atan2(*(start - centre)[::-1])
            a1 = math.atan2(*(pixel - centre)[::-1])
            swept = (a1 - a0 + math.pi) % (2.0 * math.pi) - math.pi
            return rotate_about_camera(T0, 0.0, 0.0, swept)
        du, dv = pixel - start
        return rotate_about_camera(T0, *drag_to_rotation(float(du), float(dv), focal_px_estimate(camera)), 0.0)
