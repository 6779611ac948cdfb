"""Point pairs: a laser point (a depth-matrix cell or an xyz) and a camera pixel.

File format (YAML)::

    pairs:
      - laser_rc: [row, col]        # a depth-matrix cell, 0-based
        pixel: [u, v]               # original camera image, (column, row)
      - laser_xyz: [x, y, z]        # lidar frame, metres
        pixel: [u, v]
        id: 7                       # optional: the pair's id, shown in the UI, warnings and results
        source: guided              # optional: clicked (default) | guided | auto
        precision_px: 0.3           # optional: 1-sigma of the pixel, px (weights the solve)
        check: true                 # optional: a check pair, left out of the fit and reported apart
        edge_deg: 30.0              # optional: the pixel lies on a straight image edge at this angle (degrees
                                    # from +u towards +v, [0, 180)) and may slide along it (a point-on-line pair)

Pixels use the package convention: the centre of the top-left pixel is (0, 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .cameras.base import in_image
from .errors import CalibError
from .io.atomic import write_yaml_atomic
from .io.yaml_files import finite_vector, read_yaml_mapping


def tag_fields(source: str, precision_px: float | None, check: bool, *, edge_deg: float | None = None
               ) -> dict[str, Any]:
    """A pair's tags as file fields, each written only when not the default (so files of
    unguided, all-fit, corner pairs stay as they were): ``source``, ``precision_px`` (px), ``check``,
    ``edge_deg`` (degrees, :attr:`Pair.edge_deg`; written in [0, 180))."""
    out: dict[str, Any] = {}
    if source != "clicked":
        out["source"] = source
    if precision_px is not None:
        out["precision_px"] = float(precision_px)
    if check:
        out["check"] = True
    if edge_deg is not None:
        out["edge_deg"] = float(edge_deg) % 180.0
    return out


def parse_edge_deg(value: Any, where: str) -> float:
    """An ``edge_deg`` value: a finite number of degrees, returned in [0, 180) (a line's direction is
    the same at ``a`` and ``a + 180``); anything else one :class:`CalibError` line naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not np.isfinite(float(value)):
        raise CalibError(f"{where} edge_deg: expected a finite angle in degrees (0 to 180), got {value!r}"[:300])
    return float(value) % 180.0


@dataclass(frozen=True)
class Pair:
    """One correspondence.  Exactly one of ``laser_rc`` / ``laser_xyz`` is set.

    Attributes
    ----------
    laser_rc : (row, col) or None
        Depth-matrix cell.
    laser_xyz : (x, y, z) or None
        Laser point in the lidar frame, metres.
    pixel : (u, v)
        Camera pixel in the original image (column, row).
    id : int or None
        The pair's id: one number for the pair in the UI, warnings, results and files.
    source : {"clicked", "guided", "auto"}
        How the pair was made: an unguided click, a click on a proposal, or accepted without a click.
    precision_px : float or None
        1-sigma of the pixel in px, when known; None means the solve's default.
    check : bool
        A check pair: left out of the fit, its error reported separately.
    edge_deg : float or None
        None: an ordinary (corner) pair, the pixel is where the laser point is seen.  A number: the
        pixel lies on a straight image edge at this angle (degrees from +u towards +v, in [0, 180))
        and may slide along it -- a point-on-line constraint, e.g. a laser ring crossing a painted
        lane line, whose place along the line the photo cannot show.  The solve trusts such a pixel
        only across the edge (:data:`calib_core.solve.edges.EDGE_SLIDE`), and its reported pixel
        error is the distance across the edge.
    """

    laser_rc: tuple[int, int] | None
    laser_xyz: tuple[float, float, float] | None
    pixel: tuple[float, float]
    id: int | None = None
    source: str = "clicked"
    precision_px: float | None = None
    check: bool = False
    edge_deg: float | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.laser_rc is not None:
            out["laser_rc"] = [int(self.laser_rc[0]), int(self.laser_rc[1])]
        if self.laser_xyz is not None:
            out["laser_xyz"] = [float(x) for x in self.laser_xyz]
        out["pixel"] = [float(self.pixel[0]), float(self.pixel[1])]
        if self.id is not None:
            out["id"] = int(self.id)
        out.update(tag_fields(self.source, self.precision_px, self.check, edge_deg=self.edge_deg))
        return out

    @staticmethod
    def from_dict(entry: Any, where: str) -> "Pair":
        """Parse one entry of a pairs file; ``where`` names it in errors."""
        if not isinstance(entry, dict):
            raise CalibError(f"{where}: expected a mapping with laser_rc or laser_xyz and pixel")
        unknown = set(entry) - {"laser_rc", "laser_xyz", "pixel", "id", "label", "source", "precision_px", "check",
                                "edge_deg"}
        if unknown:
            raise CalibError(f"{where}: unknown key(s) {sorted(unknown)}")
        has_rc, has_xyz = "laser_rc" in entry, "laser_xyz" in entry
        if has_rc == has_xyz:
            raise CalibError(f"{where}: give exactly one of laser_rc or laser_xyz")
        if "pixel" not in entry:
            raise CalibError(f"{where}: missing pixel: [u, v]")
        pixel = tuple(finite_vector(entry["pixel"], 2, f"{where} pixel", max_abs=MAX_PIXEL))
        extra = _optional_fields(entry, where)
        if has_rc:
            rc = parse_laser_rc(entry["laser_rc"], f"{where} laser_rc")
            return Pair((int(rc[0]), int(rc[1])), None, pixel, **extra)  # type: ignore[arg-type]
        xyz = tuple(finite_vector(entry["laser_xyz"], 3, f"{where} laser_xyz", max_abs=MAX_COORDINATE_M))
        if float(np.linalg.norm(xyz)) < MIN_LASER_RANGE_M:
            # No return comes from the sensor's own origin (drivers write 0, 0, 0 for "no return").
            name = where if "id" not in extra else f"{where} (id {extra['id']})"
            raise CalibError(
                f"{name} laser_xyz: {list(xyz)} is at the lidar origin (closer than {MIN_LASER_RANGE_M * 1000:g} mm), "
                f"not a laser return"
            )
        return Pair(None, xyz, pixel, **extra)  # type: ignore[arg-type]


PAIR_SOURCES = ("clicked", "guided", "auto")

#: Default cap on the pairs in one file (a calibration needs tens; raise with ``max_pairs``).
MAX_PAIRS = 1_000
#: Values (YAML scalars and collections) one pairs-file entry holds at most, with every optional field.
VALUES_PER_PAIR = 20
#: Largest depth-matrix row or column index accepted in ``laser_rc``.
MAX_CELL_INDEX = 10_000_000
#: Largest laser coordinate (metres) and pixel coordinate accepted; beyond them a value is absurd.
MAX_COORDINATE_M = 1e6
MAX_PIXEL = 1e7
#: A laser point closer than this to the lidar origin (metres) is no return.
MIN_LASER_RANGE_M = 1e-3


def parse_laser_rc(value: Any, where: str) -> tuple[int, int]:
    """A ``laser_rc`` value: two whole numbers in [0, MAX_CELL_INDEX] (fractions refused, not truncated)."""
    rc = finite_vector(value, 2, where, max_abs=float("inf"))
    if any(v != int(v) or not 0 <= v <= MAX_CELL_INDEX for v in rc):
        raise CalibError(f"{where}: expected two whole numbers from 0 to {MAX_CELL_INDEX:,}, got {value!r}")
    return int(rc[0]), int(rc[1])


def _optional_fields(entry: dict, where: str) -> dict[str, Any]:
    """The optional ``id``, ``source``, ``precision_px``, ``check`` and ``edge_deg`` of a pairs-file entry, checked."""
    out: dict[str, Any] = {}
    if entry.get("id") is not None:
        pid = entry["id"]
        if isinstance(pid, bool) or not isinstance(pid, int) or not 0 <= pid < 2**31:
            raise CalibError(f"{where} id: expected a whole number from 0 to 2^31-1, got {pid!r}")
        out["id"] = pid
    if "source" in entry:
        if entry["source"] not in PAIR_SOURCES:
            raise CalibError(f"{where} source: expected one of {', '.join(PAIR_SOURCES)}, got {entry['source']!r}")
        out["source"] = entry["source"]
    if entry.get("precision_px") is not None:
        (sigma,) = finite_vector([entry["precision_px"]], 1, f"{where} precision_px")
        if not 0.0 < sigma <= 1000.0:
            raise CalibError(f"{where} precision_px: expected a positive number of pixels (at most 1000), got {sigma}")
        out["precision_px"] = sigma
    if "check" in entry:
        if not isinstance(entry["check"], bool):
            raise CalibError(f"{where} check: expected true or false, got {entry['check']!r}")
        out["check"] = entry["check"]
    if entry.get("edge_deg") is not None:
        name = where if out.get("id") is None else f"{where} (id {out['id']})"
        out["edge_deg"] = parse_edge_deg(entry["edge_deg"], name)
    return out


def load_pairs_yaml(path: str | os.PathLike, max_pairs: int = MAX_PAIRS) -> list[Pair]:
    """Read a pairs file.  Malformed content raises a one-line :class:`CalibError`.

    Parameters
    ----------
    path : path-like
        The pairs YAML.
    max_pairs : int
        Most pairs accepted (the CLI's ``--max-pairs``); the file's size and
        number of values are bounded in proportion, so a huge file is refused
        before it is parsed in full.
    """
    path = Path(path)
    hint = f"the cap is {max_pairs:,} pairs (raise it with --max-pairs)"
    data = read_yaml_mapping(
        path, "pairs file", max_bytes=(1 << 20) + 512 * max_pairs, max_values=1000 + VALUES_PER_PAIR * max_pairs, limit_hint=hint
    )
    entries = data.get("pairs")
    if entries is None:
        raise CalibError(f"{path}: missing top-level key 'pairs'")
    if not isinstance(entries, list):
        raise CalibError(f"{path}: 'pairs' must be a list")
    if len(entries) > max_pairs:
        raise CalibError(f"{path}: {len(entries):,} pairs; {hint}")
    return [Pair.from_dict(e, f"{path}: pair {i}") for i, e in enumerate(entries)]


def save_pairs_yaml(path: str | os.PathLike, pairs: Sequence[Pair]) -> None:
    """Write a pairs file atomically (temporary file, then rename)."""
    write_yaml_atomic(path, {"pairs": [p.to_dict() for p in pairs]})


def _pair_name(pairs: Sequence[Pair], i: int) -> str:
    """How messages name pair ``i``: by its id when it has one (as the UI shows it), else by position."""
    pid = getattr(pairs[i], "id", None)
    return f"pair {i}" if pid is None else f"pair {pid}"


def resolve_pairs(pairs: Sequence[Pair], depth, camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Turn pairs into solver input.

    Parameters
    ----------
    pairs : sequence of Pair
    depth : DepthMatrix or None
        Needed when a pair names a ``laser_rc`` cell.
    camera : CameraModel
        Maps clicked pixels to bearings.

    Returns
    -------
    points_lidar : (N, 3) float64
        Laser points in the lidar frame, metres.
    bearings_camera : (N, 3) float64
        Unit rays of the clicked pixels, OpenCV camera frame.
    pixels : (N, 2) float64
        The clicked pixels ``(u, v)``.
    """
    n = len(pairs)
    points = np.empty((n, 3))
    pixels = np.array([p.pixel for p in pairs], dtype=np.float64).reshape(n, 2)
    rc_idx = [i for i, p in enumerate(pairs) if p.laser_rc is not None]
    xyz_idx = [i for i, p in enumerate(pairs) if p.laser_rc is None]
    if xyz_idx:
        points[xyz_idx] = np.array([pairs[i].laser_xyz for i in xyz_idx], dtype=np.float64)
    if rc_idx:
        if depth is None:
            raise CalibError("pairs name depth-matrix cells (laser_rc) but no scan was given")
        rc = np.array([pairs[i].laser_rc for i in rc_idx], dtype=np.int64)
        h, w = depth.shape
        outside = (rc[:, 0] >= h) | (rc[:, 1] >= w) | (rc < 0).any(axis=1)
        if outside.any():
            i = rc_idx[int(np.argmax(outside))]
            raise CalibError(f"{_pair_name(pairs, i)}: laser cell {tuple(pairs[i].laser_rc)} is outside the {h}x{w} depth matrix")
        no_return = ~depth.valid[rc[:, 0], rc[:, 1]]
        if no_return.any():
            i = rc_idx[int(np.argmax(no_return))]
            raise CalibError(f"{_pair_name(pairs, i)}: laser cell {tuple(pairs[i].laser_rc)} has no laser return; pick a valid cell")
        points[rc_idx] = depth.points[rc[:, 0], rc[:, 1]]
    inside = in_image(pixels, camera.width, camera.height)
    if not inside.all():
        i = int(np.argmin(inside))
        raise CalibError(
            f"{_pair_name(pairs, i)}: pixel ({pixels[i, 0]:.1f}, {pixels[i, 1]:.1f}) is outside the {camera.width}x{camera.height} camera image"
        )
    bearings = camera.bearing(pixels) if n else np.empty((0, 3))
    bad = ~np.isfinite(bearings).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise CalibError(f"{_pair_name(pairs, i)}: pixel ({pixels[i, 0]:.1f}, {pixels[i, 1]:.1f}) has no ray under the {camera.model} camera model")
    return points, bearings, pixels
