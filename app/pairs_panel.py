"""The pairs panel: clicks on the BA and camera images make and move pairs, Shift+click and the dropdown select,
the Edit buttons (undo, redo, deselect, delete), Clear all, and importing a pairs file (append or replace)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
import viser

from calib_core.errors import CalibError
from calib_core.image_edges import edge_at
from calib_core.panorama import refine_click_to_corner

from .layout import RENDER_KEY
from .loupe_framing import PairClick
from .page_builder import install_page_script
from .pair_bar import (PAIR_BAR_JS, STATUS_LINES, FixedLine, PairBar, made_hint, one_line_markdown, pending_hint,
                       undo_note)
from .pairs_import import import_upload
from .ui_common import MIN_PAIRS, SNAP_RADIUS_PX, pick_tolerance_px

#: The buttons at the top of the control panel ("Next pair" is guided picking's own).
PAIR_ACTIONS = ("Undo", "Cancel pair", "Next pair")


class PairsPanel:
    """The "Pairs" folder of one :class:`app.server.CalibrationApp` (``app.pairs_panel``) and the clicks on the images.

    It owns its widgets (built here, where the folder goes on the page) and
    where each tab's last camera click landed (:meth:`camera_click_source`).
    Every change goes through ``app.state``; the clicks are mapped through the
    app's page layout, and published (:meth:`subscribe_clicks`: the loupes follow them).  The composition root
    passes what it uses of its siblings: ``loupe_marks_after()`` and ``nearest_pick(key, uv, slot)`` (the
    overlays'), ``aligning()`` ("Align by drag" is on) and, once built, :meth:`resolve_clicks_with`.
    """

    def __init__(self, app: Any, top: float, *, loupe_marks_after: Callable[[], Any],
                 nearest_pick: Callable[[str, tuple, Any], int | None], aligning: Callable[[], bool]) -> None:
        self.app = app
        self._loupe_marks_after, self._nearest_pick_at, self._aligning = loupe_marks_after, nearest_pick, aligning
        self._loupe_target: Callable[[str, tuple], tuple] | None = None  # resolve_clicks_with
        self._render_target: Callable[[tuple, Any], tuple] | None = None
        self._render_uv: tuple[float, float] | None = None  # the render pixel of the last render click resolved
        self._last_pick: dict[Any, tuple] = {}  # client id -> (kind, pick id, "full" | "loupe")
        self._loupes_pick: int | None = None  # the pair the loupes were last framed on (refining it keeps them still)
        self._rough_photo: set[int] = set()  # pairs whose photo end was clicked on the full photo, not refined since
        self._undo_note: tuple[int, str] = (-1, "")  # (state version, what the last top Undo took back)
        self._click_listeners: list[Callable[[PairClick], None]] = []
        self._cancel_listeners: list[Callable[[], None]] = []
        gui, guard = app.server.gui, app.guard
        # The pair actions first in the panel, near the loupes: in the by-eye trials Undo and Next pair were many
        # wheel scrolls apart.  Buttons above the status line, so that they never move as the text changes.
        # ``top``: the GUI order of the intro text, which they go just above.
        self.pair_action_callback = self._on_pair_action_event
        self._bg_actions = gui.add_button_group("Pair", PAIR_ACTIONS, order=top - 1.0)
        self._bg_actions.on_click(self.pair_action_callback)
        # In the pinned bar: a person switches it on for a run of lane-line crossings and off again.
        self.edge_checkbox = gui.add_checkbox(
            "Photo end on an edge", initial_value=app.state.view.edge_pairs, order=top - 0.9,
            hint="The pair's photo end lies on a straight edge (a lane line, a pole's side) and may slide along it")
        self.edge_checkbox.on_update(guard(self.on_edge_pairs))
        # One line kept when blank: in run 7 the controls below jumped ~18 px as it came and went.
        self._status_line = FixedLine(gui, order=top - 0.5, lines=STATUS_LINES)
        # The live solve's figures right under the buttons, guided picking's status under the pair status.
        self.bar = PairBar(gui, live_order=top - 0.75, guide_order=top - 0.45)
        self.show_guide_status = self.bar.show_guide_status  # the Guide panel's hook
        app.pose_source.subscribe(lambda: self.bar.show_pose_turn(  # e.g. a refit
            app.pose_source.last_turn, app.state.all_picks))
        install_page_script(app.server, PAIR_BAR_JS)  # the bar stays in view; Delete and Ctrl+Z keys
        self._guarded_pair_action = guard(self.on_pair_action)
        self._next_pair: Callable | None = None  # guided picking's "Next pair" (set_next_pair_handler)
        self.folder = gui.add_folder("Pairs")
        with self.folder:
            self._md_pairs = gui.add_markdown("")
            self._summary = ""  # the summary's text as shown (its lines without the fixed-line markup)
            self._dd_selected = gui.add_dropdown("Selected pair", ("none",), initial_value="none")
            self._dd_selected.on_update(guard(self.on_select_dropdown))
            self._bg_edit = gui.add_button_group("Edit", ("Undo", "Redo", "Deselect", "Delete"))
            self._bg_edit.on_click(guard(self.on_edit))
            # Run 4: the per-pair table is read-only; testing a pair by leaving it out took the Verify panel.
            self._btn_leave_out = gui.add_button("Leave selected pair out of the fit / put it back",
                                                 hint="A pair left out is a check pair: not fitted, its error shown "
                                                      "apart (undoable)")
            self._btn_leave_out.on_click(guard(self.on_leave_out))
            self._btn_clear = gui.add_button("Clear all pairs (undoable)", color="red", icon=viser.Icon.TRASH)
            self._btn_clear.on_click(guard(self.on_clear))
            self.snap_checkbox = gui.add_checkbox("Snap clicks to corners", initial_value=app.state.view.snap,
                                                  hint="Refine each click to the strongest corner within 4 pixels")
            self.snap_checkbox.on_update(guard(self.on_snap))
            # Each tab gets its own upload button (see add_upload_button): viser keeps one value per button,
            # which two tabs uploading at once would overwrite.
            self._btn_pairs = gui.add_button("Download pairs YAML", icon=viser.Icon.DOWNLOAD)
            self._btn_pairs.on_click(guard(self.on_download_pairs))

    # ------------------------------------------------------------------ what the panel shows
    @property
    def text(self) -> str:
        """The panel's summary as shown (markdown)."""
        return self._summary

    @property
    def status(self) -> str:
        """The status line under the pair actions at the top of the panel (markdown; empty when nothing waits)."""
        return self._status_line.text

    @property
    def dropdown_value(self) -> str:
        """What the "Selected pair" dropdown shows."""
        return str(self._dd_selected.value)

    def resolve_clicks_with(self, loupe: Callable[[str, tuple], tuple],
                            render: Callable[[tuple, Any], tuple[tuple, tuple[float, float] | None]]) -> None:
        """How clicks on panes other panels draw become pair ends (the composition root wires it): ``loupe(kind,
        uv)`` -> target, ``render(uv, client)`` -> (target, the render pixel clicked)."""
        self._loupe_target, self._render_target = loupe, render

    # ------------------------------------------------------------------ events
    def subscribe_clicks(self, listener: Callable[[PairClick], None]) -> None:
        """Call ``listener(click)`` after each click on an image is applied (or refused by the state), on the
        action worker, before the loupes' marks are drawn (the loupes follow the clicks)."""
        self._click_listeners.append(listener)

    def subscribe_cancel(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` after "Cancel pair" dropped a half-made pair."""
        self._cancel_listeners.append(listener)

    def _publish_click(self, click: PairClick) -> None:
        for listener in list(self._click_listeners):
            listener(click)

    # ------------------------------------------------------------------ per-tab memory
    def camera_click_source(self, pick_id: int) -> str | None:
        """Where the last camera click on pick ``pick_id`` landed in its tab: ``"loupe"``, ``"full"`` or None."""
        for kind, pid, where in list(self._last_pick.values()):
            if kind == "camera" and pid == pick_id:
                return where
        return None

    def forget_last_picks(self) -> None:
        """Forget the last click of every tab, so that the next loupe click adds an end instead of refining one."""
        self._last_pick.clear()

    def on_edge_pairs(self, event: Any) -> None:
        """The "Photo end on an edge" checkbox: the photo clicks from now on are on an edge (or corners again)."""
        self.app.state.set_view(edge_pairs=bool(event.value))
        # Run 16: ticked after the photo click of the pair being made, the tick did not reach that photo end (a
        # finished pair keeps its kind: the tick is usually meant for the next one).
        half = self.app.state.pending()
        if half is not None and half.pixel is not None:
            tags = self._photo_tags(*half.pixel, event.client, bool(event.value))
            if tags["edge_deg"] != half.edge_deg:
                self.app.state.move_pixel(half.id, *half.pixel, **tags)
        self.refresh()

    def _newest(self) -> Any:
        """The newest pair of the shot (the one being made or just made), or None."""
        return max(self.app.state.picks, key=lambda p: p.id, default=None)

    def _photo_tags(self, u: float, v: float, client: Any, on_edge: bool) -> dict:
        """``edge_deg`` of a photo click at original pixel ``(u, v)``: the photo's edge direction there for an end
        ``on_edge``, else None (a corner).  Without a clear straight edge it is a corner, and the person is told."""
        if not on_edge:
            return {"edge_deg": None}
        edge = edge_at(self.app.image_gray, (u, v))
        if not edge.ok:
            self.app.notify(client, "No straight edge here", f"The photo shows no single straight edge at "
                            f"({u:.0f}, {v:.0f}): this end is a corner. Click on the edge itself.", color="yellow")
            return {"edge_deg": None}
        return {"edge_deg": edge.angle_deg}

    def on_snap(self, event: Any) -> None:
        """The "Snap clicks to corners" checkbox."""
        self.app.state.set_view(snap=bool(self.snap_checkbox.value))

    def refresh(self) -> None:
        """Show the pairs summary and the selection dropdown as they are now."""
        app = self.app
        state = app.state
        with app.ui_lock:
            picks = state.picks
            complete = [p for p in picks if p.complete]
            pending = state.pending()
            selected = state.selected
            total = sum(1 for p in state.all_picks if p.complete)  # every shot's pairs go into the solve
            # Fixed slots, each one line kept when blank: the controls under the summary never move (run 7).
            count = f"**Pairs:** {len(complete)} complete" + (
                f" in shot {state.active_shot} (shown); {total} in all {state.n_shots} shots" if state.n_shots > 1 else "")
            doing = ""
            if pending is not None:
                need = "camera" if pending.pixel is None else "BA"
                doing = f"Pair {pending.id} waits for a {need} click."
                ids, uv = app.pose_source.predicted_pixels({pending.id: pending})
                if ids:
                    doing += f" Predicted camera pixel: ({uv[0, 0]:.1f}, {uv[0, 1]:.1f}) (cross in the image)."
            status = [self._undo_note[1]] if self._undo_note[0] == state.version else []
            if pending is not None:
                status.append(pending_hint(pending))
            elif selected is None and (made := self._just_made(picks)) is not None:
                status.append(made_hint(made, next((p.edge_deg for p in picks if p.id == made), None)))
            if selected is not None:
                doing = f"**Pair {selected} selected:** clicks now move its ends (Deselect to add pairs)."
                status.append(f"Pair {selected} selected: the next click moves it (**Cancel pair** deselects).")
            self._status_line.show(" · ".join(status))
            self.bar.pairs_changed(state.all_picks)
            turn = app.pose_source.last_turn  # its reason names the pairs a refit fitted (app.align_panel)
            self.bar.show_live(app.solve_shown(), fitted=getattr(turn, "why", "") == f"refitted from {total} pairs")
            left_out = [f"#{p.id}" for p in complete if p.check]
            # Two lines, so that the Loupes folder below stays in view without scrolling at 1400 x 900.
            count += f" · pick {MIN_PAIRS - total} more to calibrate" if total < MIN_PAIRS else ""
            count += f" · left out (check pairs): {', '.join(left_out)}" if left_out else ""
            on_edges = sum(1 for p in complete if p.edge_deg is not None)
            count += f" · {on_edges} on an edge" if on_edges else ""
            count += f" · undo: {'yes' if state.can_undo else 'no'}, redo: {'yes' if state.can_redo else 'no'}"
            lines = [count, doing]
            self._summary = "  \n".join(line for line in lines if line)
            shown = "\n".join(one_line_markdown(line) for line in lines)
            if self._md_pairs.content != shown:
                self._md_pairs.content = shown
            options = ("none",) + tuple(f"#{p.id}" for p in picks)
            if tuple(self._dd_selected.options) != options:
                self._dd_selected.options = options
            want = "none" if selected is None else f"#{selected}"
            if self._dd_selected.value != want:
                self._dd_selected.value = want

    def _just_made(self, picks: list) -> int | None:
        """The newest pair, if a click in the laser loupe just completed it after a click on the full photo: its
        photo end is still the rough one (the hint then says where the refining click goes)."""
        newest = max(picks, key=lambda p: p.id, default=None)
        if newest is None or not newest.complete or newest.id not in self._rough_photo:
            return None
        return newest.id if ("ba", newest.id, "loupe") in self._last_pick.values() else None

    def on_download_pairs(self, event: Any) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "pairs.yaml"
            n = self.app.state.export_pairs_file(path)
            data = path.read_bytes()
        if event.client is not None:
            event.client.send_file_download("pairs.yaml", data, save_immediately=True)
        self.app.notify(event.client, "Pairs", f"{n} complete pairs downloaded", color="green")

    def make_click_handler(self, key: str) -> Callable:
        """The on-click callback of image slot ``key`` (a BA key, a camera view or ``loupe_*``): adds or moves an end."""
        def on_click(event: Any) -> None:
            slot = self.app.slot_of(key)
            uv = slot.pixel_from_ray(event.ray_origin, event.ray_direction)
            if uv is None or not slot.contains(uv):
                raise CalibError("click landed outside the image")
            self._click(key, uv, client=event.client)

        return self.app.guard(on_click)

    def cell_from_display(self, key: str, uv: tuple[float, float]) -> tuple[int, int]:
        """Scan cell ``(row, col)`` under display pixel ``uv`` of BA slot ``key`` (window applied)."""
        return self.app.ba_window.cell_at(uv, self.app.depth.shape[0])

    def _target_of_click(self, key: str, uv: tuple[float, float], client: Any = None) -> tuple:
        """``("ba", key, row, col)`` or ``("camera", u, v)`` (original pixel) under display pixel ``uv`` of ``key``."""
        if key.startswith("loupe_"):
            target = self._loupe_target(key[len("loupe_"):], uv)
            if self.app.state.view.snap and target[0] == "ba":
                col, row = refine_click_to_corner(self.app.laser_images.ba_display(target[1]), (target[3], target[2]), 3.0)
                target = ("ba", target[1], int(np.clip(round(row), 0, self.app.depth.shape[0] - 1)),
                          int(round(col)) % self.app.depth.shape[1])
            elif self.app.state.view.snap:
                target = ("camera", *map(float, refine_click_to_corner(self.app.image_gray, target[1:], SNAP_RADIUS_PX)))
            return target
        if key == RENDER_KEY:  # the camera-view render: the laser cell drawn there, an ordinary laser end
            # A click on a thin outline may land a screen pixel beside it: snap within a few screen pixels.
            target, self._render_uv = self._render_target(uv, client)
            return target
        if key in self.app.ba_keys:
            if self.app.state.view.snap:
                shown = self.app.laser_images.ba_display(key)[:, self.app.ba_window.columns]
                uv = tuple(refine_click_to_corner(shown, uv, 3.0))
            return ("ba", key, *self.cell_from_display(key, uv))
        if key != self.app.camera_view.key:
            raise CalibError("that camera view is hidden; click the visible one")
        if self.app.state.view.snap:
            uv = tuple(refine_click_to_corner(self.app.camera_view.gray, uv, SNAP_RADIUS_PX))
        return ("camera", *self._original_from_display(uv))

    def _click(self, key: str, uv: tuple[float, float], pick_id: int | None = None, client: Any = None) -> int:
        """A click at display pixel ``uv`` of slot ``key``: add a pair end, or move ``pick_id``'s end.

        A click in a loupe right after a click on the full image of the same
        kind (BA or camera) refines that click: it moves the end just made.
        Then the loupes frame the click and the other end (clicked or predicted).
        """
        target = self._target_of_click(key, uv, client)
        # The loupes are re-framed right after the change: their marks are drawn once, for the new view.
        with self._loupe_marks_after():
            return self._apply_click(key, target, pick_id, client)

    def click_at(self, key: str, uv: tuple[float, float], client: Any = None) -> int:
        """A click at display pixel ``uv`` of slot ``key``, as an on-click event makes it (e.g. a shaky drag)."""
        return self._click(key, uv, client=client)

    def _apply_click(self, key: str, target: tuple, pick_id: int | None, client: Any) -> int:
        kind, source = target[0], ("loupe" if key.startswith("loupe_") else "full")
        cid = None if client is None else client.client_id
        last = self._last_pick.get(cid)
        if pick_id is None and source == "loupe" and self.app.state.selected is None:
            ids = {p.id: p for p in self.app.state.picks}
            if last is not None and last[0] == kind and last[2] == "full" and last[1] in ids:
                pick_id = last[1]  # refine the end the full-image click just made
            elif self.app.state.pending() is None and self._loupes_pick in ids and \
                    (ids[self._loupes_pick].has_laser if kind == "ba" else ids[self._loupes_pick].pixel is not None):
                # The loupes show a finished pair: a click in them refines its end rather than starting a pair
                # (by-eye runs 1 and 4); a new pair starts on the full images.
                pick_id = self._loupes_pick
        # A click with a pair selected moves it; then the selection ends, so that the next click starts or
        # continues a new pair instead of moving this one again (by-eye trial: a laser end jumped to an unrelated cell).
        moves_selected = pick_id is None and self.app.state.selected is not None
        refined = None if pick_id is None else next((p for p in self.app.state.picks if p.id == pick_id), None)
        if kind == "ba":
            _, _, row, col = target
            try:
                out = self.app.state.move_laser(pick_id, row, col) if pick_id is not None else self.app.state.click_laser(row, col)
            except CalibError:  # e.g. a cell with no return: the loupe still goes there, to pick a good one
                self._publish_click(PairClick(key, target, None, client_id=cid))
                raise
        else:
            _, u, v = target
            # The tick sets the kind of the pair being made; an older pair moved keeps its own (run 16: a corner
            # pair moved with the tick on became an edge pair, unasked).
            moved = pick_id if pick_id is not None else self.app.state.selected
            on_edge = (self.app.state.view.edge_pairs if moved is None or moved == self._newest().id
                       else self.app.state.get(moved).edge_deg is not None)
            tags = self._photo_tags(u, v, client, on_edge)
            out = (self.app.state.move_pixel(pick_id, u, v, **tags) if pick_id is not None
                   else self.app.state.click_pixel(u, v, **tags))
        if moves_selected:
            self.app.state.select(None)
        if refined is not None and refined in self.app.state.picks:  # run 4: refining clicks that moved nothing
            what = f"the same cell (row {target[2]}, column {target[3]})" if kind == "ba" else "the same pixel"
            self.app.notify(client, "No change", f"Pair {out}: {what} as before; click one cell or pixel farther "
                                                 "off to move it.", color="yellow")
        self._last_pick[cid] = (kind, out, source)
        if kind == "camera":  # a photo end from the full photo is rough until a photo-loupe click refines it
            (self._rough_photo.add if source == "full" else self._rough_photo.discard)(out)
        self.refresh()  # the status line says what the next click does (it depends on this click's place)
        if source == "loupe" and out == self._loupes_pick:  # a refining click inside a loupe: they keep their crops
            self._publish_click(PairClick(key, target, out, refines_loupes=True, client_id=cid))
            return out
        self._loupes_pick = out
        self._publish_click(PairClick(key, target, out, render_uv=(
            self._render_uv if key == RENDER_KEY else None), client_id=cid))
        return out

    def _original_from_display(self, uv: tuple[float, float]) -> tuple[float, float]:
        """Original camera pixel of a click on the visible camera view."""
        raw, valid = self.app.camera_view.pixels_from_display(np.array([uv], dtype=np.float64))
        if not valid[0]:
            raise CalibError("the camera does not see that part of the panorama; click inside the picture")
        return float(raw[0, 0]), float(raw[0, 1])

    def make_select_handler(self, key: str) -> Callable:
        """The Shift+click callback of image slot ``key``: selects the pair whose marker is nearest."""
        def on_shift_click(event: Any) -> None:
            slot = self.app.slot_of(key)
            uv = slot.pixel_from_ray(event.ray_origin, event.ray_direction)
            pick_id = None if uv is None else self._nearest_pick_at(key, uv, slot, client=event.client)
            self.app.state.select(pick_id)
            if pick_id is None and uv is not None:  # run 6: a Shift+click beside a marker did nothing, silently
                tolerance = pick_tolerance_px(slot.units_per_px, slot.units_per_px_y)
                self._undo_note = (self.app.state.version, f"No pair within {tolerance:.0f} px of that Shift+click.")
                self.refresh()

        return self.app.guard(on_shift_click)

    def make_drag_handler(self, key: str) -> Callable:
        def on_drag(event: Any) -> None:
            if event.phase != "end" or self._aligning():  # aligning: the Align panel has this drag
                return
            slot = self.app.slots[key]
            start = slot.pixel_from_world(np.asarray(event.start_position)[None])[0]
            end = slot.pixel_from_world(np.asarray(event.end_position)[None])[0]
            pick_id = self._nearest_pick_at(key, tuple(start), self.app.slot_of(key))
            moved = np.hypot(*(np.asarray(event.end_screen_pos) - np.asarray(event.start_screen_pos)))
            if pick_id is None:
                if moved < 0.01 and slot.contains(start):  # a shaky click, not a drag
                    self._click(key, tuple(start), client=event.client)
                return
            if not slot.contains(end):
                raise CalibError("dropped outside the image; the pair was not moved")
            self._click(key, (float(end[0]), float(end[1])), pick_id=pick_id, client=event.client)

        return self.app.guard(on_drag)

    def on_select_dropdown(self, event: Any) -> None:
        if event.client is None:  # our own update of the widget
            return
        value = str(event.value)
        self.app.state.select(None if value == "none" else int(value.split()[0].lstrip("#")))

    def set_next_pair_handler(self, handler: Callable) -> None:
        """The viser callback of the "Next pair" button in the pair actions (guided picking's own button)."""
        self._next_pair = handler

    async def _on_pair_action_event(self, event: Any) -> None:
        """A press in the pair actions at the top: "Next pair" is guided picking's own button, the others queue
        :meth:`on_pair_action` (both on the ordered action worker)."""
        if str(getattr(event.target, "value", "")) == "Next pair":
            await self._next_pair(event)
        else:
            await self._guarded_pair_action(event)

    def on_pair_action(self, event: Any) -> None:
        """"Undo" or "Cancel pair" at the top of the panel."""
        if event.value == "Undo":  # also Ctrl+Z: the status line says what went (which half of a pair)
            before = self.app.state.picks
            if not self.app.state.undo():
                raise CalibError("nothing to undo")
            self._undo_note = (self.app.state.version, undo_note(before, self.app.state.picks))
            self.refresh()
        elif event.value == "Cancel pair":
            self.cancel_pair()

    def cancel_pair(self) -> None:
        """Drop the half-made pair in one undoable step (else end the selection); nothing if neither (Escape with
        nothing pending is no mistake: run 6 showed a red "Not accepted" for it)."""
        state = self.app.state
        pending = state.pending()
        if pending is None:
            if state.selected is not None:
                state.select(None)
            return
        state.delete(pending.id)
        for listener in list(self._cancel_listeners):  # e.g. a guided proposal's ellipse in the camera loupe goes
            listener()

    def on_edit(self, event: Any) -> None:
        action = event.value
        if action == "Undo":
            if not self.app.state.undo():
                raise CalibError("nothing to undo")
        elif action == "Redo":
            if not self.app.state.redo():
                raise CalibError("nothing to redo")
        elif action == "Deselect":
            self.app.state.select(None)
        elif action == "Delete":
            # Run 15: right after a pair was made and refined nothing is selected, yet Delete meant that pair
            # (removing it took three Undos): without a selection, Delete takes the newest pair the loupes show.
            newest = self._newest()
            sel = self.app.state.selected or (newest.id if newest is not None and newest.complete
                                              and newest.id == self._loupes_pick else None)
            if sel is None:
                raise CalibError("select a pair first (shift+click its marker or use the dropdown)")
            self.app.state.delete(sel)
            # Run 14: Delete (the key) removed the pair without a word in the bar.
            self._undo_note = (self.app.state.version, f"Deleted pair {sel} (Ctrl+Z or Undo brings it back).")
            self.refresh()

    def on_leave_out(self, event: Any) -> None:
        """Leave the selected pair out of the fit (a check pair), or put it back."""
        sel = self.app.state.selected
        if sel is None:
            raise CalibError("select a pair first (shift+click its marker or use the dropdown)")
        out = not self.app.state.get(sel).check
        self.app.state.set_check(sel, out)
        # Then the selection ends, as after a move (run 7: a left-out pair stayed selected and the next click
        # silently moved its laser end; being left out, no figure changed).
        self.app.state.select(None)
        self._undo_note = (self.app.state.version, f"Pair {sel} {'left out of the fit' if out else 'put back in the fit'}"
                                                   "; selection ended: the next click starts a new pair.")
        self.refresh()

    def add_upload_button(self, client: Any) -> None:
        """This tab's own "Import pairs YAML" button, in the shared Pairs folder above "Download pairs YAML"."""
        with self.app.folder_lock:  # a folder is one GUI context at a time
            with self.folder:
                button = client.gui.add_upload_button("Import pairs YAML", icon=viser.Icon.UPLOAD, mime_type="*/*",
                                                      order=self._btn_pairs.order - 0.5)
        button.on_upload(self.app.guard(self._on_upload))

    def _on_upload(self, event: Any) -> None:
        f = event.value  # this tab's button: no other tab's upload can have replaced it
        import_upload(self.app, event.client, getattr(f, "name", ""), getattr(f, "content", b""))

    def receive_upload(self, client: Any, name: str, content: bytes, wait: bool = False) -> None:
        """Import an uploaded pairs file as the upload button of ``client`` does (through the action queue).

        The outcome is notified to ``client``; with ``wait``, returns once it is applied.
        """
        self.app.post(lambda: import_upload(self.app, client, name, content), client=client, wait=wait)

    def on_clear(self, event: Any) -> None:
        n = len(self.app.state.picks)
        if n == 0:
            raise CalibError("there are no pairs to clear")
        self.app.state.clear()
        self.app.notify(event.client, "Pairs cleared", f"{n} pairs removed. Undo (in Edit) brings them back.",
                     color="yellow")
