"""Organising unorganized spinning-lidar clouds into depth matrices.

Truth: synthetic clouds built cell by cell, the ring field recorded by the
PJLab sensor, and the README's beam elevations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.lidar.organize import (
    cluster_elevations,
    estimate_n_cols,
    firing_order_rings,
    organize_by_elevation,
    organize_by_firing_order,
    organize_by_ring,
    organize_grid,
    organize_spherical,
)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "pjlab_opencalib_lidar2camera"
AUTO_DECODED = DATA / "auto_calib" / "calib_pcd_decoded.npz"
MANUAL_PCD = DATA / "manual_calib" / "0.pcd"
needs_data = pytest.mark.skipif(not AUTO_DECODED.is_file(), reason=f"real data not found at {DATA}")


def direction(elevation_rad, azimuth_rad) -> np.ndarray:
    el, az = np.broadcast_arrays(np.asarray(elevation_rad, float), np.asarray(azimuth_rad, float))
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


# Six beams, highest first, with uneven spacing like a real sensor.
ROW_ELEVATION_DEG = np.array([14.9, 3.0, 1.0, 0.83, -5.0, -24.9])
N_COLS = 180


def grid_cloud(seed: int = 0, fill: float = 0.8):
    """Points at the centres of randomly chosen cells of a 6 x 180 grid.

    Returns points (N, 3), ring ids (N,) (numbered bottom-up and shuffled), and
    the true (row, col) of every point.
    """
    rng = np.random.default_rng(seed)
    rows, cols = np.nonzero(rng.random((len(ROW_ELEVATION_DEG), N_COLS)) < fill)
    azimuth = np.pi - (cols + 0.5) * 2 * np.pi / N_COLS  # the documented column convention
    range_m = rng.uniform(1.0, 60.0, len(rows))
    points = range_m[:, None] * direction(np.radians(ROW_ELEVATION_DEG[rows]), azimuth)
    ring_of_row = np.array([17, 4, 9, 2, 30, 0])  # arbitrary ids, any order
    order = rng.permutation(len(rows))
    return points[order], ring_of_row[rows][order], rows[order], cols[order]


# --------------------------------------------------------------------------
# Ring organisation
# --------------------------------------------------------------------------


def test_ring_points_land_in_their_cells():
    points, ring, rows, cols = grid_cloud()
    for n_cols in (N_COLS, None):  # given, and estimated from the points
        depth = organize_by_ring(points, ring, n_cols=n_cols)
        assert depth.shape == (6, N_COLS)
        expected_valid = np.zeros((6, N_COLS), bool)
        expected_valid[rows, cols] = True
        np.testing.assert_array_equal(depth.valid, expected_valid)
        np.testing.assert_array_equal(depth.points[rows, cols], points)  # measured points, not re-projected
        np.testing.assert_allclose(depth.range_m[rows, cols], np.linalg.norm(points, axis=1), rtol=1e-15)
        np.testing.assert_array_equal(depth.meta["beam_ids"], [17, 4, 9, 2, 30, 0])
        assert depth.meta["organize"] == "ring" and depth.meta["wrap_cols"] is True
        assert depth.meta["n_points_kept"] == len(points) and depth.meta["n_points_collided"] == 0
        np.testing.assert_array_equal(depth.meta["point_index"][rows, cols], np.arange(len(points)))
        assert np.isnan(depth.range_m[~expected_valid]).all() and np.isnan(depth.points[~expected_valid]).all()


def test_empty_cells_get_row_elevation_and_column_azimuth():
    points, ring, rows, cols = grid_cloud(fill=0.5)
    depth = organize_by_ring(points, ring, n_cols=N_COLS)
    empty_rows, empty_cols = np.nonzero(~depth.valid)
    expected = direction(np.radians(ROW_ELEVATION_DEG[empty_rows]), np.pi - (empty_cols + 0.5) * 2 * np.pi / N_COLS)
    np.testing.assert_allclose(depth.directions[empty_rows, empty_cols], expected, atol=1e-9)
    # Hand check: column 45 looks left (+y), column 90 forward (+x), column 135 right (-y).
    np.testing.assert_allclose(depth.meta["col_azimuth_rad"][[45, 90, 135]] + np.pi / N_COLS, [np.pi / 2, 0.0, -np.pi / 2], atol=1e-12)


def test_collision_keeps_the_nearer_point():
    az = np.pi - 10.5 * 2 * np.pi / 36  # centre of column 10
    points = np.vstack([7.0 * direction(0.0, az), 3.0 * direction(0.0, az + 1e-4), 5.0 * direction(0.0, az - 2 * np.pi / 36)])
    depth = organize_by_ring(points, np.array([0, 0, 0]), n_cols=36)
    assert depth.range_m[0, 10] == pytest.approx(3.0)
    assert depth.range_m[0, 11] == pytest.approx(5.0)
    assert depth.meta["n_points_collided"] == 1 and depth.meta["n_cells_with_collision"] == 1


def test_beams_fired_at_cell_edges_do_not_collide():
    # A beam whose firings sit on column edges, with float noise: naive binning
    # would put neighbours into one cell; centring the beam's phase does not.
    rng = np.random.default_rng(3)
    n_cols = 360
    az = np.pi - np.arange(n_cols) * 2 * np.pi / n_cols + rng.normal(0, 1e-9, n_cols)
    points = 10.0 * direction(0.1, az)
    depth = organize_by_ring(points, np.zeros(n_cols, int), n_cols=n_cols)
    assert depth.valid.all() and depth.meta["n_points_collided"] == 0


def test_invalid_points_are_dropped_and_counted():
    points, ring, _, _ = grid_cloud()
    points = points.copy()
    points[:5] = np.nan
    points[5] = 0.0
    depth = organize_by_ring(points, ring, n_cols=N_COLS)
    assert depth.meta["n_points_dropped"] == 6 and depth.meta["n_points_kept"] == len(points) - 6
    with pytest.raises(CalibError, match="no usable points"):
        organize_by_ring(np.full((4, 3), np.nan), np.zeros(4, int))
    with pytest.raises(CalibError, match="whole numbers"):
        organize_by_ring(points, ring + 0.5)
    with pytest.raises(CalibError, match="shape"):
        organize_by_ring(points[:, :2], ring)


def test_n_cols_estimate_ignores_gaps():
    rng = np.random.default_rng(1)
    azimuth = np.radians(np.arange(0, 360, 0.25))[rng.random(1440) < 0.7]  # 30 % dropped returns
    assert estimate_n_cols(azimuth, np.zeros(len(azimuth), int)) == 1440


# --------------------------------------------------------------------------
# Elevation clustering and firing order (synthetic)
# --------------------------------------------------------------------------


def test_elevation_clustering_recovers_the_rows():
    points, ring, rows, cols = grid_cloud(seed=5)
    depth = organize_by_elevation(points, n_beams=6, n_cols=N_COLS)
    assert depth.meta["organize"] == "elevation"
    expected_valid = np.zeros((6, N_COLS), bool)
    expected_valid[rows, cols] = True
    np.testing.assert_array_equal(depth.valid, expected_valid)
    np.testing.assert_allclose(np.degrees(depth.meta["row_elevation_rad"]), ROW_ELEVATION_DEG, atol=1e-9)


def test_cluster_elevations_is_not_fooled_by_outliers():
    rng = np.random.default_rng(2)
    centres = np.radians([-15.0, -1.0, -0.8, 2.0])
    labels = rng.integers(0, 4, 4000)
    elevation = centres[labels] + rng.normal(0, np.radians(0.01), 4000)
    elevation[:3] = np.radians([10.0, 20.0, -30.0])  # three stray points far from any beam
    found, found_centres = cluster_elevations(elevation, 4)
    np.testing.assert_array_equal(found[3:], labels[3:])
    np.testing.assert_allclose(found_centres, centres, atol=np.radians(0.005))
    with pytest.raises(CalibError, match="beams"):
        cluster_elevations(np.zeros(10), 3)


def firing_order_cloud(rng, n_beams=5, n_cols=240, start_deg=180.0, start_jitter_deg=0.0, clockwise=True):
    """Ring after ring, each a 360-degree sweep from about ``start_deg``, 10 % dropped plus a long gap."""
    elevation = np.radians(np.linspace(10, -15, n_beams))
    rings, azimuth = [], []
    for beam in rng.permutation(n_beams):
        start = np.radians(start_deg + rng.uniform(-start_jitter_deg, start_jitter_deg))
        sweep = start + (-1 if clockwise else 1) * np.arange(n_cols) * 2 * np.pi / n_cols
        keep = rng.random(n_cols) > 0.1
        if beam == 0:
            keep[n_cols // 4 : 3 * n_cols // 4] = False  # half a turn of sky
        rings.append(np.full(keep.sum(), beam))
        azimuth.append(sweep[keep])
    rings, azimuth = np.concatenate(rings), np.concatenate(azimuth)
    points = rng.uniform(2, 50, len(rings))[:, None] * direction(elevation[rings], azimuth)
    return points, rings


@pytest.mark.parametrize("start_deg,jitter,clockwise", [(180.0, 0.0, True), (37.0, 0.0, False), (-120.0, 2.0, True)])
def test_firing_order_recovers_rings(start_deg, jitter, clockwise):
    rng = np.random.default_rng(int(start_deg) % 97)
    points, rings = firing_order_cloud(rng, start_deg=start_deg, start_jitter_deg=jitter, clockwise=clockwise)
    sweeps = firing_order_rings(points, 5)
    # Sweep k of storage order is the k-th ring stored.
    stored_ring = rings[np.r_[0, np.flatnonzero(np.diff(rings)) + 1]]
    np.testing.assert_array_equal(stored_ring[sweeps], rings)
    depth = organize_by_firing_order(points, 5)
    assert depth.shape == (5, 240) and depth.meta["organize"] == "firing_order"
    assert depth.meta["n_points_kept"] == len(points)


def test_firing_order_rejects_other_orders():
    rng = np.random.default_rng(0)
    points, _ = firing_order_cloud(rng)
    with pytest.raises(CalibError, match="found 1 azimuth sweeps"):
        firing_order_rings(points[np.argsort(np.arctan2(points[:, 1], points[:, 0]))], 5)
    with pytest.raises(CalibError, match="firing order"):
        firing_order_rings(points[rng.permutation(len(points))], 5)


# --------------------------------------------------------------------------
# Spherical fallback and organized grids
# --------------------------------------------------------------------------


def test_spherical_grid_cells_by_hand():
    # v_range (-2, 2) deg at 1 deg -> 4 rows with tops 2, 1, 0, -1; 36 columns of 10 deg.
    points = np.vstack(
        [
            5.0 * direction(np.radians(1.5), np.radians(3.0)),  # row 0; column 17 spans azimuth (0, 10] deg
            6.0 * direction(np.radians(-0.5), np.radians(-95.0)),  # row 2; column 27 spans (-100, -90]
            9.0 * direction(np.radians(5.0), 0.1),  # outside v_range: dropped
        ]
    )
    depth = organize_spherical(points, 1.0, 10.0, v_range_deg=(-2.0, 2.0))
    assert depth.shape == (4, 36)
    assert set(zip(*np.nonzero(depth.valid))) == {(0, 17), (2, 27)}
    np.testing.assert_array_equal(depth.points[0, 17], points[0])
    np.testing.assert_allclose(np.degrees(depth.meta["row_elevation_rad"]), [1.5, 0.5, -0.5, -1.5])
    np.testing.assert_allclose(depth.directions[1, 0], direction(np.radians(0.5), np.radians(175.0)), atol=1e-12)
    with pytest.raises(CalibError, match="resolution"):
        organize_spherical(points, 0.0, 1.0)


def test_organize_grid_turns_driver_layouts_upright():
    # Velodyne-like: row 0 = LOWEST beam, azimuth INCREASING to the right, full turn.
    elevation = np.radians([-10.0, 0.0, 10.0])[:, None]
    azimuth = (np.arange(72) * 5.0 + 2.5)[None, :]
    points = 8.0 * direction(elevation, np.radians(azimuth))
    points[1, 7] = np.nan
    depth = organize_grid(points)
    assert depth.meta["flipped_rows"] and depth.meta["flipped_cols"] and depth.meta["wrap_cols"]
    np.testing.assert_array_equal(depth.points[0, 0], points[2, 71])
    np.testing.assert_array_equal(depth.meta["point_index"][0, 0], 2 * 72 + 71)
    assert not depth.valid[1, 71 - 7]
    # A camera-like 60-degree grid does not wrap.
    narrow = organize_grid(8.0 * direction(elevation[::-1], np.radians(np.linspace(30, -30, 20))[None, :]))
    assert not narrow.meta["flipped_rows"] and not narrow.meta["flipped_cols"] and not narrow.meta["wrap_cols"]


# --------------------------------------------------------------------------
# Real PJLab scans
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pjlab_auto():
    with np.load(AUTO_DECODED) as data:
        xyz = np.stack([data["x"], data["y"], data["z"]], axis=1).astype(np.float64)
        return xyz, data["ring"].copy()


def ring_median_elevation_deg(xyz, ring) -> np.ndarray:
    elevation = np.degrees(np.arcsin(xyz[:, 2] / np.linalg.norm(xyz, axis=1)))
    return np.array([np.median(elevation[ring == r]) for r in range(64)])


@needs_data
def test_pjlab_ring_organisation(pjlab_auto):
    xyz, ring = pjlab_auto
    depth = organize_by_ring(xyz, ring)
    assert depth.shape == (64, 1800)
    meta = depth.meta
    # Ring 63 is the highest beam (README), so it is row 0.
    np.testing.assert_array_equal(meta["beam_ids"], np.arange(63, -1, -1))
    assert np.degrees(meta["row_elevation_rad"][0]) == pytest.approx(14.9, abs=0.05)
    assert np.degrees(meta["row_elevation_rad"][-1]) == pytest.approx(-24.9, abs=0.05)
    # Every point is kept except where a ring holds two returns at one azimuth.
    assert meta["n_points_kept"] + meta["n_points_collided"] == len(xyz) == 85546
    points_per_ring = np.bincount(ring)
    assert meta["n_points_collided"] >= np.sum(np.maximum(points_per_ring - 1800, 0))
    assert meta["n_points_collided"] <= 0.001 * len(xyz)
    # Cells hold the measured points of their own ring.
    rows, cols = np.nonzero(depth.valid)
    index = meta["point_index"][rows, cols]
    np.testing.assert_array_equal(depth.points[rows, cols], xyz[index])
    np.testing.assert_array_equal(ring[index], 63 - rows)


@needs_data
def test_pjlab_elevation_clustering_reproduces_the_ring_field(pjlab_auto):
    xyz, ring = pjlab_auto
    elevation = np.arcsin(xyz[:, 2] / np.linalg.norm(xyz, axis=1))
    labels, _ = cluster_elevations(elevation, 64)
    np.testing.assert_array_equal(labels, ring)  # ring 0 = lowest beam, as clusters are numbered


@needs_data
def test_pjlab_manual_scene_beams_match_auto_calib_rings(pjlab_auto):
    from calib_core.io.scan_readers import read_point_cloud

    cloud = read_point_cloud(MANUAL_PCD)
    depth = organize_by_elevation(cloud.xyz, 64)
    assert depth.shape == (64, 1800)
    reference_deg = ring_median_elevation_deg(*pjlab_auto)[::-1]  # highest first, like the rows
    np.testing.assert_allclose(np.degrees(depth.meta["row_elevation_rad"]), reference_deg, atol=0.01)
    assert depth.meta["n_points_kept"] >= 0.999 * len(cloud)


@needs_data
def test_pjlab_firing_order_rebuilt_from_real_geometry(pjlab_auto):
    # The real cloud re-stored ring after ring, each ring a clockwise sweep from behind.
    xyz, ring = pjlab_auto
    azimuth = np.arctan2(xyz[:, 1], xyz[:, 0])
    swept = np.mod(np.pi - 1e-3 - azimuth, 2 * np.pi)
    order = np.lexsort((swept, ring))
    sweeps = firing_order_rings(xyz[order], 64)
    np.testing.assert_array_equal(sweeps, ring[order])
    # The file's own order (blocks of simultaneous firings) is not ring after ring.
    with pytest.raises(CalibError, match="firing order"):
        firing_order_rings(xyz, 64)


def test_native_file_keeps_the_measured_points(tmp_path):
    from calib_core.lidar.npz_format import load_depth_npz, save_depth_npz

    points, ring, rows, cols = grid_cloud(seed=7)
    depth = organize_by_ring(points, ring, n_cols=N_COLS)
    save_depth_npz(tmp_path / "scan.npz", depth)
    loaded = load_depth_npz(tmp_path / "scan.npz")
    np.testing.assert_array_equal(loaded.points[rows, cols], points)
    np.testing.assert_array_equal(loaded.valid, depth.valid)
    assert loaded.meta["wrap_cols"] is True


# --------------------------------------------------------------------------
# Scan-order columns, beam counting, the report
# --------------------------------------------------------------------------


def test_sequence_columns_give_each_firing_its_own_cell():
    from calib_core.lidar.firing_order import sequence_columns

    # Well separated firings keep their own (nearest) columns, in any row.
    coords = np.array([0.2, 1.1, 2.0, 3.4, 7.0, 0.0, 2.1, 3.9])
    rows = np.array([0, 0, 0, 0, 0, 1, 1, 1])
    cols, moved = sequence_columns(coords, rows, 100)
    np.testing.assert_array_equal(cols, [0, 1, 2, 3, 7, 0, 2, 4])
    np.testing.assert_allclose(moved, cols - coords, atol=1e-9)
    # A crowd of four firings within 1.2 columns spreads to both sides:
    # by hand, forward push 0 1 2 3, backward push -2 -1 0 1, mean -1 0 1 2.
    cols, _ = sequence_columns(np.array([0.0, 0.9, 1.1, 1.2, 5.0]), np.zeros(5, int), 100)
    np.testing.assert_array_equal(cols, [99, 0, 1, 2, 5])
    # Random sweeps, crowded in places: never two firings of a row in one
    # cell, and no firing moved further than the worst crowding forces
    # (the most firings in excess of the columns between any two of them).
    rng = np.random.default_rng(0)
    steps = rng.choice([0.5, 1.5], size=(3, 1000))
    steps[:, 0] = 0.0
    raw = np.cumsum(steps, axis=1)
    rows = np.repeat(np.arange(3), 1000)
    cols, moved = sequence_columns(raw.ravel() % 4000, rows, 4000)
    for r in range(3):
        assert len(np.unique(cols[rows == r])) == 1000
        excess = np.arange(1000) - raw[r]
        worst = float(np.max(excess - np.minimum.accumulate(excess)))
        assert np.abs(moved[rows == r]).max() <= worst + 1.0


def test_beams_counted_only_when_elevations_are_separate_lines():
    from calib_core.lidar.organize import count_beam_elevations

    points, _, _, _ = grid_cloud(seed=3)
    assert count_beam_elevations(points) == 6
    # Elevations that drift with range (beams off the origin) are no lines.
    rng = np.random.default_rng(1)
    r = rng.uniform(2, 40, 20000)
    beam = rng.integers(0, 16, 20000)
    az = rng.uniform(-np.pi, np.pi, 20000)
    z = r * np.tan(np.radians(-15 + 2 * beam)) + 0.2
    assert count_beam_elevations(np.c_[r * np.cos(az), r * np.sin(az), z]) is None


def test_organize_report_counts_and_line():
    from calib_core.lidar.organize_cloud import organize_cloud

    points, ring, rows, cols = grid_cloud(seed=8)
    points = np.vstack([points, [[np.nan, 0, 0], [0, 0, 0]]])  # two no-returns
    ring = np.r_[ring, 0, 0]
    depth = organize_cloud(points, ring=ring, n_cols=N_COLS)
    report = depth.organize_report
    assert (report.method, report.rows, report.cols) == ("ring", 6, N_COLS)
    assert report.points_in == len(points) and report.points_usable == len(points) - 2
    assert report.points_kept == len(rows) and report.valid_cells == len(rows)
    assert report.line().startswith(f"organised by ring: 6 x {N_COLS}, {100 * len(rows) / (6 * N_COLS):.1f} % of cells valid, 100.00 %")
    assert "ring field" in report.reason
