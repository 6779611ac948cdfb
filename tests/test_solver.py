"""calib_core.solve against synthetic ground truth.

Every scene is built from a known pose: laser points all around the camera
(also behind it, as a catadioptric camera sees them) and their exact or
noise-perturbed bearings.  Truth is the generating pose, never the solver.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from calib_core import cameras
from calib_core.errors import CalibError
from calib_core.solve import pose_covariance, solve_extrinsics
from calib_core.solve import refine as refine_module
from calib_core.solve.bearing_pnp import p3p_grunert, quan_lan_pose, quan_lan_quartic
from calib_core.solve import kernels
from calib_core.solve.rigid import rigid_fit


# ---------------------------------------------------------------- helpers
def tangent_basis(bearings: np.ndarray) -> np.ndarray:
    """Rows ``e1, e2`` of each bearing's frame (``(e1, e2, b)`` right-handed orthonormal)."""
    return kernels.bearing_frames(np.ascontiguousarray(bearings, dtype=np.float64))[:, :2, :]


def random_scene(seed: int, n: int, near: float = 0.5, far: float = 20.0, max_t: float = 3.0):
    """Known pose, laser points and exact bearings, directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=rng).as_matrix()
    t = rng.uniform(-max_t, max_t, 3)
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points_camera = directions * rng.uniform(near, far, (n, 1))
    points_lidar = (points_camera - t) @ R  # R^T (X_c - t)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T, points_lidar, directions


def perturb(bearings: np.ndarray, sigma_rad: float, rng: np.random.Generator) -> np.ndarray:
    """Rotate each bearing by a 2-D Gaussian tangent vector of std sigma per axis."""
    E = tangent_basis(bearings)
    v = np.einsum("ni,nij->nj", sigma_rad * rng.normal(size=(len(bearings), 2)), E)
    angle = np.linalg.norm(v, axis=1, keepdims=True)
    return np.cos(angle) * bearings + np.sin(angle) * v / angle


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(rotation error in degrees, translation error in metres)."""
    # Rotation-vector norm: precise near zero, unlike arccos((tr - 1) / 2).
    angle = np.degrees(Rotation.from_matrix(T_est[:3, :3].T @ T_true[:3, :3]).magnitude())
    return float(angle), float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))


def rpy_deg(R: np.ndarray) -> np.ndarray:
    """Independent roll/pitch/yaw (R = Rz Ry Rx), away from gimbal lock."""
    return np.degrees([np.arctan2(R[2, 1], R[2, 2]), -np.arcsin(R[2, 0]), np.arctan2(R[1, 0], R[0, 0])])


class TinyPinhole:
    """Distortion-free pinhole, enough for the pixel cost (no dependency on calib_core.cameras)."""

    model = "tiny_pinhole"

    def __init__(self, f: float = 500.0, width: int = 1280, height: int = 960):
        self.f, self.width, self.height = f, width, height
        self.cx, self.cy = (width - 1) / 2, (height - 1) / 2

    def project(self, points):
        p = np.asarray(points, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([self.f * p[:, 0] / p[:, 2] + self.cx, self.f * p[:, 1] / p[:, 2] + self.cy], axis=1)
        front = p[:, 2] > 1e-9
        uv[~front] = np.nan
        inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= self.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= self.height - 0.5)
        return uv, front & inside

    def bearing(self, pixels):
        px = np.asarray(pixels, dtype=float)
        rays = np.column_stack([(px[:, 0] - self.cx) / self.f, (px[:, 1] - self.cy) / self.f, np.ones(len(px))])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def pinhole_scene(seed: int, n: int):
    """Pose plus points in front of a TinyPinhole, inside its image."""
    rng = np.random.default_rng(seed)
    cam = TinyPinhole()
    T, _, _ = random_scene(seed, 1)
    pixels = np.column_stack([rng.uniform(20, cam.width - 20, n), rng.uniform(20, cam.height - 20, n)])
    points_camera = cam.bearing(pixels) * rng.uniform(2, 15, (n, 1))
    points_lidar = (points_camera - T[:3, 3]) @ T[:3, :3]
    return cam, T, points_lidar, pixels


# ------------------------------------------------- noise-free recovery
@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 20))
def test_noise_free_pairs_recover_pose(seed, n):
    T_true, points, bearings = random_scene(seed, n)
    res = solve_extrinsics(points, bearings)
    rot_deg, trans_m = pose_error(res.T_camera_lidar, T_true)
    assert rot_deg < 1e-6 and trans_m < 1e-6
    # The closed-form initial pose alone is already at the truth.
    rot_deg, trans_m = pose_error(res.initial_T_camera_lidar, T_true)
    assert rot_deg < 1e-6 and trans_m < 1e-6
    assert res.residual_deg.shape == (n,) and np.all(res.residual_deg < 1e-6)
    assert res.n_pairs == n and res.cost_name == "angular" and res.outliers == []
    assert np.all(np.isnan(res.residual_px))  # no camera


@settings(max_examples=20, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 12))
def test_quan_lan_alone_noise_free(seed, n):
    T_true, points, bearings = random_scene(seed, n, near=1.0)
    T = quan_lan_pose(points, bearings)
    assert T is not None
    rot_deg, trans_m = pose_error(T, T_true)
    assert rot_deg < 1e-4 and trans_m < 1e-4


def test_quan_lan_many_points_uses_sampled_quartics():
    # n = 40 has 741 quartics per reference point; the solver samples 300.
    T_true, points, bearings = random_scene(40, 40, near=1.0)
    T = quan_lan_pose(points, bearings)
    assert T is not None and max(pose_error(T, T_true)) < 1e-6


def test_quan_lan_quartic_vanishes_at_true_depth():
    T, points, bearings = random_scene(7, 3)
    depth = np.linalg.norm(points @ T[:3, :3].T + T[:3, 3], axis=1)
    c = bearings @ bearings.T
    d = np.sum((points[:, None] - points[None]) ** 2, axis=-1)
    a = quan_lan_quartic(c[0, 1], c[0, 2], c[1, 2], d[0, 1], d[0, 2], d[1, 2])
    x = depth[0] ** 2
    g = sum(a[k] * x**k for k in range(5))
    assert abs(g) < 1e-10 * sum(abs(a[k]) * x**k for k in range(5))
    # A wrong depth is not a root.
    g_wrong = sum(a[k] * (1.3 * x) ** k for k in range(5))
    assert abs(g_wrong) > 1e-3 * sum(abs(a[k]) * (1.3 * x) ** k for k in range(5))


def test_p3p_contains_truth_and_only_points_in_front():
    T_true, points, bearings = random_scene(11, 3)
    Ts, tri = p3p_grunert(points[None], bearings[None])
    assert 1 <= len(Ts) <= 4 and np.all(tri == 0)
    errors = [max(pose_error(T, T_true)) for T in Ts]
    assert min(errors) < 1e-8
    for T in Ts:  # every solution puts the three points in front along their bearings
        pc = points @ T[:3, :3].T + T[:3, 3]
        cos = np.sum(pc * bearings, axis=1) / np.linalg.norm(pc, axis=1)
        np.testing.assert_allclose(cos, 1.0, atol=1e-8)


def test_rigid_fit_recovers_transform_and_never_reflects():
    T_true, points, _ = random_scene(3, 6)
    dst = points @ T_true[:3, :3].T + T_true[:3, 3]
    np.testing.assert_allclose(rigid_fit(points, dst), T_true, atol=1e-12)
    planar = points.copy()
    planar[:, 2] = 0.0  # a planar set lets a plain SVD return a reflection
    T = rigid_fit(planar, planar @ T_true[:3, :3].T + T_true[:3, 3])
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(T, T_true, atol=1e-12)


# ------------------------------------------------ residual and Jacobians
def _unit_whitening(n: int) -> np.ndarray:
    return np.broadcast_to(np.eye(2), (n, 2, 2)).copy()


def test_log_map_residual_norm_is_the_angle():
    bearings = np.array([[0.0, 0, 1], [0, 0, -1], [1, 0, 0]])
    points = np.array([[1.0, 0, 1], [0, 1, -1], [-1, 1e-9, 0]])  # 45, 45 and ~180 deg
    r, _ = kernels.whitened_residuals(np.eye(3), np.zeros(3), points, kernels.bearing_frames(bearings),
                                      _unit_whitening(3))
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), np.radians([45, 45, 180]), atol=1e-8)


def test_angular_jacobian_matches_finite_differences():
    rng = np.random.default_rng(5)
    T, points, bearings = random_scene(5, 8)
    F = kernels.bearing_frames(perturb(bearings, 0.2, rng))
    W = _unit_whitening(8)
    R = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix() @ T[:3, :3]
    t = T[:3, 3] + 0.1

    def f(d):  # the kernel's parameters: a left rotation perturbation exp([d_rot]) R, then t + d_t
        z, _ = kernels.whitened_residuals(Rotation.from_rotvec(d[:3]).as_matrix() @ R, t + d[3:], points, F, W)
        return z.ravel()

    h = 1e-6
    J_num = np.stack([(f(h * e) - f(-h * e)) / (2 * h) for e in np.eye(6)], axis=1)
    np.testing.assert_allclose(kernels.jacobian(R, t, points, F, W), J_num, atol=1e-7)


def test_rpy_sigmas_match_finite_difference_propagation():
    R = Rotation.from_euler("xyz", [20, -35, 140], degrees=True).as_matrix()
    h = 1e-6
    cols = []
    for e in np.eye(3):
        plus = rpy_deg(Rotation.from_rotvec(h * e).as_matrix() @ R)
        minus = rpy_deg(Rotation.from_rotvec(-h * e).as_matrix() @ R)
        cols.append(np.radians(plus - minus) / (2 * h))
    G = np.stack(cols, axis=1)  # d(roll, pitch, yaw) / d delta, rad/rad
    A = np.random.default_rng(3).normal(size=(6, 6)) * 1e-3
    cov = A @ A.T
    sigma_t, sigma_rpy = kernels.rpy_sigmas(R, cov)
    np.testing.assert_allclose(sigma_t, np.sqrt(np.diag(cov)[3:]), rtol=1e-12)
    np.testing.assert_allclose(sigma_rpy, np.degrees(np.sqrt(np.diag(G @ cov[:3, :3] @ G.T))), rtol=1e-6)


# ------------------------------------------------------------ pixel cost
def test_pixel_cost_noise_free_and_noisy():
    cam, T_true, points, pixels = pinhole_scene(21, 10)
    bearings = cam.bearing(pixels)
    res = solve_extrinsics(points, bearings, camera=cam, pixels=pixels, cost="pixel")
    assert res.cost_name == "pixel"
    assert max(pose_error(res.T_camera_lidar, T_true)) < 1e-6
    np.testing.assert_allclose(res.residual_px, 0.0, atol=1e-5)

    rng = np.random.default_rng(0)
    noisy_px = pixels + rng.normal(scale=1.0, size=pixels.shape)
    noisy_b = cam.bearing(noisy_px)
    ang = solve_extrinsics(points, noisy_b, camera=cam, pixels=noisy_px, cost="angular")
    pix = solve_extrinsics(points, noisy_b, camera=cam, pixels=noisy_px, cost="pixel")
    # Each cost is minimal at its own optimum.
    assert np.sum(pix.residual_px**2) <= np.sum(ang.residual_px**2) + 1e-9
    assert np.sum(ang.residual_deg**2) <= np.sum(pix.residual_deg**2) + 1e-12
    assert 0.3 < ang.mean_px < 3.0 and 0.3 < pix.mean_px < 3.0
    assert np.isfinite(pix.sigma_translation_m).all()


def test_pixels_default_to_projected_bearings_and_nan_where_unprojectable():
    cam, T_true, points, pixels = pinhole_scene(4, 8)
    res = solve_extrinsics(points, cam.bearing(pixels), camera=cam)
    np.testing.assert_allclose(res.residual_px, 0.0, atol=1e-5)
    assert res.mean_px < 1e-5

    # All-around scene: a pinhole cannot project the points behind it.
    T, pts, bearings = random_scene(8, 12)
    behind = (pts @ T[:3, :3].T + T[:3, 3])[:, 2] <= 0
    assert behind.any() and (~behind).any()
    fake_pixels = np.zeros((12, 2))
    res = solve_extrinsics(pts, bearings, camera=cam, pixels=fake_pixels)
    assert np.all(np.isnan(res.residual_px[behind]))
    assert any("do not reproject" in w for w in res.warnings)
    assert max(pose_error(res.T_camera_lidar, T)) < 1e-6  # the angular solve is unaffected


# ------------------------------------------------------ covariance (MC)
def test_monte_carlo_spread_matches_reported_covariance():
    rng = np.random.default_rng(1)
    T_true, points, bearings = random_scene(1, 10, near=2.0, far=10.0, max_t=1.0)
    sigma = np.radians(0.3)
    bound = pose_covariance(T_true, points, sigma)
    t_est, rpy_est, reported_t, residual_sigma_t = [], [], [], []
    for trial in range(120):
        noisy = perturb(bearings, sigma, rng)
        res = solve_extrinsics(points, noisy, noise_rad=sigma, initial_T_camera_lidar=T_true)
        t_est.append(res.T_camera_lidar[:3, 3])
        rpy_est.append(rpy_deg(res.T_camera_lidar[:3, :3]))
        reported_t.append(res.sigma_translation_m)
        if trial % 4 == 0:
            # Without noise_rad, sigma^2 is the residual variance: right on average.
            res_free = solve_extrinsics(points, noisy, initial_T_camera_lidar=T_true)
            residual_sigma_t.append(res_free.sigma_translation_m)
    empirical_t = np.std(t_est, axis=0)
    empirical_rpy = np.std(rpy_est, axis=0)
    np.testing.assert_allclose(empirical_t, bound.sigma_translation_m, rtol=0.3)
    np.testing.assert_allclose(empirical_rpy, bound.sigma_rpy_deg, rtol=0.3)
    np.testing.assert_allclose(np.mean(reported_t, axis=0), bound.sigma_translation_m, rtol=0.05)
    np.testing.assert_allclose(np.sqrt(np.mean(np.square(residual_sigma_t), axis=0)), bound.sigma_translation_m, rtol=0.3)
    assert res.covariance_6x6.shape == (6, 6)
    np.testing.assert_allclose(res.covariance_6x6, res.covariance_6x6.T, rtol=1e-10, atol=1e-18)


# ------------------------------------------------------------- outliers
def test_outlier_is_flagged():
    rng = np.random.default_rng(2)
    T, points, bearings = random_scene(2, 12, near=2.0)
    noisy = perturb(bearings, np.radians(0.05), rng)
    clean = solve_extrinsics(points, noisy)
    assert clean.outliers == [] and clean.mean_deg < 0.2
    bad = noisy.copy()
    bad[5] = Rotation.from_rotvec(np.radians(10) * tangent_basis(bad[5:6])[0, 0]).apply(bad[5])
    res = solve_extrinsics(points, bad, pair_ids=np.arange(100, 112))
    assert res.outliers == [5] and res.outlier_ids == [105]
    assert not res.inliers[5] and res.inliers.sum() == 11
    assert res.quality.status == "warning"
    assert any("pairs 105 left out as outliers" in w for w in res.quality.reasons)
    # Left out of the fit: the pose is as good as without the bad pair.
    rot_bad, trans_bad = pose_error(res.T_camera_lidar, T)
    rot_clean, trans_clean = pose_error(clean.T_camera_lidar, T)
    assert rot_bad < 2 * rot_clean + 1e-3 and trans_bad < 2 * trans_clean + 1e-4


# -------------------------------------------------------- degeneracies
def _base(n=6):
    _, points, bearings = random_scene(9, n, near=2.0)
    return points.copy(), bearings.copy()


def _nan_point():
    p, b = _base()
    p[2, 1] = np.nan
    return p, b


def _inf_bearing():
    p, b = _base()
    b[1] = [np.inf, 0, 0]
    return p, b


def _zero_bearing():
    p, b = _base()
    b[3] = 0.0
    return p, b


def _long_bearing():
    p, b = _base()
    b[4] *= 1.5
    return p, b


def _same_point():
    p, b = _base()
    p[3] = p[1]
    return p, b


def _same_bearing():
    p, b = _base()
    b[4] = b[0]
    return p, b


def _collinear():
    p, b = _base()
    p = np.outer(np.linspace(1, 6, 6), [1.0, 2.0, 0.5]) + [0, 0, 3]
    return p, b


def _tiny_cone():
    T, _, _ = random_scene(9, 1)
    rng = np.random.default_rng(0)
    d = np.array([0, 0, 1.0]) + rng.uniform(-0.005, 0.005, (6, 3))  # < 1 deg wide
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pc = d * rng.uniform(3, 9, (6, 1))
    return (pc - T[:3, 3]) @ T[:3, :3], d


@pytest.mark.parametrize(
    "make, fragments",
    [
        (lambda: (_base()[0][:3], _base()[1][:3]), ["at least 4", "got 3"]),
        (lambda: (_base()[0], _base()[1][:5]), ["6 laser points but 5 bearings"]),
        (_nan_point, ["pair 2", "laser point is not finite"]),
        (_inf_bearing, ["pair 1", "bearing is not finite"]),
        (_zero_bearing, ["pair 3", "zero length"]),
        (_long_bearing, ["pair 4", "not a unit vector"]),
        (_same_point, ["pairs 1 and 3", "same laser point"]),
        (_same_bearing, ["pairs 0 and 4", "same bearing"]),
        (_collinear, ["collinear"]),
        (_tiny_cone, ["within", "spread them"]),
    ],
)
def test_degenerate_input_raises(make, fragments):
    points, bearings = make()
    with pytest.raises(CalibError) as info:
        solve_extrinsics(points, bearings)
    for fragment in fragments:
        assert fragment in str(info.value)


def test_bad_options_raise():
    p, b = _base()
    with pytest.raises(CalibError, match="needs a camera"):
        solve_extrinsics(p, b, cost="pixel")
    with pytest.raises(CalibError, match="unknown cost"):
        solve_extrinsics(p, b, cost="chord")
    with pytest.raises(CalibError, match="noise_rad"):
        solve_extrinsics(p, b, noise_rad=-1.0)
    with pytest.raises(CalibError, match="rotation matrix"):
        solve_extrinsics(p, b, initial_T_camera_lidar=np.diag([2.0, 1, 1, 1]))
    with pytest.raises(CalibError, match="4x4"):
        solve_extrinsics(p, b, initial_T_camera_lidar=np.eye(3))


def test_small_view_cone_warns():
    T, _, _ = random_scene(9, 1)
    rng = np.random.default_rng(1)
    d = np.array([0, 0, 1.0]) + rng.uniform(-0.06, 0.06, (8, 3))  # ~8-10 deg wide
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pc = d * rng.uniform(3, 9, (8, 1))
    res = solve_extrinsics((pc - T[:3, 3]) @ T[:3, :3], d)
    assert any("all pairs lie in a small part of the view" in w and "spread them out" in w for w in res.warnings)
    assert max(pose_error(res.T_camera_lidar, T)) < 1e-6


def test_ill_conditioned_geometry_names_the_weak_parameters():
    # Laser points 0.5 % off a line parallel to the camera x axis: the rotation
    # about that line (rotation about x combined with a y/z shift) is weak.
    rng = np.random.default_rng(3)
    T, _, _ = random_scene(12, 1)
    s = np.linspace(-5, 5, 8)
    pc = np.column_stack([s, np.full(8, 1.0), np.full(8, 6.0)]) + 0.025 * rng.normal(size=(8, 3))
    bearings = pc / np.linalg.norm(pc, axis=1, keepdims=True)
    res = solve_extrinsics((pc - T[:3, 3]) @ T[:3, :3], bearings)
    weak = [w for w in res.warnings if "barely constrain" in w]
    assert len(weak) == 1 and "rotation about camera x" in weak[0]
    well = solve_extrinsics(*random_scene(12, 8)[1:])
    assert not any("barely constrain" in w for w in well.warnings)


def test_gimbal_lock_warns():
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [0, 90, 0], degrees=True).as_matrix()
    _, points, bearings = random_scene(5, 8)
    pc = points  # reuse as camera-frame points
    bearings = pc / np.linalg.norm(pc, axis=1, keepdims=True)
    res = solve_extrinsics((pc - T[:3, 3]) @ T[:3, :3], bearings)
    assert any("gimbal lock" in w for w in res.warnings)


def test_lm_failure_becomes_calib_error(monkeypatch):
    # The pixel cost runs scipy's MINPACK LM; its failures become one-line CalibErrors.
    cam, T_true, points, pixels = pinhole_scene(21, 8)
    bearings = cam.bearing(pixels)

    class Failed:
        status, message, x, cost, njev, nfev = 0, "The maximum number of function evaluations is exceeded.", np.zeros(6), 0.0, 1, 1

    monkeypatch.setattr(refine_module, "least_squares", lambda *a, **k: Failed())
    with pytest.raises(CalibError, match="Levenberg-Marquardt .*maximum number"):
        solve_extrinsics(points, bearings, camera=cam, pixels=pixels, cost="pixel")

    def boom(*a, **k):
        raise ValueError("Residuals are not finite in the initial point.")

    monkeypatch.setattr(refine_module, "least_squares", boom)
    with pytest.raises(CalibError, match="not finite in the initial point"):
        solve_extrinsics(points, bearings, camera=cam, pixels=pixels, cost="pixel")


def test_angular_lm_failure_becomes_calib_error():
    # Non-finite bearing frames make the cost non-finite: the compiled LM reports it, the wrapper raises.
    p, b = _base()
    T = np.eye(4)
    T[:3, 3] = -p[0]
    with pytest.raises(CalibError, match="Levenberg-Marquardt"):
        refine_module.refine_angular(T, p, kernels.bearing_frames(b) * np.nan)


def test_pixel_cost_with_the_package_pinhole_model():
    cam = cameras.PinholeCamera(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.array([-0.2, 0.05, 0, 0, 0]), 640, 480)
    rng = np.random.default_rng(6)
    T_true, _, _ = random_scene(6, 1)
    pixels = np.column_stack([rng.uniform(30, 610, 9), rng.uniform(30, 450, 9)])
    points_camera = cam.bearing(pixels) * rng.uniform(2, 12, (9, 1))
    points_lidar = (points_camera - T_true[:3, 3]) @ T_true[:3, :3]
    res = solve_extrinsics(points_lidar, cam.bearing(pixels), camera=cam, pixels=pixels, cost="pixel")
    assert max(pose_error(res.T_camera_lidar, T_true)) < 1e-6
    assert res.mean_px < 1e-4


# ------------------------------------- compiled common case vs the general path
class ProtocolOnlyCamera:
    """A camera with only the protocol's members, as a user might write one: the solve cannot use a
    compiled projection for it and takes its step-by-step path, the reference for the compiled one."""

    def __init__(self, camera):
        self._camera = camera
        self.model, self.width, self.height = camera.model, camera.width, camera.height

    def project(self, points):
        return self._camera.project(points)

    def bearing(self, pixels):
        return self._camera.bearing(pixels)


def _package_camera(kind: str):
    if kind == "pinhole":
        K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
        return cameras.PinholeCamera(K, np.array([-0.2, 0.05, 0.001, -0.001, 0]), 640, 480)
    if kind == "fisheye":
        K = np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]])
        return cameras.FisheyeCamera(K, np.array([0.05, -0.01, 0.002, 0.0]), 640, 480)
    # OCamCalib's model, the sample's calib_results.txt: rho -> z polynomial, inverse polynomial, centre
    # (row, column), affine part.
    invpol = [172.5167522396248, 108.1876196890501, -1.695535567957569, 8.844187868415595, 11.472821400448383,
              -0.9956662444193077, 0.8557068249478024, 7.722745755817153, -2.685037333633238, -7.700400472500214,
              3.414250193240605, 6.670703905124788, -0.8659304877271558, -3.070421516611275, -0.263886958108428,
              0.66039717892231, 0.18539331056797265]
    return cameras.OCamCamera([-111.29, 0.0, 0.0041857, -1.54014e-05, 7.42759e-08], invpol, 242.3, 318.6,
                              1.0008, 0.0011, -0.0009, 640, 480)


@pytest.mark.parametrize("kind", ["pinhole", "fisheye", "ocam"])
@pytest.mark.parametrize("n, options", [(6, {}), (12, {"pixel_sigma": 0.7}), (150, {}), (12, {"cost": "geodesic"}),
                                         (12, {"noise_rad": 2e-3}), (12, {"robust": False})])
def test_compiled_path_matches_the_step_by_step_path(kind, n, options):
    # The package's cameras take the compiled common case; the same camera without its compiled projection
    # takes the general path.  Both must give the same pose, sigmas, residuals and verdict.
    cam = _package_camera(kind)
    rng = np.random.default_rng(n)
    T_true, _, _ = random_scene(n, 1, max_t=0.3)
    margin = 40
    pixels = np.column_stack([rng.uniform(margin, cam.width - margin, 3 * n),
                              rng.uniform(margin, cam.height - margin, 3 * n)])
    rays = cam.bearing(pixels)
    keep = np.flatnonzero(np.isfinite(rays).all(axis=1))[:n]
    assert keep.size == n
    pixels, rays = pixels[keep], rays[keep]
    points_lidar = (rays * rng.uniform(2, 12, (n, 1)) - T_true[:3, 3]) @ T_true[:3, :3]
    clicked = pixels + rng.normal(0, 1.0, pixels.shape)
    bearings = cam.bearing(clicked)
    fast = solve_extrinsics(points_lidar, bearings, camera=cam, pixels=clicked, **options)
    general = solve_extrinsics(points_lidar, bearings, camera=ProtocolOnlyCamera(cam), pixels=clicked, **options)
    assert max(pose_error(fast.T_camera_lidar, general.T_camera_lidar)) < 1e-9
    np.testing.assert_allclose(fast.covariance_6x6, general.covariance_6x6, rtol=1e-6, atol=1e-16)
    np.testing.assert_allclose(fast.sigma_rpy_deg, general.sigma_rpy_deg, rtol=1e-6)
    np.testing.assert_allclose(fast.residual_px, general.residual_px, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fast.residual_deg, general.residual_deg, rtol=1e-6, atol=1e-12)
    assert fast.quality == general.quality and fast.warnings == general.warnings
    assert fast.outliers == general.outliers == [] and fast.initial_method == general.initial_method
    assert fast.residual_unit == general.residual_unit and fast.cost_name == general.cost_name
    if "noise_rad" not in options:  # (a stated noise_rad is taken as true, here it is not)
        # And the figures are right, not just alike: the truth lies within a few reported sigmas.
        err_t = np.abs(fast.T_camera_lidar[:3, 3] - T_true[:3, 3])
        assert np.all(err_t <= 5 * fast.sigma_translation_m + 1e-9)


def test_compiled_path_hands_outliers_to_the_robust_search():
    # One stray click: the compiled common case must not hide it (it hands over to the robust search).
    cam = _package_camera("pinhole")
    rng = np.random.default_rng(3)
    T_true, _, _ = random_scene(3, 1, max_t=0.3)
    pixels = np.column_stack([rng.uniform(40, 600, 15), rng.uniform(40, 440, 15)])
    points_lidar = (cam.bearing(pixels) * rng.uniform(2, 12, (15, 1)) - T_true[:3, 3]) @ T_true[:3, :3]
    clicked = pixels + rng.normal(0, 0.5, pixels.shape)
    clicked[4] += [40.0, -30.0]
    res = solve_extrinsics(points_lidar, cam.bearing(clicked), camera=cam, pixels=clicked)
    assert res.outliers == [4] and res.quality.status == "warning" and res.hypotheses > 0
    assert max(pose_error(res.T_camera_lidar, T_true)) < 0.5
