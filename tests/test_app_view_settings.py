"""ViewSettings: the one typed record of the view settings, saved in the session file (issue 11, structure)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
import yaml

from app.state import AnnotationState
from app_driver import AppDriver
from app.view_settings import AS_CLICKED, ViewSettings
from calib_core.errors import CalibError
from browser_helpers import free_port
from repo_paths import SAMPLE

IMG = (640, 480)


def make_state(path, **kwargs) -> AnnotationState:
    valid = np.ones((16, 32), dtype=bool)
    return AnnotationState(valid, IMG, session_path=path, **kwargs)


# Every field set away from its default (checked below), so a round trip that drops one is caught.
CHANGED = dict(panorama=False, show_reprojection=False, show_edges=True, snap=True, up_axis="-y",
               ba_window_mode="custom", ba_window_start=12, ba_window_width=40, contrast=2.25,
               loupe_shows="Range", last_pane_shows="Intensity", edge_opacity=0.3, hide_marks=True,
               render_mode="ba", render_blend=0.4, edge_pairs=True,
               rough_T_camera_lidar=(0.0, -1.0, 0.0, 0.1, 0.0, 0.0, -1.0, 0.2, 1.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0))


def test_changed_covers_every_field_with_a_non_default_value():
    default = ViewSettings()
    assert set(CHANGED) == {f.name for f in fields(ViewSettings)}
    assert all(getattr(default, k) != v for k, v in CHANGED.items())


def test_bad_or_unknown_values_fall_back_to_the_default():
    default = ViewSettings(up_axis="+y")
    data = {"panorama": "yes", "show_edges": 1, "snap": None, "up_axis": "sideways", "ba_window_mode": "some",
            "ba_window_start": -3, "ba_window_width": 2.5, "contrast": "high", "loupe_shows": 7, "last_pane_shows": 3,
            "edge_opacity": float("nan"), "an_old_setting": True}
    assert ViewSettings.from_dict(data, default=default) == default
    assert ViewSettings.from_dict(None) == ViewSettings()
    # Numbers out of range are clipped to it (the slider's ends), good values kept beside bad ones.
    got = ViewSettings.from_dict({"contrast": 9.0, "edge_opacity": -1, "snap": True, "up_axis": "nope"}, default)
    assert (got.contrast, got.edge_opacity, got.snap, got.up_axis) == (3.0, 0.0, True, "+y")


def test_the_record_is_frozen_and_checked_when_changed():
    view = ViewSettings()
    with pytest.raises(AttributeError):
        view.snap = True  # type: ignore[misc]
    with pytest.raises(CalibError, match="unknown view setting 'panoramma'"):
        view.changed(panoramma=False)
    with pytest.raises(CalibError, match="'up_axis' cannot be 'sideways'"):
        view.changed(up_axis="sideways")
    with pytest.raises(CalibError, match="'snap' cannot be 'yes'"):
        ViewSettings(snap="yes")  # type: ignore[arg-type]
    assert view.changed(contrast=0.1).contrast == 0.5
    assert view == ViewSettings()  # changed() returns a copy


def test_a_session_round_trip_keeps_every_field_and_view_changes_are_not_undo_steps(tmp_path):
    path = tmp_path / "session.yaml"
    s = make_state(path)
    s.add_laser(3, 4)
    s.add_pixel(10.0, 20.0)
    undo_before = s.can_undo, s.can_redo
    assert s.undo() is True and s.can_redo  # one pick end undone: the redo must survive a view change
    v = s.version
    new = s.set_view(**CHANGED)
    assert new == ViewSettings(**CHANGED) and s.view is new and s.version == v + 1
    assert s.can_redo and undo_before == (True, False)  # the view change did not clear the redo history
    assert s.set_view(**CHANGED) == new and s.version == v + 1  # no change: no new version, nothing saved
    with pytest.raises(CalibError, match="unknown view setting"):
        s.set_view(zoom=3)
    assert s.view == ViewSettings(**CHANGED)
    s.redo()
    assert s.view == ViewSettings(**CHANGED)  # undo/redo move pairs only
    s.close()
    on_disk = yaml.safe_load(path.read_text())["view"]
    assert on_disk == {k: list(v) if isinstance(v, tuple) else v for k, v in CHANGED.items()}  # YAML lists
    t = make_state(path)
    assert t.view == ViewSettings(**CHANGED)
    assert [(p.laser_rc, p.pixel) for p in t.picks] == [((3, 4), (10.0, 20.0))]
    t.close()


def test_an_old_session_without_the_new_keys_loads_with_defaults(tmp_path):
    # A session file as an older ba-calib wrote it: only the settings that existed then, one of them obsolete.
    path = tmp_path / "old.yaml"
    path.write_text(
        "format: ba-calib-session\nversion: 1\nnext_id: 3\n"
        "pairs:\n- {id: 2, laser_rc: [5, 6], laser_xyz: null, pixel: [100.0, 50.0]}\n"
        "view: {panorama: false, show_reprojection: true, show_edges: false, snap: true,\n"
        "       ba_window_mode: custom, ba_window_start: 4, ba_window_width: 20, zoom_mode: all}\n"
    )
    s = make_state(path, default_view=ViewSettings(up_axis="+y"))
    assert s.view == ViewSettings(panorama=False, show_edges=False, snap=True, up_axis="+y",
                                  ba_window_mode="custom", ba_window_start=4, ba_window_width=20)
    assert (s.view.contrast, s.view.loupe_shows, s.view.edge_opacity) == (1.0, AS_CLICKED, 0.8)
    assert [p.id for p in s.picks] == [2]
    s.set_view(snap=False)
    s.close()
    # The next save writes every setting, without the obsolete key.
    assert set(yaml.safe_load(path.read_text())["view"]) == {f.name for f in fields(ViewSettings)}


def test_the_app_shows_the_saved_settings_and_ignores_bad_ones(tmp_path):
    from app.server import CalibrationApp

    session = tmp_path / "session.yaml"
    session.write_text(
        "format: ba-calib-session\nversion: 1\nnext_id: 1\npairs: []\n"
        "view: {panorama: false, ba_window_mode: custom, ba_window_start: 30, ba_window_width: 64,\n"
        "       contrast: 2.0, loupe_shows: 'no such image', edge_opacity: wrong, up_axis: 42}\n"
    )
    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=session, port=free_port())
    try:
        driver = AppDriver(app)
        w = app.ba_window
        assert (w.start, w.width) == (30, 64) and driver.ba_columns_choice == "Custom"
        assert driver.camera_key == "raw"  # the sample camera has a panorama; the session turned it off
        assert app.state.view.contrast == 2.0 and app.display.edge_opacity == 0.8
        # A bad saved up axis takes the scene's default: +y for the sample's rotating 2-D scanner.
        assert app.depth.meta.get("model") == "rotating_2d" and app.state.view.up_axis == "+y"
        assert app.laser_images.loupe_source == AS_CLICKED  # a saved choice this scene lacks shows the clicked BA image
        assert driver.choose_loupe_source("Range") == []
        assert app.state.view.loupe_shows == "Range" and app.laser_images.loupe_source == "Range"
        assert driver.set_ba_columns(100, 80) == []
        assert (app.state.view.ba_window_start, app.state.view.ba_window_width) == (100, 80)
        assert (app.ba_window.start, app.ba_window.width) == (100, 80)
    finally:
        app.stop()
    saved = yaml.safe_load(session.read_text())["view"]
    assert saved["loupe_shows"] == "Range" and saved["ba_window_start"] == 100 and saved["panorama"] is False


def test_a_rough_pose_is_kept_only_as_a_rigid_transform():
    """The saved rough pose: 16 numbers of a rotation (orthonormal, det +1) and translation; anything else in a
    session file falls back to "none" (old files have no such key at all)."""
    R = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # camera looking along lidar +x
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (0.06, -0.08, -0.27)
    good = [float(x) for x in T.reshape(-1)]
    assert ViewSettings.from_dict({"rough_T_camera_lidar": good}).rough_T_camera_lidar == tuple(good)
    assert ViewSettings.from_dict({}).rough_T_camera_lidar == ()
    reflected = T.copy()
    reflected[:3, 0] *= -1.0
    scaled = T.copy()
    scaled[:3, :3] *= 2.0
    bottom = T.copy()
    bottom[3, 0] = 1.0
    for bad in (good[:15], good[:15] + [float("nan")], reflected.reshape(-1).tolist(), scaled.reshape(-1).tolist(),
                bottom.reshape(-1).tolist(), ["1"] * 16, [True] * 16, 5.0, "identity"):
        assert ViewSettings.from_dict({"rough_T_camera_lidar": bad}).rough_T_camera_lidar == (), bad
        with pytest.raises(CalibError, match="rough_T_camera_lidar"):
            ViewSettings(rough_T_camera_lidar=bad)  # type: ignore[arg-type]
