"""Several frames of one bag as shots (issue 21, the bag part): calib_core.io.bag_frames and ``bag frames``.

Bags are written here with rosbags' own writers (ROS 1, ROS 2 sqlite3, ROS 2 mcap), from plain arrays and
the builders of ``bag_helpers``.  Truth: the stamps, gaps and motions planted in the bags (the rig's motion
is computed here from the formulas that generated its /tf or odometry); the PJLab two-scene data
(``../shared/data/pjlab_opencalib_two_scenes``) solved from its loose files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bench.shots import TWO_SCENES, pair_rule, read_calib_txt
from bag_helpers import CloudSpec, SceneBag, _header, _typestore, camera_info, pointcloud2, tf_message
from scipy.spatial.transform import Rotation

from calib_core.errors import CalibError
from calib_core.io.bag_frames import FrameTable, choose_frames, read_frame_table, shots_from_bag
from calib_core.io.images import load_image_rgb
from cli_helpers import one_error_line, run_cli

KINDS = ["ros1", "sqlite3", "mcap"]


# ----------------------------------------------------------------------------- writing bags


def _write(path: Path, kind: str, msgs: list) -> Path:
    """``msgs``: ``(stamp s, topic, msgtype, build(store, ros1) -> message)``; received 2 ms after the stamp."""
    ros1 = kind == "ros1"
    store = _typestore(ros1)
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    if ros1:
        from rosbags.rosbag1 import Writer

        path = path.with_suffix(".bag")
        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3)
    with writer:
        conns = {}
        for t, topic, msgtype, build in sorted(msgs, key=lambda m: m[0]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], int(round((t + 0.002) * 1e9)), serialize(build(store, ros1), msgtype))
    return path


def _T(rotvec, t) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = t
    return out


def _jpeg(store, ros1, data: bytes, t: float):
    return store.types["sensor_msgs/msg/CompressedImage"](
        header=_header(store, ros1, t, "camera_optical"), format="jpeg", data=np.frombuffer(data, np.uint8))


def _cloud_msgs(clouds: list[CloudSpec], times: list[float]) -> list:
    return [(t, "/points", "sensor_msgs/msg/PointCloud2",
             lambda s, r, c=c, t=t: pointcloud2(s, r, c, t, "velodyne")) for c, t in zip(clouds, times)]


def _small_cloud(k: int) -> CloudSpec:
    rng = np.random.default_rng(k)
    return CloudSpec({a: rng.normal(size=50).astype(np.float32) for a in "xyz"})


def _tiny_image_msgs(times: list[float]) -> list:
    from bag_helpers import image_msg

    return [(t, "/camera/image_raw", "sensor_msgs/msg/Image",
             lambda s, r, t=t: image_msg(s, r, np.full((4, 6, 3), 7, np.uint8), t, "camera_optical", False))
            for t in times]


# ----------------------------------------------------------------------------- the rig's motion

T0 = 100.0  # small stamps keep the float64 seconds exact to ~1e-14 s
V = np.array([2.0, 0.5, 0.0])  # m/s while moving
OMEGA = 0.4  # yaw rate, rad/s, while moving
STOPS = [(0.25, 0.35), (0.55, 0.65), (1.05, 1.15)]  # seconds after T0 when the rig stands still
T_BASE_VELO = _T([0.0, 0.05, 0.3], [1.2, -0.1, 1.8])


def _moving_time(t: np.ndarray) -> np.ndarray:
    """Seconds of motion between T0 - 0.05 and ``t`` (the stops subtracted)."""
    rel = np.asarray(t, float) - T0
    s = rel + 0.05
    for a, b in STOPS:
        s -= np.clip(rel - a, 0.0, b - a)
    return s


def _rig_pose(t):
    """Position (m) and yaw (rad) of base_link in odom at stamps ``t``: straight line, turning on the spot."""
    s = _moving_time(t)
    return s[:, None] * V, OMEGA * s


def _motion_bag(tmp_path: Path, kind: str, odometry: bool = False, static_on_tf: bool = False) -> tuple[Path, dict]:
    """12 small clouds at 10 Hz, each image 30 ms after its cloud, except cloud 2 (5 ms, while moving).
    The rig stands still around clouds 3, 6 and 11 (STOPS): the stillest frames, one per third of the bag."""
    cloud_t = [T0 + 0.1 * k for k in range(12)]
    gaps = [0.005 if k == 2 else 0.03 for k in range(12)]
    image_t = [t + g for t, g in zip(cloud_t, gaps)]
    msgs = _cloud_msgs([_small_cloud(k) for k in range(12)], cloud_t) + _tiny_image_msgs(image_t)
    samples = T0 - 0.05 + 0.01 * np.arange(131)  # 100 Hz, knots on the stops' ends: interpolation is exact
    pos, yaw = _rig_pose(samples)
    static = [("base_link", "velodyne", T_BASE_VELO), ("base_link", "camera_optical", _T([0.1, -1.5, 0.0], [1.5, 0.2, 1.4]))]
    if not static_on_tf:
        msgs.append((T0 - 0.05, "/tf_static", "tf2_msgs/msg/TFMessage", lambda s, r: tf_message(s, r, T0 - 0.05, static)))
    for t, p, y in zip(samples, pos, yaw):
        if static_on_tf:  # as some recorders do: the fixed joints repeated on /tf with the moving one
            msgs.append((t, "/tf", "tf2_msgs/msg/TFMessage", lambda s, r, t=t: tf_message(s, r, t, static)))
        pose = _T([0.0, 0.0, y], p)
        if odometry:
            msgs.append((t, "/odom", "nav_msgs/msg/Odometry", lambda s, r, t=t, pose=pose: _odometry(s, r, t, pose)))
        else:
            msgs.append((t, "/tf", "tf2_msgs/msg/TFMessage",
                         lambda s, r, t=t, pose=pose: tf_message(s, r, t, [("odom", "base_link", pose)])))
    return _write(tmp_path / f"motion_{kind}", kind, msgs), {"cloud_t": np.array(cloud_t), "image_t": np.array(image_t)}


def _odometry(store, ros1, t, pose):
    ty = store.types
    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    p = ty["geometry_msgs/msg/Pose"](position=ty["geometry_msgs/msg/Point"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3]),
                                     orientation=ty["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w))
    v3 = ty["geometry_msgs/msg/Vector3"]
    twist = ty["geometry_msgs/msg/Twist"](linear=v3(x=0.0, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0))
    return ty["nav_msgs/msg/Odometry"](
        header=_header(store, ros1, t, "odom"), child_frame_id="base_link",
        pose=ty["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36)),
        twist=ty["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )  # fmt: skip


def _expected_lidar_motion(t_a: np.ndarray, t_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (deg) and displacement (m) of the velodyne between the stamps, from the generating formulas."""
    (pa, ya), (pb, yb) = _rig_pose(t_a), _rig_pose(t_b)
    lever = T_BASE_VELO[:3, 3]

    def rz(y):
        c, s = np.cos(y), np.sin(y)
        return np.stack([np.stack([c, -s, 0 * c], -1), np.stack([s, c, 0 * c], -1), np.stack([0 * c, 0 * c, 1 + 0 * c], -1)], -2)

    # The lidar's rotation R_z(yaw) R_bv: between two stamps it turns by |yaw_b - yaw_a| (about z).
    return np.degrees(np.abs(yb - ya)), np.linalg.norm(pb + rz(yb) @ lever - pa - rz(ya) @ lever, axis=1)


@pytest.mark.parametrize("kind", KINDS)
def test_the_moving_rig_gives_the_frames_where_it_stands_still(kind, tmp_path):
    bag, planted = _motion_bag(tmp_path, kind)
    table = read_frame_table(bag)
    assert table.motion_source == "/tf odom -> base_link"
    np.testing.assert_allclose(table.cloud_stamp_s, planted["cloud_t"], atol=1e-9)
    np.testing.assert_allclose(table.image_stamp_s, planted["image_t"], atol=1e-9)
    rot, trans = _expected_lidar_motion(planted["cloud_t"], planted["image_t"])
    np.testing.assert_allclose(table.rotation_deg, rot, atol=1e-9)
    np.testing.assert_allclose(table.translation_m, trans, atol=1e-9)
    assert rot[0] == pytest.approx(np.degrees(OMEGA * 0.03))  # moving throughout cloud 0's 30 ms
    assert np.all(rot[[3, 6, 11]] < 1e-9) and np.all(trans[[3, 6, 11]] < 1e-9)  # standing still
    assert np.all(np.delete(trans, [3, 6, 11]) > 0.005)
    # Cloud 2 has the smallest stamp gap (5 ms) but the rig is moving: the motion decides, not the gap.
    assert np.argmin(np.abs(table.gap_s)) == 2
    chosen = choose_frames(table, frames=3)
    assert chosen == [3, 6, 11]
    thirds = np.floor(3 * (table.time_s[chosen] - table.time_s.min()) / np.ptp(table.time_s)).clip(0, 2)
    assert sorted(thirds) == [0, 1, 2]  # one in each third of the bag
    # Without the trajectory (stamps only) the 5 ms frame would win its third.
    stamps_only = FrameTable(**{**table.__dict__, "rotation_deg": None, "translation_m": None})
    assert choose_frames(stamps_only, frames=3)[0] == 2


def test_odometry_gives_the_same_motion_as_tf(tmp_path):
    bag, planted = _motion_bag(tmp_path, "mcap", odometry=True)
    table = read_frame_table(bag)
    assert table.motion_source == "/odom (nav_msgs/Odometry)"
    rot, trans = _expected_lidar_motion(planted["cloud_t"], planted["image_t"])
    np.testing.assert_allclose(table.rotation_deg, rot, atol=1e-9)
    np.testing.assert_allclose(table.translation_m, trans, atol=1e-9)
    assert choose_frames(table, frames=3) == [3, 6, 11]


def test_fixed_joints_repeated_on_tf_are_not_taken_for_the_rig(tmp_path):
    bag, planted = _motion_bag(tmp_path, "sqlite3", static_on_tf=True)
    table = read_frame_table(bag)
    assert table.motion_source == "/tf odom -> base_link"  # not base_link -> velodyne, sent as often
    rot, trans = _expected_lidar_motion(planted["cloud_t"], planted["image_t"])
    np.testing.assert_allclose(table.translation_m, trans, atol=1e-9)
    assert choose_frames(table, frames=3) == [3, 6, 11]


def test_empty_windows_are_filled_by_the_farthest_frames():
    n = 4
    # Three frames early, one late: the middle window is empty; costs equal, so time decides.
    table = FrameTable(where="bag", cloud_topic="/points", image_topic="/img", camera_info_topic=None, duration_s=10.0,
                       time_s=np.array([0.0, 0.1, 0.2, 10.0]), cloud_stamp_s=np.zeros(n), image_stamp_s=np.zeros(n),
                       image_index=np.arange(n))
    # Windows [0, 3.3), [3.3, 6.7), [6.7, 10]: the first gives the frame nearest its centre (0.2 s), the last 10 s;
    # the frame farthest from both then fills the empty window (0.0 s, 0.2 s away from the nearest chosen).
    assert choose_frames(table, frames=3) == [0, 2, 3]
    assert choose_frames(table, frames=4) == [0, 1, 2, 3]


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_by_hand_and_bad_requests_give_one_line(kind, tmp_path):
    bag, planted = _motion_bag(tmp_path, kind)
    table = read_frame_table(bag)
    # The bag starts with the first /tf sample (stamp T0 - 0.05, received 2 ms later); cloud k is at 0.05 + 0.1 k s.
    assert table.duration_s == pytest.approx(1.3, abs=1e-6)  # /tf samples from T0 - 0.05 to T0 + 1.25
    assert choose_frames(table, times=[0.26, 0.04]) == [0, 2]
    assert choose_frames(table, indices=[11, 4]) == [4, 11]
    for request, fragment in (
        (dict(frames=13), "13 frames asked but /points has only 12 clouds"),
        (dict(frames=0), "must be 1 or more"),
        (dict(times=[2.5]), "time 2.5 s is outside the bag (0 to 1.300 s after its start)"),
        (dict(times=[-0.1]), "outside the bag"),
        (dict(times=[float("nan")]), "outside the bag"),
        (dict(indices=[12]), "index 12 but /points has 12 clouds (0..11)"),
        (dict(indices=[-1]), "index -1"),
        (dict(indices=[3, 3]), "indices 3 and 3 both choose cloud #3"),
        (dict(times=[0.35, 0.36]), "both choose cloud #3"),
        (dict(), "give exactly one"),
        (dict(frames=2, indices=[1]), "give exactly one"),
    ):
        with pytest.raises(CalibError) as err:
            choose_frames(table, **request)
        message = str(err.value)
        assert fragment in message and "\n" not in message, (request, message)
    out = tmp_path / "out"
    for args, fragment in ((("--frames", "13"), "only 12 clouds"), (("--time", "9"), "outside the bag"),
                           (("--index", "0", "12"), "index 12")):
        line = one_error_line(run_cli("bag", "frames", str(bag), *args, "-o", str(out)))
        assert fragment in line, line
    assert not out.exists()  # a bad request writes nothing


# ----------------------------------------------------------------------------- real frames: the two PJLab scenes


def _nearest_rotation(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(R)
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


@pytest.fixture(scope="module")
def two_scenes():
    """Per scene: the loose scan (depth matrix), camera, published T, point cloud, JPEG bytes and 11 pairs."""
    if not (TWO_SCENES / "scene1" / "calib.pcd").is_file():
        pytest.skip(f"no data at {TWO_SCENES} (../shared/data)")
    from calib_core.cameras.pinhole import PinholeCamera
    from calib_core.io.scan_readers import load_scan, read_point_cloud
    from calib_core.pairs import Pair

    rule = pair_rule()
    scenes = []
    for k, name in enumerate(("scene1", "scene2")):
        K, D, T = read_calib_txt(TWO_SCENES / name / "calib.txt")
        camera = PinholeCamera(K, D, 1920, 1200)
        depth = load_scan(TWO_SCENES / name / "calib.pcd")
        entries = rule.select_pairs(depth, camera, T, 500 + k)
        scenes.append({
            "depth": depth, "camera": camera, "T": T, "K": K, "D": D,
            "cloud": read_point_cloud(TWO_SCENES / name / "calib.pcd"),
            "jpeg": (TWO_SCENES / name / "calib.jpg").read_bytes(),
            "image": load_image_rgb(TWO_SCENES / name / "calib.jpg"),
            "pairs": [Pair(tuple(e["laser_rc"]), None, tuple(e["pixel"])) for e in entries],
        })  # fmt: skip
    return scenes


# Clouds at 10 Hz; the images' gaps to them (s).  Frames 1, 7 and 11 carry the scenes (1: scene1, 7: scene2,
# 11: scene1 again, other pairs); frame 3 is the stillest after frame 1 but lies in the same third of the bag.
REAL_T0 = 1700000000.0
REAL_GAPS = [0.03, 0.0002, -0.025, 0.0005, 0.04, -0.035, 0.02, 0.001, 0.03, -0.03, 0.025, -0.001]
SCENE_OF_FRAME = {1: 0, 7: 1, 11: 0}


def _spec_of(cloud, every: int = 1) -> CloudSpec:
    cols = {a: cloud.xyz[::every, i].astype(np.float32) for i, a in enumerate("xyz")}
    cols.update({k: v[::every] for k, v in cloud.fields.items()})  # intensity, ring, timestamp in their dtypes
    return CloudSpec(cols)


def _real_bag(tmp_path: Path, kind: str, scenes) -> tuple[Path, np.ndarray]:
    cloud_t = [REAL_T0 + 0.1 * k for k in range(12)]
    clouds = [_spec_of(scenes[SCENE_OF_FRAME[k]]["cloud"]) if k in SCENE_OF_FRAME else _spec_of(scenes[0]["cloud"], 500)
              for k in range(12)]
    msgs = _cloud_msgs(clouds, cloud_t)
    info_scene = SceneBag([], [], [], [], K=scenes[0]["K"], D=scenes[0]["D"], camera_frame="camera_optical")
    for k, (t, gap) in enumerate(zip(cloud_t, REAL_GAPS)):
        jpeg = scenes[SCENE_OF_FRAME.get(k, 0)]["jpeg"]
        msgs.append((t + gap, "/camera/image/compressed", "sensor_msgs/msg/CompressedImage",
                     lambda s, r, t=t + gap, jpeg=jpeg: _jpeg(s, r, jpeg, t)))
        msgs.append((t + gap, "/camera/camera_info", "sensor_msgs/msg/CameraInfo",
                     lambda s, r, t=t + gap: camera_info(s, r, info_scene, (1920, 1200), t)))
    # /tf_static: base_link -> velodyne and base_link -> camera_optical, composed to the published calibration.
    T_pub = scenes[0]["T"].copy()
    T_pub[:3, :3] = _nearest_rotation(T_pub[:3, :3])
    T_base_velo = _T([0.0, 0.0, 0.02], [1.0, 0.0, 1.9])
    static = [("base_link", "velodyne", T_base_velo), ("base_link", "camera_optical", T_base_velo @ np.linalg.inv(T_pub))]
    msgs.append((REAL_T0 - 0.01, "/tf_static", "tf2_msgs/msg/TFMessage", lambda s, r: tf_message(s, r, REAL_T0, static)))
    return _write(tmp_path / f"real_{kind}", kind, msgs), T_pub


@pytest.mark.realdata
@pytest.mark.parametrize("kind", KINDS)
def test_bag_frames_solve_as_the_loose_files(kind, two_scenes, tmp_path):
    from calib_core.cameras import load_camera
    from calib_core.io.extrinsics import load_extrinsics_yaml
    from calib_core.io.scan_readers import load_scan
    from calib_core.shots import Shot, solve_shots

    bag, T_pub = _real_bag(tmp_path, kind, two_scenes)
    shots = shots_from_bag(bag, frames=3, out_dir=tmp_path / "frames")
    assert [s.index for s in shots] == [1, 7, 11]  # the still frame of each third (not 3, stiller than 7)
    assert shots.motion_source is None
    for s in shots:
        assert s.stamp_s == pytest.approx(REAL_T0 + 0.1 * s.index, abs=1e-6)
        assert s.gap_s == pytest.approx(REAL_GAPS[s.index], abs=1e-6)
        assert s.scan.parent == tmp_path / "frames" / f"frame_{s.index:05d}" and s.scan.is_file()
        assert np.array_equal(load_image_rgb(s.image), two_scenes[SCENE_OF_FRAME[s.index]]["image"])
    assert np.abs(shots.T_camera_lidar_tf - T_pub).max() < 1e-9
    assert np.abs(load_extrinsics_yaml(shots.initial_extrinsics)["T_camera_lidar"] - T_pub).max() < 1e-9

    # The same pairs from the loose files and from the bag's frames: scene1 gives pairs 0-4 to frame 1 and
    # 5-9 to frame 11 (each shot its own laser points), scene2 pairs 0-4 to frame 7.
    picks = {1: two_scenes[0]["pairs"][:5], 7: two_scenes[1]["pairs"][:5], 11: two_scenes[0]["pairs"][5:10]}
    loose = [Shot.from_pairs(picks[i], two_scenes[SCENE_OF_FRAME[i]]["depth"], two_scenes[0]["camera"]) for i in picks]
    camera = load_camera(shots.camera)
    from_bag = [Shot.from_pairs(picks[s.index], load_scan(s.scan), camera) for s in shots]
    T_loose = solve_shots(loose, two_scenes[0]["camera"]).result.T_camera_lidar
    T_bag = solve_shots(from_bag, camera).result.T_camera_lidar
    diff = np.abs(T_bag - T_loose).max()
    angle = np.degrees(np.linalg.norm(Rotation.from_matrix(T_loose[:3, :3].T @ T_pub[:3, :3]).as_rotvec()))
    print(f"\n{kind}: 3 bag frames against the loose files: max |T_bag - T_loose| = {diff:.3g}; "
          f"{angle:.3f} deg from the published calibration")
    assert diff <= 1e-9
    assert angle < 0.5  # the pairs are real corners: the joint solve lands near the published calibration

    if kind == "ros1":  # the command: one line per shot, the same frames
        out = tmp_path / "cli"
        proc = run_cli("bag", "frames", str(bag), "--frames", "3", "-o", str(out))
        assert proc.returncode == 0, proc.stderr
        lines = [ln.split() for ln in proc.stdout.splitlines() if ln.startswith("shot ")]
        assert [ln[2:5] for ln in lines] == [[str(s.scan).replace(str(tmp_path / "frames"), str(out)),
                                              str(s.image).replace(str(tmp_path / "frames"), str(out)),
                                              f"{s.stamp_s:.6f}"] for s in shots]
        proc = run_cli("bag", "frames", str(bag), "--index", "7", "1", "-o", str(out))
        assert proc.returncode == 0 and len([ln for ln in proc.stdout.splitlines() if ln.startswith("shot ")]) == 2


def test_unreadable_bags_give_one_line(tmp_path):
    junk = tmp_path / "junk.bag"
    junk.write_text("hello")
    for path, fragment in ((tmp_path / "missing.bag", "bag not found"), (junk, "not a readable ROS bag")):
        line = one_error_line(run_cli("bag", "frames", str(path), "--frames", "2", "-o", str(tmp_path / "out")))
        assert fragment in line and str(path) in line, line
    with pytest.raises(CalibError, match="no point cloud topic"):
        shots_from_bag(_write(tmp_path / "images_only", "mcap", _tiny_image_msgs([1.0, 2.0])), frames=1,
                       out_dir=tmp_path / "out")
