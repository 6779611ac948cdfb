"""Extrinsics in the formats of the robotics toolchain: export and import.

A registry keyed by format name (:data:`FORMATS`).  Every export states in a
comment or a field which frame it maps into which, and carries a
machine-readable ``ba-calib-frames: lidar=<L> camera=<C>`` marker (a JSON field
in the JSON formats) so that reading it back never has to guess.

Directions (``T_a_b`` maps points of frame b into frame a; ``T_camera_lidar``
is this package's pose):

==========  =====================================================================
``ros1-tf``  ``static_transform_publisher x y z qx qy qz qw parent child``:
             ``T_parent_child`` (TF: the pose of the child in the parent)
``ros2-tf``  ``--x --y --z --qx --qy --qz --qw --frame-id --child-frame-id``:
             ``T_parent_child``
``urdf``     ``<joint type="fixed">`` with ``<origin xyz rpy>``: ``T_parent_child``
             (rpy: fixed axes, ``R = Rz(yaw) Ry(pitch) Rx(roll)``, radians)
``autoware`` ``sensor_kit_calibration.yaml``, ``parent: {child: {x, y, z, roll,
             pitch, yaw}}``: ``T_parent_child`` (radians)
``opencalib`` ``{"<lidar>-to-<camera>-extrinsic": ... sensor_calib data}``: the
             4x4 ``T_camera_lidar`` (OpenCalib's lidar-to-camera convention)
``dvlc``     direct_visual_lidar_calibration's ``calib.json``, ``results.T_lidar_camera =
             [x, y, z, qx, qy, qz, qw]``: ``T_lidar_camera``
``kitti``    ``Tr_velo_to_cam: 12 numbers``: the 3x4 of ``T_camera_lidar``; read from a
             full KITTI calib file (``P0``..``P3``, ``R0_rect``), the pose of the
             rectified camera 2 (``kitti_camera``), as KITTI projects into its images
``matrix``   a plain 4x4, ``T_parent_child`` (so both directions, chosen by the
             order of the frames)
==========  =====================================================================

With the default frames (parent ``lidar``, child ``camera``) the TF-like
formats hold ``T_lidar_camera = inv(T_camera_lidar)``; swap the frames for the
other direction.
"""

from __future__ import annotations

import json
import os
import re
import xml.etree.ElementTree as ET
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import yaml

from ..errors import CalibError
from ..transforms import R_from_quat_xyzw, R_from_rpy_deg, invert_T, make_T, quat_xyzw_from_R, rpy_deg_from_R
from .input_files import MAX_EXTRINSICS_BYTES, read_input_text
from .kitti_calib import DEFAULT_KITTI_CAMERA, kitti_T_camera_lidar, parse_kitti_calib

__all__ = [
    "FORMATS",
    "ExtrinsicFormat",
    "ParsedExtrinsics",
    "export_extrinsics",
    "parse_extrinsics",
    "read_extrinsics_any",
    "load_extrinsics_any",
    "lidar_and_camera",
    "compose_tree",
    "FrameHint",
]

MARKER = "ba-calib-frames"
_FRAME_RE = re.compile(r"^[A-Za-z0-9_./:-]+$")
# Name fragments that identify a frame as a camera or a lidar when no marker says so.
_CAMERA_HINTS = re.compile(r"cam|optical|image|rgb|color|colour", re.IGNORECASE)
_LIDAR_HINTS = re.compile(
    r"lidar|velo|laser|livox|ouster|os_sensor|os1|os0|os2|hesai|pandar|rslidar|robosense|vlp|hdl|lms|scan|pointcloud",
    re.IGNORECASE,
)


@dataclass(frozen=True)
class ParsedExtrinsics:
    """An extrinsic read from a file.

    Attributes
    ----------
    T_camera_lidar : (4, 4) ndarray
        Maps lidar points into the camera frame, metres.
    format : str
        Name of the format found (a key of :data:`FORMATS`, or ``"ba-calib"``).
    lidar_frame, camera_frame : str or None
        The frame names the file used, when it names them.
    """

    T_camera_lidar: np.ndarray
    format: str
    lidar_frame: str | None = None
    camera_frame: str | None = None


class FrameHint(NamedTuple):
    """Frame names a caller knows: which frame is the lidar's, which the camera's (None: unknown); and which
    rectified camera (0-3) a full KITTI calib file's extrinsic is for."""

    lidar: str | None = None
    camera: str | None = None
    kitti_camera: int = DEFAULT_KITTI_CAMERA


@dataclass(frozen=True)
class ExtrinsicFormat:
    """One entry of :data:`FORMATS`.

    ``write(T_camera_lidar, parent, child, lidar, camera)`` returns the file text;
    ``read(text, hint)`` returns a :class:`ParsedExtrinsics` (``hint``: a :class:`FrameHint`).
    """

    name: str
    suffix: str
    description: str
    write: Callable[[np.ndarray, str, str, str, str], str]
    read: Callable[[str, "FrameHint"], ParsedExtrinsics]


# --------------------------------------------------------------------------------------
# frames and small helpers
# --------------------------------------------------------------------------------------


def _check_frame(name: str, what: str) -> str:
    if not isinstance(name, str) or not _FRAME_RE.match(name):
        raise CalibError(f"{what} {name!r}: use letters, digits and _ . / : - only")
    return name


def lidar_and_camera(a: str, b: str, lidar_frame: str | None = None) -> tuple[str, str]:
    """Which of two frame names is the lidar: ``(lidar, camera)``.

    ``lidar_frame`` decides when given (it must be ``a`` or ``b``); otherwise a
    name that looks like a camera (``cam``, ``optical``, ...) or, failing that,
    like a lidar (``lidar``, ``velodyne``, ``os_sensor``, ...) decides.  Names
    that tell nothing raise :class:`CalibError` rather than guessing.
    """
    if a == b:
        raise CalibError(f"the two frames must differ, got {a!r} twice")
    if lidar_frame is not None:
        if lidar_frame not in (a, b):
            raise CalibError(f"lidar frame {lidar_frame!r} is neither {a!r} nor {b!r}")
        return (a, b) if lidar_frame == a else (b, a)
    cam_a, cam_b = bool(_CAMERA_HINTS.search(a)), bool(_CAMERA_HINTS.search(b))
    if cam_a != cam_b:
        return (b, a) if cam_a else (a, b)
    lid_a, lid_b = bool(_LIDAR_HINTS.search(a)), bool(_LIDAR_HINTS.search(b))
    if lid_a != lid_b:
        return (a, b) if lid_a else (b, a)
    raise CalibError(f"cannot tell which of the frames {a!r} and {b!r} is the lidar; name it (--lidar-frame)")


def _T_parent_child(T_camera_lidar: np.ndarray, parent: str, lidar: str) -> np.ndarray:
    """The TF transform from parent to child (maps child points into the parent frame) of ``T_camera_lidar``,
    and, the map being its own inverse, ``T_camera_lidar`` of a ``T_parent_child``."""
    return invert_T(T_camera_lidar) if parent == lidar else np.asarray(T_camera_lidar, dtype=np.float64)


def _direction_line(parent: str, child: str) -> str:
    return f"maps {child} points into the {parent} frame: X_{parent} = T_{parent}_{child} @ X_{child}"


def _marker(lidar: str, camera: str) -> str:
    return f"{MARKER}: lidar={lidar} camera={camera}"


def _find_marker(text: str) -> tuple[str, str] | None:
    m = re.search(MARKER + r":\s*lidar=([A-Za-z0-9_./:-]+)\s+camera=([A-Za-z0-9_./:-]+)", text)
    return (m.group(1), m.group(2)) if m else None


def _r(x: float) -> str:
    """Shortest round-trip representation of a float (exact on reading back)."""
    return repr(float(x))


def _numbers(values, count: int, where: str) -> np.ndarray:
    try:
        out = np.array([float(v) for v in values], dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibError(f"{where}: expected {count} numbers, got {values!r}") from None
    if out.size != count:
        raise CalibError(f"{where}: expected {count} numbers, got {out.size}")
    if not np.all(np.isfinite(out)):
        raise CalibError(f"{where}: numbers must be finite")
    return out


def _quat_T(xyz, q, where: str) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    if not 0.99 < np.linalg.norm(q) < 1.01:
        raise CalibError(f"{where}: quaternion must have unit norm, got norm {np.linalg.norm(q):.4f}")
    return make_T(R_from_quat_xyzw(q), xyz)


def _rpy_rad_T(xyz, rpy_rad) -> np.ndarray:
    return make_T(R_from_rpy_deg(np.degrees(rpy_rad)), xyz)


def _check_rigid(T: np.ndarray, where: str) -> np.ndarray:
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise CalibError(f"{where}: the 3x3 rotation block is not a proper rotation (orthonormal, det +1)")
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise CalibError(f"{where}: last row must be [0, 0, 0, 1]")
    return T


def _frames_for_reading(text: str, parent: str, child: str, lidar_frame: str | None) -> tuple[str, str]:
    found = _find_marker(text)
    if lidar_frame is None and found is not None and set(found) == {parent, child}:
        lidar_frame = found[0]
    return lidar_and_camera(parent, child, lidar_frame)


def compose_tree(edges: dict[tuple[str, str], np.ndarray], target: str, source: str) -> np.ndarray | None:
    """``T_target_source`` along a tree of ``{(parent, child): T_parent_child}`` (TF/URDF
    convention: ``T_parent_child`` maps child points into the parent frame), or None
    when no chain links the two frames.  Breadth-first: the shortest chain."""
    graph: dict[str, list[tuple[str, np.ndarray]]] = {}
    for (parent, child), T in edges.items():
        graph.setdefault(child, []).append((parent, T))
        graph.setdefault(parent, []).append((child, invert_T(T)))
    found = {source: np.eye(4)}  # frame -> T_frame_source
    queue = deque([source])
    while queue:
        frame = queue.popleft()
        if frame == target:
            return found[frame]
        for other, T_other_frame in graph.get(frame, ()):
            if other not in found:
                found[other] = T_other_frame @ found[frame]
                queue.append(other)
    return None


def _from_edges(edges: list[tuple[str, str, np.ndarray]], hint: "FrameHint", text: str, fmt: str) -> ParsedExtrinsics:
    """One transform, or the chain between the lidar and the camera frame of several."""
    if len(edges) == 1:
        parent, child, T = edges[0]
        lidar, camera = _frames_for_reading(text, parent, child, hint.lidar)
        return ParsedExtrinsics(_T_parent_child(T, parent, lidar), fmt, lidar, camera)
    lidar, camera = hint.lidar, hint.camera
    marker = _find_marker(text)
    if (lidar is None or camera is None) and marker is not None:
        lidar, camera = lidar or marker[0], camera or marker[1]
    if lidar is None or camera is None:
        raise CalibError(f"{fmt}: {len(edges)} transforms; name the lidar and the camera frame to choose the chain between them")
    T = compose_tree({(p, c): T for p, c, T in edges}, camera, lidar)
    if T is None:
        raise CalibError(f"{fmt}: no chain of transforms links {lidar!r} and {camera!r}")
    return ParsedExtrinsics(T, fmt, lidar, camera)


# --------------------------------------------------------------------------------------
# ros1-tf / ros2-tf
# --------------------------------------------------------------------------------------


def _tf_header(parent: str, child: str, lidar: str, camera: str, ros: str) -> str:
    return (
        f"# ROS {ros} static transform from {parent} to {child}: {_direction_line(parent, child)}\n"
        f"# (TF convention: the pose of {child} in {parent}; quaternion x y z w)\n"
        f"# {_marker(lidar, camera)}\n"
    )


def _write_ros1(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = _T_parent_child(T_camera_lidar, parent, lidar)
    q = quat_xyzw_from_R(T[:3, :3])
    args = " ".join(_r(v) for v in (*T[:3, 3], *q))
    return _tf_header(parent, child, lidar, camera, "1") + f"rosrun tf2_ros static_transform_publisher {args} {parent} {child}\n"


def _write_ros2(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = _T_parent_child(T_camera_lidar, parent, lidar)
    q = quat_xyzw_from_R(T[:3, :3])
    opts = " ".join(f"--{k} {_r(v)}" for k, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"), (*T[:3, 3], *q)))
    return (
        _tf_header(parent, child, lidar, camera, "2")
        + f"ros2 run tf2_ros static_transform_publisher {opts} --frame-id {parent} --child-frame-id {child}\n"
    )


def _command_tokens(text: str) -> list[str]:
    """Tokens after ``static_transform_publisher`` (or of the only non-comment line)."""
    lines = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    for ln in lines:
        if "static_transform_publisher" in ln:
            return ln.split("static_transform_publisher", 1)[1].split()
    if len(lines) == 1:
        return lines[0].split()
    raise CalibError("no static_transform_publisher command found")


def _read_ros1(text: str, hint: FrameHint) -> ParsedExtrinsics:
    tokens = _command_tokens(text)
    # x y z qx qy qz qw parent child [period_ms]  or  x y z yaw pitch roll parent child [period_ms]
    if len(tokens) in (9, 10) and not _is_number(tokens[7]):
        xyz = _numbers(tokens[:3], 3, "ros1-tf x y z")
        T = _quat_T(xyz, _numbers(tokens[3:7], 4, "ros1-tf qx qy qz qw"), "ros1-tf")
        parent, child = tokens[7], tokens[8]
    elif len(tokens) in (8, 9) and not _is_number(tokens[6]):
        xyz = _numbers(tokens[:3], 3, "ros1-tf x y z")
        yaw, pitch, roll = _numbers(tokens[3:6], 3, "ros1-tf yaw pitch roll")
        T = _rpy_rad_T(xyz, [roll, pitch, yaw])
        parent, child = tokens[6], tokens[7]
    else:
        raise CalibError(
            "ros1-tf: expected 'x y z qx qy qz qw parent child' or 'x y z yaw pitch roll parent child', "
            f"got {len(tokens)} arguments"
        )
    return _from_edges([(parent, child, T)], hint, text, "ros1-tf")


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _read_ros2(text: str, hint: FrameHint) -> ParsedExtrinsics:
    tokens = _command_tokens(text)
    opts: dict[str, str] = {}
    i = 0
    while i < len(tokens):
        key = tokens[i]
        if not key.startswith("--") or i + 1 >= len(tokens):
            raise CalibError(f"ros2-tf: expected '--name value' pairs, got {key!r}")
        opts[key[2:]] = tokens[i + 1]
        i += 2
    for needed in ("frame-id", "child-frame-id"):
        if needed not in opts:
            raise CalibError(f"ros2-tf: missing --{needed}")
    xyz = _numbers([opts.get(k, "0") for k in ("x", "y", "z")], 3, "ros2-tf --x --y --z")
    if any(k in opts for k in ("qx", "qy", "qz", "qw")):
        q = _numbers([opts.get(k, "0" if k != "qw" else "1") for k in ("qx", "qy", "qz", "qw")], 4, "ros2-tf quaternion")
        T = _quat_T(xyz, q, "ros2-tf")
    else:
        rpy = _numbers([opts.get(k, "0") for k in ("roll", "pitch", "yaw")], 3, "ros2-tf --roll --pitch --yaw")
        T = _rpy_rad_T(xyz, rpy)
    parent, child = opts["frame-id"], opts["child-frame-id"]
    return _from_edges([(parent, child, T)], hint, text, "ros2-tf")


# --------------------------------------------------------------------------------------
# URDF joint
# --------------------------------------------------------------------------------------


def _write_urdf(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = _T_parent_child(T_camera_lidar, parent, lidar)
    rpy = np.radians(rpy_deg_from_R(T[:3, :3]))
    xyz = " ".join(_r(v) for v in T[:3, 3])
    rpy_s = " ".join(_r(v) for v in rpy)
    return (
        f"<!-- URDF fixed joint: {_direction_line(parent, child)}; rpy in radians, fixed axes, "
        f"R = Rz(yaw) Ry(pitch) Rx(roll) -->\n"
        f"<!-- {_marker(lidar, camera)} -->\n"
        f'<joint name="{parent}_to_{child}" type="fixed">\n'
        f'  <parent link="{parent}"/>\n'
        f'  <child link="{child}"/>\n'
        f'  <origin xyz="{xyz}" rpy="{rpy_s}"/>\n'
        f"</joint>\n"
    )


def _read_urdf(text: str, hint: "FrameHint") -> ParsedExtrinsics:
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise CalibError("urdf: DOCTYPE/ENTITY declarations are not accepted")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise CalibError(f"urdf: malformed XML ({exc})") from None
    joints = [root] if root.tag == "joint" else root.findall(".//joint")
    if not joints:
        raise CalibError("urdf: no <joint> element")
    edges = []
    for joint in joints:
        origin = joint.find("origin")
        xyz = _numbers((origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split(), 3, "urdf origin xyz")
        rpy = _numbers((origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split(), 3, "urdf origin rpy")
        edges.append((_link(joint, "parent"), _link(joint, "child"), _rpy_rad_T(xyz, rpy)))
    return _from_edges(edges, hint, text, "urdf")


def _link(joint: ET.Element, which: str) -> str:
    el = joint.find(which)
    if el is None or not el.get("link"):
        raise CalibError(f"urdf: joint without <{which} link=...>")
    return el.get("link")


# --------------------------------------------------------------------------------------
# Autoware sensor_kit_calibration.yaml
# --------------------------------------------------------------------------------------


def _write_autoware(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = _T_parent_child(T_camera_lidar, parent, lidar)
    rpy = np.radians(rpy_deg_from_R(T[:3, :3]))
    body = {parent: {child: {k: float(v) for k, v in zip(("x", "y", "z", "roll", "pitch", "yaw"), (*T[:3, 3], *rpy))}}}
    return (
        f"# Autoware sensor_kit_calibration.yaml: {_direction_line(parent, child)}\n"
        f"# metres; roll pitch yaw in radians, R = Rz(yaw) Ry(pitch) Rx(roll)\n"
        f"# {_marker(lidar, camera)}\n" + yaml.safe_dump(body, sort_keys=False)
    )


def _is_autoware(data) -> bool:
    return (
        isinstance(data, dict)
        and len(data) >= 1
        and all(isinstance(v, dict) for v in data.values())
        and any(isinstance(c, dict) and {"x", "y", "z", "roll", "pitch", "yaw"} <= set(c) for v in data.values() for c in v.values())
    )


def _read_autoware(text: str, hint: "FrameHint") -> ParsedExtrinsics:
    data = _safe_yaml(text, "autoware")
    if not _is_autoware(data):
        raise CalibError("autoware: expected 'parent: {child: {x, y, z, roll, pitch, yaw}}'")
    edges = []
    for parent, children in data.items():
        for child, v in children.items():
            if not isinstance(v, dict):
                continue
            where = f"autoware {parent}.{child}"
            xyz = _numbers([v.get(k) for k in ("x", "y", "z")], 3, f"{where} x y z")
            rpy = _numbers([v.get(k) for k in ("roll", "pitch", "yaw")], 3, f"{where} roll pitch yaw")
            edges.append((str(parent), str(child), _rpy_rad_T(xyz, rpy)))
    return _from_edges(edges, hint, text, "autoware")


def _safe_yaml(text: str, what: str):
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise CalibError(f"{what}: malformed YAML/JSON{where}") from None


# --------------------------------------------------------------------------------------
# OpenCalib JSON, direct_visual_lidar_calibration JSON
# --------------------------------------------------------------------------------------


def _write_opencalib(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    key = f"{lidar}-to-{camera}-extrinsic"
    doc = {
        key: {
            "sensor_name": lidar,
            "target_sensor_name": camera,
            "device_type": "relational",
            "param_type": "extrinsic",
            "param": {
                "time_lag": 0,
                "sensor_calib": {"rows": 4, "cols": 4, "type": 6, "continuous": True, "data": T.tolist()},
            },
            "convention": f"maps {lidar} points into the {camera} frame: X_{camera} = data @ X_{lidar}",
            MARKER: {"lidar": lidar, "camera": camera},
        }
    }
    return json.dumps(doc, indent=2) + "\n"


def _read_opencalib(text: str, hint: FrameHint) -> ParsedExtrinsics:
    lidar_frame = hint.lidar
    data = _safe_yaml(text, "opencalib")
    blocks = [(k, v) for k, v in data.items() if isinstance(v, dict) and "param" in v] if isinstance(data, dict) else []
    blocks = [(k, v) for k, v in blocks if isinstance(v["param"], dict) and "sensor_calib" in v["param"]]
    if len(blocks) != 1:
        raise CalibError("opencalib: expected one '<a>-to-<b>-extrinsic' block with param.sensor_calib")
    key, block = blocks[0]
    calib = block["param"]["sensor_calib"]
    rows = calib.get("data") if isinstance(calib, dict) else None
    if not isinstance(rows, list) or len(rows) != 4:
        raise CalibError(f"opencalib {key}: sensor_calib.data must be a 4x4 nested list")
    M = _check_rigid(np.array([_numbers(r, 4, f"opencalib {key} row {i}") for i, r in enumerate(rows)]), f"opencalib {key}")
    m = re.match(r"^(.+)-to-(.+)-extrinsic$", str(key))
    source = block.get("sensor_name") or (m.group(1) if m else None)
    target = block.get("target_sensor_name") or (m.group(2) if m else None)
    if not source or not target:
        raise CalibError(f"opencalib {key}: cannot tell the two sensors (expected '<a>-to-<b>-extrinsic')")
    marker = block.get(MARKER)
    if lidar_frame is None and isinstance(marker, dict) and marker.get("lidar") in (source, target):
        lidar_frame = marker["lidar"]
    lidar, camera = lidar_and_camera(str(source), str(target), lidar_frame)
    # "a-to-b" maps a's points into b's frame.
    T = M if source == lidar else invert_T(M)
    return ParsedExtrinsics(T, "opencalib", lidar, camera)


def _write_dvlc(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = invert_T(T_camera_lidar)
    values = [float(v) for v in (*T[:3, 3], *quat_xyzw_from_R(T[:3, :3]))]
    doc = {
        "results": {"T_lidar_camera": values},
        "meta": {
            "convention": f"T_lidar_camera = [x, y, z, qx, qy, qz, qw] maps {camera} points into the {lidar} frame: "
            f"X_{lidar} = T_lidar_camera @ X_{camera}",
            MARKER: {"lidar": lidar, "camera": camera},
        },
    }
    return json.dumps(doc, indent=2) + "\n"


def _dvlc_values(data):
    if not isinstance(data, dict):
        return None
    results = data.get("results")
    if isinstance(results, dict) and "T_lidar_camera" in results:
        return results["T_lidar_camera"]
    return data.get("T_lidar_camera")


def _read_dvlc(text: str, hint: FrameHint) -> ParsedExtrinsics:
    data = _safe_yaml(text, "dvlc")
    values = _dvlc_values(data)
    if values is None:
        raise CalibError("dvlc: no T_lidar_camera (top level or under results)")
    v = _numbers(values if isinstance(values, list) else [values], 7, "dvlc T_lidar_camera [x, y, z, qx, qy, qz, qw]")
    T_lidar_camera = _quat_T(v[:3], v[3:], "dvlc T_lidar_camera")
    marker = (data.get("meta") or {}).get(MARKER) if isinstance(data.get("meta"), dict) else None
    names = (marker.get("lidar"), marker.get("camera")) if isinstance(marker, dict) else (None, None)
    return ParsedExtrinsics(invert_T(T_lidar_camera), "dvlc", *names)


# --------------------------------------------------------------------------------------
# KITTI, plain matrix
# --------------------------------------------------------------------------------------


def _write_kitti(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    # The comment holds a colon so that KITTI readers that split on ':' and
    # parse floats skip it.
    return (
        f"# KITTI calib: Tr_velo_to_cam maps lidar ({lidar}) points into the camera ({camera}) frame: "
        f"X_cam = Tr_velo_to_cam @ [X_velo; 1] (3x4, row-major, unrectified)\n"
        f"# {_marker(lidar, camera)}\n"
        f"Tr_velo_to_cam: {' '.join(_r(v) for v in T[:3, :4].ravel())}\n"
    )


def _read_kitti(text: str, hint: FrameHint) -> ParsedExtrinsics:
    # The same reader as a KITTI calib file given as a camera (calib_core.io.kitti_calib).
    calib = parse_kitti_calib(text, "kitti")
    if "Tr_velo_to_cam" not in calib:
        raise CalibError("kitti: no 'Tr_velo_to_cam:' line")
    Tr = np.eye(4)
    Tr[:3] = calib["Tr_velo_to_cam"]
    _check_rigid(Tr, "kitti Tr_velo_to_cam")
    # A full calib file (P0..P3, R0_rect): the rectified camera's pose; an export (Tr_velo_to_cam only): Tr.
    T = kitti_T_camera_lidar(calib, hint.kitti_camera, "kitti")
    found = _find_marker(text) or (None, None)
    return ParsedExtrinsics(_check_rigid(T, f"kitti camera {hint.kitti_camera}"), "kitti", *found)


def _write_matrix(T_camera_lidar, parent, child, lidar, camera) -> str:
    T = _T_parent_child(T_camera_lidar, parent, lidar)
    rows = "\n".join(" ".join(_r(v) for v in row) for row in T)
    return f"# 4x4 transform T_{parent}_{child}: {_direction_line(parent, child)}\n# {_marker(lidar, camera)}\n{rows}\n"


_MATRIX_DIRECTION = re.compile(r"X_(\S+?)\s*=\s*\S*\s*@\s*X_(\S+)")


def _read_matrix(text: str, hint: FrameHint) -> ParsedExtrinsics:
    lidar_frame = hint.lidar
    rows = [ln.split("#", 1)[0].replace(",", " ").replace("[", " ").replace("]", " ").split() for ln in text.splitlines()]
    rows = [r for r in rows if r]
    if len(rows) != 4:
        raise CalibError(f"matrix: expected 4 rows of 4 numbers, got {len(rows)} rows")
    M = _check_rigid(np.array([_numbers(r, 4, f"matrix row {i}") for i, r in enumerate(rows)]), "matrix")
    comments = "\n".join(ln for ln in text.splitlines() if ln.lstrip().startswith("#"))
    m = _MATRIX_DIRECTION.search(comments)
    if m is None:
        raise CalibError("matrix: a bare 4x4 does not say its direction; add a comment such as '# X_camera = T @ X_lidar'")
    to_frame, from_frame = m.group(1), m.group(2)
    lidar, camera = _frames_for_reading(text, to_frame, from_frame, lidar_frame)
    T = M if to_frame == camera else invert_T(M)
    return ParsedExtrinsics(T, "matrix", lidar, camera)


# --------------------------------------------------------------------------------------
# registry and entry points
# --------------------------------------------------------------------------------------

FORMATS: dict[str, ExtrinsicFormat] = {
    f.name: f
    for f in (
        ExtrinsicFormat("ros1-tf", ".sh", "ROS 1 static_transform_publisher arguments (x y z qx qy qz qw parent child)", _write_ros1, _read_ros1),
        ExtrinsicFormat("ros2-tf", ".sh", "ROS 2 static_transform_publisher (--x ... --qw --frame-id --child-frame-id)", _write_ros2, _read_ros2),
        ExtrinsicFormat("urdf", ".urdf", "URDF fixed <joint> with <origin xyz rpy>", _write_urdf, _read_urdf),
        ExtrinsicFormat("autoware", ".yaml", "Autoware sensor_kit_calibration.yaml (x y z roll pitch yaw)", _write_autoware, _read_autoware),
        ExtrinsicFormat("opencalib", ".json", "OpenCalib <lidar>-to-<camera>-extrinsic JSON (4x4 lidar -> camera)", _write_opencalib, _read_opencalib),
        ExtrinsicFormat("dvlc", ".json", "direct_visual_lidar_calibration T_lidar_camera [x, y, z, qx, qy, qz, qw]", _write_dvlc, _read_dvlc),
        ExtrinsicFormat("kitti", ".txt", "KITTI Tr_velo_to_cam line (3x4 lidar -> camera)", _write_kitti, _read_kitti),
        ExtrinsicFormat("matrix", ".txt", "plain 4x4 T_parent_child (maps child points into the parent frame)", _write_matrix, _read_matrix),
    )
}


def export_extrinsics(
    T_camera_lidar: np.ndarray,
    fmt: str,
    parent_frame: str = "lidar",
    child_frame: str = "camera",
    lidar_frame: str | None = None,
) -> str:
    """The text of ``T_camera_lidar`` in format ``fmt``.

    Parameters
    ----------
    T_camera_lidar : (4, 4) array_like
        Maps lidar points into the camera frame, metres.
    fmt : str
        A key of :data:`FORMATS`.
    parent_frame, child_frame : str
        The two sensors' frame names, in either order: TF-like formats
        (``ros1-tf``, ``ros2-tf``, ``urdf``, ``autoware``, ``matrix``) hold
        ``T_parent_child``, which maps child points into the parent frame.
    lidar_frame : str, optional
        Which of the two is the lidar, when the names do not tell
        (see :func:`lidar_and_camera`).
    """
    if fmt not in FORMATS:
        raise CalibError(f"unknown extrinsics format {fmt!r} (one of {', '.join(FORMATS)})")
    parent = _check_frame(parent_frame, "parent frame")
    child = _check_frame(child_frame, "child frame")
    lidar, camera = lidar_and_camera(parent, child, lidar_frame)
    T = _check_rigid(np.array(T_camera_lidar, dtype=np.float64).reshape(4, 4), "T_camera_lidar")
    return FORMATS[fmt].write(T, parent, child, lidar, camera)


def detect_format(text: str) -> str:
    """The name of the format of ``text`` (``"ba-calib"`` for this package's own YAML)."""
    stripped = text.lstrip()
    if stripped.startswith("<") or "<joint" in text:
        return "urdf"
    if re.search(r"^\s*Tr_velo_to_cam\b", text, re.MULTILINE):
        return "kitti"
    if "static_transform_publisher" in text:
        return "ros2-tf" if re.search(r"--(frame-id|x|qw|yaw)\b", text) else "ros1-tf"
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError:
        data = None
    if isinstance(data, dict):
        if "T_camera_lidar" in data:
            return "ba-calib"
        if _dvlc_values(data) is not None:
            return "dvlc"
        if any(isinstance(v, dict) and "param" in v for v in data.values()):
            return "opencalib"
        if _is_autoware(data):
            return "autoware"
    body = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
    body = [ln for ln in body if ln]
    if len(body) == 4:
        return "matrix"
    if len(body) == 1 and len(body[0].split()) in (8, 9, 10):
        return "ros1-tf"
    raise CalibError(f"unrecognised extrinsics format (known: ba-calib YAML, {', '.join(FORMATS)})")


def parse_extrinsics(
    text: str, fmt: str | None = None, lidar_frame: str | None = None, camera_frame: str | None = None,
    kitti_camera: int | None = None,
) -> ParsedExtrinsics:
    """Parse extrinsics text in any format of :data:`FORMATS` (detected when ``fmt`` is None).

    ``lidar_frame``/``camera_frame`` name the frames when the file does not
    tell (a URDF or Autoware file with several sensors: the chain between the
    two is composed).  The camera frame must be the optical frame (z forward,
    x right, y down), as this package's camera frame.  A full KITTI calib
    file gives the pose of rectified camera ``kitti_camera`` (0-3; None: 2,
    the colour images), see :mod:`calib_core.io.kitti_calib`.

    Raises
    ------
    CalibError
        Unrecognised or malformed text, or frames whose roles cannot be told;
        the message names the format.
    """
    fmt = fmt or detect_format(text)
    if fmt == "ba-calib":
        from .extrinsics import parse_transform

        data = _safe_yaml(text, "ba-calib extrinsics")
        if not isinstance(data, dict) or "T_camera_lidar" not in data:
            raise CalibError("ba-calib extrinsics: missing top-level key 'T_camera_lidar'")
        return ParsedExtrinsics(parse_transform(data["T_camera_lidar"], "T_camera_lidar"), "ba-calib")
    if fmt not in FORMATS:
        raise CalibError(f"unknown extrinsics format {fmt!r} (one of {', '.join(FORMATS)})")
    kitti = DEFAULT_KITTI_CAMERA if kitti_camera is None else kitti_camera
    return FORMATS[fmt].read(text, FrameHint(lidar_frame, camera_frame, kitti))


def read_extrinsics_any(
    path: str | os.PathLike, fmt: str | None = None, lidar_frame: str | None = None, camera_frame: str | None = None,
    kitti_camera: int | None = None,
) -> ParsedExtrinsics:
    """Read an extrinsics file of any supported format; errors name the file and the format."""
    path = Path(path)
    text = read_input_text(path, "extrinsics file", MAX_EXTRINSICS_BYTES)  # a regular file, bounded
    try:
        return parse_extrinsics(text, fmt, lidar_frame, camera_frame, kitti_camera)
    except CalibError as exc:
        raise CalibError(f"{path}: {exc}") from None


def load_extrinsics_any(
    path: str | os.PathLike, fmt: str | None = None, lidar_frame: str | None = None, camera_frame: str | None = None,
    kitti_camera: int | None = None,
) -> np.ndarray:
    """``T_camera_lidar`` (4, 4) from an extrinsics file of any supported format."""
    return read_extrinsics_any(path, fmt, lidar_frame, camera_frame, kitti_camera).T_camera_lidar
