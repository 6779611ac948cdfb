"""Extrinsics YAML: export and import of ``T_camera_lidar`` with its quality figures.

Layout::

    ba_calib_version: 0.1.0
    T_camera_lidar:
      matrix: [[r00, r01, r02, tx], ..., [0, 0, 0, 1]]   # X_camera = matrix @ X_lidar
      translation_m: [tx, ty, tz]
      quaternion_xyzw: [qx, qy, qz, qw]
      rpy_deg: [roll, pitch, yaw]                           # R = Rz(yaw) Ry(pitch) Rx(roll)
      viewing_deg: [azimuth, elevation, roll]               # optical axis in the lidar frame, roll about it
      viewing_direction_lidar: [dx, dy, dz]                 # the optical axis (camera +z), lidar frame
    quality: {status: ok | warning | unreliable, reasons: [...]}
    outliers: [{index, id, deg, px}, ...]                   # pairs left out of the fit (kept in pairs)
    check_pairs: [{index, id, deg, px}, ...]                # pairs marked check: not fitted, their errors
    sigma: {translation_m: [...], rpy_deg: [...], viewing_deg: [...]}   # 1-sigma at the optimum
    residuals: {n_pairs, n_inliers, error_estimated, mean_px, std_px, mean_deg, std_deg, per_pair: [...],
                warnings: [...]}

``viewing_deg`` (:func:`calib_core.transforms.viewing_direction`) stays readable where
``rpy_deg`` is in gimbal lock (pitch -90 deg: a camera looking along lidar +x); it is null
where undefined (a camera looking exactly along lidar +-z).  On reading, it and
``viewing_direction_lidar`` must agree with the rotation (files without them load as before).
``error_estimated`` is false when the pairs in the fit are too few for their residuals to
estimate the error (:func:`calib_core.solve.quality.error_estimate_reason`).
    camera: {...}                                           # the camera description
    pairs: [...]                                            # the pairs that were solved
    shots: [{index, name, residuals, leave_one_shot_out, test, ...}]  # several shots: calib_core.shots.shots_to_dict

Floats are written with Python's shortest round-trip representation, so
saving and loading again reproduces every number exactly.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import __version__
from ..errors import CalibError
from ..transforms import (
    R_from_quat_xyzw,
    R_from_rpy_deg,
    R_from_viewing_deg,
    make_T,
    quat_xyzw_from_R,
    rpy_deg_from_R,
    viewing_direction,
)
from .atomic import write_yaml_atomic
from .input_files import MAX_EXTRINSICS_BYTES
from .yaml_files import finite_vector, read_yaml_mapping

#: Largest lidar-to-camera translation accepted (metres); beyond it a value is absurd.
MAX_TRANSLATION_M = 1e4

CONVENTION = (
    "X_camera = matrix @ X_lidar (metres); rpy: R = Rz(yaw) @ Ry(pitch) @ Rx(roll); viewing_deg: azimuth "
    "atan2(dy, dx) and elevation asin(dz) of the optical axis d (camera +z) in the lidar frame, roll of the "
    "camera about d (0: camera x horizontal, image up towards lidar +z)"
)


def _floats(a) -> list:
    """Nested Python floats (``yaml.safe_dump`` cannot write numpy scalars)."""
    return np.asarray(a, dtype=np.float64).tolist()


def finite_or_none(x) -> float | None:
    """``float(x)``, or None where it is NaN or infinite (how the YAML documents write "no value")."""
    x = float(x)
    return x if np.isfinite(x) else None


def transform_to_dict(T_camera_lidar: np.ndarray) -> dict[str, Any]:
    """The ``T_camera_lidar`` block: matrix plus the same pose in three other forms."""
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    view = viewing_direction(T[:3, :3])
    return {
        "matrix": _floats(T),
        "translation_m": _floats(T[:3, 3]),
        "quaternion_xyzw": _floats(quat_xyzw_from_R(T[:3, :3])),
        "rpy_deg": _floats(rpy_deg_from_R(T[:3, :3])),
        "viewing_deg": [finite_or_none(v) for v in (view.azimuth_deg, view.elevation_deg, view.roll_deg)],
        "viewing_direction_lidar": _floats(view.direction_lidar),
        "convention": CONVENTION,
    }


def result_to_dict(result) -> dict[str, Any]:
    """``quality``, ``outliers``, ``sigma`` and ``residuals`` blocks of a :class:`CalibrationResult`.

    ``quality`` is ``{status: ok | warning | unreliable, reasons: [...]}``.
    ``outliers`` lists the pairs left out of the fit (``index`` = position in
    the pairs block, ``id`` = the pair's id, and their errors at the pose);
    they stay in the ``pairs`` block.  ``per_pair`` has every pair, with
    ``outlier: true`` for those.
    """
    from ..solve.quality import error_estimate_reason, pairs_in_fit  # (a result exists: the solver is loaded)

    per_pair = []
    outliers = [int(i) for i in result.outliers]
    ids = list(getattr(result, "outlier_ids", []) or outliers)
    out_set = set(outliers)
    res_px = np.asarray(result.residual_px, dtype=np.float64)
    res_deg = np.asarray(result.residual_deg, dtype=np.float64)
    # Rows of the result -> positions in the pairs block (check pairs are not in the fit).
    positions = getattr(result, "pair_positions", None) or list(range(len(res_deg)))

    def px_at(i: int):
        return None if i >= len(res_px) or not np.isfinite(res_px[i]) else float(res_px[i])

    for i, deg in enumerate(res_deg):
        per_pair.append({"index": int(positions[i]), "deg": float(deg), "px": px_at(i), "outlier": i in out_set})
    quality = getattr(result, "quality", None)
    check_px = np.asarray(getattr(result, "check_residual_px", np.zeros(0)), dtype=np.float64)
    check_deg = np.asarray(getattr(result, "check_residual_deg", np.zeros(0)), dtype=np.float64)
    checks = [
        {"index": int(pos), "id": int(pid), "deg": float(d), "px": None if not np.isfinite(p) else float(p)}
        for pos, pid, d, p in zip(getattr(result, "check_positions", []), getattr(result, "check_ids", []),
                                  check_deg, check_px)
    ]
    return {
        "quality": quality.to_dict() if quality is not None else {"status": "ok", "reasons": []},
        "outliers": [
            {"index": int(positions[i]), "id": int(pid), "deg": float(res_deg[i]), "px": px_at(i)}
            for i, pid in zip(outliers, ids)
        ],
        "check_pairs": checks,
        "sigma": {
            "translation_m": _floats(result.sigma_translation_m),
            "rpy_deg": _floats(result.sigma_rpy_deg),
            "viewing_deg": _floats(viewing_direction(
                np.asarray(result.T_camera_lidar)[:3, :3], np.asarray(result.covariance_6x6)[:3, :3]).sigma_deg),
        },
        "residuals": {
            "n_pairs": int(result.n_pairs),
            "n_inliers": int(result.n_pairs) - len(outliers),
            "error_estimated": error_estimate_reason(pairs_in_fit(result)) is None,
            "cost": str(result.cost_name),
            "mean_px": finite_or_none(result.mean_px),
            "std_px": finite_or_none(result.std_px),
            "mean_deg": finite_or_none(result.mean_deg),
            "std_deg": finite_or_none(result.std_deg),
            "per_pair": per_pair,
            "warnings": [str(w) for w in result.warnings],
        },
    }


def extrinsics_to_dict(
    T_camera_lidar: np.ndarray,
    result=None,
    camera=None,
    pairs: Sequence | None = None,
    base_dir: Path | None = None,
) -> dict[str, Any]:
    """The whole extrinsics document as plain Python data."""
    doc: dict[str, Any] = {"ba_calib_version": __version__, "T_camera_lidar": transform_to_dict(T_camera_lidar)}
    if result is not None:
        doc.update(result_to_dict(result))
    if camera is not None:
        doc["camera"] = camera.to_dict(base_dir)
    if pairs is not None:
        doc["pairs"] = [p.to_dict() if hasattr(p, "to_dict") else dict(p) for p in pairs]
    return doc


def save_extrinsics_yaml(
    path: str | os.PathLike,
    T_camera_lidar: np.ndarray,
    result=None,
    camera=None,
    pairs: Sequence | None = None,
) -> None:
    """Write the extrinsics YAML atomically.

    Parameters
    ----------
    path : path-like
        Output file.
    T_camera_lidar : (4, 4) array
        Lidar-to-camera transform, metres.
    result : CalibrationResult, optional
        Adds the ``sigma`` and ``residuals`` blocks.
    camera : CameraModel, optional
        Adds the ``camera`` block (paths relative to the output file).
    pairs : sequence of Pair, optional
        Adds the ``pairs`` block.
    """
    path = Path(path)
    write_yaml_atomic(path, extrinsics_to_dict(T_camera_lidar, result, camera, pairs, base_dir=path.parent))


def _check_rotation(R: np.ndarray, where: str) -> None:
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise CalibError(f"{where}: the 3x3 rotation block is not a proper rotation (orthonormal, det +1)")


def parse_transform(block: Any, where: str) -> np.ndarray:
    """A ``T_camera_lidar`` block -> (4, 4) array.

    Accepts ``matrix``, or ``translation_m`` with ``quaternion_xyzw`` or
    ``rpy_deg``.  When several forms are present they must agree.
    """
    if not isinstance(block, dict):
        raise CalibError(f"{where}: expected a mapping with 'matrix' or 'translation_m' + rotation")
    candidates: list[tuple[str, np.ndarray]] = []
    if "matrix" in block:
        rows = block["matrix"]
        if not isinstance(rows, list) or len(rows) != 4:
            raise CalibError(f"{where}.matrix: expected a 4x4 nested list")
        T = np.array([finite_vector(r, 4, f"{where}.matrix row {i}", MAX_TRANSLATION_M) for i, r in enumerate(rows)])
        if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
            raise CalibError(f"{where}.matrix: last row must be [0, 0, 0, 1], got {T[3].tolist()}")
        _check_rotation(T[:3, :3], f"{where}.matrix")
        candidates.append(("matrix", T))
    if "translation_m" in block:
        t = np.array(finite_vector(block["translation_m"], 3, f"{where}.translation_m", MAX_TRANSLATION_M))
        if "quaternion_xyzw" in block:
            q = np.array(finite_vector(block["quaternion_xyzw"], 4, f"{where}.quaternion_xyzw"))
            if not 0.99 < np.linalg.norm(q) < 1.01:
                raise CalibError(f"{where}.quaternion_xyzw: must have unit norm, got {np.linalg.norm(q):.4f}")
            candidates.append(("quaternion_xyzw", make_T(R_from_quat_xyzw(q), t)))
        if "rpy_deg" in block:
            rpy = np.array(finite_vector(block["rpy_deg"], 3, f"{where}.rpy_deg", 1e4))
            candidates.append(("rpy_deg", make_T(R_from_rpy_deg(rpy), t)))
    if not candidates:
        raise CalibError(f"{where}: needs 'matrix', or 'translation_m' with 'quaternion_xyzw' or 'rpy_deg'")
    name0, T0 = candidates[0]
    for name, T in candidates[1:]:
        # Values printed with fewer digits by hand still agree to ~1e-6.
        if not np.allclose(T, T0, atol=1e-5):
            raise CalibError(f"{where}: '{name}' disagrees with '{name0}'; fix or remove one of them")
    _check_viewing(block, T0[:3, :3], name0, where)
    return T0


def _check_viewing(block: dict, R: np.ndarray, name0: str, where: str) -> None:
    """The optional ``viewing_direction_lidar`` and ``viewing_deg`` must agree with the rotation ``R``."""
    if "viewing_direction_lidar" in block:
        d = np.array(finite_vector(block["viewing_direction_lidar"], 3, f"{where}.viewing_direction_lidar"))
        if not np.allclose(d, R[2], atol=1e-5):
            raise CalibError(f"{where}: 'viewing_direction_lidar' disagrees with '{name0}'; fix or remove one of them")
    if "viewing_deg" in block:
        angles = block["viewing_deg"]
        if isinstance(angles, list) and len(angles) == 3 and (angles[0] is None or angles[2] is None):
            return  # written for a camera looking exactly along lidar +-z: azimuth and roll undefined
        v = np.array(finite_vector(angles, 3, f"{where}.viewing_deg", 1e4))
        if not np.allclose(R_from_viewing_deg(*v), R, atol=1e-5):
            raise CalibError(f"{where}: 'viewing_deg' disagrees with '{name0}'; fix or remove one of them")


def load_extrinsics_yaml(path: str | os.PathLike) -> dict[str, Any]:
    """Read an extrinsics YAML.

    Returns
    -------
    dict
        The document as read, except that ``"T_camera_lidar"`` is replaced by
        the (4, 4) float64 array (the authoritative ``matrix`` when present).
        The original block is kept under ``"T_camera_lidar_block"``.
    """
    path = Path(path)
    # The file repeats the solved pairs and their residuals (about 25 values per pair): the default
    # 100,000 values hold about 4,000 pairs.
    doc = read_yaml_mapping(path, "extrinsics file", max_bytes=MAX_EXTRINSICS_BYTES)
    if "T_camera_lidar" not in doc:
        raise CalibError(f"{path}: missing top-level key 'T_camera_lidar'")
    block = doc["T_camera_lidar"]
    out = dict(doc)
    out["T_camera_lidar_block"] = block
    out["T_camera_lidar"] = parse_transform(block, f"{path}: T_camera_lidar")
    return out
