"""The test driver's part for the camera-view render and the Align folder (mixed into :class:`app_driver.AppDriver`).

As the rest of the driver: every action goes through the handler the viser event would reach, queued on the app's
action worker, and returns once it is applied (:meth:`RenderDriver.wait_render` also waits for the render).
"""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any

import numpy as np

from app.render_pane import RENDER_KEY


class RenderDriver:
    """The camera-view render pane and the Align folder, driven as a tab would (``self.app``, ``self.tab``,
    ``self._fire`` and ``self.click`` come from :class:`app_driver.AppDriver`)."""

    app: Any
    tab: Any

    # ------------------------------------------------------------------ reading
    def wait_render(self, timeout: float = 120.0) -> bool:
        """Wait until queued actions are applied and the render of the newest pose is shown."""
        deadline = time.monotonic() + timeout
        while True:
            self.app.actions.join()
            if not self.app.render_pane.wait_idle(max(0.0, deadline - time.monotonic())):
                return False
            if not self.app.actions.busy and self.app.render_pane.wait_idle(0.0):
                shown = self.app.render_pane.current
                want = self.app.render_pane.view_pose()[0]
                if shown is not None and np.array_equal(shown.T_camera_lidar, want):
                    return True
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)

    @property
    def render_shown(self) -> Any:
        """The render the page shows (:class:`app.shown_render.ShownRender`) or None."""
        return self.app.render_pane.current

    def render_texture(self) -> np.ndarray:
        """The texture the render pane shows now."""
        return np.asarray(self.app.render_pane._handle.image)

    @property
    def rough_pose(self) -> np.ndarray | None:
        """The rough ``T_camera_lidar`` predictions use before a solve (None: none)."""
        return self.app.pose_source.initial_T_camera_lidar

    @property
    def align_text(self) -> str:
        """The Align folder's pose line."""
        return self.app.align.text

    # ------------------------------------------------------------------ clicks and widgets
    def click_render(self, u: float, v: float) -> list[tuple[str, str]]:
        """Click the camera-view render where it shows original camera pixel ``(u, v)``."""
        disp, ok = self.app.display_from_pixels(np.array([[u, v]], dtype=np.float64))
        if not ok[0]:
            raise ValueError(f"pixel ({u}, {v}) is not shown")
        return self.click(RENDER_KEY, (float(disp[0, 0]), float(disp[0, 1])))

    def _press(self, handler: Any, value: Any) -> list[tuple[str, str]]:
        return self._fire(self.app.guard(handler), SimpleNamespace(client=self.tab, target=SimpleNamespace(value=value)))

    def press_preset(self, name: str) -> list[tuple[str, str]]:
        """Press a "Camera looks along lidar" button: ``"+x"``, ``"-y"``, ``"+y"`` or ``"-x"``."""
        return self._press(self.app.align.on_preset, name)

    def press_turn(self, label: str) -> list[tuple[str, str]]:
        """Press a "Turn render" button (:data:`app.align_panel.TURN_LABELS`)."""
        return self._press(self.app.align.on_turn, label)

    def press_move(self, label: str) -> list[tuple[str, str]]:
        """Press a "Move camera" button (:data:`app.align_panel.MOVE_LABELS`)."""
        return self._press(self.app.align.on_move, label)

    def press_align_undo(self) -> list[tuple[str, str]]:
        """Press "Undo align step"."""
        return self._press(self.app.align.on_undo, None)

    def press_back_to_imported(self) -> list[tuple[str, str]]:
        """Press "Back to the imported extrinsic"."""
        return self._press(self.app.align.on_imported, None)

    def set_align_by_drag(self, on: bool) -> list[tuple[str, str]]:
        """Tick or clear "Align by drag"."""
        self.app.align._cb_drag.value = bool(on)
        return self._press(self.app.align.on_drag_checkbox, bool(on))

    def choose_render_shading(self, label: str) -> list[tuple[str, str]]:
        """Choose in "Render shading": ``"Range"``, ``"Intensity"`` or ``"Bearing angle"``."""
        return self._press(self.app.render_pane.on_mode, label)

    def set_render_blend(self, value: float) -> list[tuple[str, str]]:
        """Move the "Render over photo" slider."""
        self.app.render_pane._sl_blend.value = float(value)
        return self._fire(self.app.guard(self.app.render_pane.on_blend), SimpleNamespace(
            client=self.tab, target=self.app.render_pane._sl_blend))

    def set_panorama(self, on: bool) -> list[tuple[str, str]]:
        """Tick or clear View -> "Unwrapped panorama" (the camera view and the render follow)."""
        view = self.app.view
        view._cb_pano.value = bool(on)
        return self._fire(self.app.guard(view.on_view_checkbox), SimpleNamespace(client=self.tab, target=view._cb_pano))

    # ------------------------------------------------------------------ drags
    def drag(self, key: str, start_uv: tuple[float, float], end_uv: tuple[float, float], *, shift: bool = False,
             steps: int = 4) -> list[tuple[str, str]]:
        """Left-drag (``shift``: Shift+left) on ``key`` (``"render"``, ``"camera_overlay"`` or a camera view)
        from original camera pixel ``start_uv`` to ``end_uv`` in ``steps`` moves: the start, update and end
        events viser sends, to every handler the node has for that button and modifier."""
        app = self.app
        slot = app.slot_of(RENDER_KEY) if key == RENDER_KEY else app.camera_slot()
        node = app.align.drag_nodes()[key]

        def world(uv: Any) -> np.ndarray:
            disp, ok = app.display_from_pixels(np.asarray(uv, np.float64).reshape(1, 2))
            if not ok[0]:
                raise ValueError(f"pixel {tuple(uv)} is not shown")
            return slot.world_from_pixel(disp)[0]

        modifier = "shift" if shift else None
        handlers = app.align.drag_callbacks(key, modifier)
        start = world(start_uv)
        before = len(self.tab.notifications)
        for k in range(steps + 1):
            phase = "start" if k == 0 else ("end" if k == steps else "update")
            uv = np.asarray(start_uv) + (np.asarray(end_uv) - np.asarray(start_uv)) * max(k, 1) / steps
            end = world(uv)
            event = SimpleNamespace(client=self.tab, client_id=getattr(self.tab, "client_id", 0), target=node,
                                    phase=phase, start_position=tuple(start), end_position=tuple(end),
                                    start_screen_pos=(0.0, 0.0), end_screen_pos=(0.1, 0.1), modifier=modifier,
                                    button="left", instance_index=None)
            for handler in handlers:
                self._fire(handler, event)
        return self.tab.notifications[before:]
