"""Several shots in one session (issue 21), the app side: the session file, ``serve --shot``, the joint
live solve and the per-shot Verify numbers.

Truth: the pairs put in (the session must give back exactly those), a one-shot session file as
ba-calib wrote it before shots existed (copied below, written by the code of main at 72ab6b2),
:func:`calib_core.shots.solve_shots` called here on the same pairs (the app must show that solve), and the
ground truth of the synthetic rig (two rooms seen with the sample's ``T_camera_lidar``).
"""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line, run_cli
from shots_helpers import sample_shot_server

from app.picks import ShotFiles
from app.state import AnnotationState
from calib_core.errors import CalibError
from calib_core.io.images import load_image_rgb, save_image_rgb
from calib_core.shots import Shot, solve_shots
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import rotation_angle_deg
from repo_paths import REPO, SAMPLE

#: A one-shot session as the app wrote it before shots (main at 72ab6b2: AnnotationState on the sample,
#: 5 pairs of sample_data/pairs.yaml imported, pair 5 made a check pair, one more BA click, closed).
OLD_SESSION = """\
format: ba-calib-session
version: 1
next_id: 7
pairs:
- id: 1
  laser_rc: [82, 397]
  laser_xyz: null
  pixel: [359.9765076747813, 223.61543968419545]
- id: 2
  laser_rc: [91, 137]
  laser_xyz: null
  pixel: [119.09350431947195, 300.70524899187143]
- id: 3
  laser_rc: [106, 560]
  laser_xyz: null
  pixel: [506.60358776387557, 258.49289824095735]
- id: 4
  laser_rc: [38, 221]
  laser_xyz: null
  pixel: [222.06628674012563, 149.83990487865069]
- id: 5
  laser_rc: [107, 266]
  laser_xyz: null
  pixel: [253.533858129672, 298.2973918646013]
  check: true
- id: 6
  laser_rc: [40, 200]
  laser_xyz: null
  pixel: null
view:
  panorama: true
  show_reprojection: true
  show_edges: true
  snap: false
  up_axis: +z
  ba_window_mode: all
  ba_window_start: 0
  ba_window_width: 0
  contrast: 1.0
  loupe_shows: BA as clicked
  last_pane_shows: ''
  edge_opacity: 0.8
  hide_marks: false
  render_mode: range
  render_blend: 0.0
  rough_T_camera_lidar: []
journal_seq: 3
session_id: de0268ec729645eb8db85934420665b9
"""


@pytest.fixture(scope="module")
def two_shots(second_shot):
    """The sample (shot 0) and room 1 on the sample's rig (shot 1), as files (tests/conftest.py: made once)."""
    return second_shot


def _masks():
    sample = load_sample(SAMPLE)
    h, w = sample.depth.valid.shape
    other = np.zeros((h + 3, w), dtype=bool)  # another scan: another size, and only its row 0 has returns
    other[0] = True
    return sample, [sample.depth.valid, other]


# ----------------------------------------------------------------------------- the session file


def test_the_session_round_trips_with_shots_and_undo_removes_an_added_shot(tmp_path):
    sample, masks = _masks()
    size = (sample.camera.width, sample.camera.height)
    path = tmp_path / "session.yaml"
    files = [ShotFiles("/data/a.pcd", "/data/a.png"), ShotFiles("/data/b.pcd", "/data/b.png")]
    s = AnnotationState(masks, size, path, shots=files)
    s.add_laser(82, 397)
    s.add_pixel(360.0, 223.5)
    s.set_active_shot(1)
    assert s.picks == () and len(s.all_picks) == 1  # the panes show shot 1: shot 0's pair is not drawn
    with pytest.raises(CalibError, match="has no laser return"):
        s.add_laser(82, 397)  # shot 1's scan has no return there
    s.add_laser(0, 5)
    s.add_pixel(10.0, 20.0)
    with pytest.raises(CalibError, match="pair 1 is in shot 0"):
        s.move_pixel(1, 5.0, 5.0)  # checked against the shot shown: refused
    s.close()

    data = yaml.safe_load(path.read_text())
    assert data["version"] == 2 and data["active_shot"] == 1
    assert data["shots"] == [{"scan": "/data/a.pcd", "image": "/data/a.png"}, {"scan": "/data/b.pcd", "image": "/data/b.png"}]
    assert [(p["id"], p["shot"], p["laser_rc"], p["pixel"]) for p in data["pairs"]] == [
        (1, 0, [82, 397], [360.0, 223.5]), (2, 1, [0, 5], [10.0, 20.0])]

    again = AnnotationState(masks, size, path)  # no shots given: the session's
    assert again.shots == tuple(files) and again.active_shot == 1
    assert [(p.id, p.shot, p.laser_rc, p.pixel) for p in again.all_picks] == [
        (1, 0, (82, 397), (360.0, 223.5)), (2, 1, (0, 5), (10.0, 20.0))]
    assert [p.id for p in again.picks] == [2]
    # Adding a shot is one undoable step; undoing it while it is shown shows the last shot left.
    k = again.add_shot("/data/c.pcd", "/data/c.png", masks[0])
    assert k == 2 and again.n_shots == 3
    again.set_active_shot(2)
    again.add_laser(82, 397)
    again.add_pixel(1.0, 1.0)
    assert again.undo() and again.undo() and again.undo()  # the pair's two clicks, then the shot
    assert again.n_shots == 2 and again.active_shot == 1 and [p.id for p in again.all_picks] == [1, 2]
    assert again.redo() and again.n_shots == 3
    with pytest.raises(CalibError, match="already shot 0"):
        again.add_shot("/data/a.pcd", "/data/a.png", masks[0])
    again.close()


def test_a_session_of_two_shots_needs_both_scans(tmp_path):
    sample, masks = _masks()
    size = (sample.camera.width, sample.camera.height)
    path = tmp_path / "session.yaml"
    AnnotationState(masks, size, path, shots=[ShotFiles("a", "b"), ShotFiles("c", "d")]).set_active_shot(1)
    with pytest.raises(CalibError, match="lists 2 shots but 1 scan") as err:
        AnnotationState(masks[0], size, path)
    assert "--shot SCAN IMAGE" in str(err.value) and "\n" not in str(err.value)


def test_an_old_one_shot_session_opens_as_one_shot(tmp_path):
    from app_driver import sample_app

    path = tmp_path / "old.yaml"
    path.write_text(OLD_SESSION)
    app = sample_app(path)
    try:
        state = app.state
        assert state.n_shots == 1 and state.active_shot == 0
        assert state.shots == (ShotFiles.of(SAMPLE / "scan.npz", SAMPLE / "image.png"),)
        old = yaml.safe_load(OLD_SESSION)["pairs"]
        assert [(p.id, p.shot, p.laser_rc, p.pixel, p.check) for p in state.picks] == [
            (e["id"], 0, tuple(e["laser_rc"]), None if e["pixel"] is None else tuple(e["pixel"]), e.get("check", False))
            for e in old]
        assert state.undo() is False  # restored, not a change
    finally:
        app.stop()
    data = yaml.safe_load(path.read_text())
    assert data["version"] == 2 or data.get("version") == 1  # rewritten only after a change


# ----------------------------------------------------------------------------- the joint live solve


def _serve_two(tmp_path, two_shots, n0=6, n1=6, seed=0):

    s0, s1, scan1, image1 = two_shots
    server = sample_shot_server(tmp_path / "session.yaml", (scan1, image1))
    rng = np.random.default_rng(seed)
    pairs0, pairs1 = simulate_pairs(s0, n0, rng), simulate_pairs(s1, n1, rng)
    return server, pairs0, pairs1


def test_the_live_solve_uses_every_shot_and_equals_solve_shots(tmp_path, two_shots):
    s0, s1, _, _ = two_shots
    server, pairs0, pairs1 = _serve_two(tmp_path, two_shots)
    try:
        app = server.load()
        assert app.active_shot == 0
        app.state.import_pairs(pairs0)
        app = server.load(1)  # the panes of shot 1; the state (and its undo history) lives on
        assert app.active_shot == 1 and app.state.can_undo
        app.state.import_pairs(pairs1)
        assert app.wait_idle(120)
        bundle = app.solve_bundle
        assert bundle is not None and bundle.shots is not None
        # The same pairs, resolved and solved here: the app shows exactly that solve.
        ids0 = [p.id for p in app.state.all_picks if p.shot == 0]
        ids1 = [p.id for p in app.state.all_picks if p.shot == 1]
        here = solve_shots([
            Shot.from_pairs([dataclasses.replace(p, id=i) for p, i in zip(pairs0, ids0)], s0.depth, s0.camera),
            Shot.from_pairs([dataclasses.replace(p, id=i) for p, i in zip(pairs1, ids1)], s1.depth, s1.camera)],
            s0.camera)
        np.testing.assert_allclose(app.result.T_camera_lidar, here.result.T_camera_lidar, rtol=0, atol=1e-12)
        np.testing.assert_allclose(app.result.covariance_6x6, here.result.covariance_6x6, rtol=0, atol=1e-12)
        assert app.result.n_pairs == len(pairs0) + len(pairs1) == 12
        assert bundle.pick_ids == ids0 + ids1
        # One rig: the joint pose is the truth, to the click noise.
        T, truth = app.result.T_camera_lidar, s0.T_camera_lidar
        rot, shift = rotation_angle_deg(T[:3, :3], truth[:3, :3]), float(np.linalg.norm(T[:3, 3] - truth[:3, 3]))
        print(f"\njoint solve of 6 + 6 pairs: {rot:.3f} deg, {100 * shift:.2f} cm from the truth")
        assert rot < 0.5 and shift < 0.05
        # Shot 0's pairs are not drawn on shot 1's panes, but counted.
        other = np.isin(bundle.pick_ids, ids0)
        assert np.isnan(bundle.pixels[other]).all() and np.isfinite(bundle.pixels[~other]).all()
        assert "6 complete in shot 1 (shown); 12 in all 2 shots" in app.pairs_panel._md_pairs.content
        assert "shot 0: 6, shot 1: 6 (shown); **12 in the calibration**" in server.panel.summary
        # Verify: every shot's pairs, per-shot errors and leave-one-shot-out (each shot alone has 6 pairs).
        assert app.verify_panel.wait_idle(120) and app.wait_idle(60) and app.verify_panel.wait_idle(120)
        text = app.verify_panel.shots_text
        assert "2 shots, one calibration" in text
        rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| 0") or line.startswith("| 1")}
        for k, e in enumerate(here.leave_one_shot_out):
            assert f"| {e.mean_px:.2f} |" in rows[str(k) if k != 1 else "1 (shown)"]
        assert "Fit on 12 pairs" in app.verify_panel.summary
    finally:
        server.stop()


def test_a_rotated_shot_is_named_in_verify(tmp_path, two_shots):
    """Three shots, one of them the sample's scan turned by 2 degrees (a rig that turned between the photo
    and the scan): Verify names it and the calibration leaves it out."""
    from app.serving import ShotServer
    from calib_core.io.scan_readers import load_scan
    from calib_core.lidar import save_depth_npz

    s0, s1, scan1, image1 = two_shots
    depth = load_scan(SAMPLE / "scan.npz")
    c, s = np.cos(np.radians(2.0)), np.sin(np.radians(2.0))
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # about the lidar's z (the room's vertical)
    # Stored as its points (an organised cloud): the scanner model would rebuild them unturned.
    turned = dataclasses.replace(depth, points=depth.points @ R.T, directions=depth.directions @ R.T,
                                 meta={**depth.meta, "model": "organized"})
    save_depth_npz(tmp_path / "turned.npz", turned)
    shutil.copy(SAMPLE / "image.png", tmp_path / "turned.png")
    server = ShotServer([(SAMPLE / "scan.npz", SAMPLE / "image.png"), (scan1, image1),
                         (tmp_path / "turned.npz", tmp_path / "turned.png")], SAMPLE / "camera.yaml",
                        session_path=tmp_path / "session.yaml", port=0)
    try:
        rng = np.random.default_rng(5)
        app = server.load()
        app.state.import_pairs(simulate_pairs(s0, 8, rng))
        app = server.load(1)
        app.state.import_pairs(simulate_pairs(s1, 8, rng))
        app = server.load(2)
        app.state.import_pairs(simulate_pairs(s0, 8, np.random.default_rng(11)))  # cells of the turned scan
        assert app.wait_idle(120) and app.verify_panel.wait_idle(120)
        assert app.wait_idle(60) and app.verify_panel.wait_idle(120)
        assert app.solve_bundle.shots.solved.disagreeing == [2]
        assert "Shot 2 disagrees with the others" in app.verify_panel.shots_text
        assert any("shot 2" in r for r in app.result.quality.reasons)
    finally:
        server.stop()


# ----------------------------------------------------------------------------- serve --shot, bad input


def test_serve_shot_bad_input_is_one_line(tmp_path, two_shots):
    _, _, scan1, image1 = two_shots
    cam = str(SAMPLE / "camera.yaml")
    scan0, image0 = str(SAMPLE / "scan.npz"), str(SAMPLE / "image.png")
    line = one_error_line(run_cli("serve", "--camera", cam, "--shot", scan0, image0, "--shot",
                                  str(tmp_path / "missing.npz"), str(image1), "--port", "0"))
    assert line == f"error: shot 1: the scan {tmp_path / 'missing.npz'} does not exist"
    small = tmp_path / "small.png"
    save_image_rgb(small, load_image_rgb(image1)[:240, :320])
    line = one_error_line(run_cli("serve", "--camera", cam, "--shot", scan0, image0, "--shot", str(scan1),
                                  str(small), "--port", "0"))
    assert line.startswith(f"error: shot 1: {small}: the image is 320x240 but the camera model") and "640x480" in line
    line = one_error_line(run_cli("serve", "--camera", cam, "--scan", scan0, "--shot", scan0, image0, "--port", "0"))
    assert "leave out --scan, --image and --bag" in line
    line = one_error_line(run_cli("serve", "--shot", scan0, image0, "--port", "0"))
    assert "serve --shot needs --camera" in line
    line = one_error_line(run_cli("serve", "--camera", cam, "--shot", scan0, image0, "--shot", scan0, image0,
                                  "--port", "0"))
    assert "is given twice" in line


def test_the_shots_panel_switches_shots_and_an_undone_shot_is_left(tmp_path, two_shots):
    from app.session_store import peek_session

    _, _, scan1, image1 = two_shots
    server = sample_shot_server(tmp_path / "session.yaml")
    try:
        app = server.load()
        assert server.add_shot(scan1, image1) == 1  # what "Add this shot" does before asking for it
        # On disk before it returns (journal first), as every change: what a restart after kill -9 reads.
        on_disk = peek_session(tmp_path / "session.yaml")
        assert [e["scan"] for e in on_disk["shots"]] == [str((SAMPLE / "scan.npz").absolute()), str(Path(scan1).absolute())]
        panel = server.panel
        assert tuple(panel.dropdown.options) == ("Shot 0: scan.npz + image.png", "Shot 1: scan1.npz + image1.png")
        panel.dropdown.value = panel.dropdown.options[1]
        panel.show_chosen()
        assert server.requests.get_nowait() == 1
        app = server.load(1)
        assert app.active_shot == 1 and np.array_equal(app.image, load_image_rgb(image1))
        assert "Showing shot 1 of 2" in server.panel.summary
        assert app.state.undo()  # the added shot goes: the panes go back to shot 0
        assert server.requests.get(timeout=10) == 0
        assert len(peek_session(tmp_path / "session.yaml")["shots"]) == 1
        app = server.load(0)
        assert app.state.n_shots == 1 and app.active_shot == 0 and np.array_equal(app.image, load_image_rgb(SAMPLE / "image.png"))
        with pytest.raises(CalibError, match="no shot 1"):
            server.load(1)
    finally:
        server.stop()


# ----------------------------------------------------------------------------- real data: two road scenes


TWO_SCENES = REPO.parent / "shared" / "data" / "pjlab_opencalib_two_scenes"


@pytest.mark.realdata
@pytest.mark.skipif(not (TWO_SCENES / "scene1" / "calib.pcd").is_file(), reason=f"no data at {TWO_SCENES}")
def test_serve_two_real_road_scenes_three_pairs_each(tmp_path):
    """The two PJLab scenes of one rig as two shots: 3 pairs per scene (the published calibration's
    projections of real corners plus 1 px noise, tools/make_real_pairs.py's rule, as tests/test_shots.py
    takes them) solve in the app together, to the published calibration."""
    from bench.shots import pair_rule, read_calib_txt
    from test_shots import _errors

    from app.serving import ShotServer
    from calib_core.cameras import save_camera_yaml
    from calib_core.cameras.pinhole import PinholeCamera
    from calib_core.pairs import Pair

    K, D, T_pub = read_calib_txt(TWO_SCENES / "scene1" / "calib.txt")
    save_camera_yaml(PinholeCamera(K, D, 1920, 1200), tmp_path / "camera.yaml")
    server = ShotServer([(TWO_SCENES / n / "calib.pcd", TWO_SCENES / n / "calib.jpg") for n in ("scene1", "scene2")],
                        tmp_path / "camera.yaml", session_path=tmp_path / "session.yaml", port=0)
    select_pairs = pair_rule().select_pairs
    try:
        per_shot = []
        for k in (0, 1):
            app = server.load(k)
            entries = select_pairs(app.depth, app.camera, T_pub, 1000 + k)[:3]
            per_shot.append([Pair(tuple(e["laser_rc"]), None, tuple(e["pixel"])) for e in entries])
            app.state.import_pairs(per_shot[-1])
        assert app.wait_idle(120)
        assert "3 complete in shot 1 (shown); 6 in all 2 shots" in app.pairs_panel._md_pairs.content
        ids = [[p.id for p in app.state.all_picks if p.shot == k] for k in (0, 1)]
        here = solve_shots([Shot.from_pairs([dataclasses.replace(p, id=i) for p, i in zip(pairs, ids[k])],
                                            server.scenes[k].depth, app.camera) for k, pairs in enumerate(per_shot)],
                           app.camera)
        np.testing.assert_allclose(app.result.T_camera_lidar, here.result.T_camera_lidar, rtol=0, atol=1e-12)
        rot, shift = _errors(app.result.T_camera_lidar, T_pub)
        print(f"\ntwo road scenes in the app, 3 + 3 pairs: {rot:.3f} deg, {100 * shift:.2f} cm from the published T")
        assert rot <= 0.5 and shift <= 0.10
        assert app.verify_panel.wait_idle(120) and app.wait_idle(60) and app.verify_panel.wait_idle(120)
        assert "2 shots, one calibration" in app.verify_panel.shots_text
        assert "do not determine a pose alone" in app.verify_panel.shots_text  # 3 pairs cannot: said, not hidden
    finally:
        server.stop()


def test_a_session_shot_whose_files_are_gone_is_named(tmp_path, two_shots):
    from app.serving import ShotServer

    _, _, scan1, image1 = two_shots
    moved = tmp_path / "moved"
    moved.mkdir()
    scan, image = shutil.copy(scan1, moved / "s.npz"), shutil.copy(image1, moved / "i.png")
    session = tmp_path / "session.yaml"
    server = ShotServer([(SAMPLE / "scan.npz", SAMPLE / "image.png"), (scan, image)], SAMPLE / "camera.yaml",
                        session_path=session, port=0)
    server.state.set_active_shot(1)  # a change: the session file now lists both shots
    server.stop()
    Path(scan).unlink()
    with pytest.raises(CalibError) as err:
        ShotServer([(SAMPLE / "scan.npz", SAMPLE / "image.png")], SAMPLE / "camera.yaml", session_path=session, port=0)
    assert str(err.value) == f"shot 1 (listed in the session {session}): the scan {scan} does not exist"


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_serve_bag_frames_opens_one_session_of_three_shots(tmp_path, monkeypatch, kind):
    """``serve --bag BAG --frames 3`` on a ROS 1, a ROS 2 sqlite and an MCAP bag of three clouds and images
    (tests/bag_helpers.py): the three frames are written as shots and served as one session of three shots."""
    from bag_helpers import CloudSpec, SceneBag, write_bag

    import app.serving
    from app.cli import build_parser
    from app.serving import ShotServer
    from calib_core.io.scan_readers import read_point_cloud

    cloud = read_point_cloud(SAMPLE / "scan.npz")
    spec = CloudSpec({a: cloud.xyz[:, i].copy() for i, a in enumerate("xyz")}, organized_shape=cloud.organized_shape)
    image = load_image_rgb(SAMPLE / "image.png")
    images = [image, image[::-1].copy(), image[:, ::-1].copy(), image[::-1, ::-1].copy()]
    times = [50.0, 51.0, 52.0, 53.0]
    bag = write_bag(tmp_path / ("bag.bag" if kind == "ros1" else "bag"), kind,
                    SceneBag(clouds=[spec] * 4, cloud_times=times, images=images, image_times=times))
    served = {}
    monkeypatch.setattr(app.serving, "serve", lambda *a, **k: served.update(args=a, kwargs=k))
    session = tmp_path / "session.yaml"
    args = build_parser().parse_args(["serve", "--bag", str(bag), "--frames", "3", "--camera", str(SAMPLE / "camera.yaml"),
                                      "--session", str(session), "--port", "0"])
    assert args.func(args) == 0
    shots = served["kwargs"]["shots"]
    assert len(shots) == 3 and served["args"][2] == SAMPLE / "camera.yaml"
    server = ShotServer(shots, served["args"][2], session_path=served["kwargs"]["session_path"], port=0,
                        bag_frames=served["kwargs"]["shot_bag"])
    try:
        assert server.state.n_shots == 3
        shown = []
        for k in range(3):
            app_k = server.load(k)
            shown.append(next(i for i, im in enumerate(images) if np.array_equal(app_k.image, im)))
        assert len(set(shown)) == 3  # each shot shows its own frame's photo
        # The frame left out is added from the Shots panel: one undoable step.
        left = ({0, 1, 2, 3} - set(shown)).pop()
        k = server.panel.add_bag_frame(left)
        assert (k, server.state.n_shots) == (3, 4)
        assert np.array_equal(server.load(3).image, images[left])
        server.state.undo()
        assert server.state.n_shots == 3
    finally:
        server.stop()
    with pytest.raises(CalibError, match="give --bag too"):
        bad = build_parser().parse_args(["serve", "--frames", "3", "--camera", str(SAMPLE / "camera.yaml")])
        bad.func(bad)
