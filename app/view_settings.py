"""The app's view settings: one frozen, typed record, saved in the session file.

:class:`ViewSettings` is the one place the view settings live: the
:class:`app.state.AnnotationState` holds the current one (``state.view``) and
changes it with ``state.set_view(**changes)``; the panels read it from there.
Session files store it as a plain mapping (:meth:`ViewSettings.to_dict`);
:meth:`ViewSettings.from_dict` reads it back, and a missing, unknown or bad
value there falls back to the default, so files of older versions still load.

Which choices exist for a given scene (a panorama, the loupe's image sources,
the scan's width) is not known here: the app checks those where it uses them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any, Mapping

import numpy as np

from calib_core.errors import CalibError

#: What the BA images show: every column, the columns the camera sees, or the sliders' window.
BA_WINDOW_MODES = {"all": "All columns", "camera": "Facing the camera", "custom": "Custom"}
#: The 3-D pane's up direction, in the lidar frame (None: the solved camera's up).
UP_AXES = {"+z": (0.0, 0.0, 1.0), "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0), "camera up (-y of camera)": None}
#: The BA loupe shows the direction that was clicked (other choices are scene-specific names).
AS_CLICKED = "BA as clicked"
CONTRAST_RANGE = (0.5, 3.0)
EDGE_OPACITY_RANGE = (0.0, 1.0)
#: How the camera-view laser render is shaded (key: what the session saves; value: what the page shows).
RENDER_MODES = {"range": "Range", "intensity": "Intensity", "ba": "Bearing angle"}
RENDER_BLEND_RANGE = (0.0, 1.0)


@dataclass(frozen=True)
class ViewSettings:
    """How the page shows the scene (no pairs: changing these is not an undoable step)."""

    panorama: bool = True  # show the camera image unwrapped (when the camera model has a panorama)
    show_reprojection: bool = True  # draw the reprojected pairs with their residuals
    show_edges: bool = False  # the reprojected BA-edge points; runs 7 and 8: they cluttered the zoomed photo
    snap: bool = False  # snap clicks to the nearest corner
    # The photo clicks made now are on a straight edge (a lane line crossed by a ring, a pole's side): the
    # pair's photo end may slide along that edge (calib_core.pairs.Pair.edge_deg).
    edge_pairs: bool = False
    up_axis: str = "+z"  # key of UP_AXES: the 3-D pane's up direction
    ba_window_mode: str = "all"  # key of BA_WINDOW_MODES
    # The custom column window (scan columns; width 0: every column), clipped to the scan by ColumnWindow.make.
    ba_window_start: int = 0
    ba_window_width: int = 0
    contrast: float = 1.0  # of the laser panes, in CONTRAST_RANGE
    loupe_shows: str = AS_CLICKED  # what the BA loupe shows: AS_CLICKED or a name of the scene's laser images
    # What the last (bottom) laser pane shows instead of its BA direction: a name of the scene's laser images
    # ("Intensity", "Range"), or "" for its BA direction.
    last_pane_shows: str = ""
    edge_opacity: float = 0.8  # of the BA-edge overlay, in EDGE_OPACITY_RANGE (0 hides it)
    # Hide every mark drawn over the images and in the loupes (pair markers, their numbers, the selection,
    # predictions, reprojection overlays, the loupes' outlines), to see what lies under them.
    hide_marks: bool = False
    render_mode: str = "range"  # key of RENDER_MODES: how the scan seen from the camera is shaded
    render_blend: float = 0.0  # opacity of that render over the camera image, in RENDER_BLEND_RANGE (0 hides it)
    # The rough pose set in the Align folder or imported (predictions use it until a solve exists):
    # T_camera_lidar (maps lidar points into the camera frame, metres) as 16 numbers, row by row; empty: none set.
    rough_T_camera_lidar: tuple = ()

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _checked(f.name, getattr(self, f.name)))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None, default: "ViewSettings | None" = None) -> "ViewSettings":
        """Settings from a session file's ``view`` mapping; missing, unknown or bad values take ``default``'s."""
        base = cls() if default is None else default
        good = {}
        for name, value in dict(data or {}).items():
            if name in _FIELDS:
                try:
                    good[name] = _checked(name, value)
                except CalibError:
                    pass
        return replace(base, **good)

    def to_dict(self) -> dict[str, Any]:
        """Every setting as plain YAML-able data (what the session file holds)."""
        return {f.name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v for f in fields(self)}

    def changed(self, **changes: Any) -> "ViewSettings":
        """A copy with ``changes``; CalibError names an unknown setting or a bad value."""
        unknown = sorted(set(changes) - set(_FIELDS))
        if unknown:
            raise CalibError(f"unknown view setting {unknown[0]!r}; known: {', '.join(_FIELDS)}")
        return replace(self, **changes)


def _checked(name: str, value: Any) -> Any:
    """``value`` as setting ``name`` holds it (numbers clipped to their range), or CalibError."""
    kind = _FIELDS[name]
    if kind is bool:
        if isinstance(value, bool):
            return value
    elif kind is str:
        if isinstance(value, str) and (name not in _CHOICES or value in _CHOICES[name]):
            return value
    elif kind is tuple:
        pose = _checked_pose(value)
        if pose is not None:
            return pose
    elif kind is int:
        if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
            return int(value)
    elif isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
        lo, hi = _RANGES[name]
        return float(min(max(float(value), lo), hi))
    raise CalibError(f"view setting {name!r} cannot be {value!r}")


def _checked_pose(value: Any) -> tuple | None:
    """16 finite numbers of a rigid transform (rotation orthonormal to 1e-6, last row 0 0 0 1) as a tuple of
    floats, or the empty tuple; None when ``value`` is neither."""
    if not isinstance(value, (list, tuple)):
        return None
    if len(value) == 0:
        return ()
    if len(value) != 16 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        return None
    T = np.asarray(value, dtype=np.float64).reshape(4, 4)
    if not np.isfinite(T).all() or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
        return None
    if not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6) or np.linalg.det(T[:3, :3]) < 0:
        return None
    return tuple(float(x) for x in T.reshape(-1))


#: Each setting's type, the type of its default.
_FIELDS = {f.name: type(f.default) for f in fields(ViewSettings)}
_CHOICES = {"up_axis": tuple(UP_AXES), "ba_window_mode": tuple(BA_WINDOW_MODES), "render_mode": tuple(RENDER_MODES)}
_RANGES = {"contrast": CONTRAST_RANGE, "edge_opacity": EDGE_OPACITY_RANGE, "render_blend": RENDER_BLEND_RANGE}
