"""Compiled solve kernels, the whitening and the honesty of sigma, against independent truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import norm

from bench.common import sigma_coverage
from calib_core.lidar.depth_matrix import DepthMatrix
from calib_core.solve import kernels, solve_extrinsics, warm_up
from calib_core.solve.whiten import cell_pick_covariance, whitening

from test_solver import TinyPinhole, perturb, pinhole_scene, pose_error, random_scene


def test_dlt_recovers_a_noise_free_pose_and_refuses_coplanar_points():
    T, points, bearings = random_scene(31, 9)
    R, t, ok = kernels.dlt_pose(points, bearings)
    assert ok
    np.testing.assert_allclose(R, T[:3, :3], atol=1e-9)
    np.testing.assert_allclose(t, T[:3, 3], atol=1e-9)
    flat = points.copy()
    flat[:, 2] = 1.5  # coplanar laser points: the 12-unknown DLT has a second null vector
    pc = flat @ T[:3, :3].T + T[:3, 3]
    _, _, ok = kernels.dlt_pose(flat, pc / np.linalg.norm(pc, axis=1, keepdims=True))
    assert not ok
    _, _, ok = kernels.dlt_pose(points[:5], bearings[:5])
    assert not ok


def _geodesic_residuals(R, t, points, frames):
    """Independent of the kernels: ``theta * y_12 / |y_12|`` with ``y = F_i (R p_i + t)`` (paper eq. 7)."""
    y = np.einsum("nij,nj->ni", frames, points @ R.T + t)
    rho = np.linalg.norm(y[:, :2], axis=1)
    theta = np.arctan2(rho, y[:, 2])
    return (theta / rho)[:, None] * y[:, :2]


def test_lm_reaches_the_true_pose_and_returns_the_normal_matrix_there():
    T, points, bearings = random_scene(4, 30, near=2.0)
    noisy = perturb(bearings, 1e-3, np.random.default_rng(4))
    F = kernels.bearing_frames(noisy)
    W = np.broadcast_to(np.eye(2), (30, 2, 2)).copy()
    # Start 3 deg and 10 cm off the truth.
    R0 = Rotation.from_rotvec([0.03, -0.02, 0.04]).as_matrix() @ T[:3, :3]
    t0 = T[:3, 3] + [0.1, -0.05, 0.05]
    R, t, it, status, H = kernels.lm_refine(R0, t0, points, F, W, 200)
    assert status == 1 and 1 <= it < 50
    # The optimum: the gradient of the independent cost vanishes (central differences, left perturbation).
    h = 1e-6
    J = np.empty((60, 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        Rp, Rm = Rotation.from_rotvec(d[:3]).as_matrix() @ R, Rotation.from_rotvec(-d[:3]).as_matrix() @ R
        J[:, k] = (_geodesic_residuals(Rp, t + d[3:], points, F) - _geodesic_residuals(Rm, t - d[3:], points, F)
                   ).ravel() / (2 * h)
    r = _geodesic_residuals(R, t, points, F).ravel()
    assert np.linalg.norm(J.T @ r) < 1e-9 * np.linalg.norm(J.T @ J) ** 0.5
    # H is J^T J at the returned pose.
    np.testing.assert_allclose(H, J.T @ J, rtol=1e-5, atol=1e-6 * np.abs(H).max())
    # Near the truth: 1 mrad noise on 30 pairs 2-10 m away.
    assert np.degrees(Rotation.from_matrix(R @ T[:3, :3].T).magnitude()) < 0.5
    assert np.linalg.norm(t - T[:3, 3]) < 0.05


def test_whitened_residual_is_the_pixel_error_to_first_order():
    cam, T, points, pixels = pinhole_scene(8, 12)
    rng = np.random.default_rng(1)
    clicked = pixels + rng.normal(0.0, 0.7, pixels.shape)
    bearings = cam.bearing(clicked)
    F = kernels.bearing_frames(bearings)
    W, unit = whitening(12, camera=cam, frames=F)
    assert unit == "px"
    z, _ = kernels.whitened_residuals(T[:3, :3].copy(), T[:3, 3].copy(), points, F, W)
    # Independent truth: the pixel distance between the click and the true projection.
    np.testing.assert_allclose(np.linalg.norm(z, axis=1), np.linalg.norm(clicked - pixels, axis=1), rtol=0.02,
                               atol=1e-3)
    sig = np.full(12, 2.0)
    W2, unit2 = whitening(12, camera=cam, frames=F, pixel_sigma=sig)
    assert unit2 == "sigma"
    np.testing.assert_allclose(W2, W / 2.0)


def test_cell_pick_covariance_of_a_regular_grid():
    # A spherical grid with 1 deg rows and 0.5 deg columns, every range 4 m.
    el = np.radians(np.arange(10, -10, -1.0))
    az = np.radians(np.arange(0, 20, 0.5))
    E, A = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1)
    rng_m = np.full(E.shape, 4.0)
    depth = DepthMatrix(rng_m, d, d * 4.0, np.ones(E.shape, bool), {})
    cov = cell_pick_covariance(depth, np.array([[10, 20]]), cell_sigma=12**-0.5, range_sigma_m=0.02)[0]
    w = np.sort(np.linalg.eigvalsh(cov))
    # Hand-computed: uniform over one cell, variance (rho * step)^2 / 12 per axis; range noise along the beam.
    e10 = E[10, 20]
    expected = np.sort([(4 * np.radians(1.0)) ** 2 / 12, (4 * np.radians(0.5) * np.cos(e10)) ** 2 / 12, 0.02**2])
    np.testing.assert_allclose(w, expected, rtol=2e-3)
    # One sigma per axis: rows (elevation, vertical here) and columns (azimuth, horizontal).
    cov2 = cell_pick_covariance(depth, np.array([[10, 20]]), cell_sigma=(0.3, 0.7), range_sigma_m=0.02)[0]
    up = np.array([-np.sin(e10) * np.cos(A[10, 20]), -np.sin(e10) * np.sin(A[10, 20]), np.cos(e10)])
    side = np.array([-np.sin(A[10, 20]), np.cos(A[10, 20]), 0.0])
    np.testing.assert_allclose(up @ cov2 @ up, (0.3 * 4 * np.radians(1.0)) ** 2, rtol=2e-3)
    np.testing.assert_allclose(side @ cov2 @ side, (0.7 * 4 * np.radians(0.5) * np.cos(e10)) ** 2, rtol=2e-3)
    np.testing.assert_allclose(d[10, 20] @ cov2 @ d[10, 20], 0.02**2, rtol=2e-3)
    np.testing.assert_allclose(up @ cov2 @ side, 0.0, atol=1e-9)


def test_student_t_sigma_covers_68_and_95_percent():
    """With the noise estimated from few residuals, +-1 and +-2 reported sigma cover 68.3 % and 94.3 %."""
    # 10 pairs: 14 degrees of freedom.  The factor makes 1 sigma cover 68.27 % exactly; 2 such sigmas
    # cover the t distribution's share, P(|t| < 2 t_68) = 94.3 % at 14 (92.8 % at 6), not the normal 95.45 %.
    T, points, bearings = random_scene(12, 10, near=2.0, far=8.0, max_t=1.0)
    rng = np.random.default_rng(0)
    trials = 600
    inside = np.zeros((2, 3))
    for _ in range(trials):
        noisy = perturb(bearings, np.radians(0.2), rng)
        res = solve_extrinsics(points, noisy, initial_T_camera_lidar=T, robust=False)
        err = res.T_camera_lidar[:3, 3] - T[:3, 3]
        inside[0] += np.abs(err) <= res.sigma_translation_m
        inside[1] += np.abs(err) <= 2 * res.sigma_translation_m
    cover = inside / trials
    # Binomial standard error at 600 trials: 1.9 points at 68 %, 0.9 at 95 %.
    assert np.all(np.abs(cover[0] - (2 * norm.cdf(1) - 1)) < 0.06), cover
    one, two = sigma_coverage(10)
    # scipy.stats.t(14).cdf(2 * 1.0370) = 0.97150: 2 * 0.97150 - 1; and 68.27 % by the factor's construction.
    assert abs(two - 0.943) < 5e-4 and abs(one - (2 * norm.cdf(1) - 1)) < 1e-9
    assert np.all(np.abs(cover[1] - two) < 0.03), cover


def test_warm_up_compiles_once():
    first = warm_up()
    second = warm_up()
    assert first > 0 and second < 1.0


def test_geodesic_cost_is_eq7_unweighted():
    """cost='geodesic' ignores the camera: the same pose as the solve without a camera."""
    cam, T, points, pixels = pinhole_scene(5, 10)
    rng = np.random.default_rng(2)
    clicked = pixels + rng.normal(0.0, 1.0, pixels.shape)
    b = cam.bearing(clicked)
    geo = solve_extrinsics(points, b, camera=cam, pixels=clicked, cost="geodesic")
    plain = solve_extrinsics(points, b)
    np.testing.assert_allclose(geo.T_camera_lidar, plain.T_camera_lidar, atol=1e-9)
    assert geo.residual_unit == "rad"
    wh = solve_extrinsics(points, b, camera=cam, pixels=clicked)
    pix = solve_extrinsics(points, b, camera=cam, pixels=clicked, cost="pixel")
    # The whitened angular cost is the pixel cost to first order: the two optima nearly coincide.
    assert max(pose_error(wh.T_camera_lidar, pix.T_camera_lidar)) < 0.1 * max(pose_error(geo.T_camera_lidar, pix.T_camera_lidar)) + 1e-6


def test_laser_term_of_the_whitening_against_a_sampled_bearing_error():
    """The laser term and the whitening with it, against independent truth: bearings of laser points drawn
    from their covariance (the tangent-plane spread of the moved point's direction), and W^T W = C^-1."""
    from calib_core.solve.whiten import laser_tangent_covariance

    cam, T, points, pixels = pinhole_scene(5, 6)
    bearings = cam.bearing(pixels)
    F = kernels.bearing_frames(bearings)
    rng = np.random.default_rng(3)
    G = rng.normal(size=(6, 3, 3)) * 0.02
    S = G @ np.swapaxes(G, 1, 2)  # laser covariances, m^2
    L = laser_tangent_covariance(T, points, F, S)
    R, t = T[:3, :3], T[:3, 3]
    for i in range(6):
        X = rng.multivariate_normal(points[i], S[i], size=20000) @ R.T + t
        u = X / np.linalg.norm(X, axis=1, keepdims=True)
        tangent = u @ F[i, :2].T  # the moved bearing in the pair's tangent plane, rad to first order
        np.testing.assert_allclose(L[i], np.cov(tangent.T), rtol=0.05, atol=0.05 * np.abs(L[i]).max())
    sig = np.linspace(0.5, 2.0, 6)
    W, unit = whitening(6, camera=cam, frames=F, pixel_sigma=sig, laser_tangent_cov=L)
    assert unit == "sigma"
    A, _ = whitening(6, camera=cam, frames=F)  # px/rad, the camera's own Jacobian
    for i in range(6):
        Ainv = np.linalg.inv(A[i])
        C = sig[i] ** 2 * Ainv @ Ainv.T + L[i]
        np.testing.assert_allclose(W[i].T @ W[i], np.linalg.inv(C), rtol=1e-9)
        assert W[i, 0, 1] == 0.0  # lower triangular: the inverse of C's Cholesky factor


def _whitened_optimum(T0, points, F, W):
    """Independent of the kernels: scipy's LM on ``W_i`` times :func:`_geodesic_residuals`, from ``T0``."""
    from scipy.optimize import least_squares

    R0 = T0[:3, :3]

    def fun(x):
        r = _geodesic_residuals(Rotation.from_rotvec(x[:3]).as_matrix() @ R0, x[3:], points, F)
        return np.einsum("nij,nj->ni", W, r).ravel()

    sol = least_squares(fun, np.concatenate([np.zeros(3), T0[:3, 3]]), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rotation.from_rotvec(sol.x[:3]).as_matrix() @ R0, sol.x[3:]
    return T


def test_laser_term_whitening_is_that_of_the_estimate_itself():
    """With ``laser_cov_m2`` the solve re-whitens inside its one compiled LM (fit_pose_laser): its estimate
    is optimal for the whitening with the laser term at itself.  Checked with scipy and numpy alone: the
    whitening rebuilt at the returned pose, scipy's LM from there stays put; and the estimate is near
    the two-solve one (click whitening, laser term added at that optimum, solved again), far nearer than
    the laser term moves the pose."""
    from calib_core.solve.whiten import laser_tangent_covariance

    for seed, n in ((11, 8), (12, 40)):
        cam, T, points, pixels = pinhole_scene(seed, n)
        rng = np.random.default_rng(seed)
        clicked = pixels + rng.normal(0.0, 1.0, pixels.shape)
        bearings = cam.bearing(clicked)
        G = rng.normal(size=(n, 3, 3)) * 0.03
        S = G @ np.swapaxes(G, 1, 2)  # laser covariances, m^2 (a few cm, anisotropic)
        sig = rng.uniform(0.5, 2.0, n)
        F = kernels.bearing_frames(bearings)
        A, _ = whitening(n, camera=cam, frames=F)
        Ainv = np.linalg.inv(A)
        click = sig[:, None, None] ** 2 * Ainv @ np.swapaxes(Ainv, 1, 2)

        def laser_whitening_at(T_at):
            return np.linalg.inv(np.linalg.cholesky(click + laser_tangent_covariance(T_at, points, F, S)))

        res = solve_extrinsics(points, bearings, camera=cam, pixels=clicked, pixel_sigma=sig, laser_cov_m2=S)
        assert res.quality.status != "unreliable"
        T_hat = res.T_camera_lidar
        rot, trans = pose_error(_whitened_optimum(T_hat, points, F, laser_whitening_at(T_hat)), T_hat)
        assert rot < 1e-6 and trans < 1e-7
        T1 = _whitened_optimum(T, points, F, A / sig[:, None, None])
        T2 = _whitened_optimum(T1, points, F, laser_whitening_at(T1))
        moved_rot, moved_trans = pose_error(T1, T2)  # what the laser term changes
        rot, trans = pose_error(T_hat, T2)
        assert moved_rot > 1e-3 and moved_trans > 1e-4
        assert rot < 0.05 * moved_rot and trans < 0.05 * moved_trans


def test_symmetric_eigen_solver_against_lapack():
    """sym_eigh (Jacobi rotations, used for the covariance and the geometry figures) against numpy's LAPACK
    eigh: random, ill-conditioned, rank-deficient and diagonal matrices of the sizes the solve uses."""
    rng = np.random.default_rng(5)
    cases = []
    for n in (3, 6):
        G = rng.normal(size=(n, n))
        cases.append(G @ G.T)
        Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        cases.append(Q @ np.diag(np.logspace(-12, 3, n)) @ Q.T)  # condition 1e15
        cases.append(Q @ np.diag([0.0] * (n - 2) + [1.0, 2.0]) @ Q.T)  # two or more zero eigenvalues
        cases.append(np.diag(rng.uniform(-1, 1, n)))
    pts = rng.normal(size=(40, 3)) * [5.0, 1e-4, 1e-4]  # nearly collinear points' scatter
    cases.append(np.cov(pts.T))
    for S in cases:
        w, V = kernels.sym_eigh(S)
        w_ref = np.linalg.eigvalsh(S)
        scale = np.abs(w_ref).max()
        np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=1e-14 * scale)
        np.testing.assert_allclose(V.T @ V, np.eye(len(S)), atol=1e-13)
        np.testing.assert_allclose(S @ V, V * w, atol=1e-12 * scale)


def test_reported_angles_are_the_geodesic_errors_at_the_estimate():
    """``residual_deg`` (taken from the LM's whitened residuals when they are at the final pose) against the
    angle between each bearing and its laser point's direction at the returned pose, computed here."""
    cam, T, points, pixels = pinhole_scene(21, 30)
    rng = np.random.default_rng(21)
    clicked = pixels + rng.normal(0.0, 1.0, pixels.shape)
    bearings = cam.bearing(clicked)
    G = rng.normal(size=(30, 3, 3)) * 0.02
    for laser in (None, G @ np.swapaxes(G, 1, 2)):
        res = solve_extrinsics(points, bearings, camera=cam, pixels=clicked, laser_cov_m2=laser)
        Th = res.T_camera_lidar
        q = points @ Th[:3, :3].T + Th[:3, 3]
        angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(bearings, q), axis=1), np.sum(bearings * q, axis=1)))
        assert angle.max() > 0.01  # noisy clicks: the test can fail
        np.testing.assert_allclose(res.residual_deg, angle, rtol=1e-9, atol=1e-12)


def _any_close_brute(X, radius, angular):
    """Every pair's distance in numpy (the angle between unit rows, or the Euclidean distance)."""
    if angular:
        d = np.arccos(np.clip(X @ X.T, -1.0, 1.0))
    else:
        d = np.linalg.norm(X[:, None, :] - X[None, :, :], axis=2)
    iu = np.triu_indices(len(X), 1)
    return bool((d[iu] <= radius).any())


def test_bucketed_duplicate_check_finds_exactly_the_pairs_within_the_radius():
    """``_any_close`` (buckets along x, no sort) says what every pair's distance says, also where the
    buckets are crowded (all rows at one x) and for pairs just inside and just outside the radius."""
    rng = np.random.default_rng(5)
    r = 1e-6
    for n in (4, 10, 300):
        P = rng.uniform(-10, 10, (n, 3))
        U = rng.normal(size=(n, 3))
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        cases = [(P, False), (U, True)]
        for X, angular in list(cases):
            i, j = rng.choice(n, 2, replace=False)
            for offset in (0.5 * r, 0.99 * r, 1.5 * r, 3 * r):  # just inside / outside the radius
                Y = X.copy()
                step = np.array([0.0, 0.6, 0.8]) if not angular else np.cross(Y[i], [0.0, 0.0, 1.0])
                step = step / np.linalg.norm(step) * offset
                Y[j] = Y[i] + step
                if angular:
                    Y[j] /= np.linalg.norm(Y[j])
                cases.append((Y, angular))
            same_x = X.copy()
            same_x[:, 0] = 0.25 if not angular else 0.0  # one bucket for all: the quadratic fallback
            if angular:
                same_x /= np.linalg.norm(same_x, axis=1, keepdims=True)
            cases.append((same_x, angular))
        # Buckets about one radius wide (all x within n r / 2) and pairs 0.9 r apart in x: most such pairs
        # straddle two buckets, which the adjacent-bucket comparison must see.
        for trial in range(10):
            Q = np.column_stack([rng.uniform(0, n * r / 2, n), rng.uniform(-10, 10, (n, 2))])
            i, j = rng.choice(n, 2, replace=False)
            Q[j] = Q[i] + [0.9 * r, 0.0, 0.0]
            cases.append((Q, False))
        for X, angular in cases:
            X = np.ascontiguousarray(X)
            assert kernels._any_close(X, r, angular) == _any_close_brute(X, r, angular)
            # The sorted sweep, which names the pair in the messages, agrees on whether there is one.
            assert (kernels._first_close(X, r, angular)[0] >= 0) == _any_close_brute(X, r, angular)


def test_pair_checks_frames_gives_the_frames_and_probes_of_the_separate_kernels():
    _, points, bearings = random_scene(7, 12)
    out = kernels.pair_checks_frames(points, bearings * 1.0000001, 1e-6, 1e-6, 1e-3, 1e-4)
    U, F, probes = out[5], out[13], out[14]
    np.testing.assert_allclose(U, bearings, atol=1e-12)
    np.testing.assert_array_equal(F, kernels.bearing_frames(U))
    h = 1e-4
    expected = np.concatenate([F[:, 2] + h * F[:, 0], F[:, 2] - h * F[:, 0], F[:, 2] + h * F[:, 1],
                               F[:, 2] - h * F[:, 1]])
    np.testing.assert_allclose(probes, expected, atol=1e-15)
