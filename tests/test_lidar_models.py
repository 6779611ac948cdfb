"""Laser models -> DepthMatrix, and the native .npz scan file.

Expected values are worked out by hand from the paper's eq. 3 (written out
entry by entry below) and from plain spherical geometry.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.lidar import (
    DepthMatrix,
    load_depth_npz,
    organized_cloud_depth,
    rotating_scanner_beams,
    rotating_scanner_depth,
    save_depth_npz,
    spherical_depth,
)

DEG = math.pi / 180.0


def eq3_point(rho, theta, phi, dx, dz):
    """Paper eq. 3, the 3x4 matrix entries typed in as printed (i <-> phi, j <-> theta)."""
    ci, si, cj, sj = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    matrix = [
        [ci * cj, -ci * sj, si, ci * dx + si * dz],
        [sj, cj, 0.0, 0.0],
        [-si * cj, si * sj, ci, -si * dx + ci * dz],
    ]
    vector = [rho, 0.0, 0.0, 1.0]
    return [sum(m * v for m, v in zip(row, vector)) for row in matrix]


# --------------------------------------------------------------------------
# Rotating 2-D scanner (eq. 3)
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "theta_deg, phi_deg, expected",
    [
        # theta = phi = 0: straight ahead, shifted by the mirror offset.
        (0.0, 0.0, (2.0 + 0.1, 0.0, 0.05)),
        # phi = 90 deg turns +x onto -z and +z onto +x: (dz, 0, -(rho + dx)).
        (0.0, 90.0, (0.05, 0.0, -(2.0 + 0.1))),
        # theta = 90 deg: along the rotation axis +y, the offset stays in x-z.
        (90.0, 0.0, (0.1, 2.0, 0.05)),
        (90.0, 90.0, (0.05, 2.0, -0.1)),
        # phi = 180 deg: x and z flip sign.
        (0.0, 180.0, (-(2.0 + 0.1), 0.0, -0.05)),
        # theta = -90 deg: along -y.
        (-90.0, 37.0, (0.1 * math.cos(37 * DEG) + 0.05 * math.sin(37 * DEG), -2.0, -0.1 * math.sin(37 * DEG) + 0.05 * math.cos(37 * DEG))),
    ],
)
def test_eq3_special_angles(theta_deg, phi_deg, expected):
    depth = rotating_scanner_depth(np.array([[2.0]]), theta_deg * DEG, phi_deg * DEG, 0.1, 0.05)
    np.testing.assert_allclose(depth.points[0, 0], expected, atol=1e-12)
    np.testing.assert_allclose(depth.range_m[0, 0], 2.0)


def test_eq3_matches_paper_matrix_at_general_angles():
    rng = np.random.default_rng(3)
    theta = rng.uniform(-math.pi / 2, math.pi / 2, size=(4, 1))
    phi = rng.uniform(0, 2 * math.pi, size=(5,))
    rho = rng.uniform(0.5, 30.0, size=(4, 5))
    depth = rotating_scanner_depth(rho, theta, phi, -0.07, 0.12)
    for r in range(4):
        for c in range(5):
            expected = eq3_point(rho[r, c], theta[r, 0], phi[c], -0.07, 0.12)
            np.testing.assert_allclose(depth.points[r, c], expected, atol=1e-12)


def test_beams_origin_plus_range_times_direction_is_eq3():
    theta = np.array([10.0, -40.0, 75.0]) * DEG
    phi = np.array([0.0, 130.0, 260.0]) * DEG
    origins, directions = rotating_scanner_beams(theta, phi, 0.03, -0.02)
    assert origins.shape == directions.shape == (3, 3)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    for k in range(3):
        for rho in (0.7, 12.0):
            expected = eq3_point(rho, theta[k], phi[k], 0.03, -0.02)
            np.testing.assert_allclose(origins[k] + rho * directions[k], expected, atol=1e-12)


def test_beams_broadcast_together():
    origins, directions = rotating_scanner_beams(np.zeros((4, 1)), np.zeros(6), 0.1, np.zeros((1, 1)))
    assert origins.shape == directions.shape == (4, 6, 3)
    with pytest.raises(CalibError, match="broadcast"):
        rotating_scanner_beams(np.zeros(4), np.zeros(6), 0.0, 0.0)


def test_rotating_depth_sample_layout_and_wrap():
    # The synthetic sample's layout: theta per row from +89.5 down to -89.5 deg,
    # phi per column over 360 deg in 0.5 deg steps.
    theta = np.deg2rad(np.arange(89.5, -90.0, -1.0))[:, None]
    phi = np.deg2rad(np.arange(720) * 0.5)
    depth = rotating_scanner_depth(np.full((180, 720), 3.0), theta, phi, 0.0, 0.0, wrap_cols=True)
    assert depth.shape == (180, 720)
    assert depth.meta["model"] == "rotating_2d" and depth.meta["wrap_cols"] is True
    # Row 90 is theta = -0.5 deg; column 180 is phi = 90 deg: the beam points at -z.
    expected = 3.0 * np.array([0.0, math.sin(-0.5 * DEG), -math.cos(-0.5 * DEG)])
    np.testing.assert_allclose(depth.points[90, 180], expected, atol=1e-12)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 0.0, -1.0])
def test_rotating_no_return_cells_are_nan_not_origin(bad):
    rho = np.array([[1.0, bad, 2.0]])
    depth = rotating_scanner_depth(rho, 0.0, np.array([0.0, 0.1, 0.2]), 0.1, 0.0)
    assert depth.valid.tolist() == [[True, False, True]]
    assert np.isnan(depth.range_m[0, 1])
    assert np.isnan(depth.points[0, 1]).all()
    # The beam geometry is still known for a no-return cell.
    np.testing.assert_allclose(np.linalg.norm(depth.directions[0, 1]), 1.0)


def test_rotating_bad_arguments():
    with pytest.raises(CalibError, match="range_m"):
        rotating_scanner_depth(np.zeros(5), 0.0, 0.0, 0.0, 0.0)
    with pytest.raises(CalibError, match="theta_rad"):
        rotating_scanner_depth(np.ones((3, 4)), np.zeros(3), 0.0, 0.0, 0.0)  # (3,) is per column, not per row
    with pytest.raises(CalibError, match="phi_rad"):
        rotating_scanner_depth(np.ones((3, 4)), 0.0, [0.0, np.nan, 0.0, 0.0], 0.0, 0.0)
    with pytest.raises(CalibError, match="dx_m"):
        rotating_scanner_depth(np.ones((3, 4)), 0.0, 0.0, [0.1, 0.2], 0.0)
    with pytest.raises(CalibError, match="wrap_cols"):
        rotating_scanner_depth(np.ones((3, 4)), 0.0, 0.0, 0.0, 0.0, wrap_cols="yes")
    with pytest.raises(CalibError, match="numeric"):
        rotating_scanner_depth([["a", "b"]], 0.0, 0.0, 0.0, 0.0)


# --------------------------------------------------------------------------
# Spherical and organized models
# --------------------------------------------------------------------------


def test_spherical_directions_by_hand():
    elevation = np.array([90.0, 30.0, 0.0]) * DEG
    azimuth = np.array([0.0, 45.0, 90.0, 180.0]) * DEG
    depth = spherical_depth(np.full((3, 4), 2.0), elevation, azimuth)
    np.testing.assert_allclose(depth.points[0, 1], (0.0, 0.0, 2.0), atol=1e-12)  # straight up
    np.testing.assert_allclose(depth.points[2, 2], (0.0, 2.0, 0.0), atol=1e-12)  # left (+y)
    np.testing.assert_allclose(depth.points[2, 3], (-2.0, 0.0, 0.0), atol=1e-12)  # behind
    c30 = math.sqrt(3) / 2
    np.testing.assert_allclose(depth.points[1, 1], (2 * c30 / math.sqrt(2), 2 * c30 / math.sqrt(2), 1.0), atol=1e-12)
    assert depth.meta["model"] == "spherical" and depth.meta["wrap_cols"] is False


def test_spherical_invalid_cells_and_shapes():
    rho = np.array([[1.0, np.nan], [0.0, 4.0]])
    depth = spherical_depth(rho, [0.1, -0.1], [0.0, 0.5])
    assert depth.valid.tolist() == [[True, False], [False, True]]
    assert np.isnan(depth.points[~depth.valid]).all()
    assert np.isfinite(depth.points[depth.valid]).all()
    with pytest.raises(CalibError, match=r"elevation_rad must have shape \(2,\)"):
        spherical_depth(rho, [0.1, -0.1, 0.0], [0.0, 0.5])
    with pytest.raises(CalibError, match="azimuth_rad"):
        spherical_depth(rho, [0.1, -0.1], [[0.0, 0.5]])


def test_organized_cloud_range_and_direction():
    points = np.array(
        [
            [[3.0, 4.0, 12.0], [0.0, 0.0, 0.0]],
            [[np.nan, 1.0, 1.0], [-2.0, 0.0, 0.0]],
        ]
    )
    depth = organized_cloud_depth(points)
    assert depth.valid.tolist() == [[True, False], [False, True]]
    np.testing.assert_allclose(depth.range_m[0, 0], 13.0)
    np.testing.assert_allclose(depth.directions[0, 0], np.array([3.0, 4.0, 12.0]) / 13.0)
    np.testing.assert_allclose(depth.directions[1, 1], (-1.0, 0.0, 0.0))
    assert np.isnan(depth.points[0, 1]).all() and np.isnan(depth.range_m[0, 1])
    assert np.isnan(depth.points[1, 0]).all()
    with pytest.raises(CalibError, match=r"\(H, W, 3\)"):
        organized_cloud_depth(np.zeros((4, 3)))


# --------------------------------------------------------------------------
# Native .npz scan file
# --------------------------------------------------------------------------


def _assert_same_depth(a: DepthMatrix, b: DepthMatrix):
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.range_m, b.range_m)  # NaN == NaN here
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.directions, b.directions)
    assert a.meta["model"] == b.meta["model"]
    assert a.meta["wrap_cols"] == b.meta["wrap_cols"]


def _example_depths():
    rho = np.array([[1.0, np.nan, 3.0], [4.0, 5.0, 0.0]])
    yield rotating_scanner_depth(rho, np.array([[0.2], [-0.2]]), np.array([0.0, 2.0, 4.0]), 0.02, -0.03, wrap_cols=True)
    yield spherical_depth(rho, [0.1, -0.1], [1.0, 0.0, -1.0])
    # At least 3 valid cells: a native scan with fewer is refused on loading.
    yield organized_cloud_depth(np.array([[[1.0, 2.0, 3.0], [np.nan] * 3, [0.5, 1.0, -2.0]],
                                          [[0.0] * 3, [-1.0, 0.5, 0.0], [2.0, 2.0, 2.0]]]))


@pytest.mark.parametrize("depth", list(_example_depths()), ids=lambda d: d.meta["model"])
def test_npz_round_trip(tmp_path, depth):
    path = tmp_path / "scan.npz"
    save_depth_npz(path, depth)
    save_depth_npz(path, depth)  # overwriting is fine
    loaded = load_depth_npz(path)
    _assert_same_depth(depth, loaded)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan.npz"]  # no temp file left behind


def test_npz_rotating_keeps_parameters(tmp_path):
    depth = next(_example_depths())
    save_depth_npz(tmp_path / "s.npz", depth)
    with np.load(tmp_path / "s.npz") as data:
        assert str(data["model"]) == "rotating_2d"
        assert float(data["dx_m"]) == 0.02 and float(data["dz_m"]) == -0.03
        assert bool(data["wrap_cols"]) is True
        assert np.isnan(data["range_m"][0, 1]) and np.isnan(data["range_m"][1, 2])


def test_npz_without_model_meta_is_saved_as_points(tmp_path):
    source = next(_example_depths())
    bare = DepthMatrix(source.range_m, source.directions, source.points, source.valid, meta={})
    save_depth_npz(tmp_path / "bare.npz", bare)
    loaded = load_depth_npz(tmp_path / "bare.npz")
    assert loaded.meta["model"] == "organized"
    np.testing.assert_array_equal(loaded.points, source.points)


def _write_npz(path, **arrays):
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize(
    "arrays, pattern",
    [
        ({"range_m": np.ones((2, 2))}, "missing key 'model'"),
        ({"model": np.array("velodyne")}, "key 'model' is 'velodyne'"),
        ({"model": np.array(3)}, "key 'model' must be one string"),
        ({"model": np.array("spherical"), "range_m": np.ones((2, 3)), "elevation_rad": np.zeros(2)}, "missing key 'azimuth_rad'"),
        (
            {"model": np.array("spherical"), "range_m": np.ones((2, 3)), "elevation_rad": np.zeros(3), "azimuth_rad": np.zeros(3)},
            "elevation_rad must have shape",
        ),
        (
            {"model": np.array("rotating_2d"), "range_m": np.ones((2, 3)), "theta_rad": np.zeros((2, 1)), "phi_rad": np.zeros(2), "dx_m": np.array(0.0), "dz_m": np.array(0.0)},
            "phi_rad with shape",
        ),
        ({"model": np.array("organized"), "points": np.ones((2, 3))}, "points must be an organized"),
        ({"model": np.array("organized"), "points": np.array([["a", "b", "c"]])}, "key 'points' must be numeric"),
        ({"model": np.array("organized"), "points": np.ones((1, 1, 3)), "wrap_cols": np.array(1.5)}, "key 'wrap_cols' must be one bool"),
    ],
)
def test_npz_malformed_names_file_and_key(tmp_path, arrays, pattern):
    path = _write_npz(tmp_path / "bad.npz", **arrays)
    with pytest.raises(CalibError, match=pattern) as info:
        load_depth_npz(path)
    assert "bad.npz" in str(info.value)
    assert "\n" not in str(info.value)


def test_npz_object_array_is_rejected_without_unpickling(tmp_path):
    path = tmp_path / "pickle.npz"
    np.savez(path, model=np.array("organized"), points=np.array([None, 1], dtype=object))
    with pytest.raises(CalibError, match="pickle.npz"):
        load_depth_npz(path)


def test_npz_not_a_scan_file(tmp_path):
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"this is not a zip archive")
    with pytest.raises(CalibError, match="garbage.npz"):
        load_depth_npz(garbage)
    single = tmp_path / "single.npy"
    np.save(single, np.ones(3))
    with pytest.raises(CalibError, match="single.npy"):
        load_depth_npz(single)
    with pytest.raises(CalibError, match="not found"):
        load_depth_npz(tmp_path / "missing.npz")
    truncated = tmp_path / "truncated.npz"
    save_depth_npz(truncated, next(_example_depths()))
    truncated.write_bytes(truncated.read_bytes()[:200])
    with pytest.raises(CalibError, match="truncated.npz"):
        load_depth_npz(truncated)


def test_npz_save_to_missing_folder_is_a_calib_error(tmp_path):
    with pytest.raises(CalibError, match="cannot write"):
        save_depth_npz(tmp_path / "no" / "such" / "dir" / "scan.npz", next(_example_depths()))
