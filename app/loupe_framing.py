"""Where the loupes look after a click on the images (what :class:`app.loupes.Loupes` does on a
:class:`PairClick`, the event the pairs panel publishes after each click).

The clicked loupe goes to the click, the other to the pair's other end or its prediction under the app's pose
(:class:`app.pose_source.PoseSource`); a refining click inside a loupe keeps both still unless the other end would
leave the other loupe's middle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .layout import RENDER_KEY

#: After a refining click in one loupe the other keeps its view while the pair's other end lies at least this
#: share of its side from its edges.
STEADY_MARGIN = 0.15


@dataclass(frozen=True)
class PairClick:
    """A click on an image slot, as the pairs panel applied it."""

    key: str  # the slot clicked: a BA key, a camera view, the render (app.layout.RENDER_KEY) or loupe_*
    target: tuple  # ("ba", key, row, col) (scan cell) or ("camera", u, v) (original camera pixel)
    pick_id: int | None  # the pair whose end the click made or moved; None: the state refused it
    refines_loupes: bool = False  # a click inside a loupe on the pair the loupes show: they keep their crops
    render_uv: tuple[float, float] | None = None  # the camera pixel (original) of a click on the render
    client_id: int | None = None  # the tab that clicked (None: not from a tab)

    @property
    def on_full_image(self) -> bool:
        """The click was on a full image, not inside a loupe."""
        return not self.key.startswith("loupe_")


def follow_click(loupes: Any, app: Any, click: PairClick) -> None:
    """Frame ``loupes`` (:class:`app.loupes.Loupes`) after ``click``; ``app`` gives the picks and predictions."""
    kind = click.target[0]
    if click.pick_id is None:  # refused: still bring the BA loupe there, to pick a good cell nearby
        if kind == "ba" and click.on_full_image:
            loupes.frame_ba(*click.target[1:])
        return
    if kind == "ba":
        # The laser loupe shows the render's crop after a click on the render (or in that loupe), else the BA's.
        loupes.show_render(click.key == RENDER_KEY or (click.key == "loupe_ba" and loupes.shows_render))
        loupes.prefers_ba = not loupes.shows_render  # a click on a BA image: its loupe stays the BA image's
    elif click.on_full_image and loupes.has_render and not loupes.prefers_ba and not _has_laser(app, click.pick_id):
        # A photo end waiting for its laser end: the laser loupe shows the render at the same place, so that one
        # click in it makes the laser end (no rough click on the render first: run 8 took 4 clicks a pair).
        loupes.show_render(True)
    if click.refines_loupes:
        # The loupes keep their crops (the next click may be planned from this look); the clicked loupe's title
        # names the new cell or pixel.  The other loupe moves only if the pair's other end (or its prediction)
        # would leave its middle.
        loupes.show_click(kind, click.target[2:] if kind == "ba" else click.target[1:])
        _keep_other_end_shown(loupes, app, kind, click.pick_id)
    else:
        _frame(loupes, app, click.target, click.pick_id, click.on_full_image, click.render_uv)
    _hold_render_loupe(loupes, app, click.pick_id)


def _has_laser(app: Any, pick_id: int) -> bool:
    return any(p.id == pick_id and p.has_laser for p in app.state.picks)


def _pick(app: Any, pick_id: int | None) -> Any:
    return next((p for p in app.state.picks if p.id == pick_id), None)


def _end(app: Any, pick: Any, kind: str) -> tuple | None:
    """Pair ``pick``'s laser cell ``(row, col)`` (``kind`` "ba") or camera pixel ``(u, v)`` ("camera"); an end not
    clicked yet: its prediction under the app's pose from the other end (None: neither)."""
    poses = app.pose_source
    if kind == "ba":
        return pick.laser_rc if pick.laser_rc is not None else (
            None if pick.pixel is None else poses.predict_cell(*pick.pixel))
    return pick.pixel if pick.pixel is not None else (
        None if pick.laser_rc is None else poses.predict_pixel(*pick.laser_rc))


def _hold_render_loupe(loupes: Any, app: Any, pick_id: int | None) -> None:
    """While the laser loupe shows the render, hold it on pair ``pick_id``'s laser end as it shows it now (a refit
    of the rough pose then leaves that end where it is in the loupe: run 7)."""
    pick = _pick(app, pick_id)
    if loupes.shows_render:
        loupes.anchor_render(None if pick is None else pick.laser_rc)


def _keep_other_end_shown(loupes: Any, app: Any, clicked: str, pick_id: int) -> None:
    """After a refining click in loupe ``clicked``: frame the other loupe on pick ``pick_id``'s other end (or
    its prediction) only if that is not inside the middle of what it shows (a margin of
    :data:`STEADY_MARGIN` of its side)."""
    pick = _pick(app, pick_id)
    if pick is None or (clicked == "camera" and loupes.shows_render):
        return  # the laser loupe shows the camera loupe's crop of the render: both stay
    if clicked == "ba":
        uv = _end(app, pick, "camera")
        if uv is not None and not _well_inside(loupes, "camera", (uv[0], uv[1])):
            loupes.frame_camera(*uv)
        return
    cell = _end(app, pick, "ba")
    if cell is not None and not _well_inside(loupes, "ba", (cell[1], cell[0])):
        loupes.frame_ba(loupes.ba_crop.key, *cell)


def _well_inside(loupes: Any, kind: str, target: tuple[float, float]) -> bool:
    """Does loupe ``kind`` show ``target`` (``(col, row)`` of a cell or an original pixel) away from its edges?"""
    shown = loupes.display_of(kind, target)
    if shown is None:
        return False
    slot = loupes.slot(kind)
    mx, my = STEADY_MARGIN * slot.width_px, STEADY_MARGIN * slot.height_px
    return (mx - 0.5 <= shown[0] <= slot.width_px - 0.5 - mx
            and my - 0.5 <= shown[1] <= slot.height_px - 0.5 - my)


def _frame(loupes: Any, app: Any, target: tuple, pick_id: int, recentre: bool,
           render_uv: tuple[float, float] | None = None) -> None:
    """After a click: the clicked loupe on the click, the other loupe on the pair's other end or its prediction
    (a click on the render: the camera loupe on the clicked pixel, the laser loupe showing the same crop)."""
    pick = _pick(app, pick_id)
    if target[0] == "ba":
        if recentre:
            loupes.frame_ba(*target[1:])
        else:  # a click inside the loupe: it keeps its view, its title names the new cell
            loupes.show_click("ba", target[2:])
        if pick is not None and pick.pixel is not None:
            loupes.frame_camera(*pick.pixel)
        elif render_uv is not None:
            loupes.frame_camera(*render_uv)
        else:
            predicted = app.pose_source.predict_pixel(target[2], target[3])
            if predicted is not None:
                loupes.frame_camera(*predicted)
    else:
        if recentre:
            loupes.frame_camera(target[1], target[2])
        else:
            loupes.show_click("camera", target[1:])
        if pick is not None and pick.laser_rc is not None:
            loupes.frame_ba(loupes.ba_crop.key, *pick.laser_rc)
        else:
            cell = app.pose_source.predict_cell(target[1], target[2])
            if cell is not None:
                loupes.frame_ba(loupes.ba_crop.key, *cell)


def frame_pair(loupes: Any, app: Any, pick_id: int) -> None:
    """Frame both ``loupes`` on pair ``pick_id``'s two ends (an end not clicked yet: its prediction under the
    app's pose), e.g. when it is selected (run 6: selecting a pair left the loupes where they were)."""
    pick = _pick(app, pick_id)
    if pick is None:
        return
    cell, uv = _end(app, pick, "ba"), _end(app, pick, "camera")
    if cell is not None:
        loupes.frame_ba(loupes.ba_crop.key, *cell)
    if uv is not None:
        loupes.frame_camera(float(uv[0]), float(uv[1]))
    _hold_render_loupe(loupes, app, pick_id)
