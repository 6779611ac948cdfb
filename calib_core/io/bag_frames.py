"""Several frames of one ROS bag as shots: which frames to take, and their files.

A *frame* is one cloud of the cloud topic with the image whose ``header.stamp``
is nearest to the cloud's.  :func:`read_frame_table` reads the stamps of every
frame (and the rig's motion when the bag records it);
:func:`choose_frames` chooses frames, spread over the bag and still, or by
hand (times or indices); :func:`extract_frames` writes each chosen frame's scan
and image into a folder of its own; :func:`shots_from_bag` does all three.

Stillness
---------
A calibration shot needs the photo and the scan taken from the same pose.  How
far the rig moved between a frame's two stamps is judged from what the bag has:

* **A trajectory of the rig**, when the bag records one: the dynamic ``/tf``
  transform whose child frame is the lidar's frame or is linked to it by
  ``/tf_static`` (or by a transform that never changes on ``/tf``), e.g.
  ``odom -> base_link``, the most frequent if several; or else the pose of the only
  ``nav_msgs/Odometry`` topic.  The lidar's pose is interpolated at the cloud's
  and at the image's stamp (linear in position, spherical in rotation) and the
  motion between the two is its rotation angle ``theta`` (rad) and the
  displacement ``d`` of the lidar's origin (m).  A frame's *stillness cost* is
  ``theta + d / 10 m``: the angle by which the motion shifts a point 10 m
  away, in radians.  A frame whose stamps the trajectory does not cover has an
  unknown cost and is taken only when its part of the bag has nothing else.
* **Stamps only** (no trajectory): the cost is ``|image stamp - cloud stamp|``
  in seconds; a rig standing still or moving slowly is not told apart.

Spread
------
``N`` frames: the bag's timeline (receive times of the clouds) is cut into
``N`` windows of equal duration and each window gives its stillest frame (the
one nearest the window's centre among equal costs).  Windows without a cloud
are made up by the frames farthest in time from those already chosen.

Every problem raises a one-line :class:`~calib_core.errors.CalibError`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from ..errors import CalibError, one_line
from .bags import (
    CAMERA_INFO,
    IMAGE_TYPES,
    POINTCLOUD2,
    TF_MESSAGE,
    BagScene,
    _Bag,
    _bag_path,
    _frame,
    _pick_topic,
    _scene_of,
    _stamp_s,
    _tf_edges,
    write_bag_scene,
)
from .extrinsic_formats import compose_tree

__all__ = [
    "BagShot",
    "BagShots",
    "FrameTable",
    "REFERENCE_DISTANCE_M",
    "choose_frames",
    "default_frames_dir",
    "extract_frames",
    "read_frame_table",
    "shots_from_bag",
]

ODOMETRY = "nav_msgs/msg/Odometry"
#: A displacement of the lidar of d metres counts as d / REFERENCE_DISTANCE_M radians of motion.
REFERENCE_DISTANCE_M = 10.0
#: Above this gap between a frame's stamps a note warns of a blurred calibration (as ``bag extract`` does).
GAP_WARNING_S = 0.05


@dataclass
class FrameTable:
    """The stamps of every frame of a bag (one row per cloud), and the rig's motion when known.

    Attributes
    ----------
    where : str
        The bag, as given (for messages).
    cloud_topic, image_topic : str
    camera_info_topic : str or None
    duration_s : float
        The bag's duration (its timeline runs from 0 to this), seconds.
    time_s : (F,) ndarray
        Each cloud's receive time, seconds after the bag's first message (the timeline of ``bag info``).
    cloud_stamp_s, image_stamp_s : (F,) ndarray
        ``header.stamp`` of each cloud and of the image nearest to it, seconds since the epoch.
    image_index : (F,) int ndarray
        That image's 0-based index on the image topic.
    info_stamp_s : (C,) ndarray
        Stamps of the camera info messages (empty without a camera info topic).
    rotation_deg, translation_m : (F,) ndarray or None
        The lidar's rotation (degrees) and displacement (metres) between each
        frame's two stamps; NaN where the trajectory does not cover them; None
        without a trajectory.
    motion_source : str or None
        Where the trajectory came from, e.g. ``"/tf odom -> base_link"``.
    notes : list of str
    """

    where: str
    cloud_topic: str
    image_topic: str
    camera_info_topic: str | None
    duration_s: float
    time_s: np.ndarray
    cloud_stamp_s: np.ndarray
    image_stamp_s: np.ndarray
    image_index: np.ndarray
    info_stamp_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rotation_deg: np.ndarray | None = None
    translation_m: np.ndarray | None = None
    motion_source: str | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return len(self.time_s)

    @property
    def gap_s(self) -> np.ndarray:
        """``image stamp - cloud stamp`` of each frame, seconds."""
        return self.image_stamp_s - self.cloud_stamp_s

    @property
    def stillness_cost(self) -> np.ndarray:
        """Per frame, lower is stiller (module docstring): radians with a trajectory
        (``theta + d / REFERENCE_DISTANCE_M``, inf where unknown), else ``|gap|`` in seconds."""
        if self.rotation_deg is None:
            return np.abs(self.gap_s)
        cost = np.radians(self.rotation_deg) + self.translation_m / REFERENCE_DISTANCE_M
        return np.where(np.isfinite(cost), cost, np.inf)


@dataclass(frozen=True)
class BagShot:
    """One chosen frame, written to files: a shot (a scan and the photo taken with it).

    ``scan``, ``image`` and ``stamp_s`` (the cloud's ``header.stamp``, seconds since
    the epoch) are what a shot needs; the rest says how good the frame is.
    ``rotation_deg`` / ``translation_m`` are NaN when the motion is not known.
    """

    scan: Path
    image: Path
    stamp_s: float
    index: int
    time_s: float
    image_stamp_s: float
    gap_s: float
    camera: Path | None
    rotation_deg: float = float("nan")
    translation_m: float = float("nan")
    notes: tuple[str, ...] = ()

    def line(self) -> str:
        """One line for a terminal."""
        motion = ""
        if np.isfinite(self.rotation_deg):
            motion = f", rig moved {self.rotation_deg:.3f} deg / {100 * self.translation_m:.2f} cm"
        return (f"cloud #{self.index} at {self.time_s:.3f} s (stamp {self.stamp_s:.6f}), image gap "
                f"{1000 * self.gap_s:+.3f} ms{motion}")


@dataclass
class BagShots:
    """The shots taken from a bag; iterating gives the :class:`BagShot` objects, in time order.

    Attributes
    ----------
    shots : list of BagShot
    camera : Path or None
        ``camera.yaml`` of the first shot (from CameraInfo); None when the bag has none.
    T_camera_lidar_tf : (4, 4) ndarray or None
        ``/tf_static`` between the cloud's and the image's frames (maps lidar
        points into the camera frame, metres): the initial extrinsic on offer.
    initial_extrinsics : Path or None
        That transform as an extrinsics YAML (in the first shot's folder).
    lidar_frame, camera_frame : str
    motion_source : str or None
        The trajectory the stillness was judged from (None: stamps only).
    notes : list of str
    """

    shots: list[BagShot]
    camera: Path | None
    T_camera_lidar_tf: np.ndarray | None
    initial_extrinsics: Path | None
    lidar_frame: str
    camera_frame: str
    motion_source: str | None
    notes: list[str] = field(default_factory=list)

    def __iter__(self) -> Iterator[BagShot]:
        return iter(self.shots)

    def __len__(self) -> int:
        return len(self.shots)

    def __getitem__(self, k: int) -> BagShot:
        return self.shots[k]


# --------------------------------------------------------------------------------------
# the frame table
# --------------------------------------------------------------------------------------


def _stamps(bag: _Bag, conns) -> tuple[np.ndarray, np.ndarray]:
    """``(receive ns, header stamp s)`` of every message of ``conns``, in time order."""
    receive, stamps = [], []
    for t_ns, msg in bag.messages(conns):
        receive.append(t_ns)
        stamps.append(_stamp_s(msg, t_ns))
    return np.array(receive, dtype=np.int64), np.array(stamps, dtype=np.float64)


def _nearest_index(values: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Index into ``values`` (any order) of the value nearest to each target (the earlier one on a tie)."""
    order = np.argsort(values, kind="stable")
    ordered = values[order]
    if len(ordered) == 1:
        return np.zeros(len(targets), dtype=np.int64)
    k = np.clip(np.searchsorted(ordered, targets), 1, len(ordered) - 1)
    k = np.where(np.abs(targets - ordered[k - 1]) <= np.abs(ordered[k] - targets), k - 1, k)
    return order[k]


@dataclass
class _Trajectory:
    """Poses ``T_parent_child(t)`` of the rig: times (s, increasing), positions (m), quaternions (x, y, z, w)."""

    times: np.ndarray
    positions: np.ndarray
    quats: np.ndarray
    child: str
    source: str

    def lidar_motion(self, T_child_lidar: np.ndarray, t_a: np.ndarray, t_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (deg) and displacement (m) of the lidar between ``t_a`` and ``t_b``; NaN outside the trajectory."""
        from scipy.spatial.transform import Rotation, Slerp

        inside = (np.minimum(t_a, t_b) >= self.times[0]) & (np.maximum(t_a, t_b) <= self.times[-1])
        rot = np.full(len(t_a), np.nan)
        trans = np.full(len(t_a), np.nan)
        if not inside.any():
            return rot, trans
        slerp = Slerp(self.times, Rotation.from_quat(self.quats))
        ta, tb = t_a[inside], t_b[inside]
        Ra, Rb = slerp(ta), slerp(tb)
        pa = np.stack([np.interp(ta, self.times, self.positions[:, i]) for i in range(3)], axis=1)
        pb = np.stack([np.interp(tb, self.times, self.positions[:, i]) for i in range(3)], axis=1)
        R_cl, t_cl = T_child_lidar[:3, :3], T_child_lidar[:3, 3]
        # Lidar pose in the parent frame: R(t) R_cl, p(t) + R(t) t_cl.
        La, Lb = Ra * Rotation.from_matrix(R_cl), Rb * Rotation.from_matrix(R_cl)
        rot[inside] = np.degrees((La.inv() * Lb).magnitude())
        trans[inside] = np.linalg.norm((pb + Rb.apply(t_cl)) - (pa + Ra.apply(t_cl)), axis=1)
        return rot, trans


def _trajectory_from(times, positions, quats, child: str, source: str) -> _Trajectory | None:
    times = np.asarray(times, dtype=np.float64)
    if len(times) < 2:
        return None
    order = np.argsort(times, kind="stable")
    times, positions, quats = times[order], np.asarray(positions)[order], np.asarray(quats)[order]
    keep = np.concatenate([[True], np.diff(times) > 0])  # Slerp needs increasing times
    norms = np.linalg.norm(quats, axis=1)
    keep &= np.all(np.isfinite(positions), axis=1) & np.isfinite(norms) & (norms > 0)
    if keep.sum() < 2:
        return None
    return _Trajectory(times[keep], positions[keep], quats[keep], child, source)


def _rig_trajectory(bag: _Bag, lidar_frame: str, static_edges: dict, notes: list[str]) -> tuple[_Trajectory, np.ndarray] | None:
    """The rig's trajectory and ``T_child_lidar`` (module docstring), or None when the bag records none."""
    from ..transforms import R_from_quat_xyzw, make_T

    tf_conns = [c for c in bag.reader.connections if c.topic.lstrip("/") == "tf" and c.msgtype == TF_MESSAGE]
    samples: dict[tuple[str, str], list] = {}
    for _, msg in bag.messages(tf_conns) if tf_conns else ():
        for ts in msg.transforms:
            t, q, s = ts.transform.translation, ts.transform.rotation, ts.header.stamp
            samples.setdefault((_frame(ts), str(ts.child_frame_id).lstrip("/")), []).append(
                (s.sec + 1e-9 * s.nanosec, (t.x, t.y, t.z), (q.x, q.y, q.z, q.w)))
    # A transform that never changes is static even when sent on /tf (some recorders do): it links frames.
    linked, moving = dict(static_edges), {}
    for edge, rows in samples.items():
        pose = np.array([(*p, *q) for _, p, q in rows], dtype=np.float64)
        if np.ptp(pose, axis=0).max() == 0.0:
            try:
                linked[edge] = make_T(R_from_quat_xyzw(pose[0, 3:]), pose[0, :3])
            except CalibError:
                pass
        else:
            moving[edge] = rows
    candidates = []
    for (parent, child), rows in moving.items():
        T_child_lidar = np.eye(4) if child == lidar_frame else compose_tree(linked, child, lidar_frame)
        parent_linked = parent == lidar_frame or compose_tree(linked, parent, lidar_frame) is not None
        if T_child_lidar is not None and not parent_linked:  # the rig itself moving, not a joint within it
            candidates.append((len(rows), parent, child, T_child_lidar))
    if not candidates and len(moving) == 1:
        (parent, child), = moving
        notes.append(f"/tf {parent} -> {child} is taken as the rig's motion (no /tf_static links it to {lidar_frame or 'the lidar'})")
        candidates.append((len(moving[(parent, child)]), parent, child, np.eye(4)))
    if candidates:
        _, parent, child, T_child_lidar = max(candidates, key=lambda c: c[0])
        rows = samples[(parent, child)]
        traj = _trajectory_from([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows], child,
                                f"/tf {parent} -> {child}")
        if traj is not None:
            return traj, T_child_lidar
    odometry = sorted({c.topic for c in bag.reader.connections if c.msgtype == ODOMETRY})
    if len(odometry) > 1:
        notes.append(f"several odometry topics ({', '.join(odometry)}): the rig's motion is not used")
    if len(odometry) != 1:
        return None
    times, positions, quats, child = [], [], [], ""
    for t_ns, msg in bag.messages(bag.connections(odometry[0])):
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        times.append(_stamp_s(msg, t_ns))
        positions.append((p.x, p.y, p.z))
        quats.append((q.x, q.y, q.z, q.w))
        child = str(msg.child_frame_id).lstrip("/")
    T_child_lidar = np.eye(4) if child in ("", lidar_frame) else compose_tree(static_edges, child, lidar_frame)
    if T_child_lidar is None:
        notes.append(f"{odometry[0]}: no /tf_static links {child} to {lidar_frame}; its pose is taken as the lidar's")
        T_child_lidar = np.eye(4)
    traj = _trajectory_from(times, positions, quats, child, f"{odometry[0]} (nav_msgs/Odometry)")
    return None if traj is None else (traj, T_child_lidar)


def read_frame_table(
    path: str | os.PathLike,
    cloud_topic: str | None = None,
    image_topic: str | None = None,
    camera_info_topic: str | None = None,
) -> FrameTable:
    """The stamps of every frame of a bag, and the rig's motion between each frame's two stamps.

    Parameters
    ----------
    path : path-like
        ``.bag``, or a ROS 2 bag folder (or a file in it).
    cloud_topic, image_topic, camera_info_topic : str, optional
        Default: the only topic of the right type (an error when there are
        several); no camera info when there is none.
    """
    notes: list[str] = []
    with _Bag(path) as bag:
        cloud_topic = _pick_topic(bag, cloud_topic, (POINTCLOUD2,), "point cloud", "--cloud-topic", notes)
        image_topic = _pick_topic(bag, image_topic, IMAGE_TYPES, "image", "--image-topic", notes)
        info_topic = _pick_topic(bag, camera_info_topic, (CAMERA_INFO,), "camera info", "--camera-info-topic", notes)
        cloud_ns, cloud_stamp = _stamps(bag, bag.connections(cloud_topic))
        if not len(cloud_ns):
            raise CalibError(f"{bag.given}: topic {cloud_topic} holds no messages")
        _, image_stamp = _stamps(bag, bag.connections(image_topic))
        if not len(image_stamp):
            raise CalibError(f"{bag.given}: topic {image_topic} holds no messages")
        info_stamp = _stamps(bag, bag.connections(info_topic))[1] if info_topic is not None else np.zeros(0)
        image_index = _nearest_index(image_stamp, cloud_stamp)
        start_ns, duration_s = bag.reader.start_time, bag.reader.duration * 1e-9

        # The lidar's frame, from the first cloud (all clouds of a topic share it).
        lidar_frame = ""
        for _, msg in bag.messages(bag.connections(cloud_topic)):
            lidar_frame = _frame(msg)
            break
        static_edges = _tf_edges(bag)
        found = _rig_trajectory(bag, lidar_frame, static_edges, notes)
    table = FrameTable(
        where=str(bag.given), cloud_topic=cloud_topic, image_topic=image_topic, camera_info_topic=info_topic,
        duration_s=float(duration_s), time_s=(cloud_ns - start_ns) * 1e-9, cloud_stamp_s=cloud_stamp,
        image_stamp_s=image_stamp[image_index], image_index=image_index.astype(np.int64), info_stamp_s=info_stamp,
        notes=notes,
    )  # fmt: skip
    if found is not None:
        traj, T_child_lidar = found
        table.rotation_deg, table.translation_m = traj.lidar_motion(T_child_lidar, table.cloud_stamp_s, table.image_stamp_s)
        table.motion_source = traj.source
        n_unknown = int(np.sum(~np.isfinite(table.rotation_deg)))
        notes.append(f"the rig's motion between each cloud and its image: from {traj.source}"
                     + (f" ({n_unknown} of {table.n_frames} frames outside it)" if n_unknown else ""))
    else:
        notes.append("no /tf or odometry of the rig: stillness judged by the cloud-to-image stamp gap alone")
    return table


# --------------------------------------------------------------------------------------
# choosing frames
# --------------------------------------------------------------------------------------


def _spread_and_still(table: FrameTable, n: int) -> list[int]:
    t, cost = table.time_s, table.stillness_cost
    lo, hi = float(t.min()), float(t.max())
    edges = np.linspace(lo, hi, n + 1)
    window = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n - 1)
    chosen: list[int] = []
    for w in range(n):  # a loop over the n windows
        members = np.flatnonzero(window == w)
        if members.size:
            centre = 0.5 * (edges[w] + edges[w + 1])
            best = np.lexsort((np.abs(t[members] - centre), cost[members]))[0]
            chosen.append(int(members[best]))
    while len(chosen) < n:  # empty windows: the frame farthest in time from those chosen, then the stillest
        free = np.setdiff1d(np.arange(len(t)), chosen)
        distance = np.min(np.abs(t[free, None] - t[None, chosen]), axis=1)
        chosen.append(int(free[np.lexsort((cost[free], -distance))[0]]))
    return sorted(chosen)


def choose_frames(
    table: FrameTable,
    frames: int | None = None,
    times: Sequence[float] | None = None,
    indices: Sequence[int] | None = None,
) -> list[int]:
    """The frames (cloud indices, increasing) to take as shots.

    Parameters
    ----------
    table : FrameTable
        From :func:`read_frame_table`.
    frames : int, optional
        Choose this many, spread over the bag and preferring still moments
        (module docstring: *Stillness*, *Spread*).
    times : sequence of float, optional
        By hand: for each time (seconds after the bag's start, the timeline
        of ``bag info``), the cloud received nearest to it.
    indices : sequence of int, optional
        By hand: 0-based cloud indices on the cloud topic.

    Exactly one of the three is given.

    Raises
    ------
    CalibError
        More frames asked than the bag has, a time outside the bag, an index
        out of range, or two requests that choose the same frame.
    """
    where, n_all = table.where, table.n_frames
    given = [name for name, v in (("a number of frames", frames), ("times", times), ("indices", indices)) if v is not None]
    if len(given) != 1:
        raise CalibError("choose frames by a number of frames, by times or by indices: give exactly one"
                         + (f" (got {' and '.join(given)})" if given else ""))
    if frames is not None:
        if isinstance(frames, bool) or int(frames) != frames or frames < 1:
            raise CalibError(f"the number of frames must be 1 or more, got {frames}")
        if frames > n_all:
            raise CalibError(f"{where}: {frames} frames asked but {table.cloud_topic} has only {n_all} cloud"
                             f"{'s' if n_all != 1 else ''}")
        return _spread_and_still(table, int(frames))
    if times is not None:
        if not len(times):
            raise CalibError("give at least one time")
        chosen = []
        for t in times:
            if not np.isfinite(t) or t < 0.0 or t > table.duration_s:
                raise CalibError(f"{where}: time {t} s is outside the bag (0 to {table.duration_s:.3f} s after its start)")
            chosen.append(int(np.argmin(np.abs(table.time_s - t))))
        requests = list(times)
    else:
        if not len(indices):
            raise CalibError("give at least one index")
        chosen = []
        for i in indices:
            if int(i) != i or not 0 <= i < n_all:
                raise CalibError(f"{where}: index {i} but {table.cloud_topic} has {n_all} clouds (0..{n_all - 1})")
            chosen.append(int(i))
        requests = list(indices)
    seen: dict[int, Any] = {}
    for request, k in zip(requests, chosen):
        if k in seen:
            what = "times" if times is not None else "indices"
            raise CalibError(f"{where}: {what} {seen[k]} and {request} both choose cloud #{k}; each shot needs its own frame")
        seen[k] = request
    return sorted(chosen)


# --------------------------------------------------------------------------------------
# writing the chosen frames
# --------------------------------------------------------------------------------------


def default_frames_dir(bag: str | os.PathLike, session: str | os.PathLike | None = None) -> Path:
    """Where a bag's frames go: beside the session file (``<session stem>.frames``), else ``./<bag name>.ba-calib-frames``."""
    if session is not None:
        s = Path(session)
        return s.parent / f"{s.stem}.frames"
    path, _ = _bag_path(bag)
    name = path.name if path.is_dir() else path.stem
    return Path.cwd() / f"{name}.ba-calib-frames"


def _raw_at(bag: _Bag, conns, wanted: set[int]) -> dict[int, Any]:
    """The deserialized messages of ``conns`` at the given 0-based positions (only those are deserialized)."""
    out: dict[int, Any] = {}
    if not wanted:
        return out
    last = max(wanted)
    try:
        for i, (conn, t_ns, raw) in enumerate(bag.reader.messages(connections=conns)):
            if i in wanted:
                out[i] = (t_ns, bag.reader.deserialize(raw, conn.msgtype))
            if i >= last:
                break
    except Exception as exc:  # rosbags raises many types for bad data
        raise CalibError(f"{bag.given}: unreadable message ({one_line(exc)})") from None
    return out


def extract_frames(
    path: str | os.PathLike,
    table: FrameTable,
    indices: Sequence[int],
    out_dir: str | os.PathLike,
) -> BagShots:
    """Write each chosen frame into ``out_dir/frame_NNNNN/`` (atomically): ``scan.pcd``, ``image.png``,
    ``camera.yaml`` (from CameraInfo) and ``initial_extrinsics.yaml`` (when ``/tf_static`` links the frames),
    as :func:`calib_core.io.bags.write_bag_scene` writes one frame.

    Parameters
    ----------
    path : path-like
        The bag the table was read from.
    table : FrameTable
    indices : sequence of int
        Cloud indices, e.g. from :func:`choose_frames`.
    out_dir : path-like
        Made when missing.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise CalibError(f"{out}: exists and is not a folder")
    indices = sorted(int(i) for i in indices)
    for i in indices:
        if not 0 <= i < table.n_frames:
            raise CalibError(f"{table.where}: index {i} but {table.cloud_topic} has {table.n_frames} clouds")
    image_wanted = {int(table.image_index[i]) for i in indices}
    info_for = {}
    if table.camera_info_topic is not None and len(table.info_stamp_s):
        near = _nearest_index(table.info_stamp_s, table.image_stamp_s[indices])
        info_for = {i: int(k) for i, k in zip(indices, near)}
    with _Bag(path) as bag:
        clouds = _raw_at(bag, bag.connections(table.cloud_topic), set(indices))
        images = _raw_at(bag, bag.connections(table.image_topic), image_wanted)
        infos = _raw_at(bag, bag.connections(table.camera_info_topic), set(info_for.values())) if info_for else {}
        static_edges = _tf_edges(bag)
    shots: list[BagShot] = []
    notes = list(table.notes)
    first_scene: BagScene | None = None
    first_paths: dict[str, Path] = {}
    camera_texts = set()
    for i in indices:
        if i not in clouds or int(table.image_index[i]) not in images:
            raise CalibError(f"{table.where}: cloud #{i} or its image could not be read again (the bag changed?)")
        gap = float(table.image_stamp_s[i] - table.cloud_stamp_s[i])
        frame_notes = [f"warning: the image is {1000 * gap:+.1f} ms from the cloud"] if abs(gap) > GAP_WARNING_S else []
        scene = _scene_of(table.where, (table.cloud_topic, table.image_topic, table.camera_info_topic), i,
                          clouds[i][1], images[int(table.image_index[i])][1],
                          infos[info_for[i]][1] if i in info_for else None, table.cloud_stamp_s[i],
                          table.image_stamp_s[i], lambda: static_edges, frame_notes)
        paths = write_bag_scene(scene, out / f"frame_{i:05d}")
        if "camera" in paths:
            camera_texts.add(paths["camera"].read_bytes())
        if first_scene is None:
            first_scene, first_paths = scene, paths
        rot = float(table.rotation_deg[i]) if table.rotation_deg is not None else float("nan")
        trans = float(table.translation_m[i]) if table.translation_m is not None else float("nan")
        shots.append(BagShot(
            scan=paths["scan"], image=paths["image"], stamp_s=float(table.cloud_stamp_s[i]), index=i,
            time_s=float(table.time_s[i]), image_stamp_s=float(table.image_stamp_s[i]), gap_s=gap,
            camera=paths.get("camera"), rotation_deg=rot, translation_m=trans, notes=tuple(frame_notes),
        ))  # fmt: skip
    if len(camera_texts) > 1:
        notes.append("warning: the camera info differs between the chosen frames; the first frame's camera is used")
    assert first_scene is not None
    if first_scene.T_camera_lidar_tf is not None:
        notes.append(f"/tf_static gives {first_scene.camera_frame} <- {first_scene.lidar_frame}: "
                     "offered as the initial extrinsic")
    return BagShots(
        shots=shots, camera=first_paths.get("camera"), T_camera_lidar_tf=first_scene.T_camera_lidar_tf,
        initial_extrinsics=first_paths.get("initial_extrinsics"), lidar_frame=first_scene.lidar_frame,
        camera_frame=first_scene.camera_frame, motion_source=table.motion_source, notes=notes,
    )  # fmt: skip


def shots_from_bag(
    bag: str | os.PathLike,
    frames: int | None = None,
    times: Sequence[float] | None = None,
    indices: Sequence[int] | None = None,
    out_dir: str | os.PathLike | None = None,
    *,
    cloud_topic: str | None = None,
    image_topic: str | None = None,
    camera_info_topic: str | None = None,
) -> BagShots:
    """Choose frames of a bag and write them as shots (one call for ``serve --bag --frames``).

    Parameters
    ----------
    bag : path-like
        ``.bag``, or a ROS 2 bag folder (or a file in it).
    frames, times, indices
        Exactly one: see :func:`choose_frames`.
    out_dir : path-like, optional
        Where the frames go (default :func:`default_frames_dir` of the bag); pass
        ``default_frames_dir(bag, session)`` to put them beside a session file.
    cloud_topic, image_topic, camera_info_topic : str, optional
        Default: the bag's only topic of that type.

    Returns
    -------
    BagShots
        One :class:`BagShot` per chosen frame (``scan``, ``image``, ``stamp_s``, ...),
        in time order, with the bag's camera file and ``/tf_static`` extrinsic.
    """
    table = read_frame_table(bag, cloud_topic, image_topic, camera_info_topic)
    chosen = choose_frames(table, frames=frames, times=times, indices=indices)
    return extract_frames(bag, table, chosen, default_frames_dir(bag) if out_dir is None else out_dir)
