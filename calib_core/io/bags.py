"""ROS bags without ROS: topics, point clouds, images, camera info and static TF.

Reads ROS 1 ``.bag`` files and ROS 2 bags (a folder with ``metadata.yaml`` and
``.db3`` or ``.mcap`` storage; the folder or any file in it may be given) with
the pure-Python ``rosbags`` package.  ROS 1 bags embed their message
definitions; ``ROS1_NOETIC`` (ROS 1) or the latest ROS 2 store is the fallback.

Conversions:

* ``sensor_msgs/PointCloud2`` -> :class:`~calib_core.io.scan_readers.PointCloud`
  from its ``PointField`` list (``offset``, ``datatype``, ``count``,
  ``point_step``, ``row_step``, ``is_bigendian``), keeping every field
  (``intensity``, ``ring``, ``time``/``t``, ...) in its own dtype;
* ``sensor_msgs/Image`` and ``CompressedImage`` -> RGB uint8 (``rosbags-image``);
* ``sensor_msgs/CameraInfo`` -> a camera of :mod:`calib_core.cameras` (K and D of
  the raw image: ``plumb_bob``/``rational_polynomial`` -> ``pinhole``,
  ``equidistant`` -> ``fisheye``);
* ``/tf_static`` -> ``T_camera_lidar`` between the cloud's and the image's
  ``frame_id``, composed along the static tree (TF: a transform from parent to
  child maps child points into the parent frame).

Times are the messages' ``header.stamp`` (the bag's receive time when the stamp
is zero), in seconds.  Every problem raises a one-line
:class:`~calib_core.errors.CalibError` naming the bag.
"""

from __future__ import annotations

import dataclasses
import io
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from ..errors import CalibError, one_line
from .extrinsic_formats import compose_tree
from .scan_readers import PointCloud

__all__ = [
    "BagInfo",
    "BagScene",
    "TopicInfo",
    "bag_info",
    "camera_info_to_camera",
    "image_to_rgb",
    "pointcloud2_to_cloud",
    "read_bag_scene",
    "write_bag_scene",
    "write_cloud_pcd",
    "POINTCLOUD2",
    "IMAGE_TYPES",
    "CAMERA_INFO",
    "TF_MESSAGE",
]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

# PointField datatypes -> numpy type characters (sensor_msgs/PointField constants 1..8).
_POINTFIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
# numpy kind + size -> the PCD TYPE letter.
_PCD_TYPE = {"f": "F", "u": "U", "i": "I"}


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: ``rate_hz`` from the first and last receive times (NaN for one message)."""

    name: str
    msgtype: str
    count: int
    rate_hz: float


@dataclass(frozen=True)
class BagInfo:
    """What :func:`bag_info` reports; times in seconds since the epoch."""

    path: Path
    kind: str
    start_s: float
    duration_s: float
    topics: list[TopicInfo]


@dataclass
class BagScene:
    """One lidar scan with the image nearest in time, as read from a bag.

    Attributes
    ----------
    cloud : PointCloud
        The scan in the cloud's ``frame_id`` (the lidar frame), metres.
    image : (H, W, 3) uint8
        RGB.
    camera : CameraModel or None
        From the CameraInfo topic, if one was given or found.
    cloud_index : int
        0-based index of the cloud on its topic.
    cloud_time_s, image_time_s : float
        ``header.stamp`` of both, seconds since the epoch.
    gap_s : float
        ``image_time_s - cloud_time_s``.
    lidar_frame, camera_frame : str
        The ``frame_id`` of the cloud and of the image.
    T_camera_lidar_tf : (4, 4) ndarray or None
        ``/tf_static`` between the two frames: the initial extrinsic on offer.
    cloud_topic, image_topic, camera_info_topic : str
        The topics read (``camera_info_topic`` None when there was none).
    notes : list of str
        What was chosen automatically, and warnings.
    """

    cloud: PointCloud
    image: np.ndarray
    camera: Any
    cloud_index: int
    cloud_time_s: float
    image_time_s: float
    gap_s: float
    lidar_frame: str
    camera_frame: str
    T_camera_lidar_tf: np.ndarray | None = None
    cloud_topic: str = ""
    image_topic: str = ""
    camera_info_topic: str | None = None
    notes: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------------------
# opening bags
# --------------------------------------------------------------------------------------


def _bag_path(path: str | os.PathLike) -> tuple[Path, bool]:
    """The path rosbags opens, and whether it is a ROS 2 bag."""
    path = Path(path)
    if not path.exists():
        raise CalibError(f"{path}: bag not found")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise CalibError(f"{path}: a folder but not a ROS 2 bag (no metadata.yaml)")
        return path, True
    suffix = path.suffix.lower()
    if suffix == ".bag":
        return path, False
    if suffix in (".db3", ".mcap", ".yaml"):
        if (path.parent / "metadata.yaml").is_file():
            return path.parent, True
        raise CalibError(f"{path}: a ROS 2 {suffix} file needs the metadata.yaml of its bag folder next to it")
    raise CalibError(f"{path}: not a ROS bag (expected a .bag file or a ROS 2 bag folder with metadata.yaml)")


class _Bag:
    """Context manager around ``rosbags.highlevel.AnyReader`` with one-line errors."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.given = Path(path)
        self.path, self.is2 = _bag_path(path)

    def __enter__(self):
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.LATEST if self.is2 else Stores.ROS1_NOETIC)
        try:
            self.reader = AnyReader([self.path], default_typestore=store)
            self.reader.open()
        except CalibError:
            raise
        except Exception as exc:  # rosbags raises many types for bad files
            raise CalibError(f"{self.given}: not a readable ROS bag ({one_line(exc)})") from None
        return self

    def __exit__(self, *exc) -> bool:
        try:
            self.reader.close()
        except Exception:  # noqa: BLE001 - closing a broken reader must not hide the first error
            pass
        return False

    def kind(self) -> str:
        if not self.is2:
            return "ROS1"
        storages = {p.suffix.lower() for p in self.path.iterdir()}
        return "ROS2 mcap" if ".mcap" in storages else "ROS2 sqlite3"

    def connections(self, topic: str, msgtypes: tuple[str, ...] | None = None) -> list:
        conns = [c for c in self.reader.connections if c.topic == topic]
        if not conns:
            names = sorted({c.topic for c in self.reader.connections})
            raise CalibError(f"{self.given}: no topic {topic!r} (topics: {', '.join(names)})")
        if msgtypes is not None and conns[0].msgtype not in msgtypes:
            raise CalibError(f"{self.given}: topic {topic!r} is {conns[0].msgtype}, expected {' or '.join(msgtypes)}")
        return conns

    def messages(self, conns) -> Iterator[tuple[int, Any]]:
        """``(receive time ns, message)`` of the given connections, in time order."""
        try:
            for conn, t_ns, raw in self.reader.messages(connections=conns):
                yield t_ns, self.reader.deserialize(raw, conn.msgtype)
        except CalibError:
            raise
        except Exception as exc:
            raise CalibError(f"{self.given}: unreadable message ({one_line(exc)})") from None

    def raw_times(self, conns) -> np.ndarray:
        try:
            return np.array([t for _, t, _ in self.reader.messages(connections=conns)], dtype=np.int64)
        except Exception as exc:
            raise CalibError(f"{self.given}: unreadable bag ({one_line(exc)})") from None


def _stamp_s(msg: Any, receive_ns: int) -> float:
    stamp = getattr(getattr(msg, "header", None), "stamp", None)
    if stamp is not None and (stamp.sec or stamp.nanosec):
        return stamp.sec + 1e-9 * stamp.nanosec
    return receive_ns * 1e-9


def _frame(msg: Any) -> str:
    return str(getattr(getattr(msg, "header", None), "frame_id", "") or "").lstrip("/")


# --------------------------------------------------------------------------------------
# bag summary
# --------------------------------------------------------------------------------------


def bag_info(path: str | os.PathLike) -> BagInfo:
    """Topics, types, message counts and rates of a bag."""
    with _Bag(path) as bag:
        r = bag.reader
        first: dict[str, int] = {}
        last: dict[str, int] = {}
        count: dict[str, int] = {}
        try:
            for conn, t_ns, _ in r.messages():  # one pass, nothing deserialized
                name = conn.topic
                count[name] = count.get(name, 0) + 1
                first[name] = min(first.get(name, t_ns), t_ns)
                last[name] = max(last.get(name, t_ns), t_ns)
        except Exception as exc:
            raise CalibError(f"{bag.given}: unreadable bag ({one_line(exc)})") from None
        topics = []
        for name, info in sorted(r.topics.items()):
            n = count.get(name, 0)
            span = (last.get(name, 0) - first.get(name, 0)) * 1e-9
            rate = (n - 1) / span if n > 1 and span > 0 else float("nan")
            topics.append(TopicInfo(name, info.msgtype or "(mixed types)", n, float(rate)))
        n_all = sum(count.values())
        start = r.start_time * 1e-9 if n_all else float("nan")
        duration = r.duration * 1e-9 if n_all else 0.0
        return BagInfo(bag.path, bag.kind(), start, duration, topics)


# --------------------------------------------------------------------------------------
# message conversions
# --------------------------------------------------------------------------------------


def pointcloud2_to_cloud(msg: Any, where: str = "PointCloud2") -> PointCloud:
    """A ``sensor_msgs/PointCloud2`` as a :class:`PointCloud` (no Python loop over points).

    The points keep the message's layout: an organized cloud (``height > 1``)
    is returned with ``organized_shape = (height, width)``.  ``x``, ``y``,
    ``z`` become float64 ``xyz``; every other field is kept in its own dtype
    (native byte order), ``(N, count)`` when ``count > 1``.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in msg.fields:
        name = str(f.name)
        if f.datatype not in _POINTFIELD_TYPES:
            raise CalibError(f"{where}: field {name!r} has unknown PointField datatype {f.datatype}")
        if not name or any(c.isspace() for c in name) or name in names:
            raise CalibError(f"{where}: bad or repeated field name {name!r}")
        count = max(int(f.count), 1)
        base = np.dtype(order + _POINTFIELD_TYPES[f.datatype])
        if f.offset + base.itemsize * count > point_step:
            raise CalibError(f"{where}: field {name!r} (offset {f.offset}, {count} x {base.itemsize} bytes) overruns point_step {point_step}")
        names.append(name)
        formats.append((base, (count,)) if count > 1 else base)
        offsets.append(int(f.offset))
    missing = [a for a in "xyz" if a not in names]
    if missing:
        raise CalibError(f"{where}: no {', '.join(missing)} field (fields: {', '.join(names) or 'none'})")
    n = height * width
    if n == 0:
        raise CalibError(f"{where}: the point cloud is empty")
    if row_step < width * point_step:
        raise CalibError(f"{where}: row_step {row_step} is less than width x point_step = {width * point_step}")
    data = np.frombuffer(memoryview(msg.data).cast("B"), dtype=np.uint8)
    if data.size < (height - 1) * row_step + width * point_step:
        raise CalibError(f"{where}: {data.size} data bytes for {height} x {width} points of {point_step} bytes")
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step})
    # Rows may carry padding beyond width * point_step: take each row's points, then view.
    rows = np.lib.stride_tricks.as_strided(data, shape=(height, width * point_step), strides=(row_step, 1))
    points = np.ascontiguousarray(rows).view(dtype).reshape(n)
    xyz = np.stack([points[a].astype(np.float64) for a in "xyz"], axis=1)
    fields = {k: points[k].astype(points[k].dtype.newbyteorder("=")) for k in names if k not in ("x", "y", "z")}
    meta = {"format": "ros_pointcloud2", "frame_id": _frame(msg)}
    return PointCloud(xyz=xyz, fields=fields, organized_shape=(height, width) if height > 1 else None, meta=meta)


def image_to_rgb(msg: Any, where: str = "image") -> np.ndarray:
    """A ``sensor_msgs/Image`` or ``CompressedImage`` as (H, W, 3) uint8 RGB."""
    from rosbags.image import message_to_cvimage

    try:
        img = message_to_cvimage(msg, "rgb8")
    except Exception as exc:  # unsupported encodings, bad data
        raise CalibError(f"{where}: cannot decode image ({one_line(exc)})") from None
    img = np.asarray(img)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise CalibError(f"{where}: decoded image has shape {img.shape} and type {img.dtype}, expected RGB uint8")
    return np.ascontiguousarray(img)


def camera_info_to_camera(msg: Any, image_size: tuple[int, int] | None = None, where: str = "CameraInfo"):
    """A ``sensor_msgs/CameraInfo`` as a camera model (intrinsics of the raw image: K and D).

    Parameters
    ----------
    msg : CameraInfo (ROS 1 ``K``/``D`` or ROS 2 ``k``/``d``)
    image_size : (width, height), optional
        Used when the message's size is 0 (some drivers leave it unset).
    """
    from ..cameras.io import camera_from_dict, ros_camera_info_to_dict

    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=np.float64)
    D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64)
    width, height = int(msg.width), int(msg.height)
    if (width == 0 or height == 0) and image_size is not None:
        width, height = image_size
    if image_size is not None and (width, height) != tuple(image_size):
        raise CalibError(f"{where}: says {width}x{height} but the image is {image_size[0]}x{image_size[1]}")
    if int(getattr(msg, "binning_x", 0)) > 1 or int(getattr(msg, "binning_y", 0)) > 1:
        raise CalibError(f"{where}: binned camera info (binning_x/y > 1) is not supported")
    data = {
        "image_width": width,
        "image_height": height,
        "camera_matrix": {"rows": 3, "cols": 3, "data": K.ravel().tolist()},
        "distortion_model": str(msg.distortion_model or "plumb_bob"),
        "distortion_coefficients": {"data": D.ravel().tolist()},
    }
    try:
        return camera_from_dict(ros_camera_info_to_dict(data))
    except CalibError as exc:
        raise CalibError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------------------
# static TF
# --------------------------------------------------------------------------------------


def _tf_edges(bag: _Bag) -> dict[tuple[str, str], np.ndarray]:
    """``{(parent, child): T_parent_child}`` of every ``/tf_static`` transform."""
    from ..transforms import R_from_quat_xyzw, make_T

    conns = [c for c in bag.reader.connections if c.topic.lstrip("/") == "tf_static" and c.msgtype == TF_MESSAGE]
    edges = {}
    for _, msg in bag.messages(conns) if conns else ():
        for ts in msg.transforms:
            t, q = ts.transform.translation, ts.transform.rotation
            try:
                edges[(_frame(ts), str(ts.child_frame_id).lstrip("/"))] = make_T(
                    R_from_quat_xyzw([q.x, q.y, q.z, q.w]), [t.x, t.y, t.z]
                )
            except CalibError:
                continue  # a broken transform elsewhere in the tree must not stop the rest
    return edges


# --------------------------------------------------------------------------------------
# one scene
# --------------------------------------------------------------------------------------


def _pick_topic(bag: _Bag, given: str | None, msgtypes: tuple[str, ...], what: str, option: str, notes: list[str]) -> str | None:
    if given is not None:
        bag.connections(given, msgtypes)
        return given
    names = sorted({c.topic for c in bag.reader.connections if c.msgtype in msgtypes})
    if len(names) == 1:
        notes.append(f"{what} topic: {names[0]} (the only one)")
        return names[0]
    if what == "camera info":
        return None
    if not names:
        raise CalibError(f"{bag.given}: no {what} topic ({' or '.join(msgtypes)})")
    raise CalibError(f"{bag.given}: several {what} topics ({', '.join(names)}); choose one with {option}")


def _nearest(bag: _Bag, conns, target_s: float, topic: str) -> tuple[float, Any]:
    """The message of ``conns`` whose stamp is nearest to ``target_s``, one message held at a time."""
    best: tuple[float, float, Any] | None = None
    for t_ns, msg in bag.messages(conns):
        stamp = _stamp_s(msg, t_ns)
        gap = abs(stamp - target_s)
        if best is None or gap < best[0]:
            best = (gap, stamp, msg)
        elif stamp - target_s > best[0] + 1.0:
            break  # stamps grow with the recording: nothing nearer follows
    if best is None:
        raise CalibError(f"{bag.given}: topic {topic} holds no messages")
    return best[1], best[2]


def _scene_of(where: str, topics: tuple[str, str, str | None], index: int, cloud_msg: Any, image_msg: Any,
              info_msg: Any, cloud_time_s: float, image_time_s: float,
              tf_edges: Callable[[], dict[tuple[str, str], np.ndarray]], notes: list[str]) -> BagScene:
    """Cloud ``index`` of a bag and its image as a :class:`BagScene`.

    ``topics``: the cloud, image and camera info topics; ``info_msg``: the CameraInfo (None: no camera);
    ``tf_edges``: gives the ``/tf_static`` tree, asked only when the cloud's and the image's frames differ.
    """
    cloud_topic, image_topic, info_topic = topics
    cloud = pointcloud2_to_cloud(cloud_msg, f"{where}: {cloud_topic} #{index}")
    image = image_to_rgb(image_msg, f"{where}: {image_topic}")
    camera = None
    if info_msg is not None:
        camera = camera_info_to_camera(info_msg, (image.shape[1], image.shape[0]), f"{where}: {info_topic}")
    lidar_frame, camera_frame = _frame(cloud_msg), _frame(image_msg)
    T_tf = None
    if lidar_frame and camera_frame and lidar_frame != camera_frame:
        T_tf = compose_tree(tf_edges(), camera_frame, lidar_frame)
    return BagScene(
        cloud=dataclasses.replace(cloud, meta={**cloud.meta, "source": f"{where}:{cloud_topic}#{index}"}),
        image=image, camera=camera, cloud_index=index, cloud_time_s=float(cloud_time_s),
        image_time_s=float(image_time_s), gap_s=float(image_time_s - cloud_time_s), lidar_frame=lidar_frame,
        camera_frame=camera_frame, T_camera_lidar_tf=T_tf, cloud_topic=cloud_topic, image_topic=image_topic,
        camera_info_topic=info_topic, notes=notes,
    )  # fmt: skip


def read_bag_scene(
    path: str | os.PathLike,
    cloud_topic: str | None = None,
    image_topic: str | None = None,
    camera_info_topic: str | None = None,
    time_s: float | None = None,
    index: int | None = None,
) -> BagScene:
    """Read one cloud and the image nearest to it in time.

    Parameters
    ----------
    path : path-like
        ``.bag``, or a ROS 2 bag folder (or a file in it).
    cloud_topic, image_topic, camera_info_topic : str, optional
        Default: the only topic of the right type (an error when there are
        several); no camera info when there is none.
    time_s : float, optional
        Choose the cloud received nearest to this time, in seconds after the
        bag's first message (the bag's timeline, as ``bag info`` shows it).
        The image is then paired by ``header.stamp``.
    index : int, optional
        Choose the cloud by its 0-based index on its topic (default 0).
        ``time_s`` and ``index`` exclude each other.
    """
    if time_s is not None and index is not None:
        raise CalibError("give either a time or an index, not both")
    if index is not None and index < 0:
        raise CalibError(f"index must be 0 or more, got {index}")
    if time_s is not None and not np.isfinite(time_s):
        raise CalibError(f"time must be a finite number of seconds, got {time_s}")
    notes: list[str] = []
    with _Bag(path) as bag:
        cloud_topic = _pick_topic(bag, cloud_topic, (POINTCLOUD2,), "point cloud", "--cloud-topic", notes)
        image_topic = _pick_topic(bag, image_topic, IMAGE_TYPES, "image", "--image-topic", notes)
        info_topic = _pick_topic(bag, camera_info_topic, (CAMERA_INFO,), "camera info", "--camera-info-topic", notes)

        cloud_conns = bag.connections(cloud_topic)
        n_clouds = sum(max(int(c.msgcount), 0) for c in cloud_conns)
        if time_s is not None:
            # The bag's own timeline (receive times), as `bag info` and bag players show it.
            times = bag.raw_times(cloud_conns)
            if not times.size:
                raise CalibError(f"{bag.given}: topic {cloud_topic} holds no messages")
            chosen = int(np.argmin(np.abs(times - (bag.reader.start_time + time_s * 1e9))))
        else:
            chosen = 0 if index is None else index
        cloud_msg = None
        for i, (t_ns, msg) in enumerate(bag.messages(cloud_conns)):  # stops at the chosen cloud
            if i == chosen:
                cloud_msg, cloud_time = msg, _stamp_s(msg, t_ns)
                break
        if cloud_msg is None:
            if n_clouds == 0:
                raise CalibError(f"{bag.given}: topic {cloud_topic} holds no messages")
            raise CalibError(f"{bag.given}: index {chosen} but {cloud_topic} has {n_clouds} clouds (0..{n_clouds - 1})")
        image_time, image_msg = _nearest(bag, bag.connections(image_topic), cloud_time, image_topic)
        info = None if info_topic is None else _nearest(bag, bag.connections(info_topic), image_time, info_topic)[1]
        scene = _scene_of(str(bag.given), (cloud_topic, image_topic, info_topic), chosen, cloud_msg, image_msg, info,
                          cloud_time, image_time, lambda: _tf_edges(bag), notes)
        if scene.T_camera_lidar_tf is not None:
            notes.append(f"/tf_static gives {scene.camera_frame} <- {scene.lidar_frame}: offered as the initial extrinsic")
            if "optical" not in scene.camera_frame:
                # ROS images live in an optical frame (z forward, x right, y down), as this package's camera frame.
                notes.append(
                    f"warning: the image frame {scene.camera_frame!r} is not named *optical*; if it is a body frame "
                    "(x forward) the initial extrinsic misses the optical rotation"
                )
    if abs(scene.gap_s) > 0.05:
        scene.notes.append(f"warning: the image is {1000 * scene.gap_s:+.1f} ms from the cloud; a moving rig blurs the calibration")
    return scene


def write_cloud_pcd(path: str | os.PathLike, cloud: PointCloud) -> None:
    """Write a cloud as a binary PCD (atomically), with every field and an organized cloud's grid."""
    from pypcd4 import Encoding, MetaData
    from pypcd4 import PointCloud as PcdCloud

    from .atomic import write_bytes_atomic

    xyz = np.asarray(cloud.xyz, dtype=np.float64)
    # float32 when that loses nothing (the usual PointCloud2 layout), else float64.
    as32 = xyz.astype(np.float32)
    if np.array_equal(as32.astype(np.float64), xyz, equal_nan=True):
        xyz = as32
    columns = [(a, xyz[:, i]) for i, a in enumerate("xyz")]
    columns += [(k, np.asarray(v)) for k, v in cloud.fields.items()]
    dtype = np.dtype([(k, v.dtype.newbyteorder("<"), v.shape[1:]) for k, v in columns])
    packed = np.empty(len(cloud.xyz), dtype=dtype)
    for k, v in columns:
        packed[k] = v
    h, w = cloud.organized_shape if cloud.organized_shape is not None else (1, len(cloud.xyz))
    meta = MetaData(
        fields=tuple(k for k, _ in columns),
        size=tuple(v.dtype.itemsize for _, v in columns),
        type=tuple(_PCD_TYPE[v.dtype.kind] for _, v in columns),
        count=tuple(int(np.prod(v.shape[1:], dtype=int)) for _, v in columns),
        width=w,
        height=h,
        points=len(cloud.xyz),
    )
    buf = io.BytesIO()
    PcdCloud(meta, packed.view(meta.build_dtype())).save(buf, encoding=Encoding.BINARY)
    write_bytes_atomic(path, buf.getvalue())


def write_bag_scene(scene: BagScene, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write ``scan.pcd``, ``image.png``, ``camera.yaml`` (when known) and
    ``initial_extrinsics.yaml`` (when ``/tf_static`` links the frames) into ``out_dir``.

    The scan keeps the message's float32 coordinates and every field, so
    reading it back gives the same points and rings as the message.
    """
    from ..cameras.io import save_camera_yaml
    from .extrinsics import save_extrinsics_yaml
    from .images import save_image_rgb

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise CalibError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    paths = {"scan": out / "scan.pcd", "image": out / "image.png"}
    if scene.camera is not None:
        paths["camera"] = out / "camera.yaml"
    if scene.T_camera_lidar_tf is not None:
        paths["initial_extrinsics"] = out / "initial_extrinsics.yaml"
    for p in paths.values():
        if os.path.lexists(p) and not p.is_file():
            raise CalibError(f"{p}: exists and is not a regular file; not replacing it")
    write_cloud_pcd(paths["scan"], scene.cloud)
    save_image_rgb(paths["image"], scene.image)
    if scene.camera is not None:
        save_camera_yaml(scene.camera, paths["camera"])
    if scene.T_camera_lidar_tf is not None:
        save_extrinsics_yaml(paths["initial_extrinsics"], scene.T_camera_lidar_tf)
    return paths
