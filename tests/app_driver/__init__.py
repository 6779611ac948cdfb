"""A test driver for :class:`app.server.CalibrationApp`: act as a browser tab would, read what it shows.

Tests (and ``bench/app_click.py``) use :class:`AppDriver` instead of the app's private members.  Every
action goes through the same handler the viser event would reach (a click is
a ray onto the image, queued on the app's ordered action worker) and returns
once the app has applied it and redrawn -- that is, once the page would show
it.  Notifications the app sends to the tab are collected.

It lives in the tests tree, not in the installed package: ``tests/conftest.py`` puts ``tests/`` on
``sys.path``, so tests import it as ``app_driver``.  ``python -m app_driver`` (with ``tests/`` on
``PYTHONPATH``) runs the kill -9 durability test's app children: see ``app_driver/__main__.py``.
"""
from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import viser.transforms as vtf

from app.render_pane import RENDER_KEY
from calib_core.cameras.pinhole import PinholeCamera
from calib_core.transforms import invert_T, transform_points

from .fakes import FakeCamera, FakeTab
from .render import RenderDriver


def sample_app(session_path, **kwargs: Any):
    """The app on the committed sample scene (a free port), its session at ``session_path``."""
    from app.server import CalibrationApp
    from repo_paths import SAMPLE

    return CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                          session_path=session_path, port=0, **kwargs)

__all__ = ["AppDriver", "FakeCamera", "FakeTab"]


class AppDriver(RenderDriver):
    """Drive one :class:`app.server.CalibrationApp` as a user in one tab (``tab``) would."""

    def __init__(self, app: Any, tab: FakeTab | None = None) -> None:
        self.app = app
        self.tab = tab if tab is not None else FakeTab()

    # ------------------------------------------------------------------ actions
    def _fire(self, handler: Any, event: Any) -> list[tuple[str, str]]:
        """Deliver ``event`` to a guarded handler as viser does, wait until applied; new notifications."""
        before = len(self.tab.notifications)
        asyncio.run(handler(event))
        self.app.actions.join()
        return self.tab.notifications[before:]

    def _ray(self, key: str, uv: tuple[float, float], **extra: Any) -> Any:
        world = self.app.slot_of(key).world_from_pixel(np.asarray(uv, dtype=np.float64).reshape(1, 2))[0]
        return SimpleNamespace(ray_origin=tuple(world - [0.0, 0.0, 1.0]), ray_direction=(0.0, 0.0, 1.0),
                               client=self.tab, target=None, **extra)

    def click(self, key: str, uv: tuple[float, float]) -> list[tuple[str, str]]:
        """Click display pixel ``uv`` of image ``key`` (a BA key, ``raw`` or ``panorama``)."""
        return self._fire(self.app.make_click_handler(key), self._ray(key, uv))

    def click_cell(self, key: str, row: int, col: int) -> list[tuple[str, str]]:
        """Click the centre of scan cell ``(row, col)`` on BA image ``key`` (it must be in the shown columns)."""
        u, shown = self.app.ba_window.display_cols(np.array([col]))
        if not shown[0]:
            raise ValueError(f"column {col} is not shown")
        return self.click(key, (float(u[0]), float(row)))

    def click_camera(self, u: float, v: float) -> list[tuple[str, str]]:
        """Click original camera pixel ``(u, v)`` in the visible camera view."""
        key = self.camera_key
        disp, ok = self.app.display_from_pixels(np.array([[u, v]], dtype=np.float64))
        if not ok[0]:
            raise ValueError(f"pixel ({u}, {v}) is not shown")
        return self.click(key, (float(disp[0, 0]), float(disp[0, 1])))

    # ---------------------------------------------------------------- loupes
    def loupe_display_pixel(self, kind: str, uv: tuple[float, float]) -> tuple[float, float] | None:
        """Where loupe ``kind`` (``"ba"`` or ``"camera"``) shows ``uv``: ``(col, row)`` of a scan cell (BA) or an
        original camera pixel ``(u, v)``; loupe pixel coordinates, None when the loupe does not show it."""
        return self.app.loupes.display_of(kind, uv)

    def click_loupe(self, kind: str, uv: tuple[float, float]) -> list[tuple[str, str]]:
        """Click *through* loupe ``kind`` at ``uv``: ``(col, row)`` of a scan cell or an original pixel ``(u, v)``."""
        shown = self.loupe_display_pixel(kind, uv)
        if shown is None:
            raise ValueError(f"{uv} is not shown in the {kind} loupe")
        return self.click(f"loupe_{kind}", shown)

    def click_loupe_cell(self, row: int, col: int) -> list[tuple[str, str]]:
        """Click scan cell ``(row, col)`` in the BA loupe (it must show it)."""
        return self.click_loupe("ba", (float(col), float(row)))

    def click_loupe_camera(self, u: float, v: float) -> list[tuple[str, str]]:
        """Click original camera pixel ``(u, v)`` in the camera loupe (it must show it)."""
        return self.click_loupe("camera", (float(u), float(v)))

    def press_loupe_zoom(self, label: str) -> list[tuple[str, str]]:
        """Press a "Loupe zoom" button: ``"BA +"``, ``"BA -"``, ``"Camera +"`` or ``"Camera -"``."""
        return self._fire(self.app.guard(self.app.loupes.on_zoom), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=label)))

    def upload_initial_extrinsics(self, name: str, content: bytes) -> list[tuple[str, str]]:
        """Upload an extrinsics file through this tab's "Import initial extrinsics" button."""
        support = self.app.align
        handler = self.app.guard(lambda action: support.receive_initial_extrinsics(action.client, name, content))
        return self._fire(handler, SimpleNamespace(client=self.tab, target=None))

    def choose_loupe_source(self, name: str) -> list[tuple[str, str]]:
        """Choose what the BA loupe shows in its dropdown (see ``app.laser_images.loupe_sources()``)."""
        return self._fire(self.app.guard(self.app.display.on_loupe_source), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=name)))

    def choose_last_pane_source(self, name: str) -> list[tuple[str, str]]:
        """Choose what the last laser pane shows in its dropdown (see ``app.laser_images.last_pane_sources()``)."""
        return self._fire(self.app.guard(self.app.display.on_last_pane_source), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=name)))

    def set_slider(self, label: str, value: float) -> list[tuple[str, str]]:
        """Move a slider of the View folder: ``"Laser contrast"`` or ``"BA-edge opacity"``."""
        handler = {"Laser contrast": self.app.display.on_contrast, "BA-edge opacity": self.app.display.on_edge_opacity}[label]
        target = SimpleNamespace(value=value)
        return self._fire(self.app.guard(handler), SimpleNamespace(client=self.tab, target=target))

    def set_hide_marks(self, on: bool) -> list[tuple[str, str]]:
        """Tick (or clear) "Hide marks" in the Loupes folder."""
        return self._fire(self.app.guard(self.app.display.on_hide_marks), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=bool(on))))

    def set_edge_pairs(self, on: bool) -> list[tuple[str, str]]:
        """Tick (or clear) "Photo end on an edge" in the pinned pair bar."""
        return self._fire(self.app.guard(self.app.pairs_panel.on_edge_pairs), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=bool(on))))

    def drawn_labels(self) -> dict[str, str]:
        """The number labels the scene shows now, by node name (``/annot/labels/<image>/<id>``): their texts."""
        return {name: spec[1] for name, (_, spec) in self.app.nodes.drawn.items() if spec[0] == "label"}

    def loupe_title(self, kind: str) -> str:
        """The title the page shows above loupe ``kind`` (``"ba"`` or ``"camera"``): the text sent to its label."""
        return str(self.app.loupes._titles[kind].text)

    def loupe_texture(self, kind: str) -> np.ndarray:
        """The texture the loupe shows now (a nearest-neighbour enlarged crop)."""
        return self.app.loupes.texture(kind)

    def drawn_points(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World positions and colours of scene points node ``name`` (e.g. ``/annot/overlay/edges``); empty if none."""
        entry = self.app.nodes.drawn.get(name)
        if entry is None:
            return np.empty((0, 3)), np.empty((0, 3), np.uint8)
        return np.asarray(entry[1][1]), np.asarray(entry[1][2])

    def drawn_display_pixels(self, name: str, key: str) -> np.ndarray:
        """Display pixels ``(N, 2)`` on image ``key`` of the points scene node ``name`` draws (as sent to viser)."""
        world, _ = self.drawn_points(name)
        return self.app.slot_of(key).pixel_from_world(world)

    def drawn_segment_pixels(self, name: str, key: str) -> np.ndarray:
        """Display pixels ``(N, 2, 2)`` on image ``key`` of the line segments node ``name`` draws (padding dropped)."""
        segs = self.app.nodes.segments(name)
        return self.app.slot_of(key).pixel_from_world(segs.reshape(-1, 3)).reshape(-1, 2, 2)

    def drawn_marker_pixels(self, key: str) -> np.ndarray:
        """Display pixels ``(N, 2)`` on image ``key`` of the pick markers drawn there: the centres of the rings as sent."""
        from app.ui_common import RING_SEGMENTS, marker_segments

        segs = self.app.nodes.segments(f"/annot/markers/{key}/ring")
        per = len(marker_segments(np.zeros((1, 3)), 1.0, cell_half_size=(1.0, 1.0) if key in self.app.ba_keys else None))
        rings = segs.reshape(-1, per, 2, 3)[:, :RING_SEGMENTS, 0, :].astype(np.float64)
        return self.app.slot_of(key).pixel_from_world(rings.mean(axis=1))

    def loupe_view(self, kind: str) -> dict:
        """What loupe ``kind`` shows: ``{"center", "size"}`` (+ ``"key"`` for BA): its centre cell ``(row, col)``
        or pixel ``(u, v)`` and its width in cells or pixels."""
        if kind == "ba":
            c = self.app.loupes.ba_crop
            return {"key": c.key, "center": c.center, "size": c.n_cols}
        c = self.app.loupes.camera_crop
        return {"center": c.center, "size": c.n}

    # ---------------------------------------------------------------- view folder
    def choose_ba_columns(self, label: str) -> list[tuple[str, str]]:
        """Choose in the "BA columns" dropdown: ``"All columns"``, ``"Facing the camera"`` or ``"Custom"``."""
        return self._fire(self.app.guard(self.app.view.on_ba_window_mode), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=label)))

    def set_ba_columns(self, start: int, width: int) -> list[tuple[str, str]]:
        """Move the "BA first column" and "BA columns shown" sliders to ``start`` and ``width``."""
        view = self.app.view
        view.ba_start_slider.value, view.ba_width_slider.value = int(start), int(width)
        return self._fire(self.app.guard(view.on_ba_window_slider), SimpleNamespace(
            client=self.tab, target=view.ba_width_slider))

    @property
    def ba_columns_choice(self) -> str:
        """What the "BA columns" dropdown shows."""
        return str(self.app.view.ba_columns_dropdown.value)

    def ba_texture(self, key: str) -> np.ndarray:
        """The texture BA image ``key`` shows now (cells enlarged by nearest neighbour)."""
        return self.app.page.texture(key)

    def press_zoom(self, name: str) -> list[tuple[str, str]]:
        """Press a "Zoom" button of the 2-D view: ``"In"``, ``"Out"`` or ``"On last click"``."""
        return self._fire(self.app.guard(self.app.view.on_magnify), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=name)))

    def show(self, view: str) -> list[tuple[str, str]]:
        """Press "Show": ``"2D annotation"`` or ``"3D cloud"``."""
        return self._fire(self.app.guard(self.app.view.on_view_mode), SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=view)))

    @property
    def cloud_colors(self) -> np.ndarray:
        """The 3-D cloud's colours ``(K, 3)`` as the page shows them."""
        return self.app.cloud.colors

    @property
    def cloud_shows_current_solve(self) -> bool:
        """True when the 3-D cloud's colours come from the newest solve."""
        shows = self.app.cloud.shows
        return shows is not None and shows is self.app.live.bundle

    def shift_click(self, key: str, uv: tuple[float, float]) -> list[tuple[str, str]]:
        """Shift+click display pixel ``uv`` of image ``key`` (selects the pair whose marker is there)."""
        return self._fire(self.app.make_select_handler(key), self._ray(key, uv))

    def select_in_dropdown(self, pick_id: int | None) -> list[tuple[str, str]]:
        """Choose a pair (or ``None``) in the "Selected pair" dropdown."""
        # The value the tab sent (setting the handle's value from Python would fire the callback itself).
        chosen = SimpleNamespace(value="none" if pick_id is None else f"#{pick_id}")
        return self._fire(self.app.guard(self.app.pairs_panel.on_select_dropdown), SimpleNamespace(client=self.tab,
                                                                                         target=chosen))

    def press_edit(self, name: str) -> list[tuple[str, str]]:
        """Press one of the Edit buttons: ``Undo``, ``Redo``, ``Deselect``, ``Delete``."""
        return self._fire(self.app.guard(self.app.pairs_panel.on_edit), SimpleNamespace(client=self.tab,
                                                                              target=SimpleNamespace(value=name)))

    def press_pair_action(self, name: str) -> list[tuple[str, str]]:
        """Press one of the pair actions at the top of the panel: ``Undo``, ``Cancel pair``, ``Next pair``."""
        return self._fire(self.app.pairs_panel.pair_action_callback, SimpleNamespace(
            client=self.tab, target=SimpleNamespace(value=name)))

    @property
    def pair_status(self) -> str:
        """The status line under the pair actions at the top of the panel."""
        return self.app.pairs_panel.status

    def upload_pairs(self, name: str, content: bytes, answer: str | None = "Append") -> list[tuple[str, str]]:
        """Upload a pairs file through this tab's "Import pairs YAML" button; the notifications it gave.

        If the app asks whether to append or replace (there are pairs already), ``answer`` is
        pressed (``"Append"``, ``"Replace all"`` or ``"Cancel"``); None leaves the question open.
        """
        before = len(self.tab.notifications)
        asked = len(self.tab.gui.modals)
        self.app.pairs_panel.receive_upload(self.tab, name, content, wait=True)
        if answer is not None and len(self.tab.gui.modals) > asked:
            self.answer_question(answer)
        return self.tab.notifications[before:]

    @property
    def open_question(self) -> str | None:
        """The text of the question the app asks in this tab (None: none open)."""
        for modal, widgets in reversed(self.tab.gui.modals):
            if not modal.closed:
                return modal.label + ": " + " ".join(w.content for w in widgets if w.kind == "markdown")
        return None

    def answer_question(self, label: str) -> list[tuple[str, str]]:
        """Press button ``label`` of the open question in this tab."""
        for modal, widgets in reversed(self.tab.gui.modals):
            if not modal.closed:
                button = next(w for w in widgets if w.kind == "button" and w.label == label)
                return self._fire(button.callbacks[-1], SimpleNamespace(client=self.tab, target=None))
        raise ValueError("no question is open")

    def press_clear_all(self) -> list[tuple[str, str]]:
        """Press "Clear all pairs"."""
        return self._fire(self.app.guard(self.app.pairs_panel.on_clear), SimpleNamespace(client=self.tab, target=None))

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Wait for the live solve and cloud work the last actions started."""
        return self.app.wait_idle(timeout)

    # ------------------------------------------------------------- for real tabs
    def client_ids(self) -> list[int]:
        """Ids of the browser tabs connected to the app."""
        return sorted(self.app.server.get_clients())

    def page_position(self, client_id: int, target: str, uv: tuple[float, float]) -> tuple[float, float]:
        """Where a pixel appears in a real tab's canvas, as fractions of the canvas width and height, from the
        camera that tab reported.

        Parameters
        ----------
        client_id : int
            The tab (see :meth:`client_ids`).
        target : str
            ``"camera"`` (``uv`` is an ORIGINAL camera-image pixel, shown in the
            visible camera view), ``"render"`` (an original pixel, in the camera-view render), a BA key
            (``uv`` = (col, row) of a scan cell, which must lie in the shown column window; fractions of a
            cell aim off its centre), ``"loupe_camera"`` (an original pixel the
            camera loupe shows) or ``"loupe_ba"`` ((col, row) of a cell the BA loupe shows).
        """
        app = self.app
        disp = np.asarray(uv, dtype=np.float64).reshape(1, 2)
        if target.startswith("loupe_"):
            kind = target[len("loupe_"):]
            slot = app.loupes.slot(kind)
            shown = app.loupes.display_of(kind, (disp[0, 0], disp[0, 1]))
            if shown is None:
                raise ValueError(f"{uv} is not shown in the {kind} loupe")
            disp = np.array([shown])
        elif target in ("camera", RENDER_KEY):  # the render shows original pixels as the camera view does
            slot = app.camera_slot() if target == "camera" else app.view.slots[RENDER_KEY]
            disp, ok = app.display_from_pixels(disp)
            if not ok[0]:
                raise ValueError(f"pixel {uv} is not shown in the camera view")
        else:
            slot = app.view.slots[target]
            u, shown = app.view.ba_window.display_cols(np.array([int(round(disp[0, 0]))]))
            if not shown[0]:
                raise ValueError(f"BA column {uv[0]} is outside the shown columns")
            disp = np.array([[u[0] + disp[0, 0] - round(disp[0, 0]), disp[0, 1]]])
        world = slot.world_from_pixel(disp)
        cam = app.server.get_clients()[client_id].camera
        # The tab's view as a distortion-free pinhole (viser's camera frame is OpenCV's: +z forward, +y down).
        T_world_view = np.eye(4)
        T_world_view[:3, :3] = vtf.SO3(np.asarray(cam.wxyz)).as_matrix()
        T_world_view[:3, 3] = cam.position
        f = (cam.image_height / 2) / math.tan(cam.fov / 2)
        view = PinholeCamera([[f, 0.0, cam.image_width / 2], [0.0, f, cam.image_height / 2], [0.0, 0.0, 1.0]], [],
                             int(cam.image_width), int(cam.image_height))
        xy, _ = view.project(transform_points(invert_T(T_world_view), world))
        return float(xy[0, 0]) / cam.image_width, float(xy[0, 1]) / cam.image_height

    def node_name(self, key: str) -> str:
        """Scene node of image ``key`` (a BA key, ``raw`` or ``panorama``) that takes the clicks."""
        return {"raw": "/annot/camera_raw", "panorama": "/annot/camera_pano", "loupe_ba": "/annot/loupe_ba",
                "loupe_camera": "/annot/loupe_camera"}.get(key, f"/annot/ba_{key}")

    def click_ray(self, key: str, uv: tuple[float, float]) -> tuple[str, tuple, tuple]:
        """``(node, ray_origin, ray_direction)`` of a click on display pixel ``uv`` of image ``key``."""
        ev = self._ray(key, uv)
        return self.node_name(key), ev.ray_origin, ev.ray_direction

    def camera_display_pixel(self, u: float, v: float) -> tuple[float, float] | None:
        """Where original camera pixel ``(u, v)`` is shown in the visible camera view (None: not shown)."""
        disp, ok = self.app.display_from_pixels(np.array([[u, v]], dtype=np.float64))
        return (float(disp[0, 0]), float(disp[0, 1])) if ok[0] else None

    # ------------------------------------------------------------------ reading
    @property
    def camera_key(self) -> str:
        """The camera view the page shows (``raw`` or ``panorama``)."""
        return self.app.camera_slot().key

    def marker_ids(self, key: str) -> list[int]:
        """Pair ids whose markers are drawn on image ``key``."""
        return list(self.app.overlays.pick_ends(key)[0])

    def marker_display_pixel(self, key: str, pick_id: int) -> tuple[float, float]:
        """Display pixel of pair ``pick_id``'s marker on image ``key``."""
        ids, uv = self.app.overlays.pick_ends(key)
        return tuple(float(x) for x in uv[ids.index(pick_id)])

    def selection_drawn(self, key: str) -> int:
        """Number of selection-ring line segments drawn on image ``key`` (0: no selection shown there)."""
        return len(self.app.nodes.segments(f"/annot/selected/{key}"))

    @property
    def dropdown_value(self) -> str:
        """What the "Selected pair" dropdown shows."""
        return self.app.pairs_panel.dropdown_value

    @property
    def pairs_panel(self) -> str:
        """The text of the Pairs panel."""
        return self.app.pairs_panel.text

    @property
    def residual_table(self) -> str:
        """The per-pair residual table (markdown) of the Calibration panel."""
        return self.app.calibration_panel.table_text

    @property
    def result_panel(self) -> str:
        """The text of the Calibration panel (errors, solve failures)."""
        return self.app.calibration_panel.result_text

    # ------------------------------------------------ guided picking (guided helper; app/guide_panel.py)
    def press_guide(self, name: str) -> list[tuple[str, str]]:
        """Press a button of the Guided picking panel (``Next pair``, ``Skip``, ``Not a corner``, ``Stop``);
        returns once it is applied (not waiting for proposals: see :meth:`wait_guide`)."""
        return self._fire(self.app.guide.callback(name), SimpleNamespace(client=self.tab, target=None))

    def set_auto_accept(self, on: bool) -> list[tuple[str, str]]:
        """Tick or clear "Auto-accept clean corners"."""
        return self._fire(self.app.guide.callback("auto"), SimpleNamespace(client=self.tab, target=SimpleNamespace(
            value=bool(on))))

    def wait_guide(self, timeout: float = 120.0) -> bool:
        """Wait until the proposals are computed and what follows them (next pair started, auto pairs) is applied."""
        import time

        deadline = time.monotonic() + timeout
        while True:
            left = max(0.0, deadline - time.monotonic())
            if not (self.app.guide.wait_idle(left) and self.app.wait_idle(left)):
                return False
            if self.app.guide.idle and not self.app.actions.busy:
                return True

    @property
    def guide_proposal(self) -> Any:
        """The proposal the Guided picking panel shows (a :class:`calib_core.guide.Proposal`) or None."""
        return self.app.guide.current

    @property
    def guide_panel(self) -> str:
        """The text of the Guided picking panel."""
        return self.app.guide.text


    # ------------------------------------------------ verify helper: Export formats and the Verify panel
    def mark_check_pair(self, pick_id: int, check: bool = True) -> list[tuple[str, str]]:
        """Choose pair ``pick_id`` in Verify's "Pair to mark" and press "Make check pair" (or "Put back in fit")."""
        panel = self.app.verify_panel
        option = next((o for o in panel._dd_pair.options if o.split()[0] == f"#{pick_id}"), f"#{pick_id}")
        panel._dd_pair.value = option
        label = "Make check pair" if check else "Put back in fit"
        return self._fire(self.app.guard(panel._on_check_button),
                          SimpleNamespace(client=self.tab, target=SimpleNamespace(value=label)))

    def download_format(self, fmt: str, parent: str = "lidar", child: str = "camera") -> tuple[str, bytes]:
        """Choose ``fmt`` and the frames in "Export to robotics formats", press Download; ``(file name, bytes)``."""
        panel = self.app.format_export
        panel._dd_format.value, panel._tx_parent.value, panel._tx_child.value = fmt, parent, child
        # The widgets' own update callbacks arrive from viser's event loop at their own pace: refresh once more
        # after all three values are set, as the last of those callbacks would.
        self._fire(self.app.guard(lambda action: panel._refresh()), SimpleNamespace(client=self.tab, target=None))
        before = len(self.tab.downloads)
        notes = self._fire(self.app.guard(panel._on_download), SimpleNamespace(client=self.tab, target=None))
        if len(self.tab.downloads) == before:
            raise ValueError(f"no download: {notes}")
        return self.tab.downloads[-1]

    def upload_reference(self, name: str, content: bytes) -> list[tuple[str, str]]:
        """Upload a reference extrinsic through this tab's "Import reference extrinsic" button."""
        before = len(self.tab.notifications)
        self.app.format_export.receive_reference(self.tab, name, content, wait=True)
        return self.tab.notifications[before:]

    def download_extrinsics_yaml(self) -> bytes:
        """Press "Download extrinsics YAML"; the bytes the tab receives."""
        before = len(self.tab.downloads)
        self._fire(self.app.guard(self.app.export_panel.on_download_yaml), SimpleNamespace(client=self.tab, target=None))
        if len(self.tab.downloads) == before:
            raise ValueError("no download")
        return self.tab.downloads[-1][1]

    def wait_verified(self, timeout: float = 60.0) -> bool:
        """Wait for the live solve and then for the Verify panel's computation of the newest pairs."""
        return self.app.wait_idle(timeout) and self.app.verify_panel.wait_idle(timeout)

    @property
    def verify_summary(self) -> str:
        """The Verify panel's summary text."""
        return self.app.verify_panel.summary

    @property
    def verify_table(self) -> str:
        """The Verify panel's per-pair table (markdown)."""
        return self.app.verify_panel.table

    def verify_plots(self) -> dict[str, tuple]:
        """The data of the Verify plots: ``pairs``, ``count``, ``sigma``."""
        return self.app.verify_panel.plot_data()

    @property
    def export_direction(self) -> str:
        """The direction line of the format export panel."""
        return self.app.format_export.direction_text
    # ------------------------------------------------ end of the verify helper's block
