"""ROS bags without ROS: bags written by rosbags' own writers, read back by calib_core.io.bags.

Three storage kinds (ROS 1 .bag, ROS 2 sqlite3, ROS 2 mcap).  The real-scene
tests put the PJLab auto_calib scene (../shared/data) and the committed sample
into bags, extract them with ``ba-calib bag extract`` and check that the
extracted files calibrate to the same pose as the loose files, to 1e-9.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from bag_helpers import CloudSpec, SceneBag, write_bag

from calib_core.cameras import load_camera
from calib_core.errors import CalibError
from calib_core.io.bags import bag_info, read_bag_scene, write_bag_scene
from calib_core.io.images import load_image_rgb
from calib_core.io.scan_readers import load_scan, read_point_cloud
from calib_core.pairs import load_pairs_yaml, resolve_pairs
from calib_core.solve import solve_extrinsics
from repo_paths import REPO, SAMPLE
from cli_helpers import run_cli

AUTO = REPO.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"
KINDS = ["ros1", "sqlite3", "mcap"]


def _small_scene(rng, **cloud_kw) -> tuple[SceneBag, dict]:
    n = 60
    cols = {
        "x": rng.normal(size=n).astype(np.float32),
        "y": rng.normal(size=n).astype(np.float32),
        "z": rng.normal(size=n).astype(np.float32),
        "intensity": rng.random(n).astype(np.float32),
        "ring": rng.integers(0, 64, n).astype(np.uint16),
        "t": rng.random((n, 3)),  # a count-3 float64 field
        "flag": rng.integers(-100, 100, n).astype(np.int8),
    }
    images = [np.full((30, 40, 3), 10 * (k + 1), np.uint8) for k in range(5)]
    for k, img in enumerate(images):
        img[k, k] = (255, 0, k)  # each image distinct and not symmetric in its channels
    clouds = [CloudSpec({**cols, "x": cols["x"] + np.float32(k)}, **cloud_kw) for k in range(3)]
    scene = SceneBag(
        clouds=clouds,
        cloud_times=[1000.0, 1000.1, 1000.2],
        images=images,
        image_times=[999.99, 1000.04, 1000.12, 1000.16, 1000.25],
        K=np.array([[40.0, 0.0, 19.5], [0.0, 41.0, 14.5], [0.0, 0.0, 1.0]]),
        D=np.array([-0.2, 0.05, 0.001, 0.002, -0.01]),
    )
    return scene, cols


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("layout", [{}, {"bigendian": True}, {"pad_point": 5, "pad_row": 7}])
def test_pointcloud2_fields_and_layouts(kind, layout, tmp_path):
    scene, cols = _small_scene(np.random.default_rng(1), **layout)
    bag = write_bag(tmp_path / "b", kind, scene)
    got = read_bag_scene(bag, index=1)
    expected_xyz = np.stack([cols["x"] + np.float32(1), cols["y"], cols["z"]], axis=1).astype(np.float64)
    assert np.array_equal(got.cloud.xyz, expected_xyz)
    assert set(got.cloud.fields) == {"intensity", "ring", "t", "flag"}
    for name in ("intensity", "ring", "t", "flag"):
        assert got.cloud.fields[name].dtype == cols[name].dtype
        assert np.array_equal(got.cloud.fields[name], cols[name])
    assert got.lidar_frame == "velodyne" and got.camera_frame == "camera_optical"


@pytest.mark.parametrize("kind", KINDS)
def test_nearest_image_and_the_gap(kind, tmp_path):
    scene, _ = _small_scene(np.random.default_rng(2))
    bag = write_bag(tmp_path / "b", kind, scene)
    # cloud times 1000.0 / .1 / .2; images at 999.99, 1000.04, 1000.12, 1000.16, 1000.25
    for index, image_k, gap in ((0, 0, -0.01), (1, 2, 0.02), (2, 3, -0.04)):
        got = read_bag_scene(bag, index=index)
        assert got.cloud_index == index
        assert np.array_equal(got.image, scene.images[image_k]), (index, image_k)
        assert got.gap_s == pytest.approx(gap, abs=1e-6)
    # --time counts from the bag's first message (999.99 s stamp, received 2 ms later).
    got = read_bag_scene(bag, time_s=0.17)
    assert got.cloud_index == 2
    with pytest.raises(CalibError, match="index 3"):
        read_bag_scene(bag, index=3)


@pytest.mark.parametrize("kind", KINDS)
def test_camera_info_becomes_a_camera(kind, tmp_path):
    scene, _ = _small_scene(np.random.default_rng(3))
    scene.compressed_images = kind == "mcap"
    got = read_bag_scene(write_bag(tmp_path / "b", kind, scene))
    assert got.camera.model == "pinhole" and (got.camera.width, got.camera.height) == (40, 30)
    assert np.array_equal(got.camera.K, scene.K) and np.array_equal(got.camera.dist, scene.D)
    assert np.array_equal(got.image, scene.images[0])

    scene.distortion_model, scene.D = "equidistant", np.array([0.01, -0.002, 0.0003, 0.0])
    fish = read_bag_scene(write_bag(tmp_path / "f", kind, scene)).camera
    assert fish.model == "fisheye"


@pytest.mark.parametrize("kind", KINDS)
def test_tf_static_chain_gives_the_initial_extrinsic(kind, tmp_path):
    from scipy.spatial.transform import Rotation

    def T(rotvec, t):
        out = np.eye(4)
        out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
        out[:3, 3] = t
        return out

    # base_link -> velodyne and base_link -> camera_link -> camera_optical (TF: T_parent_child).
    T_base_velo = T([0.0, 0.0, 0.3], [1.2, 0.0, 1.8])
    T_base_cam = T([0.0, 0.1, 0.0], [1.5, 0.2, 1.4])
    T_cam_opt = T(Rotation.from_euler("zyx", [-90, 0, -90], degrees=True).as_rotvec(), [0, 0, 0])
    scene, _ = _small_scene(np.random.default_rng(4))
    scene.static_tf = [("base_link", "velodyne", T_base_velo), ("base_link", "camera_link", T_base_cam), ("camera_link", "camera_optical", T_cam_opt)]
    bag = write_bag(tmp_path / "b", kind, scene)
    # X_opt = inv(T_cam_opt) inv(T_base_cam) T_base_velo X_velo
    expected = np.linalg.inv(T_cam_opt) @ np.linalg.inv(T_base_cam) @ T_base_velo
    got = read_bag_scene(bag)
    assert np.abs(got.T_camera_lidar_tf - expected).max() < 1e-12
    # A frame the tree does not link gives no transform.
    from calib_core.io.extrinsic_formats import compose_tree

    assert compose_tree({(p, c): T_pc for p, c, T_pc in scene.static_tf}, "camera_optical", "no_such_frame") is None
    out = write_bag_scene(got, tmp_path / "out")
    from calib_core.io.extrinsics import load_extrinsics_yaml

    assert np.abs(load_extrinsics_yaml(out["initial_extrinsics"])["T_camera_lidar"] - expected).max() < 1e-12


def test_bag_info_lists_topics_counts_and_rates(tmp_path):
    scene, _ = _small_scene(np.random.default_rng(5))
    bag = write_bag(tmp_path / "b", "mcap", scene)
    info = bag_info(bag)
    topics = {t.name: t for t in info.topics}
    assert info.kind == "ROS2 mcap"
    assert topics["/points"].msgtype == "sensor_msgs/msg/PointCloud2" and topics["/points"].count == 3
    assert topics["/points"].rate_hz == pytest.approx(10.0, rel=1e-6)  # 3 clouds over 0.2 s
    assert topics["/camera/image_raw"].count == 5 and topics["/camera/image_raw"].rate_hz == pytest.approx(4 / 0.26, rel=1e-6)
    proc = run_cli("bag", "info", str(bag / "b.mcap"))
    assert proc.returncode == 0, proc.stderr
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("/points")][0]
    assert line.split()[1:] == ["sensor_msgs/msg/PointCloud2", "3", "10.00"]


def _bad_bag(kind: str, d: Path) -> Path:
    if kind == "header_only":
        path = d / "x.bag"
        path.write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 50)
    elif kind == "text":
        path = d / "junk.bag"
        path.write_text("hello")
    elif kind == "folder":
        path = d / "folder"
        path.mkdir()
    elif kind == "bare_mcap":
        path = d / "a.mcap"
        path.write_bytes(b"\x89MCAP0\r\n")
    elif kind == "missing":
        path = d / "missing.bag"
    else:
        path = d / "scan.pcd"
        path.write_text("x")
    return path


@pytest.mark.parametrize(
    "kind,fragment",
    [
        ("header_only", "not a readable ROS bag"),
        ("text", "not a readable ROS bag"),
        ("folder", "no metadata.yaml"),
        ("bare_mcap", "metadata.yaml"),
        ("missing", "not found"),
        ("pcd", "not a ROS bag"),
    ],
)
def test_bad_bags_give_one_line(kind, fragment, tmp_path):
    path = _bad_bag(kind, tmp_path)
    for args in (("bag", "info", str(path)), ("bag", "extract", str(path), "-o", str(tmp_path / "out"))):
        proc = run_cli(*args)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], proc.stderr


def test_truncated_bag_and_wrong_topics(tmp_path):
    scene, _ = _small_scene(np.random.default_rng(6))
    bag = write_bag(tmp_path / "b", "ros1", scene)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    for args, fragment in (
        (("bag", "extract", str(cut), "-o", str(tmp_path / "o1")), "cut.bag"),
        (("bag", "extract", str(bag), "--cloud-topic", "/nope", "-o", str(tmp_path / "o2")), "no topic '/nope'"),
        (("bag", "extract", str(bag), "--cloud-topic", "/camera/image_raw", "-o", str(tmp_path / "o3")), "expected sensor_msgs/msg/PointCloud2"),
        (("bag", "extract", str(bag), "--index", "9", "-o", str(tmp_path / "o4")), "index 9"),
    ):
        proc = run_cli(*args)
        assert proc.returncode == 2 and fragment in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


# --------------------------------------------------------------------------------------
# real scenes through bags
# --------------------------------------------------------------------------------------


def _solve(scan: Path, camera, pairs_path: Path, **scan_options) -> np.ndarray:
    depth = load_scan(scan, **scan_options)
    points, bearings, pixels = resolve_pairs(load_pairs_yaml(pairs_path), depth, camera)
    return solve_extrinsics(points, bearings, camera=camera, pixels=pixels).T_camera_lidar


@pytest.fixture(scope="module")
def auto_calib_scene():
    if not (AUTO / "calib.pcd").is_file():
        pytest.skip(f"PJLab auto_calib scene not found at {AUTO} (../shared/data)")
    cloud = read_point_cloud(AUTO / "calib.pcd")
    intr = json.loads((AUTO / "center_camera-intrinsic.json").read_text())
    param = next(iter(intr.values()))["param"]
    return cloud, load_image_rgb(AUTO / "calib.png"), np.array(param["cam_K"]["data"], float), np.array(param["cam_dist"]["data"], float).ravel()


@pytest.mark.realdata
@pytest.mark.parametrize("kind", KINDS)
def test_auto_calib_scene_through_a_bag_calibrates_to_the_same_pose(kind, auto_calib_scene, tmp_path):
    cloud, image, K, D = auto_calib_scene
    cols = {"x": cloud.xyz[:, 0].astype(np.float32), "y": cloud.xyz[:, 1].astype(np.float32), "z": cloud.xyz[:, 2].astype(np.float32)}
    assert np.array_equal(np.stack(list(cols.values()), 1).astype(np.float64), cloud.xyz), "calib.pcd holds float32 points"
    cols.update(cloud.fields)  # intensity (f4), ring (u2), timestamp (f8)
    scene = SceneBag(
        clouds=[CloudSpec(cols, bigendian=kind == "ros1", pad_point=4 if kind == "sqlite3" else 0)],
        cloud_times=[1700000000.05],
        images=[image, np.zeros_like(image)],
        image_times=[1700000000.06, 1700000000.3],
        K=K, D=D,
        lidar_frame="top_center_lidar", camera_frame="center_camera",
        compressed_images=kind == "mcap",
    )  # fmt: skip
    bag = write_bag(tmp_path / "bag", kind, scene)
    out = tmp_path / "extracted"
    proc = run_cli("bag", "extract", str(bag), "--cloud-topic", "/points", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "gap +10.000 ms" in proc.stdout
    assert np.array_equal(load_image_rgb(out / "image.png"), image)

    pairs = REPO / "real_data" / "pairs" / "auto_calib_pairs.yaml"
    T_loose = _solve(AUTO / "calib.pcd", load_camera(AUTO / "center_camera-intrinsic.json"), pairs)
    T_bag = _solve(out / "scan.pcd", load_camera(out / "camera.yaml"), pairs)
    diff = np.abs(T_bag - T_loose).max()
    print(f"\nauto_calib via {kind} bag: max |T_bag - T_loose| = {diff:.3g}")
    assert diff <= 1e-9


@pytest.mark.parametrize("kind", KINDS)
def test_sample_scene_through_a_bag_calibrates_to_the_same_pose(kind, tmp_path):
    cloud = read_point_cloud(SAMPLE / "scan.npz")  # organized 180 x 720, NaN where no return
    h, w = cloud.organized_shape
    cols = {a: cloud.xyz[:, i].copy() for i, a in enumerate("xyz")}  # float64
    image = load_image_rgb(SAMPLE / "image.png")
    scene = SceneBag(clouds=[CloudSpec(cols, organized_shape=(h, w))], cloud_times=[50.0], images=[image], image_times=[50.0])
    bag = write_bag(tmp_path / "bag", kind, scene)
    out = tmp_path / "extracted"
    proc = run_cli("bag", "extract", str(bag), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "no camera info" in proc.stdout and not (out / "camera.yaml").exists()
    camera = load_camera(SAMPLE / "camera.yaml")
    T_loose = _solve(SAMPLE / "scan.npz", camera, SAMPLE / "pairs.yaml")
    # An organized cloud is turned to the depth matrix's orientation on loading
    # (organize_grid may mirror it), so the pairs' cells are mapped through the
    # matrix's point_index: the same laser points, looked up in the new grid.
    depth = load_scan(out / "scan.pcd")
    where = {int(i): rc for rc, i in np.ndenumerate(depth.meta["point_index"]) if i >= 0}
    pairs = [dataclasses.replace(p, laser_rc=where[p.laser_rc[0] * w + p.laser_rc[1]]) for p in load_pairs_yaml(SAMPLE / "pairs.yaml")]
    points, bearings, pixels = resolve_pairs(pairs, depth, camera)
    T_bag = solve_extrinsics(points, bearings, camera=camera, pixels=pixels).T_camera_lidar
    diff = np.abs(T_bag - T_loose).max()
    print(f"\nsample via {kind} bag: max |T_bag - T_loose| = {diff:.3g}")
    assert diff <= 1e-9


def _cloud_msg(fields, point_step, row_step, data, height=1, width=2):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.LATEST)
    PF, Msg = ts.types["sensor_msgs/msg/PointField"], ts.types["sensor_msgs/msg/PointCloud2"]
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    return Msg(
        header=Header(stamp=Time(sec=1, nanosec=0), frame_id="lidar"), height=height, width=width,
        fields=[PF(name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields],
        is_bigendian=False, point_step=point_step, row_step=row_step, data=np.frombuffer(data, np.uint8), is_dense=True,
    )  # fmt: skip


XYZ = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)]


@pytest.mark.parametrize(
    "fields,point_step,row_step,nbytes,fragment",
    [
        (XYZ[:2], 12, 24, 24, "no z field"),
        (XYZ + [("i", 10, 7, 1)], 12, 24, 24, "overruns point_step"),
        (XYZ + [("i", 12, 9, 1)], 16, 32, 32, "unknown PointField datatype 9"),
        (XYZ + [("x", 0, 7, 1)], 12, 24, 24, "repeated field name"),
        (XYZ, 12, 20, 24, "row_step 20"),
        (XYZ, 12, 24, 23, "23 data bytes"),
    ],
)
def test_malformed_pointcloud2(fields, point_step, row_step, nbytes, fragment):
    from calib_core.io.bags import pointcloud2_to_cloud

    with pytest.raises(CalibError, match=fragment):
        pointcloud2_to_cloud(_cloud_msg(fields, point_step, row_step, bytes(nbytes)))


def test_organized_pointcloud2_with_row_padding():
    from calib_core.io.bags import pointcloud2_to_cloud

    # 2 rows x 2 points of 12 bytes, each row padded to 30 bytes; float32 little-endian by hand.
    values = np.arange(12, dtype="<f4").reshape(2, 2, 3)
    raw = b"".join(values[r].tobytes() + b"\xee" * 6 for r in range(2))
    cloud = pointcloud2_to_cloud(_cloud_msg(XYZ, 12, 30, raw, height=2, width=2))
    assert cloud.organized_shape == (2, 2)
    assert np.array_equal(cloud.xyz, values.reshape(4, 3).astype(np.float64))


@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "mono8", "bgra8", "mono16"])
def test_image_encodings_decode_to_rgb(encoding):
    import cv2
    from rosbags.typesys import Stores, get_typestore

    from calib_core.io.bags import image_to_rgb

    ts = get_typestore(Stores.LATEST)
    Image, Header, Time = ts.types["sensor_msgs/msg/Image"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    rgb = np.zeros((6, 8, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 200, 100, 30  # distinct channels reveal a swap
    if encoding == "rgb8":
        raw, expected = rgb, rgb
    elif encoding == "bgr8":
        raw, expected = rgb[..., ::-1], rgb
    elif encoding == "bgra8":
        raw, expected = np.dstack([rgb[..., ::-1], np.full((6, 8), 255, np.uint8)]), rgb
    else:
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        raw = grey if encoding == "mono8" else grey.astype(np.uint16) * 257
        expected = np.repeat(grey[..., None], 3, axis=2)
    raw = np.ascontiguousarray(raw)
    msg = Image(
        header=Header(stamp=Time(sec=0, nanosec=0), frame_id="cam"), height=6, width=8, encoding=encoding,
        is_bigendian=0, step=raw.strides[0], data=raw.view(np.uint8).ravel(),
    )  # fmt: skip
    got = image_to_rgb(msg)
    assert got.shape == (6, 8, 3) and got.dtype == np.uint8
    assert np.abs(got.astype(int) - expected.astype(int)).max() <= 1


def test_undecodable_image_is_one_line():
    from rosbags.typesys import Stores, get_typestore

    from calib_core.io.bags import image_to_rgb

    ts = get_typestore(Stores.LATEST)
    Msg, Header, Time = ts.types["sensor_msgs/msg/CompressedImage"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    msg = Msg(header=Header(stamp=Time(sec=0, nanosec=0), frame_id="cam"), format="jpeg", data=np.frombuffer(b"not a jpeg", np.uint8))
    with pytest.raises(CalibError, match="cannot decode image"):
        image_to_rgb(msg, "bag: /cam")
