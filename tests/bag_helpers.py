"""Write test bags with rosbags' own writers (ROS 1, ROS 2 sqlite3, ROS 2 mcap).

Messages are built here from plain arrays, independently of
``calib_core.io.bags``: the PointCloud2 layout (offsets, padding, byte order)
is laid out by hand so that the reader's handling of ``point_step``,
``row_step``, ``is_bigendian`` and ``count`` is checked against a known truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

# numpy dtype -> PointField datatype
_DATATYPE = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}

TF_MESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms\n"


@dataclass
class CloudSpec:
    """Arrays of one cloud: name -> (N,) or (N, k) array; x, y, z required."""

    columns: dict[str, np.ndarray]
    organized_shape: tuple[int, int] | None = None
    bigendian: bool = False
    pad_point: int = 0  # extra bytes at the end of each point
    pad_row: int = 0  # extra bytes at the end of each row


@dataclass
class SceneBag:
    clouds: list[CloudSpec]
    cloud_times: list[float]
    images: list[np.ndarray]  # RGB uint8
    image_times: list[float]
    K: np.ndarray | None = None
    D: np.ndarray | None = None
    distortion_model: str = "plumb_bob"
    lidar_frame: str = "velodyne"
    camera_frame: str = "camera_optical"
    # (parent, child, T_parent_child) for /tf_static
    static_tf: list[tuple[str, str, np.ndarray]] = field(default_factory=list)
    compressed_images: bool = False


def _typestore(ros1: bool):
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(get_types_from_msg(TF_MESSAGE_MSG, "tf2_msgs/msg/TFMessage"))
    return store


def _time(store, t: float):
    Time = store.types["builtin_interfaces/msg/Time"]
    sec = int(np.floor(t))
    return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))


def _header(store, ros1: bool, t: float, frame: str):
    Header = store.types["std_msgs/msg/Header"]
    if ros1:
        return Header(seq=0, stamp=_time(store, t), frame_id=frame)
    return Header(stamp=_time(store, t), frame_id=frame)


def pointcloud2(store, ros1: bool, spec: CloudSpec, t: float, frame: str):
    PointField = store.types["sensor_msgs/msg/PointField"]
    order = ">" if spec.bigendian else "<"
    names, formats, offsets, fields = [], [], [], []
    offset = 0
    for name, arr in spec.columns.items():
        count = 1 if arr.ndim == 1 else arr.shape[1]
        base = np.dtype(order + arr.dtype.str[1:])
        names.append(name)
        formats.append((base, (count,)) if count > 1 else base)
        offsets.append(offset)
        fields.append(PointField(name=name, offset=offset, datatype=_DATATYPE[arr.dtype.str[1:]], count=count))
        offset += base.itemsize * count
    point_step = offset + spec.pad_point
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step})
    n = len(spec.columns["x"])
    h, w = spec.organized_shape or (1, n)
    packed = np.zeros(n, dtype=dtype)
    for name, arr in spec.columns.items():
        packed[name] = arr
    rows = packed.view(np.uint8).reshape(h, w * point_step)
    row_step = w * point_step + spec.pad_row
    data = np.zeros((h, row_step), np.uint8)
    data[:, : w * point_step] = rows
    Msg = store.types["sensor_msgs/msg/PointCloud2"]
    return Msg(
        header=_header(store, ros1, t, frame), height=h, width=w, fields=fields, is_bigendian=spec.bigendian,
        point_step=point_step, row_step=row_step, data=data.ravel(), is_dense=False,
    )  # fmt: skip


def image_msg(store, ros1: bool, rgb: np.ndarray, t: float, frame: str, compressed: bool):
    if compressed:
        ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        assert ok
        Msg = store.types["sensor_msgs/msg/CompressedImage"]
        return Msg(header=_header(store, ros1, t, frame), format="png", data=buf.ravel())
    Msg = store.types["sensor_msgs/msg/Image"]
    h, w = rgb.shape[:2]
    return Msg(
        header=_header(store, ros1, t, frame), height=h, width=w, encoding="rgb8", is_bigendian=0,
        step=3 * w, data=np.ascontiguousarray(rgb).ravel(),
    )  # fmt: skip


def camera_info(store, ros1: bool, scene: SceneBag, size: tuple[int, int], t: float):
    Msg = store.types["sensor_msgs/msg/CameraInfo"]
    Roi = store.types["sensor_msgs/msg/RegionOfInterest"]
    K = np.asarray(scene.K, dtype=np.float64).ravel()
    P = np.zeros(12)
    P[[0, 1, 2, 4, 5, 6, 10]] = K[[0, 1, 2, 3, 4, 5, 8]]
    R = np.eye(3).ravel()
    D = np.asarray(scene.D, dtype=np.float64)
    kw = dict(D=D, K=K, R=R, P=P) if ros1 else dict(d=D, k=K, r=R, p=P)
    return Msg(
        header=_header(store, ros1, t, scene.camera_frame), height=size[1], width=size[0],
        distortion_model=scene.distortion_model, binning_x=0, binning_y=0,
        roi=Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False), **kw,
    )  # fmt: skip


def tf_message(store, ros1: bool, t: float, transforms: list[tuple[str, str, np.ndarray]]):
    from scipy.spatial.transform import Rotation

    TS = store.types["geometry_msgs/msg/TransformStamped"]
    Tr = store.types["geometry_msgs/msg/Transform"]
    V = store.types["geometry_msgs/msg/Vector3"]
    Q = store.types["geometry_msgs/msg/Quaternion"]
    out = []
    for parent, child, T in transforms:
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        out.append(
            TS(
                header=_header(store, ros1, t, parent), child_frame_id=child,
                transform=Tr(translation=V(x=T[0, 3], y=T[1, 3], z=T[2, 3]), rotation=Q(x=x, y=y, z=z, w=w)),
            )  # fmt: skip
        )
    return store.types["tf2_msgs/msg/TFMessage"](transforms=out)


def write_bag(path: Path, kind: str, scene: SceneBag) -> Path:
    """Write ``scene`` as a ROS 1 ``.bag`` (kind "ros1") or a ROS 2 bag folder ("sqlite3", "mcap")."""
    ros1 = kind == "ros1"
    store = _typestore(ros1)
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    msgs = []  # (time, topic, msgtype, message)
    image_type = "sensor_msgs/msg/CompressedImage" if scene.compressed_images else "sensor_msgs/msg/Image"
    image_topic = "/camera/image_raw/compressed" if scene.compressed_images else "/camera/image_raw"
    for spec, t in zip(scene.clouds, scene.cloud_times):
        msgs.append((t, "/points", "sensor_msgs/msg/PointCloud2", pointcloud2(store, ros1, spec, t, scene.lidar_frame)))
    for rgb, t in zip(scene.images, scene.image_times):
        msgs.append((t, image_topic, image_type, image_msg(store, ros1, rgb, t, scene.camera_frame, scene.compressed_images)))
        if scene.K is not None:
            size = (rgb.shape[1], rgb.shape[0])
            msgs.append((t, "/camera/camera_info", "sensor_msgs/msg/CameraInfo", camera_info(store, ros1, scene, size, t)))
    t0 = min(scene.cloud_times + scene.image_times)
    if scene.static_tf:
        msgs.append((t0, "/tf_static", "tf2_msgs/msg/TFMessage", tf_message(store, ros1, t0, scene.static_tf)))
    msgs.sort(key=lambda m: m[0])
    if ros1:
        from rosbags.rosbag1 import Writer

        path = path.with_suffix(".bag")
        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=plugin)
    with writer:
        conns = {}
        for t, topic, msgtype, msg in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            # Receive time a little after the stamp, as a recorder would see it.
            writer.write(conns[topic], int(round((t + 0.002) * 1e9)), serialize(msg, msgtype))
    return path
