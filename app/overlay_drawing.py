"""Drawing on the annotation views: pick markers and labels, the selection ring, and the camera-view overlays
(reprojected pairs, residual lines, BA-edge points, predicted pixels).  Only changed scene nodes are sent
(:class:`app.scene_nodes.SceneNodes`)."""

from __future__ import annotations

import contextlib
from typing import Any, Callable, Iterator

import numpy as np

from calib_core.solve.edges import slide_along_edges

from .layout import ImageSlot
from .state import Pick
from .ui_common import (EDGE_MIN_SIZE, LABEL_EM_SCREEN_PX, MARKER_SIZE, PICK_RADII, draw_ring_markers, marker_segments,
                        ring_radius, units_per_screen_px)


class OverlayDrawing:
    """What is drawn over the annotation images of one :class:`app.server.CalibrationApp` (``app.overlays``).

    It owns what it last drew from (so a redraw only sends what changed) and
    where the pick ends are drawn (:meth:`pick_ends`, also what Shift+click and
    drags hit).  :meth:`refresh` redraws; :meth:`invalidate` forces the next
    redraw of the camera-view overlays; :meth:`subscribe` tells others (the
    loupes, which draw the same marks magnified) that the marks were redrawn.
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        self._marker_cache: dict[str, tuple[tuple, dict]] = {}  # slot key -> (inputs, number labels) last drawn
        self._overlay_inputs: tuple | None = None  # (solve, inputs) the overlays were last drawn from
        self._loupe_marks_held = 0  # > 0: refresh() leaves the loupes' marks to loupe_marks_after()
        self._labels_drawn: dict[str, tuple[str, tuple]] | None = None  # number labels as last sent
        self._camera_view_drawn: str | None = None  # the camera view whose markers are drawn
        self._marks_listeners: list[Callable[[], None]] = []
        self._loupe_display_of: Callable[[str, Any], Any] | None = None  # the loupes' projection (place_loupes_by)
        app.subscribe_solve(lambda shown: self.refresh())  # the reprojection overlays follow the solve shown

    def place_loupes_by(self, display_of: Callable[[str, Any], Any]) -> None:
        """Place the pick ends on slots ``loupe_*`` by ``display_of(kind, (x, y))`` -> loupe display pixel or None
        (:meth:`app.loupes.Loupes.display_of`; the composition root wires it once the loupes are built)."""
        self._loupe_display_of = display_of

    def subscribe(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` after each redraw of the marks (under the UI lock, in the redraw's message batch),
        or once at the end of a :meth:`loupe_marks_after` block."""
        self._marks_listeners.append(listener)

    def _marks_drawn(self) -> None:
        for listener in list(self._marks_listeners):
            listener()

    def invalidate(self) -> None:
        """Redraw the camera-view overlays on the next :meth:`refresh` even if their inputs look unchanged."""
        self._overlay_inputs = None
        self._labels_drawn = None
        self._camera_view_drawn = None

    def refresh(self) -> None:
        """Redraw markers, labels, selection and the reprojection overlays (only what changed is sent)."""
        app = self.app
        with app.ui_lock, app.server.atomic():
            hidden = app.state.view.hide_marks  # "Hide marks": draw as if there were no picks and no solve
            picks = {} if hidden else {p.id: p for p in app.state.picks}
            selected = None if hidden else app.state.selected
            labels: dict[str, tuple[str, tuple]] = {}
            cam_slot = app.camera_slot()
            for key in (*app.ba_keys, cam_slot.key):
                labels.update(self._draw_markers(key, picks, selected))
            predictions = self.predictions(picks)
            for pid, uv in predictions:
                w = cam_slot.world_from_pixel(uv[None], z_offset=-0.015)[0] + np.array([0.06, -0.06, 0.0])
                labels[f"/annot/labels/predicted/{pid}"] = (f"{pid}?", tuple(float(x) for x in w))
            if self._camera_view_drawn != cam_slot.key:  # the camera view changed: hide the other one's markers
                for other in ("raw", "panorama"):
                    if other in app.slots and other != cam_slot.key:
                        self._marker_cache.pop(other, None)
                        draw_ring_markers(app.nodes, other, np.empty((0, 3)), np.empty((0, 3)), 1.0, [])
                self._camera_view_drawn = cam_slot.key
            drawn = self._labels_drawn
            if labels != drawn:  # usually one slot's labels moved, or none: only those are touched
                for name in [n for n in app.nodes.label_names() if n not in labels]:
                    app.nodes.remove(name)
                for name, (text, pos) in labels.items():
                    if drawn is None or drawn.get(name) != (text, pos):
                        app.nodes.label(name, text, pos)
                self._labels_drawn = labels
            self._draw_overlays(picks, predictions)
            if not self._loupe_marks_held:
                self._marks_drawn()

    @contextlib.contextmanager
    def loupe_marks_after(self) -> Iterator[None]:
        """Within the block, :meth:`refresh` leaves the loupes' marks alone; they are drawn once at its end.

        For a click, which changes the pairs and then re-frames the loupes:
        their marks are drawn for the new view only, not also for the old one.
        """
        app = self.app
        with app.ui_lock:
            self._loupe_marks_held += 1
        try:
            yield
        finally:
            with app.ui_lock, app.server.atomic():
                self._loupe_marks_held -= 1
                if not self._loupe_marks_held:
                    self._marks_drawn()  # nothing is sent for a loupe whose marks are up to date

    def pick_ends(self, key: str) -> tuple[list[int], np.ndarray]:
        """Ids and display pixels of the pick ends drawn on slot ``key`` (a BA key, camera view or ``loupe_*``)."""
        app = self.app
        picks = app.state.picks
        if key.startswith("loupe_"):
            kind = key[len("loupe_"):]
            sel = [p for p in picks if (p.laser_rc if kind == "ba" else p.pixel) is not None]
            shown = [self._loupe_display_of(kind, (p.laser_rc[1], p.laser_rc[0]) if kind == "ba" else p.pixel)
                     for p in sel]
            keep = [(p.id, xy) for p, xy in zip(sel, shown) if xy is not None]
            return [i for i, _ in keep], np.array([xy for _, xy in keep], np.float64).reshape(-1, 2)
        if key in app.ba_keys:
            # Only cells inside the shown column window have a place on the BA image.
            sel = [p for p in picks if p.laser_rc is not None]
            rc = np.array([p.laser_rc for p in sel], dtype=np.int64).reshape(-1, 2)
            u, shown = app.ba_window.display_cols(rc[:, 1])
            uv = np.stack([u, rc[:, 0].astype(np.float64)], axis=1)[shown]
            return [p.id for p, ok in zip(sel, shown) if ok], uv
        sel = [p for p in picks if p.pixel is not None]
        uv, ok = app.display_from_pixels(np.array([p.pixel for p in sel], dtype=np.float64).reshape(-1, 2))
        return [p.id for p, good in zip(sel, ok) if good], uv[ok]

    def _draw_markers(self, key: str, picks: dict[int, Pick], selected: int | None) -> dict[str, tuple[str, tuple]]:
        """Draw the pick markers of slot ``key``; returns its number labels.  Skipped when nothing on it changed."""
        app = self.app
        slot = app.slots[key]
        # What the drawing depends on, known before mapping any end: the ends of this slot's kind, the slot,
        # and the BA column window (BA) or the camera view (its slot key).
        is_ba = key in app.ba_keys
        ends = tuple((p.id, p.laser_rc if is_ba else p.pixel) for p in picks.values())
        inputs = (slot, app.ba_window if is_ba else None, ends, selected)
        cached = self._marker_cache.get(key)
        if cached is not None and cached[0] == inputs:
            return cached[1]
        ids, uv = self.pick_ends(key) if picks else ([], np.empty((0, 2)))
        world = slot.world_from_pixel(uv, z_offset=-0.01)
        colors = np.array([picks[i].color for i in ids], np.uint8).reshape(-1, 3)
        r = ring_radius(slot.units_per_px, slot.units_per_px_y)
        # Hollow rings with ticks pointing at the clicked spot, and on BA images the
        # outline of the picked cell: they mark the spot without hiding it.
        outline = (0.5 * slot.units_per_px, 0.5 * slot.units_per_px_y) if key in app.ba_keys else None
        draw_ring_markers(app.nodes, key, world, colors, r, [k for k, i in enumerate(ids) if i == selected], outline)
        offset = np.array([0.75 * r, -0.75 * r, -0.005])
        labels = {f"/annot/labels/{key}/{i}": (str(i), tuple(float(x) for x in w + offset)) for i, w in zip(ids, world)}
        self._marker_cache[key] = (inputs, labels)
        return labels

    def nearest_pick(self, key: str, uv: tuple[float, float], slot: ImageSlot, client: Any = None) -> int | None:
        """The pair whose end marker on slot ``key`` (placed at ``slot``) is nearest display pixel ``uv``, if within
        :data:`app.ui_common.PICK_RADII` ring radii; else the pair whose number label, as tab ``client`` draws it
        (its camera gives the label's size), holds ``uv`` (run 7: a Shift+click on the "2" label found no pair);
        else None."""
        ids, ends = self.pick_ends(key)
        if not ids:
            return None
        delta = ends - np.asarray(uv, dtype=np.float64)
        d = np.hypot(delta[:, 0] * slot.units_per_px, delta[:, 1] * slot.units_per_px_y)  # world units
        k = int(np.argmin(d))
        if d[k] <= PICK_RADII * ring_radius(slot.units_per_px, slot.units_per_px_y):
            return ids[k]
        return self._label_under(key, uv, slot, client)

    def _label_under(self, key: str, uv: tuple[float, float], slot: ImageSlot, client: Any) -> int | None:
        """The pair whose number label drawn on slot ``key`` covers display pixel ``uv`` in tab ``client``.

        The labels keep a constant size on screen (:data:`app.ui_common.LABEL_EM_SCREEN_PX` per em); their box
        starts at the label's anchor and goes right and up the screen (world -y: the annotation camera's up)."""
        units = units_per_screen_px(getattr(client, "camera", None))
        cached = self._marker_cache.get(key)
        if units is None or cached is None or not cached[1]:
            return None
        names = list(cached[1])
        text_len = np.array([len(cached[1][n][0]) for n in names], np.float64)
        anchors = np.array([cached[1][n][1][:2] for n in names], np.float64)
        em = LABEL_EM_SCREEN_PX * units  # world units
        margin = 2.0 * units  # a click on the label's edge counts
        width = (0.65 * text_len + 0.4) * em
        height = 1.6 * em
        x, y = slot.world_from_pixel(np.asarray(uv, np.float64).reshape(1, 2))[0, :2]
        inside = ((x >= anchors[:, 0] - margin) & (x <= anchors[:, 0] + width + margin)
                  & (y <= anchors[:, 1] + margin) & (y >= anchors[:, 1] - height - margin))
        if not inside.any():
            return None
        hit = np.flatnonzero(inside)
        best = hit[int(np.argmin(np.hypot(*(anchors[hit] - [x, y]).T)))]
        return int(names[best].rsplit("/", 1)[1])

    def _draw_overlays(self, picks: dict[int, Pick], predictions: list[tuple[int, np.ndarray]]) -> None:
        """Reprojected pairs, residual lines, BA-edge points and predicted-pixel crosses on the camera view."""
        app = self.app
        slot = app.camera_slot()
        bundle = None if app.state.view.hide_marks else app.solve_bundle
        camera, cview = app.camera, app.camera_view
        # Skipped when neither the solve, the view nor the picks it colours changed (e.g. a click on a BA image).
        self._draw_predictions(slot, predictions)  # cheap, changes with every BA click
        view = app.state.view
        inputs = (slot, cview.key, view.show_reprojection, view.show_edges, view.edge_opacity,
                  () if bundle is None else tuple(picks[i].color if i in picks else None for i in bundle.pick_ids))
        if self._overlay_inputs is not None and self._overlay_inputs[0] is bundle and self._overlay_inputs[1] == inputs:
            return
        self._overlay_inputs = (bundle, inputs)
        reproj_pts, reproj_cols = np.empty((0, 3)), np.empty((0, 3), np.uint8)
        segs = np.empty((0, 2, 3))
        edge_world, edge_cols = np.empty((0, 3)), np.empty((0, 3), np.uint8)
        if bundle is not None:
            if view.show_reprojection and len(bundle.pick_ids):
                pixels = bundle.pixels
                edges = np.array([np.nan if picks.get(pid) is None or picks[pid].edge_deg is None
                                  else picks[pid].edge_deg for pid in bundle.pick_ids], np.float64)
                if np.isfinite(edges).any():  # an edge pair's residual runs across its edge, not along it
                    raw_proj, _ = camera.project(bundle.points_camera)
                    pixels = slide_along_edges(np.asarray(raw_proj, np.float64), pixels, edges)
                clicked, ok_c = app.display_from_pixels(pixels)
                proj, ok_p = cview.display_from_camera_points(bundle.points_camera)
                colors = np.array([picks[pid].color if pid in picks else (255, 255, 0) for pid in bundle.pick_ids],
                                  np.uint8).reshape(-1, 3)
                reproj_pts = slot.world_from_pixel(proj[ok_p], z_offset=-0.012)
                reproj_cols = colors[ok_p]
                both = ok_p & ok_c
                segs = np.stack([slot.world_from_pixel(clicked[both], z_offset=-0.008),
                                 slot.world_from_pixel(proj[both], z_offset=-0.008)], axis=1)
            if view.show_edges and view.edge_opacity > 0 and len(bundle.edges_camera):
                uv, ok = cview.display_from_camera_points(bundle.edges_camera)
                # Only where the camera sees (inside a fisheye circle); blended with the image under each point.
                raw, ok_raw = camera.project(bundle.edges_camera)
                ij = np.clip(np.nan_to_num(np.round(raw), nan=0.0, posinf=0.0, neginf=0.0), 0,
                             [camera.width - 1, camera.height - 1]).astype(np.int64)
                ok &= ok_raw & app.scene_data.image_valid[ij[:, 1], ij[:, 0]]
                edge_world = slot.world_from_pixel(uv[ok], z_offset=-0.004)
                under = app.image[ij[ok, 1], ij[ok, 0]].astype(np.float64)
                a = view.edge_opacity
                edge_cols = np.round(a * np.array([0.0, 190.0, 255.0]) + (1.0 - a) * under).astype(np.uint8)
        app.nodes.points("/annot/overlay/reprojected", reproj_pts, reproj_cols, MARKER_SIZE * 0.55, shape="diamond")
        app.nodes.lines("/annot/overlay/residuals", segs, np.full(segs.shape, (255, 230, 0), np.uint8), thickness=2.0)
        app.nodes.points("/annot/overlay/edges", edge_world, edge_cols, edge_dot_size(slot.units_per_px),
                         shape="circle")

    def _draw_predictions(self, slot: ImageSlot, predictions: list[tuple[int, np.ndarray]]) -> None:
        """Predicted pixels of pending laser picks on the camera view."""
        pred_segs, pred_cols = [], []
        # Where the pose (solve or imported) predicts pending laser picks: a hollow ring with a gapped cross,
        # white on a black halo, so it stands out on any background and leaves the corner itself visible.
        for pid, uv in predictions:
            c = slot.world_from_pixel(uv[None], z_offset=-0.015)[0]
            r = MARKER_SIZE * 1.2
            ring = marker_segments(c[None], r, ticks=False)
            pred_segs.extend(ring)
            for d in (np.array([1.0, 0, 0]), np.array([0, 1.0, 0])):
                pred_segs.append(np.stack([c - 1.8 * r * d, c - 0.45 * r * d]))
                pred_segs.append(np.stack([c + 0.45 * r * d, c + 1.8 * r * d]))
            pred_cols += [(255, 255, 255)] * (len(ring) + 4)
        pred = np.array(pred_segs).reshape(-1, 2, 3)
        self.app.nodes.lines("/annot/overlay/predicted_halo", pred + [0.0, 0.0, 0.001], np.zeros(pred.shape, np.uint8),
                         thickness=5.0)
        self.app.nodes.lines("/annot/overlay/predicted", pred,
                         np.repeat(np.array(pred_cols, np.uint8).reshape(-1, 1, 3), 2, axis=1), thickness=2.0)

    def predictions(self, picks: dict[int, Pick]) -> list[tuple[int, np.ndarray]]:
        """Display pixels where the last good calibration expects picks that have only a BA end."""
        ids, pixels = self.app.pose_source.predicted_pixels(picks)
        uv, ok = self.app.display_from_pixels(pixels)
        return [(pid, uv[k]) for k, pid in enumerate(ids) if ok[k]]


#: The widest a BA-edge dot is drawn, in photo pixels: in by-eye run 4 the dots (then squares of up to 2.9 pixels of a
#: 1920 px photo) covered small corners once 4 pairs were solved.
EDGE_MAX_PX = 2.0


def edge_dot_size(units_per_px: float) -> float:
    """The world size of one BA-edge dot on a photo of ``units_per_px`` world units per pixel: 1.6 pixels, at least
    :data:`EDGE_MIN_SIZE` world units (one pixel of a 1920 px photo is too small to see in the full view) but at
    most :data:`EDGE_MAX_PX` pixels."""
    return max(units_per_px * 1.6, min(EDGE_MIN_SIZE, units_per_px * EDGE_MAX_PX))
