"""Bearing Angle images (paper eq. 4, law-of-cosines form).

Truth comes from plane geometry worked out by hand, from explicit 3-D vector
geometry in this file, and from PCL's published unit-test values
(pcl/test/common/test_bearing_angle_image.cpp).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calib_core.bearing_angle import (
    BA_DIRECTIONS,
    ba_to_display,
    ba_to_uint8,
    bearing_angle_images,
)
from calib_core.errors import CalibError
from calib_core.lidar import (
    DepthMatrix,
    organized_cloud_depth,
    rotating_scanner_beams,
    rotating_scanner_depth,
    spherical_depth,
)

DEG = math.pi / 180.0
F32_TOL = 2e-6  # rad; float32 images on well-conditioned test geometry


def bearing_angle(range_prev, range_cur, cos_dphi) -> np.ndarray:
    """Bearing angle of eq. 4 (law-of-cosines form), elementwise: the independent reference of the compiled images.

    Parameters
    ----------
    range_prev : array_like
        Range rho_{i-1} of the previous beam, metres.
    range_cur : array_like
        Range rho_i of the current beam, metres (same origin as the previous).
    cos_dphi : array_like
        Cosine of the angle between the two beams.  All three broadcast.

    Returns
    -------
    ndarray, float64
        The angle in [0, pi] radians between the current beam and the segment
        from the previous point to the current one.  NaN where a range is not
        finite or <= 0, ``cos_dphi`` is not finite or outside [-1, 1] (beyond
        rounding), or the two points coincide.
    """
    rho_prev, rho_cur, cos_d = np.broadcast_arrays(
        np.asarray(range_prev, dtype=np.float64),
        np.asarray(range_cur, dtype=np.float64),
        np.asarray(cos_dphi, dtype=np.float64),
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = (
            np.isfinite(rho_prev)
            & np.isfinite(rho_cur)
            & (rho_prev > 0.0)
            & (rho_cur > 0.0)
            & np.isfinite(cos_d)
            & (np.abs(cos_d) <= 1.0 + 1e-9)
        )
        cos_d = np.clip(cos_d, -1.0, 1.0)
        segment_sq = rho_cur**2 + rho_prev**2 - 2.0 * rho_cur * rho_prev * cos_d
        segment = np.sqrt(np.maximum(segment_sq, 0.0))
        ok &= segment > 0.0
        # Clipping only absorbs rounding: |argument| <= 1 for any real triangle.
        argument = np.clip((rho_cur - rho_prev * cos_d) / segment, -1.0, 1.0)
        return np.where(ok, np.arccos(argument), np.nan)


def angle_between(u, v) -> float:
    """Angle between two 3-vectors, float64, from first principles."""
    u, v = np.asarray(u, float), np.asarray(v, float)
    return math.acos(max(-1.0, min(1.0, float(u @ v) / (np.linalg.norm(u) * np.linalg.norm(v)))))


# --------------------------------------------------------------------------
# The formula itself
# --------------------------------------------------------------------------


def test_pcl_get_angle_value():
    # PCL: getAngle((1,2,3), (2,1,1)) == 40.203 deg.  PCL's angle sits at its
    # first point, so (1,2,3) is our current point and (2,1,1) the previous.
    current, previous = np.array([1.0, 2.0, 3.0]), np.array([2.0, 1.0, 1.0])
    cos_dphi = 7.0 / math.sqrt(14.0 * 6.0)  # (1,2,3).(2,1,1) / (|.| |.|)
    ba = bearing_angle(math.sqrt(6.0), math.sqrt(14.0), cos_dphi)
    assert math.degrees(float(ba)) == pytest.approx(40.203, abs=1e-3)


@pytest.mark.parametrize("rho_prev, rho_cur, dphi_deg, expected_deg", [
    (1.0, 1.0, 60.0, 60.0),  # equilateral triangle
    (5.0, 5.0, 45.0, 67.5),  # isosceles: (180 - 45) / 2
    (1.0, 2.0, 60.0, 30.0),  # right angle at the previous point: 30-60-90 triangle
    (2.0, 1.0, 60.0, 90.0),  # right angle at the current point
])
def test_bearing_angle_triangles_by_hand(rho_prev, rho_cur, dphi_deg, expected_deg):
    ba = bearing_angle(rho_prev, rho_cur, math.cos(dphi_deg * DEG))
    assert math.degrees(float(ba)) == pytest.approx(expected_deg, abs=1e-9)


def test_bearing_angle_invalid_inputs_are_nan():
    rho_prev = np.array([np.nan, 1.0, 0.0, -1.0, 1.0, 1.0, np.inf, 1.0])
    rho_cur = np.array([1.0, np.nan, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0])
    cos_dphi = np.array([0.9, 0.9, 0.9, 0.9, 1.0, np.nan, 0.9, 1.0])
    ba = bearing_angle(rho_prev, rho_cur, cos_dphi)
    # 0-3 and 6: missing or impossible range; 4: coincident points; 5: no beam geometry.
    assert np.isnan(ba[:7]).all()
    # Same beam, farther point: the segment runs along the beam.
    assert ba[7] == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------
# Images on hand-built scenes
# --------------------------------------------------------------------------


def test_horizontal_flat_wall():
    # A wall x = d seen by one row of beams at elevation 0, azimuth falling
    # from 40 deg (left) to -40 deg (right).  Each point is (d, d tan az, 0);
    # walking right the wall segment runs along -y, and the angle between the
    # beam (cos az, sin az, 0) and -y is 90 deg + az.
    d = 3.0
    azimuth = np.arange(40.0, -41.0, -10.0) * DEG
    depth = spherical_depth((d / np.cos(azimuth))[None, :], [0.0], azimuth)
    ba = bearing_angle_images(depth)["horizontal"]
    assert ba.dtype == np.float32 and ba.shape == (1, 9)
    assert np.isnan(ba[0, 0])
    np.testing.assert_allclose(ba[0, 1:], 90.0 * DEG + azimuth[1:], atol=F32_TOL)
    # The elementwise formula agrees for one pair of beams.
    pair = bearing_angle(d / math.cos(20 * DEG), d / math.cos(10 * DEG), math.cos(10 * DEG))
    assert float(pair) == pytest.approx(100.0 * DEG, abs=1e-12)


def test_vertical_flat_wall():
    # One column looking along +x at the wall x = d, elevation falling with
    # the row: points (d, 0, d tan el); walking down the segment runs along
    # -z and its angle with the beam (cos el, 0, sin el) is 90 deg + el.
    d = 2.5
    elevation = np.array([30.0, 23.0, 10.0, -5.0, -40.0]) * DEG
    depth = spherical_depth((d / np.cos(elevation))[:, None], elevation, [0.0])
    ba = bearing_angle_images(depth)["vertical"][:, 0]
    assert np.isnan(ba[0])
    np.testing.assert_allclose(ba[1:], 90.0 * DEG + elevation[1:], atol=F32_TOL)


def test_diagonal_uses_true_angle_between_beams():
    # 2 x 2 grid: rows at elevation 40 and 0 deg, columns at azimuth 0 and 60 deg.
    elevation = np.array([40.0, 0.0]) * DEG
    azimuth = np.array([0.0, 60.0]) * DEG
    rho = np.array([[1.5, 2.0], [3.0, 4.0]])
    depth = spherical_depth(rho, elevation, azimuth)

    def point(r, c):
        el, az = elevation[r], azimuth[c]
        return rho[r, c] * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])

    images = bearing_angle_images(depth)
    # diag_pos45: cell (0, 1)'s previous neighbour is (1, 0), down-left.
    expected_pos = angle_between(point(0, 1), point(0, 1) - point(1, 0))
    assert images["diag_pos45"][0, 1] == pytest.approx(expected_pos, abs=F32_TOL)
    # diag_neg45: cell (1, 1)'s previous neighbour is (0, 0), up-left.
    expected_neg = angle_between(point(1, 1), point(1, 1) - point(0, 0))
    assert images["diag_neg45"][1, 1] == pytest.approx(expected_neg, abs=F32_TOL)
    # Spherical law of cosines for the beams (40, 60) and (0, 0): cos dphi = cos 40 cos 60.
    cos_dphi = math.cos(40 * DEG) * math.cos(60 * DEG)
    assert float(bearing_angle(rho[1, 0], rho[0, 1], cos_dphi)) == pytest.approx(expected_pos, abs=1e-12)
    # Neither the row step (40 deg) nor the column step (60 deg) would do.
    for step in (40.0, 60.0):
        assert abs(float(bearing_angle(rho[1, 0], rho[0, 1], math.cos(step * DEG))) - expected_pos) > 2 * DEG
    # Every other cell lacks a neighbour on the diagonals.
    assert np.isnan(images["diag_pos45"][[0, 1, 1], [0, 0, 1]]).all()
    assert np.isnan(images["diag_neg45"][[0, 0, 1], [0, 1, 0]]).all()


def test_pcl_gray_values():
    # PCL's GenerateBAImage test: a 3 x 2 organized cloud, expected grays
    # (0, 0, 0, 112, 80, 0) with gray = uint8(theta_deg * 255 / 180).  PCL
    # writes pixel (r, c) from the angle at its point with the point at
    # (r - 1, c + 1) (up-right).  Turned by 180 deg that neighbour becomes
    # (r + 1, c - 1), our diag_pos45 previous neighbour.
    # By hand: pixel (1, 0): (2,3,1) vs (1,3,2): a = 14, b = 2, c = 14,
    # acos(2 / (2 sqrt 28)) = 79.11 deg -> 112; pixel (1, 1): (4,2,2) vs
    # (2,3,2): a = 24, b = 5, c = 17, acos(12 / (2 sqrt 120)) = 56.79 deg -> 80.
    cloud = np.array(
        [
            [[3.0, 1.5, -2.0], [1.0, 3.0, 2.0], [2.0, 3.0, 2.0]],
            [[2.0, 3.0, 1.0], [4.0, 2.0, 2.0], [-1.5, 3.0, 1.0]],
        ]
    )
    depth = organized_cloud_depth(cloud[::-1, ::-1])
    ba = bearing_angle_images(depth)["diag_pos45"][::-1, ::-1]
    assert math.degrees(ba[1, 0]) == pytest.approx(79.1066, abs=1e-3)
    assert ba_to_uint8(ba).ravel().tolist() == [0, 0, 0, 112, 80, 0]


def _expected_nan_mask(shape, invalid_cells, direction, wrap=False):
    """Which BA pixels must be NaN, from the neighbour table in the docstring."""
    offsets = {"horizontal": (0, -1), "vertical": (-1, 0), "diag_pos45": (1, -1), "diag_neg45": (-1, -1)}
    d_row, d_col = offsets[direction]
    n_rows, n_cols = shape
    mask = np.zeros(shape, bool)
    for r in range(n_rows):
        for c in range(n_cols):
            pr, pc = r + d_row, c + d_col
            if wrap:
                pc %= n_cols
            if not (0 <= pr < n_rows and 0 <= pc < n_cols) or (r, c) in invalid_cells or (pr, pc) in invalid_cells:
                mask[r, c] = True
    return mask


@pytest.mark.parametrize("wrap", [False, True])
def test_missing_returns_and_borders_give_nan(wrap):
    rng = np.random.default_rng(5)
    rho = rng.uniform(2.0, 4.0, size=(4, 5))
    invalid_cells = {(1, 2), (3, 0), (0, 4)}
    for r, c in invalid_cells:
        rho[r, c] = np.nan
    depth = spherical_depth(rho, np.array([3.0, 1.0, -1.0, -3.0]) * DEG, np.array([4.0, 2.0, 0.0, -2.0, -4.0]) * DEG, wrap_cols=wrap)
    images = bearing_angle_images(depth)
    assert set(images) == set(BA_DIRECTIONS)
    for name in BA_DIRECTIONS:
        expected = _expected_nan_mask(rho.shape, invalid_cells, name, wrap)
        np.testing.assert_array_equal(np.isnan(images[name]), expected, err_msg=name)
        assert np.all((images[name][~expected] >= 0) & (images[name][~expected] <= np.pi))


def test_wrap_cols_links_column_zero_to_the_last_column():
    # A full turn of 8 beams, 45 deg apart, azimuth falling with the column.
    # All ranges 1 except the last column (range 2).
    azimuth = -np.arange(8) * 45.0 * DEG
    rho = np.ones((3, 8))
    rho[:, 7] = 2.0
    elevation = np.array([10.0, 0.0, -10.0]) * DEG
    wrapped = bearing_angle_images(spherical_depth(rho, elevation, azimuth, wrap_cols=True))
    open_ = bearing_angle_images(spherical_depth(rho, elevation, azimuth, wrap_cols=False))
    assert np.isnan(open_["horizontal"][:, 0]).all()
    # Row 1 (elevation 0): previous range 2, current range 1, 45 deg apart.
    # Law of cosines by hand: cos BA = (1 - 2 cos 45) / sqrt(1 + 4 - 4 cos 45) -> 106.33 deg.
    c45 = math.cos(45 * DEG)
    expected = math.acos((1.0 - 2.0 * c45) / math.sqrt(5.0 - 4.0 * c45))
    assert math.degrees(expected) == pytest.approx(106.325, abs=1e-3)
    assert wrapped["horizontal"][1, 0] == pytest.approx(expected, abs=F32_TOL)
    # Equal ranges: an isosceles triangle, base angle 90 - 45 / 2 deg.
    assert wrapped["horizontal"][1, 3] == pytest.approx(67.5 * DEG, abs=F32_TOL)
    # Diagonals wrap too: (1, 0)'s diag_pos45 neighbour is (2, 7), diag_neg45's is (0, 7).
    for name, prev_row in (("diag_pos45", 2), ("diag_neg45", 0)):
        p_cur = np.array([1.0, 0.0, 0.0])
        el, az = elevation[prev_row], azimuth[7]
        p_prev = 2.0 * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        assert wrapped[name][1, 0] == pytest.approx(angle_between(p_cur, p_cur - p_prev), abs=F32_TOL)
        assert np.isnan(open_[name][1, 0])


def test_coincident_points_are_nan():
    p, q = [1.0, 2.0, 0.5], [1.0, 2.5, 0.5]
    depth = organized_cloud_depth(np.array([[p, p, q]]))
    ba = bearing_angle_images(depth)["horizontal"][0]
    assert np.isnan(ba[:2]).all()
    assert ba[2] == pytest.approx(angle_between(q, np.subtract(q, p)), abs=F32_TOL)


def test_invalid_cell_is_masked_even_if_its_range_is_not_nan():
    # A hand-built DepthMatrix that marks a cell invalid but leaves a range in it.
    good = spherical_depth(np.full((1, 3), 2.0), [0.0], [0.2, 0.0, -0.2])
    valid = good.valid.copy()
    valid[0, 1] = False
    depth = DepthMatrix(good.range_m, good.directions, good.points, valid, dict(good.meta))
    ba = bearing_angle_images(depth)["horizontal"][0]
    assert np.isnan(ba).all()


def test_offset_scanner_uses_true_segment_geometry():
    # The paper's scanner with (exaggerated) axis offsets looking at the wall
    # x = 4.  Ranges come from intersecting each beam with the wall; the
    # expected BA is the angle between the beam and the segment joining the
    # two wall points, computed here with plain vector algebra.
    dx, dz, wall_x = 0.3, 0.2, 4.0
    theta = np.array([20.0, 10.0, 0.0, -10.0])[:, None] * DEG
    phi = np.array([-30.0, -20.0, -10.0, 0.0, 10.0]) * DEG
    origins, directions = rotating_scanner_beams(theta, phi, dx, dz)
    rho = (wall_x - origins[..., 0]) / directions[..., 0]
    depth = rotating_scanner_depth(rho, theta, phi, dx, dz)
    points = origins + rho[..., None] * directions
    np.testing.assert_allclose(points[..., 0], wall_x)  # the beams do hit the wall
    images = bearing_angle_images(depth)
    checks = {"horizontal": (2, 3, 2, 2), "vertical": (2, 3, 1, 3), "diag_pos45": (1, 2, 2, 1), "diag_neg45": (2, 2, 1, 1)}
    for name, (r, c, pr, pc) in checks.items():
        expected = angle_between(directions[r, c], points[r, c] - points[pr, pc])
        assert images[name][r, c] == pytest.approx(expected, abs=1e-5), name
    # Ignoring the offsets (eq. 4 on the raw ranges) would be off by degrees here.
    naive = bearing_angle(rho[2, 2], rho[2, 3], float(directions[2, 2] @ directions[2, 3]))
    assert abs(float(naive) - images["horizontal"][2, 3]) > 1 * DEG


def test_images_agree_with_elementwise_formula_on_a_noisy_cloud():
    rng = np.random.default_rng(11)
    n_rows, n_cols = 16, 64
    elevation = np.linspace(15.0, -15.0, n_rows)[:, None] * DEG
    azimuth = np.linspace(180.0, -180.0, n_cols, endpoint=False)[None, :] * DEG
    rho = rng.uniform(1.0, 20.0, size=(n_rows, n_cols))
    # Jittered beam directions: an organized cloud, where dphi varies per cell.
    el = elevation + rng.normal(0, 0.1 * DEG, (n_rows, n_cols))
    az = azimuth + rng.normal(0, 0.1 * DEG, (n_rows, n_cols))
    cloud = rho[..., None] * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    cloud[rng.random((n_rows, n_cols)) < 0.1] = np.nan
    depth = organized_cloud_depth(cloud, wrap_cols=True)
    images = bearing_angle_images(depth)
    rows, cols = np.mgrid[0:n_rows, 0:n_cols]
    for name, (d_row, d_col) in {"horizontal": (0, -1), "vertical": (-1, 0), "diag_pos45": (1, -1), "diag_neg45": (-1, -1)}.items():
        pr, pc = rows + d_row, (cols + d_col) % n_cols
        inside = (pr >= 0) & (pr < n_rows)
        pr = np.clip(pr, 0, n_rows - 1)
        cos_dphi = np.sum(depth.directions * depth.directions[pr, pc], axis=2)
        expected = np.where(inside, bearing_angle(depth.range_m[pr, pc], depth.range_m, cos_dphi), np.nan)
        np.testing.assert_array_equal(np.isnan(images[name]), np.isnan(expected), err_msg=name)
        np.testing.assert_allclose(images[name], expected, atol=5e-5, equal_nan=True, err_msg=name)


@pytest.mark.parametrize("dphi_deg", [0.1, 1.0, 20.0, 60.0, 120.0])
def test_images_match_eq4_over_the_whole_angle_range(dphi_deg):
    # The images evaluate the angle with a float32 polynomial; eq. 4 in
    # float64 (arccos) is the truth.  Log-uniform ranges from 5 cm to 200 m
    # put the BA all over 0..180 deg.  The ranges are float32 numbers, so
    # that only the angle evaluation is measured: the documented bound is
    # 4e-7 rad (2.3e-5 deg).
    rng = np.random.default_rng(int(dphi_deg * 10))
    n = 20001
    azimuth = -np.arange(n) * dphi_deg * DEG
    rho = np.exp(rng.uniform(math.log(0.05), math.log(200.0), n)).astype(np.float32).astype(np.float64)
    depth = spherical_depth(rho[None, :], [0.0], azimuth)
    ba = bearing_angle_images(depth, ("horizontal",))["horizontal"][0, 1:].astype(np.float64)
    cos_dphi = np.sum(depth.directions[0, 1:] * depth.directions[0, :-1], axis=1)
    expected = bearing_angle(rho[:-1], rho[1:], cos_dphi)
    assert np.degrees(expected.min()) < dphi_deg / 10 and np.degrees(expected.max()) > 180.0 - dphi_deg * 1.01
    assert np.max(np.abs(ba - expected)) < 4e-7


def test_separate_origins_match_the_definition_on_random_beams():
    # Beams in random directions from random origins: the BA is the angle
    # between the beam and the segment from the previous point, computed here
    # in float64 with arctan2(|d x s|, d . s).  Inputs are float32 numbers so
    # that only the evaluation is measured.
    rng = np.random.default_rng(3)
    n_rows, n_cols = 40, 60
    beams = rng.normal(size=(n_rows, n_cols, 3))
    beams = (beams / np.linalg.norm(beams, axis=2, keepdims=True)).astype(np.float32).astype(np.float64)
    rho = rng.uniform(0.5, 20.0, (n_rows, n_cols))
    points = (rng.normal(0, 0.3, (n_rows, n_cols, 3)) + rho[..., None] * beams).astype(np.float32).astype(np.float64)
    valid = rng.random((n_rows, n_cols)) > 0.05
    points[~valid] = np.nan
    depth = DepthMatrix(np.where(valid, rho, np.nan), beams, points, valid, {"wrap_cols": True})
    images = bearing_angle_images(depth)
    rows, cols = np.mgrid[0:n_rows, 0:n_cols]
    for name, (d_row, d_col) in {"horizontal": (0, -1), "vertical": (-1, 0), "diag_pos45": (1, -1), "diag_neg45": (-1, -1)}.items():
        pr, pc = rows + d_row, (cols + d_col) % n_cols
        inside = (pr >= 0) & (pr < n_rows)
        segment = points - points[np.clip(pr, 0, n_rows - 1), pc]
        with np.errstate(invalid="ignore"):
            expected = np.arctan2(np.linalg.norm(np.cross(beams, segment), axis=2), np.sum(beams * segment, axis=2))
        expected[~inside] = np.nan
        np.testing.assert_array_equal(np.isnan(images[name]), np.isnan(expected), err_msg=name)
        assert np.nanmax(np.abs(images[name] - expected)) < 4e-7, name


def test_sample_layout_full_scan_runs():
    theta = np.deg2rad(np.arange(89.5, -90.0, -1.0))[:, None]
    phi = np.deg2rad(np.arange(720) * 0.5)
    rho = np.full((180, 720), 5.0)
    depth = rotating_scanner_depth(rho, theta, phi, 0.0, 0.0, wrap_cols=True)
    images = bearing_angle_images(depth)
    # A sphere of radius 5 around the origin: every beam meets the surface
    # at a right angle, so each segment makes (180 - dphi) / 2 deg with the beam.
    assert images["horizontal"].shape == (180, 720)
    assert not np.isnan(images["horizontal"]).any()
    cos_dphi = np.cos(theta) ** 2 * math.cos(0.5 * DEG) + np.sin(theta) ** 2  # same theta, phi 0.5 deg apart
    expected = (math.pi - np.arccos(cos_dphi)) / 2.0
    np.testing.assert_allclose(images["horizontal"], np.broadcast_to(expected, (180, 720)), atol=1e-5)
    np.testing.assert_allclose(images["vertical"][1:], (180.0 - 1.0) / 2.0 * DEG, atol=1e-5)


def test_unknown_direction_and_bad_input():
    depth = spherical_depth(np.ones((2, 2)), [0.0, 0.1], [0.0, 0.1])
    with pytest.raises(CalibError, match="diagonal"):
        bearing_angle_images(depth, directions=("diagonal",))
    with pytest.raises(CalibError, match="DepthMatrix"):
        bearing_angle_images(np.ones((2, 2)))
    assert set(bearing_angle_images(depth, directions=("vertical",))) == {"vertical"}


# --------------------------------------------------------------------------
# Display mappings
# --------------------------------------------------------------------------


def test_ba_to_uint8():
    ba = np.array([[0.0, np.pi / 2, np.pi, np.nan, 2.0]], dtype=np.float32)
    # floor(x * 255 / pi): pi/2 -> 127.5 -> 127, 2 rad -> 162.34 -> 162.
    assert ba_to_uint8(ba).tolist() == [[0, 127, 255, 0, 162]]
    assert ba_to_uint8(ba).dtype == np.uint8


def test_ba_to_display_equalises_valid_pixels_only():
    ba = np.full((10, 10), np.nan, dtype=np.float32)
    # 40 cells share one angle (like a road surface), 10 spread above it.
    ba[:8, :5] = 1.0
    ba[8:, :5] = np.linspace(2.0, 3.0, 10).reshape(2, 5)
    gray = ba_to_display(ba)
    assert gray.dtype == np.uint8
    assert (gray[:, 5:] == 0).all(), "no-return cells stay black"
    valid = gray[:, :5].ravel()
    assert valid.min() >= 32, "valid cells never look like holes"
    # Ranks: the shared angle sits at its mid-rank 20/50, the rest spread above it.
    assert abs(int(gray[0, 0]) - (32 + 223 * 0.4)) <= 1
    spread = gray[8:, :5].ravel()
    assert np.all(np.diff(spread.astype(int)) > 0) and spread.max() >= 250
    # A flat image maps to mid-gray; an empty one to black.
    flat = ba_to_display(np.where(np.isnan(ba), np.nan, 1.0))
    assert set(np.unique(flat)) == {0, int(np.rint(32 + 223 * 0.5))}
    assert not ba_to_display(np.full((2, 2), np.nan)).any()
    with pytest.raises(CalibError):
        ba_to_display(ba, min_gray=0)


# --------------------------------------------------------------------------
# The compiled kernels' disk cache
# --------------------------------------------------------------------------

_CACHE_CHECK = """
import numba, numpy as np
from calib_core.bearing_angle import bearing_angle_images
from calib_core.lidar import spherical_depth
ba = bearing_angle_images(spherical_depth(np.array([[1.0, 2.0, 2.0]]), [0.0], [0.2, 0.0, -0.2]))
print(numba.config.CACHE_DIR)
print(float(ba["horizontal"][0, 2]))
"""


def test_kernels_are_cached_where_numba_finds_no_cache_directory(tmp_path):
    # A read-only install with no writable home: numba finds no cache
    # directory.  Simulated by letting numba try only locators that give
    # none here (no IPython, no NUMBA_CACHE_DIR); the kernels must then be
    # cached in a per-user directory under the temp directory, and give the
    # right BA: equal ranges 0.2 rad apart make an isosceles triangle.
    import numba

    if not hasattr(numba.config, "CACHE_LOCATOR_CLASSES"):
        pytest.skip(f"numba {numba.__version__} cannot restrict its cache locators")
    repo = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(NUMBA_CACHE_LOCATOR_CLASSES="IPythonCacheLocator,UserProvidedCacheLocator", TMPDIR=str(tmp_path),
               PYTHONPATH=str(repo) + os.pathsep + env.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", _CACHE_CHECK], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    cache_dir, ba = out.stdout.split()
    assert Path(cache_dir).parent == tmp_path and Path(cache_dir).name.startswith("ba-calib-numba-cache-")
    assert any(Path(cache_dir).rglob("*.nbi")), "no kernel was written to the cache"
    assert float(ba) == pytest.approx((math.pi - 0.2) / 2, abs=F32_TOL)
