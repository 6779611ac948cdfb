"""The laser pick model (calib_core.solve.whiten.cell_pick_covariance) against the true pick errors of the sample."""

from __future__ import annotations


import numpy as np
import pytest

from calib_core.solve.whiten import cell_pick_covariance
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def picks():
    from calib_core.synthetic import load_sample
    from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks

    sc = load_sample(SAMPLE)
    corners = np.asarray(sc.corners_lidar, dtype=np.float64)
    rc, err = laser_picks(sc.depth, corners)  # the cells a careful user picks
    ok = err <= MAX_LASER_PICK_ERROR_M
    return sc, rc[ok], corners[ok]


def _camera_plane_d2(sc, corners, errors, cov):
    """Squared Mahalanobis distance of each error's part across the camera's line of sight (2 dof)."""
    R, t = sc.T_camera_lidar[:3, :3], sc.T_camera_lidar[:3, 3]
    pc = corners @ R.T + t
    u = pc / np.linalg.norm(pc, axis=1, keepdims=True)
    # Two unit vectors across the line of sight, rotated into the lidar frame.
    a = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    E = np.stack([e1, np.cross(u, e1)], axis=1) @ R  # (N, 2, 3)
    r = np.einsum("nij,nj->ni", E, errors)
    C = np.einsum("nij,njk,nlk->nil", E, cov, E)
    return np.einsum("ni,ni->n", r, np.linalg.solve(C, r[:, :, None])[:, :, 0])


def test_pick_model_matches_the_true_pick_errors(picks):
    sc, rc, corners = picks
    errors = sc.depth.points[rc[:, 0], rc[:, 1]] - corners  # against the ground-truth corners
    d2 = _camera_plane_d2(sc, corners, errors, cell_pick_covariance(sc.depth, rc))
    assert len(d2) > 100
    # Chi-square with 2 degrees of freedom: mean 2, 68.3 % below 2.30, 95.4 % below 6.18;
    # binomial standard error with ~125 corners: 4 points at 1 sigma, 2 at 2 sigma.
    assert 1.6 < d2.mean() < 2.4
    assert 0.60 < np.mean(d2 <= 2.296) < 0.77
    assert np.mean(d2 <= 6.18) > 0.91


def test_uniform_within_the_cell_understates_the_error(picks):
    """A pick is often not the cell containing the corner: uniform within one cell is too narrow."""
    sc, rc, corners = picks
    errors = sc.depth.points[rc[:, 0], rc[:, 1]] - corners
    d2 = _camera_plane_d2(sc, corners, errors, cell_pick_covariance(sc.depth, rc, cell_sigma=12**-0.5))
    assert d2.mean() > 3.0


def test_pick_error_per_axis_matches_the_model(picks):
    """The true errors, split along one row step, one column step and the beam, have the model's spreads."""
    from calib_core.solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M

    sc, rc, corners = picks
    errors = sc.depth.points[rc[:, 0], rc[:, 1]] - corners
    H, W = sc.depth.shape
    r, c = rc[:, 0], rc[:, 1]
    dirs = sc.depth.directions
    rho = sc.depth.range_m[r, c]
    g_row = (dirs[np.minimum(r + 1, H - 1), c] - dirs[np.maximum(r - 1, 0), c]) / 2
    g_col = (dirs[r, (c + 1) % W] - dirs[r, (c - 1) % W]) / 2
    basis = np.stack([rho[:, None] * g_row, rho[:, None] * g_col, dirs[r, c]], axis=2)
    parts = np.linalg.solve(basis, errors[:, :, None])[:, :, 0]  # (rows, columns, metres along the beam)
    rms = np.sqrt(np.mean(parts**2, axis=0))
    # ~125 corners: the RMS has a sampling error of about 6 %.
    np.testing.assert_allclose(rms, [*PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M], rtol=0.15)
    assert rms[1] > 1.2 * rms[0]  # the finer column axis errs by more cells


def test_calibrate_uses_the_pick_model_it_is_given(picks):
    """calibrate(cell_sigma=..., range_sigma_m=...) solves with that model: the same pose and sigma as
    solve_extrinsics given the model's covariance; the defaults are the package's model."""
    from calib_core.pairs import resolve_pairs
    from calib_core.solve import calibrate, solve_extrinsics
    from calib_core.synthetic import simulate_pairs

    sc = picks[0]
    pairs = simulate_pairs(sc, 10, np.random.default_rng(5), pixel_noise_px=1.0)
    rc = np.array([p.laser_rc for p in pairs])
    pts, b, px = resolve_pairs(pairs, sc.depth, sc.camera)
    results = {}
    for model in (((0.37, 0.52), 0.015), ((1.0, 1.5), 0.05)):
        got = calibrate(pairs, sc.depth, sc.camera, cell_sigma=model[0], range_sigma_m=model[1])
        ref = solve_extrinsics(pts, b, camera=sc.camera, pixels=px, pair_ids=list(range(10)),
                               laser_cov_m2=cell_pick_covariance(sc.depth, rc, *model))
        np.testing.assert_allclose(got.T_camera_lidar, ref.T_camera_lidar, atol=1e-12)
        np.testing.assert_allclose(got.sigma_translation_m, ref.sigma_translation_m, rtol=1e-12)
        results[model[0]] = got
    default = calibrate(pairs, sc.depth, sc.camera)
    np.testing.assert_allclose(default.T_camera_lidar, results[(0.37, 0.52)].T_camera_lidar, atol=1e-12)
    # The model weighs the pairs: another model, another pose (the argument is not ignored).
    assert np.abs(results[(1.0, 1.5)].T_camera_lidar - default.T_camera_lidar).max() > 1e-6
