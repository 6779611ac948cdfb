"""The two loupes: magnified, clickable crops of one BA image and of the original camera image (how they are used:
docs/app.md, "Loupes").

Each is a viser scene image whose texture is a crop enlarged by nearest neighbour (crisp cells and pixels).  A click
in a loupe maps back exactly: sub-pixel for the camera (the loupe shows the *original* image, whatever the main view
shows), a whole scan cell for the BA loupe.  They follow each click (:mod:`app.loupe_framing`).  Display plumbing
only (predictions: :mod:`calib_core.predict`).
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from calib_core.errors import CalibError

from .layout import ImageSlot, LoupeArea, bounds_of, loupe_areas
from .loupe_crops import (BaCrop, CameraCrop, ba_crop_texture, camera_crop_texture, default_camera_crop_px,
                          draw_ba_outline, draw_camera_centre, node_name, crop_around, render_crop_of, slot_key)
from .loupe_framing import PairClick, follow_click, frame_pair
from .loupe_marks import LEGEND, ba_title, camera_title, draw_camera_marks, draw_camera_outline
from .shown_render import cell_at_pixel, loupe_texture, loupe_title, pixel_of_cells
from .ui_common import marker_segments, segment_colours

#: Columns the BA loupe shows at zoom 1 (the camera loupe's crop side: :data:`app.loupe_crops.CAMERA_LOUPE_PX`).
BA_LOUPE_COLUMNS = 32
ZOOM_FACTOR = 1.5
BA_COLUMN_LIMITS = (8, 400)
CAMERA_PX_LIMITS = (8, 1200)
TEXTURE_TEXELS = 320  # texels along the longer side of a loupe texture (at least 1 per cell or pixel)
PAD_GRAY = 60  # outside the scan or the image
KINDS = ("ba", "camera")
#: Scene nodes drawn from a loupe's view (not from the picks): its outline on the main image, the camera loupe's centre.
FRAMING_NODES = {"ba": ("/annot/loupe/ba_outline",),
                 "camera": ("/annot/loupe/camera_centre_halo", "/annot/loupe/camera_centre", "/annot/loupe/ellipse",
                            "/annot/loupe/camera_outline")}


class Loupes:
    """The BA loupe and the camera loupe of one :class:`app.server.CalibrationApp`.

    It owns the "Loupes" folder (the zoom buttons; the display panel adds its loupe widgets there).
    """

    def __init__(self, app: Any, add_controls: Callable[[Any], None] = lambda gui: None) -> None:
        self.app = app
        main = list(app.slots.values())  # camera views, the camera-view render, BA images
        self.areas: dict[str, LoupeArea] = loupe_areas(bounds_of(main))
        n_rows, n_cols = app.depth.shape
        self._ba_cols = min(BA_LOUPE_COLUMNS, n_cols)
        cam_w, cam_h = app.camera.width, app.camera.height
        self._cam_n = default_camera_crop_px(cam_w, cam_h)
        self._cam_n_chosen = self._cam_n  # the side the zoom buttons chose; framing may show more, never less
        self.ba_crop = self._make_ba_crop(app.ba_keys[0], n_rows // 2, n_cols // 2)
        self.camera_crop = crop_around((cam_w - 1) / 2.0, (cam_h - 1) / 2.0, self._cam_n)
        self._slots: dict[str, ImageSlot] = {}
        self._marks_of: dict[str, tuple] = {}  # kind -> inputs its marks were last drawn from
        self._framing_of: dict[str, tuple] = {}  # kind -> inputs its outline (and centre marker) were drawn from
        self._clicked: dict[str, tuple] = {}  # kind -> the cell / pixel a click inside it chose: its title names it
        self.shows_render = False  # the laser loupe shows the camera-view render's crop (after a click on it)
        self.prefers_ba = False  # the last laser click was on a BA image: a photo click keeps the BA image's loupe
        self._render: Any = None  # the render the render pane shows (app.shown_render.ShownRender; on_render)
        self.photo_gamma = 1.0  # the photo loupe's brightness (display only: "Photo loupe brightness")
        self._render_n: int | None = None  # the render loupe's own side (px; None: the camera loupe's), zoomed alone
        # ((row, col), (du, dv)): the laser end the render loupe is held on, and its crop centre's offset from where
        # the render draws it; a new render (a refit) keeps that end still in the loupe (run 7).  None: it follows
        # the camera loupe.
        self._render_anchor: tuple | None = None
        scene = app.server.scene
        self._handles: dict[str, Any] = {}
        self._titles: dict[str, Any] = {}
        for kind in KINDS:
            area = self.areas[kind]
            self._titles[kind] = scene.add_label(f"/annot/titles/loupe_{kind}", "", position=(area.x0, area.y0 - 0.03, -0.01),
                                                 anchor="bottom-left", font_screen_scale=0.9)
        # Which camera-loupe mark is which, in the line layout.loupe_areas keeps free under that loupe.
        self._legend = scene.add_label("/annot/titles/loupe_legend", LEGEND, position=self._legend_position(),
                                       anchor="top-left", font_screen_scale=0.8)
        self._handles["ba"] = scene.add_image(node_name("ba"), self._ba_texture(), 1.0, 1.0, format="png")
        self._handles["camera"] = scene.add_image(node_name("camera"), self._camera_texture(), 1.0, 1.0, format="png")
        for kind, handle in self._handles.items():
            key = slot_key(kind)
            handle.on_click(app.make_click_handler(key))
            handle.on_click(modifier="shift")(app.make_select_handler(key))
            handle.on_drag(lambda event: None)  # keeps left-drags from orbiting; a click is a click
        for kind in KINDS:
            self._place(kind)  # sends the size and place once; later only when they change
        self.refresh()
        self._build_folder(app.server.gui, add_controls)  # the display panel's loupe widgets
        self._selected_seen: int | None = None
        app.state.subscribe(self._on_state_change)  # a pair selected: both loupes go to it

    def _build_folder(self, gui: Any, add_controls: Callable[[Any], None]) -> None:
        """The "Loupes" folder: used while picking, so right below the Pairs folder, found without scrolling."""
        self.folder = gui.add_folder("Loupes", order=self.app.pairs_folder.order + 0.25)
        with self.folder:
            zoom = gui.add_button_group("Loupe zoom", ("BA +", "BA -", "Camera +", "Camera -"))
            zoom.on_click(self.app.guard(self.on_zoom))
            # Run 6: shadowed bins were black in the photo loupe.  Display only: the pairs never change with it.
            self._sl_gamma = gui.add_slider("Photo loupe brightness", 1.0, 3.0, 0.1, initial_value=self.photo_gamma,
                                            hint="Lifts the photo loupe's shadows (gamma); display only")
            self.photo_gamma_callback = self.app.guard(lambda event: self.set_photo_gamma(float(event.target.value)))
            self._sl_gamma.on_update(self.photo_gamma_callback)
            add_controls(gui)  # what the BA loupe shows, the contrast, "Hide marks"

    def set_photo_gamma(self, gamma: float) -> None:
        """Show the photo loupe with its shadows lifted by ``gamma`` (>= 1; 1: the photo as it is)."""
        with self.app.ui_lock:
            self.photo_gamma = float(min(max(gamma, 1.0), 3.0))
            self._show("camera")

    def on_zoom(self, event: Any) -> None:
        """The "Loupe zoom" buttons: magnify or widen one loupe around the same centre."""
        kind, step = {"BA +": ("ba", ZOOM_FACTOR), "BA -": ("ba", 1 / ZOOM_FACTOR),
                      "Camera +": ("camera", ZOOM_FACTOR), "Camera -": ("camera", 1 / ZOOM_FACTOR)}[str(event.value)]
        self.zoom(kind, step)

    # ------------------------------------------------------------------ public
    def frame_ba(self, key: str, row: int, col: int) -> None:
        """Centre the BA loupe on scan cell ``(row, col)`` of BA image ``key``."""
        if key not in self.app.ba_keys:
            raise CalibError(f"no BA image {key!r} (one of {', '.join(self.app.ba_keys)})")
        n_rows, n_cols = self.app.depth.shape
        if not (0 <= int(row) < n_rows and 0 <= int(col) < n_cols):
            raise CalibError(f"cell ({row}, {col}) is outside the {n_rows} x {n_cols} scan")
        with self.app.ui_lock:
            self._clicked.pop("ba", None)  # the title names the framed cell again
            crop = self._make_ba_crop(key, int(row), int(col))
            if crop != self.ba_crop:
                self.ba_crop = crop
                self._show("ba")
            self._titles["ba"].text = self.title("ba")  # sent only if it changed

    def frame_camera(self, u: float, v: float, cov_px2: np.ndarray | None = None,
                     min_side_px: float | None = None) -> None:
        """Centre the camera loupe on original-image pixel ``(u, v)``; ``cov_px2`` (2x2, px^2) draws its 3-sigma
        ellipse; ``min_side_px`` zooms out (never in) so the crop is at least that many pixels wide, else the
        zoom the buttons chose is used."""
        if not (np.isfinite(u) and np.isfinite(v)):
            raise CalibError("the camera loupe needs a finite pixel")
        cov = None
        if cov_px2 is not None:
            c = np.asarray(cov_px2, dtype=np.float64)
            if c.shape != (2, 2) or not np.isfinite(c).all():
                raise CalibError("cov_px2 must be a finite 2x2 covariance (pixels squared)")
            cov = tuple(map(tuple, c))
        with self.app.ui_lock:
            self._clicked.pop("camera", None)
            self._render_anchor = None  # the render loupe follows the camera loupe again (until anchor_render)
            follows = self._render_on()
            if follows:  # ... and its title names its new centre, not the last pair's laser end (run 12)
                self._clicked.pop("ba", None)
            side = self._cam_n_chosen if min_side_px is None else max(self._cam_n_chosen, math.ceil(min_side_px))
            self._cam_n = int(min(side, CAMERA_PX_LIMITS[1]))
            crop = crop_around(float(u), float(v), self._cam_n, cov)
            if crop != self.camera_crop:
                self.camera_crop = crop
                self._show("camera")
            self._titles["camera"].text = self.title("camera")
            if follows:
                self._titles["ba"].text = self.title("ba")

    def show_render(self, on: bool) -> None:
        """Let the laser loupe show the camera-view render's crop (the camera loupe's crop), or the BA image's."""
        with self.app.ui_lock:
            if bool(on) != self.shows_render:
                self.shows_render = bool(on)
                self._show("ba")

    def on_render(self, what: str, shown: Any) -> None:
        """A new render ``shown`` (:meth:`app.render_pane.RenderPane.subscribe`), in the laser loupe if it shows it."""
        if what == "render":
            self._render = shown
            if self.shows_render:
                with self.app.ui_lock:
                    self._show("ba")

    @property
    def has_render(self) -> bool:  # is there a render the laser loupe can show?
        return self._render is not None

    def _render_on(self) -> bool:
        """Does the laser loupe show the render now (asked for, and a render exists)?"""
        return self.shows_render and self._render is not None

    @property
    def render_crop(self) -> CameraCrop:
        """The camera pixels the laser loupe shows while it shows the render: around the camera loupe's centre, or
        held on a pair's laser end (:meth:`anchor_render`), its own side (the two loupes zoom alone: run 6)."""
        anchor = self._render_anchor
        if anchor is not None and self._render is not None:
            uv = pixel_of_cells(self._render, self.app.camera, self.app.depth, np.array([anchor[0]]))[0]
            if np.isfinite(uv).all():
                n = self.camera_crop.n if self._render_n is None else self._render_n
                return crop_around(uv[0] + anchor[1][0], uv[1] + anchor[1][1], n)
        return render_crop_of(self.camera_crop, self._render_n)

    def anchor_render(self, cell: tuple[int, int] | None) -> None:
        """Hold the render loupe on laser cell ``cell`` (``(row, col)``, a pair's laser end) as it shows it now: a
        new render (a refit of the rough pose) moves its crop with the cell, so the cell stays where it is in the
        loupe and its title names it (run 7: the loupe re-framed after a photo-loupe click).  None: let go."""
        with self.app.ui_lock:
            centre = self.render_crop.center  # as it shows now (held or not)
            self._render_anchor = None
            if cell is None or not self._render_on():
                return
            uv = pixel_of_cells(self._render, self.app.camera, self.app.depth, np.array([cell]))[0]
            if np.isfinite(uv).all():
                self._render_anchor = ((int(cell[0]), int(cell[1])), (centre[0] - uv[0], centre[1] - uv[1]))
            self._titles["ba"].text = self.title("ba")

    def zoom(self, kind: str, factor: float) -> None:
        """Magnify loupe ``kind`` by ``factor`` (> 1 shows less, bigger) around the same centre; only that one."""
        with self.app.ui_lock:
            if kind == "ba" and self._render_on():
                lo, hi = CAMERA_PX_LIMITS
                self._render_n = int(min(max(round(self.render_crop.n / factor), lo), hi))
            elif kind == "ba":
                lo, hi = BA_COLUMN_LIMITS
                self._ba_cols = int(min(max(round(self._ba_cols / factor), lo), hi, self.app.depth.shape[1]))
                c = self.ba_crop
                self.ba_crop = self._make_ba_crop(c.key, *c.center)
            else:
                lo, hi = CAMERA_PX_LIMITS
                self._cam_n = self._cam_n_chosen = int(min(max(round(self._cam_n / factor), lo), hi))
                c = self.camera_crop
                self.camera_crop = crop_around(*c.center, self._cam_n, c.cov_px2)
            self._show(kind)

    def on_pair_click(self, click: PairClick) -> None:
        """Follow a click on the images (:meth:`app.pairs_panel.PairsPanel.subscribe_clicks`)."""
        follow_click(self, self.app, click)

    def _on_state_change(self, state: Any) -> None:
        self._forget_gone_ends(state.picks)
        selected = state.selected
        if selected != self._selected_seen:
            self._selected_seen = selected
            if selected is not None:
                frame_pair(self, self.app, selected)

    def _forget_gone_ends(self, picks: Any) -> None:
        """A title naming a cell or pixel no pair has any more (an Undo took the click back: run 8) names the crop's
        centre again, and the render loupe lets go of a laser end no pair has."""
        cells, pixels = {p.laser_rc for p in picks}, {p.pixel for p in picks}
        with self.app.ui_lock:
            for kind, ends in (("ba", cells), ("camera", pixels)):
                if kind in self._clicked and self._clicked[kind] not in ends:
                    del self._clicked[kind]
                    self._titles[kind].text = self.title(kind)
            if self._render_anchor is not None and self._render_anchor[0] not in cells:
                self._render_anchor = None
                self._show("ba")

    def on_pair_cancelled(self) -> None:
        """A half-made pair was cancelled: a guided proposal's ellipse in the camera loupe goes too."""
        if self.camera_crop.cov_px2 is not None:
            self.frame_camera(*self.camera_crop.center)

    def show_click(self, kind: str, point: tuple) -> None:
        """Name a click made inside loupe ``kind`` in its title: scan cell ``(row, col)`` (BA) or original pixel
        ``(u, v)``.  The loupe keeps its view (the click was aimed in it)."""
        with self.app.ui_lock:
            self._clicked[kind] = tuple(point)
            self._titles[kind].text = self.title(kind)

    def relayout(self, moved: bool = True) -> None:
        """Place both loupes beside the images again if they ``moved`` (the page layout changed, e.g. another BA
        column window: :meth:`app.view_panel.ViewPanel.subscribe_layout`), not where the old ones ended."""
        if not moved:
            return
        app = self.app
        with app.ui_lock, app.server.atomic():
            main = list(app.slots.values())  # camera views, the camera-view render, BA images
            self.areas = loupe_areas(bounds_of(main))
            for kind in KINDS:
                area = self.areas[kind]
                self._titles[kind].position = (area.x0, area.y0 - 0.03, -0.01)
                self._legend.position = self._legend_position()
                self._place(kind)
                self._draw_marks(kind)  # their marks follow the slots

    def _legend_position(self) -> tuple[float, float, float]:
        cam = self.areas["camera"]
        return (cam.x0, cam.y0 + cam.height + 0.03, -0.01)

    @property
    def legend(self) -> str:
        """The legend line under the camera loupe."""
        return str(self._legend.text)

    def texture(self, kind: str) -> np.ndarray:
        """The loupe's current texture (what the page shows)."""
        return self._ba_texture() if kind == "ba" else self._camera_texture()

    def slot(self, kind: str) -> ImageSlot:
        """The loupe's image slot: its pixels are crop cells (BA) or original-image pixels (camera), offset by the crop."""
        return self._slots[kind]

    def target_at(self, kind: str, uv: tuple[float, float]) -> tuple:
        """What loupe pixel ``uv`` shows: ``("ba", key, row, col)`` or ``("camera", u, v)`` (original pixel).

        Raises CalibError outside the scan or the image.
        """
        x, y = float(uv[0]), float(uv[1])
        if kind == "ba" and self._render_on():
            c = self.render_crop
            if (stale := self.app.pose_source.stale_click_reason(self._render)) is not None:  # run 6: a refit
                raise CalibError(stale)  # the click was planned on the render before it
            cell = cell_at_pixel(self._render, c.u0 + x, c.v0 + y)
            if cell is None:
                raise CalibError("no laser return here: click where the camera-view render shows the scan")
            return ("ba", self.ba_crop.key, *cell)
        if kind == "ba":
            c = self.ba_crop
            n_rows, n_cols = self.app.depth.shape
            row = c.row0 + int(math.floor(y + 0.5))
            col = c.col0 + int(math.floor(x + 0.5))
            if self.app.wrap_cols:
                col %= n_cols
            if not (0 <= row < n_rows and 0 <= col < n_cols):
                raise CalibError("that part of the loupe is outside the scan")
            return ("ba", c.key, row, col)
        c = self.camera_crop
        u, v = c.u0 + x, c.v0 + y
        w, h = self.app.camera.width, self.app.camera.height
        if not (-0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5):
            raise CalibError("that part of the loupe is outside the camera image")
        return ("camera", u, v)

    def display_of(self, kind: str, target: tuple[float, float]) -> tuple[float, float] | None:
        """Loupe pixel showing ``target``: ``(col, row)`` of a scan cell (fractions aim off its centre) or an
        original-image pixel ``(u, v)``; None when the loupe does not show it."""
        if kind == "ba" and self._render_on():  # where the render's pose draws the cell
            c = self.render_crop
            uv = pixel_of_cells(self._render, self.app.camera, self.app.depth,
                                np.array([[round(target[1]), round(target[0])]]))[0]
            x, y = float(uv[0]) - c.u0, float(uv[1]) - c.v0
        elif kind == "ba":
            c = self.ba_crop
            n_cols = self.app.depth.shape[1]
            x = float(target[0]) - c.col0
            if self.app.wrap_cols:
                x = (x + 0.5) % n_cols - 0.5
            y = float(target[1]) - c.row0
        else:
            c = self.camera_crop
            x, y = float(target[0]) - c.u0, float(target[1]) - c.v0
        slot = self._slots[kind]
        return (x, y) if slot.contains((x, y)) else None

    # ------------------------------------------------------------------ drawing
    def draw_marks(self) -> None:
        """Pick ends, predictions and the ellipse inside the loupes, and the loupes' outlines on the main images."""
        self._draw_marks("ba")
        self._draw_marks("camera")

    def _draw_marks(self, kind: str) -> None:
        """One loupe's marks and outline; skipped when neither its view, the picks nor the main view changed."""
        app = self.app
        hidden = app.state.view.hide_marks  # "Hide marks": the outline on the main image; the loupe's stay (run 4)
        picks = app.state.picks
        crop = self.ba_crop if kind == "ba" else self.camera_crop
        main = app.slots.get(crop.key) if kind == "ba" else app.camera_slot()
        # Only the ends this loupe draws: moving a pixel leaves the BA loupe's marks alone, and vice versa.
        ends = tuple((p.id, p.laser_rc if kind == "ba" else (p.pixel, p.laser_rc)) for p in picks)
        inputs = (crop, self._slots[kind], ends, main, app.ba_window, hidden)
        if kind == "camera":  # the pairs' laser points are drawn projected under the current pose
            pose = app.pose()
            inputs += (None if pose is None else np.asarray(pose, np.float64).tobytes(),)
        if kind == "ba" and self._render_on():
            inputs += (self.render_crop, id(self._render))
        if self._marks_of.get(kind) == inputs:
            return
        self._marks_of[kind] = inputs
        if kind == "ba":
            self._draw_ba_marks(list(picks))
        else:  # clicks as crosses, the pairs' laser points projected as rings (app.loupe_marks)
            draw_camera_marks(app, self._slots["camera"], self.camera_crop, list(picks), app.pose())
        # The outline on the main image (and the camera loupe's centre marker) follow the crop, not the picks.
        framing = (crop, self._slots[kind], main, app.ba_window, hidden)
        if self._framing_of.get(kind) != framing:
            self._framing_of[kind] = framing
            if kind == "camera":
                draw_camera_centre(app, self._slots["camera"], self.camera_crop)
            if hidden:
                app.nodes.lines(FRAMING_NODES[kind][-1], np.empty((0, 2, 3)), (0, 0, 0))  # the outline
            elif kind == "ba":
                draw_ba_outline(app, self.ba_crop)
            else:
                draw_camera_outline(app, self.camera_crop)

    def _draw_ba_marks(self, picks: list) -> None:
        nodes = self.app.nodes
        app = self.app
        # BA loupe: the picked cells it shows, outlined in their pair colour.
        s, c = self._slots["ba"], self.ba_crop
        rc = np.array([p.laser_rc for p in picks if p.laser_rc is not None], np.float64).reshape(-1, 2)
        cols = np.array([p.color for p in picks if p.laser_rc is not None], np.uint8).reshape(-1, 3)
        xy = np.stack([rc[:, 1] - c.col0, rc[:, 0] - c.row0], axis=1)
        if app.wrap_cols and len(xy):
            xy[:, 0] = (xy[:, 0] + 0.5) % app.depth.shape[1] - 0.5
        hx, hy = 0.5 * s.units_per_px, 0.5 * s.units_per_px_y
        radius, cell = 1.6 * max(hx, hy), (hx, hy)
        if self._render_on():  # the render's crop: rings where the render's pose draws the cells
            rc_crop = self.render_crop
            xy = pixel_of_cells(self._render, app.camera, app.depth, rc) - [rc_crop.u0, rc_crop.v0]
            radius, cell = max(3.0, 0.06 * rc_crop.n) * s.units_per_px, None
        inside = np.array([s.contains(p) for p in xy], bool)
        segs = marker_segments(s.world_from_pixel(xy[inside], z_offset=-0.01), radius, cell_half_size=cell,
                               ticks=True)
        nodes.lines("/annot/loupe/ba_marks", segs, segment_colours(cols[inside], len(segs)), thickness=2.5)

    # ------------------------------------------------------------------ internals
    def _make_ba_crop(self, key: str, row: int, col: int) -> BaCrop:
        n_rows_scan, n_cols_scan = self.app.depth.shape
        n_cols = self._ba_cols
        aspect = self.app.ba_cell_aspect
        n_rows = int(min(max(round(n_cols / aspect), 1), n_rows_scan))
        return BaCrop(key, int(row) - n_rows // 2, int(col) - n_cols // 2, n_rows, n_cols, (int(row), int(col)))

    def _ba_texture(self) -> np.ndarray:
        if self._render_on():
            cc = self.render_crop
            return loupe_texture(self._render, self.app.camera, cc.u0, cc.v0, cc.n)
        gray = self.app.laser_images.loupe_image(self.ba_crop.key)[0]
        return ba_crop_texture(gray, self.ba_crop, self.app.wrap_cols, TEXTURE_TEXELS, PAD_GRAY)

    def _camera_texture(self) -> np.ndarray:
        return camera_crop_texture(self.app.image, self.camera_crop, self.photo_gamma, TEXTURE_TEXELS, PAD_GRAY)

    def _place(self, kind: str) -> None:
        """Fit the crop into the loupe's area (cells keep their drawn aspect), top-left aligned."""
        area = self.areas[kind]
        if kind == "ba" and not self._render_on():
            c = self.ba_crop
            unit_x = area.width / c.n_cols
            unit_y = unit_x * self.app.ba_cell_aspect
            if unit_y * c.n_rows > area.height:
                unit_y = area.height / c.n_rows
            w_px, h_px, rw, rh = c.n_cols, c.n_rows, area.width, unit_y * c.n_rows
        else:  # the camera loupe, or the laser loupe showing the render's crop around the same centre
            n = (self.render_crop if kind == "ba" else self.camera_crop).n
            w_px = h_px = n
            rw = rh = min(area.width, area.height)
        slot = ImageSlot(slot_key(kind), w_px, h_px, (area.x0 + rw / 2, area.y0 + rh / 2, 0.0), rw, rh)
        old = self._slots.get(kind)
        self._slots[kind] = slot
        if old is not None and (old.render_width, old.render_height, old.center) == (rw, rh, slot.center):
            return  # same place and size: only the texture changes
        handle = self._handles[kind]
        handle.render_width = rw
        handle.render_height = rh
        handle.position = slot.center

    def title(self, kind: str) -> str:
        """The loupe's title as the page shows it."""
        if kind == "ba" and self._render_on():  # the pair's cell it is held on, else the cell a click inside chose
            held = None if self._render_anchor is None else self._render_anchor[0]
            return loupe_title(self._render, self.app.depth, self.render_crop.center, held or self._clicked.get("ba"),
                               self.render_crop.n)
        if kind == "ba":
            c = self.ba_crop
            row, col = self._clicked.get("ba", c.center)
            rng = float(self.app.depth.range_m[row, col]) if self.app.depth.valid[row, col] else None
            return ba_title(self.app.laser_images.loupe_image(c.key)[1], row, col, rng)  # short: fits the loupe
        c = self.camera_crop
        return camera_title(*self._clicked.get("camera", c.center), c.n)

    def _show(self, kind: str) -> None:
        """Send the loupe's new texture, size and title, and redraw its marks (in one message batch)."""
        app = self.app
        with app.server.atomic():
            self._handles[kind].image = self._ba_texture() if kind == "ba" else self._camera_texture()
            self._place(kind)
            self._titles[kind].text = self.title(kind)
            self._draw_marks(kind)
            if kind == "camera" and self._render_on():
                self._show("ba")  # the laser loupe shows the same crop of the render

    def refresh(self) -> None:
        """Re-send both loupes (e.g. after the BA display changed)."""
        with self.app.ui_lock:
            self._show("ba")
            self._show("camera")
