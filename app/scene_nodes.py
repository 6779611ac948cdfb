"""A cache of the scene nodes the app has drawn: redraws send only what changed, mostly as in-place updates."""

from __future__ import annotations

import itertools
import threading
from typing import Any

import numpy as np

#: Hidden labels kept ready: a new pick then shows its numbers without creating scene nodes on the click path.
LABEL_POOL = 48


#: Where padding goes: behind the annotation backdrop (z = 0.5), seen by no view.
HIDDEN = (0.0, 0.0, 50.0)


class SceneNodes:
    """What the scene shows now, per node name: ``drawn[name] = (handle, data sent)``.

    Parameters
    ----------
    scene : viser.SceneApi
        The server's scene.
    """

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self.drawn: dict[str, tuple[Any, tuple]] = {}
        self._label_pool: list[Any] = []
        self._pool_ids = itertools.count()
        self._refilling = threading.Lock()

    def fill_label_pool(self, n: int = LABEL_POOL) -> None:
        """Create hidden labels until ``n`` are ready (returns at once if another thread is at it)."""
        if not self._refilling.acquire(blocking=False):
            return
        try:
            while len(self._label_pool) < n:
                self._label_pool.append(self.scene.add_label(
                    f"/annot/label_pool/{next(self._pool_ids)}", "", position=HIDDEN, anchor="bottom-left",
                    font_screen_scale=0.8, visible=False))
        finally:
            self._refilling.release()

    def label_names(self) -> list[str]:
        """Names of the labels drawn now."""
        return [n for n, (_, spec) in self.drawn.items() if spec[0] == "label"]

    def remove(self, name: str) -> None:
        entry = self.drawn.pop(name, None)
        if entry is None:
            return
        if entry[1][0] == "label":  # back to the pool, hidden
            entry[0].visible = False
            self._label_pool.append(entry[0])
        else:
            entry[0].remove()

    def points(self, name: str, points: np.ndarray, colors, size: float, shape: str = "circle") -> None:
        """Show ``points (N, 3)`` (world) as node ``name``; empty removes it.  Only changes are sent."""
        pts = np.asarray(points, np.float32).reshape(-1, 3)
        if len(pts) == 0:
            self.remove(name)
            return
        cols = np.asarray(colors, np.uint8)
        size = float(size)
        old = self.drawn.get(name)
        if old is not None and old[1][0] == "points" and old[1][4] == shape:
            handle, (_, old_pts, old_cols, old_size, _) = old
            if old_pts.shape == pts.shape and old_cols.shape == cols.shape:
                same_pts, same_cols = np.array_equal(old_pts, pts), np.array_equal(old_cols, cols)
                if old_size == size and same_pts and same_cols:
                    return
                # In place, setting only what differs (each assignment costs viser a type cast and a compare).
                if not same_pts:
                    handle.points = pts
                if not same_cols:
                    handle.colors = cols
                if old_size != size:
                    handle.point_size = size
                self.drawn[name] = (handle, ("points", pts, cols, size, shape))
                return
        handle = self.scene.add_point_cloud(
            name, pts, cols, point_size=size, point_shape=shape, precision="float32", point_shading="flat",
        )
        self.drawn[name] = (handle, ("points", pts, cols, size, shape))

    def lines(self, name: str, segments: np.ndarray, colors, thickness: float = 2.0) -> None:
        """Show line ``segments (N, 2, 3)`` (world) as node ``name``; empty removes it.  Only changes are sent."""
        segs = np.asarray(segments, np.float32).reshape(-1, 2, 3)
        if len(segs) == 0:
            old = self.drawn.get(name)
            if old is not None and old[1][0] == "lines" and len(self.segments(name)):
                # Hidden in place rather than removed: the next marker then needs no new node.
                handle, (_, old_segs, old_cols, old_thickness) = old
                hidden = np.broadcast_to(np.float32(HIDDEN), old_segs.shape).copy()
                handle.points = hidden
                self.drawn[name] = (handle, ("lines", hidden, old_cols, old_thickness))
            return
        cols = np.asarray(colors, np.uint8)
        thickness = float(thickness)
        # Padded to a power of two with empty segments hidden behind the backdrop, so that one more marker
        # updates the node in place instead of re-creating it (a new node costs ~1-3 ms in viser).
        capacity = max(8, 1 << (len(segs) - 1).bit_length())
        if capacity > len(segs):
            if cols.ndim == 1:
                cols = np.broadcast_to(cols, segs.shape)
            pad = capacity - len(segs)
            segs = np.concatenate([segs, np.broadcast_to(np.float32(HIDDEN), (pad, 2, 3))])
            cols = np.concatenate([np.asarray(cols, np.uint8).reshape(-1, 2, 3), np.zeros((pad, 2, 3), np.uint8)])
        old = self.drawn.get(name)
        if old is not None and old[1][0] == "lines" and old[1][3] == thickness:
            handle, (_, old_segs, old_cols, _) = old
            if old_segs.shape == segs.shape and old_cols.shape == cols.shape:
                same_segs, same_cols = np.array_equal(old_segs, segs), np.array_equal(old_cols, cols)
                if same_segs and same_cols:
                    return
                # Same number of segments: update in place, only what differs.
                if not same_segs:
                    handle.points = segs
                if not same_cols:
                    handle.colors = cols
                self.drawn[name] = (handle, ("lines", segs, cols, thickness))
                return
        # A new node, or a different number of segments (points and colours must change together).
        handle = self.scene.add_line_segments(name, segs, cols, thickness=thickness, thickness_units="screen")
        self.drawn[name] = (handle, ("lines", segs, cols, thickness))

    def segments(self, name: str) -> np.ndarray:
        """The line segments ``(N, 2, 3)`` node ``name`` shows (padding dropped); empty if it shows none."""
        entry = self.drawn.get(name)
        if entry is None or entry[1][0] != "lines":
            return np.empty((0, 2, 3), np.float32)
        segs = entry[1][1]
        return segs[~np.all(segs == np.float32(HIDDEN), axis=(1, 2))]

    def label(self, name: str, text: str, position: np.ndarray) -> None:
        """Show a pick-number label at ``position`` (world); an existing label is moved, not re-created."""
        pos = tuple(float(x) for x in position)
        old = self.drawn.get(name)
        if old is not None and old[1][0] == "label":
            handle, (_, old_text, old_pos) = old
            if old_text == text and old_pos == pos:
                return
            if old_text != text:
                handle.text = text
            if old_pos != pos:
                handle.position = pos
        else:
            try:
                handle = self._label_pool.pop()
            except IndexError:
                handle = None
            if handle is None:
                handle = self.scene.add_label(name, text, position=pos, anchor="bottom-left", font_screen_scale=0.8)
            else:
                handle.text = text
                handle.position = pos
                handle.visible = True
            if len(self._label_pool) < LABEL_POOL // 4:  # top up off the click path
                threading.Thread(target=self.fill_label_pool, name="ba-calib-labels", daemon=True).start()
        self.drawn[name] = (handle, ("label", text, pos))
