"""The camera's viewing direction and roll about it (issue 20): readable where roll/pitch/yaw are in gimbal lock.

Truth: hand-computed cases (a camera looking along lidar +x), rotations built independently with SciPy's
Euler compositions, finite differences for the propagated sigmas, and a solve against a known pose.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from app_driver.fakes import FakeGui
from calib_core.errors import CalibError
from calib_core.solve.quality import NEAR_SINGULAR_DEG, orientation_notes
from calib_core.transforms import R_from_viewing_deg, rpy_deg_from_R, viewing_direction

#: Camera axes (OpenCV: x right, y down, z forward) in lidar coordinates for a level camera looking along lidar +x.
FORWARD = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # rows = camera axes: R_camera_lidar


def built(az_deg: float, el_deg: float, roll_deg: float) -> np.ndarray:
    """``R_camera_lidar`` composed with SciPy: the level forward camera turned about its own axis by roll,
    tilted up by el about lidar y, then turned by az about lidar z (camera axes C = Rz Ry C0 Rz_cam)."""
    C0 = FORWARD.T
    C = (Rotation.from_euler("z", az_deg, degrees=True).as_matrix()
         @ Rotation.from_euler("y", -el_deg, degrees=True).as_matrix()
         @ C0 @ Rotation.from_euler("z", roll_deg, degrees=True).as_matrix())
    return C.T


def angles(R) -> np.ndarray:
    v = viewing_direction(R)
    return np.array([v.azimuth_deg, v.elevation_deg, v.roll_deg])


def wrap(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def test_forward_camera_by_hand():
    """Looking along lidar +x, image up = lidar +z: az 0, el 0, roll 0 -- where roll/pitch/yaw are in gimbal lock."""
    v = viewing_direction(FORWARD)
    np.testing.assert_allclose(v.direction_lidar, [1.0, 0.0, 0.0])
    assert (v.azimuth_deg, v.elevation_deg, v.roll_deg) == (0.0, 0.0, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # SciPy says "Gimbal lock detected": that is the point
        assert abs(rpy_deg_from_R(FORWARD)[1] + 90.0) < 1e-9  # pitch -90
    # Looking along lidar +y (to the left): az 90; camera x (right) = lidar +x, y (down) = lidar -z.
    left = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(angles(left), [90.0, 0.0, 0.0], atol=1e-12)
    # Turned 90 deg clockwise (seen from behind) about the axis: camera x points down (-z), y to the left (+y).
    rolled = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(angles(rolled), [0.0, 0.0, 90.0], atol=1e-12)
    np.testing.assert_allclose(built(0.0, 0.0, 90.0), rolled, atol=1e-12)


def test_pitched_down_86_deg():
    """A camera looking 86 deg down: el -86, and the roll it was built with (defined, finite sigma)."""
    R = built(30.0, -86.0, 5.0)
    v = viewing_direction(R, np.diag([1e-6, 1e-6, 1e-6]))
    np.testing.assert_allclose([v.azimuth_deg, v.elevation_deg, v.roll_deg], [30.0, -86.0, 5.0], atol=1e-9)
    assert np.all(np.isfinite(v.sigma_deg))
    # Near its pole, azimuth and roll are uncertain by about sigma / cos(el); elevation by sigma.
    s = np.degrees(1e-3)
    assert abs(v.sigma_deg[1] - s) < 1e-6 * s
    assert 0.5 / np.cos(np.radians(86)) < v.sigma_deg[0] / s < 2 / np.cos(np.radians(86))


def test_inverse_and_independent_construction_agree():
    rng = np.random.default_rng(20)
    for _ in range(200):
        a = np.array([rng.uniform(-180, 180), rng.uniform(-89.5, 89.5), rng.uniform(-180, 180)])
        R = built(*a)
        np.testing.assert_allclose(wrap(angles(R) - a), 0.0, atol=1e-8)
        np.testing.assert_allclose(R_from_viewing_deg(*a), R, atol=1e-12)
        np.testing.assert_allclose(viewing_direction(R).direction_lidar, R.T @ [0, 0, 1], atol=1e-15)


@pytest.mark.parametrize("az, el, roll", [(0.0, 0.0, 0.0), (12.0, -3.4, 0.6), (-150.0, 40.0, 100.0),
                                          (30.0, -86.0, 5.0)])
def test_sigma_matches_finite_differences(az, el, roll):
    """sqrt(diag(J cov J^T)) with J from central differences of the angles under exp([delta]) R."""
    R = built(az, el, roll)
    rng = np.random.default_rng(7)
    A = rng.normal(size=(3, 3)) * 1e-3
    cov = A @ A.T
    h = 1e-6
    J = np.empty((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        plus = angles(Rotation.from_rotvec(e).as_matrix() @ R)
        minus = angles(Rotation.from_rotvec(-e).as_matrix() @ R)
        J[:, k] = wrap(plus - minus) / (2 * h)  # deg per rad
    expected = np.sqrt(np.diag(J @ cov @ J.T))
    got = viewing_direction(R, cov).sigma_deg
    np.testing.assert_allclose(got, expected, rtol=1e-5)


def test_sigma_needs_a_3x3_covariance_and_is_nan_without():
    assert np.all(np.isnan(viewing_direction(FORWARD).sigma_deg))
    with pytest.raises(CalibError):
        viewing_direction(FORWARD, np.eye(6))
    assert np.all(np.isinf(viewing_direction(FORWARD, np.full((3, 3), np.inf)).sigma_deg))


def test_straight_up_has_no_azimuth_or_roll():
    R = built(0.0, 90.0, 0.0)
    v = viewing_direction(R, np.eye(3) * 1e-6)
    assert v.elevation_deg == pytest.approx(90.0)
    assert np.isnan(v.azimuth_deg) and np.isnan(v.roll_deg)
    assert np.isinf(v.sigma_deg[0]) and np.isinf(v.sigma_deg[2]) and np.isfinite(v.sigma_deg[1])


def test_notes_name_the_chart_that_is_near_its_singularity():
    """Looking 4 deg off lidar +x: pitch -86, the gimbal-lock note; looking 4 deg off lidar +z: the viewing note."""
    off_x = built(0.0, 4.0, 0.0)
    assert rpy_deg_from_R(off_x)[1] == pytest.approx(-86.0)
    notes = orientation_notes(off_x)
    assert len(notes) == 1 and "gimbal lock" in notes[0] and "pitch is -86.0 deg" in notes[0]
    up = built(20.0, 86.0, 0.0)
    notes = orientation_notes(up)
    assert len(notes) == 1 and "4.0 deg from lidar +z" in notes[0]
    assert orientation_notes(built(20.0, 45.0, 10.0)) == []
    # The two singularities are 90 deg apart, so at most one note applies.
    rng = np.random.default_rng(1)
    for _ in range(500):
        assert len(orientation_notes(Rotation.random(random_state=rng).as_matrix())) <= 1
    assert NEAR_SINGULAR_DEG < 45.0


# --- a solve near gimbal lock: the note, the panel, the CLI and the YAML ------------------------------------------


@pytest.fixture(scope="module")
def solved():
    """10 pairs of a pinhole camera looking 4 deg above lidar +x, 1 deg left, rolled 2 deg (pitch -86)."""
    from calib_core.cameras import PinholeCamera
    from calib_core.solve import solve_extrinsics
    from calib_core.transforms import invert_T, transform_points

    cam = PinholeCamera(np.array([[800.0, 0, 639.5], [0, 800, 479.5], [0, 0, 1]]), np.zeros(5), 1280, 960)
    truth = np.eye(4)
    truth[:3, :3] = built(1.0, 4.0, 2.0)
    truth[:3, 3] = [0.05, -0.3, 0.1]
    rng = np.random.default_rng(86)
    px = rng.uniform([60, 60], [1220, 900], (10, 2))
    points = transform_points(invert_T(truth), cam.bearing(px) * rng.uniform(3, 15, (10, 1)))
    clicked = px + rng.normal(0, 1.0, px.shape)
    res = solve_extrinsics(points, cam.bearing(clicked), camera=cam, pixels=clicked)
    return res, truth


def test_solve_near_gimbal_lock_notes_it_once_everywhere(solved, tmp_path):
    from app.calibration_panel import CalibrationPanel
    from app.cli import format_summary
    from app.ui_common import SolveBundle, md_escape
    from calib_core.io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml

    res, truth = solved
    assert res.quality.status == "ok"
    pitch = rpy_deg_from_R(res.T_camera_lidar[:3, :3])[1]
    assert -87.0 < pitch < -85.0
    notes = [w for w in res.warnings if "gimbal lock" in w]
    assert len(notes) == 1 and notes == orientation_notes(res.T_camera_lidar[:3, :3])
    # The roll/yaw sigmas are inflated, the viewing angles' are not.
    v = viewing_direction(res.T_camera_lidar[:3, :3], res.covariance_6x6[:3, :3])
    assert max(res.sigma_rpy_deg[0], res.sigma_rpy_deg[2]) > 5 * np.max(v.sigma_deg)
    # Against the truth, within 4 reported sigma.
    err = wrap(angles(res.T_camera_lidar[:3, :3]) - angles(truth[:3, :3]))
    assert np.all(np.abs(err) < 4 * v.sigma_deg), (err, v.sigma_deg)

    panel = CalibrationPanel(FakeGui())
    bundle = SolveBundle(list(range(1, 11)), [], res, np.zeros((10, 2)), np.zeros((10, 3)), np.zeros((0, 3)), 0.01)
    panel.show(bundle, None, False, 10)
    text = panel.result_text
    assert text.count(md_escape(notes[0])) == 1  # the solve's note, shown once
    line = next(ln for ln in text.split("  \n") if ln.startswith("looking along"))
    assert (f"az {v.azimuth_deg:.3f} deg, el {v.elevation_deg:.3f} deg" in line
            and f"roll about the axis {v.roll_deg:.3f} deg" in line)
    assert f"sigma ({v.sigma_deg[0]:.3f}, {v.sigma_deg[1]:.3f}, {v.sigma_deg[2]:.3f}) deg" in line

    summary = format_summary(res, 10)
    assert summary.count(notes[0]) == 1
    assert f"view el [deg] {v.elevation_deg:12.3f}{v.sigma_deg[1]:10.3f}" in summary

    path = tmp_path / "x.yaml"
    save_extrinsics_yaml(path, res.T_camera_lidar, res)
    doc = load_extrinsics_yaml(path)
    block = doc["T_camera_lidar_block"]
    np.testing.assert_allclose(block["viewing_deg"], [v.azimuth_deg, v.elevation_deg, v.roll_deg], rtol=0, atol=0)
    np.testing.assert_allclose(block["viewing_direction_lidar"], res.T_camera_lidar[2, :3], rtol=0, atol=0)
    np.testing.assert_allclose(doc["sigma"]["viewing_deg"], v.sigma_deg, rtol=0, atol=0)
    assert doc["residuals"]["warnings"].count(notes[0]) == 1


def test_yaml_viewing_fields_are_checked_and_optional(solved, tmp_path):
    import yaml

    from calib_core.io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml

    res, _ = solved
    path = tmp_path / "x.yaml"
    save_extrinsics_yaml(path, res.T_camera_lidar, res)
    doc = yaml.safe_load(path.read_text())
    # Old files (no viewing fields) load as before.
    old = {k: v for k, v in doc["T_camera_lidar"].items() if not k.startswith("viewing")}
    (tmp_path / "old.yaml").write_text(yaml.safe_dump({**doc, "T_camera_lidar": old}))
    np.testing.assert_array_equal(load_extrinsics_yaml(tmp_path / "old.yaml")["T_camera_lidar"], res.T_camera_lidar)
    # A hand-edited azimuth that no longer matches the matrix is refused with one line.
    bad = dict(doc["T_camera_lidar"])
    bad["viewing_deg"] = [bad["viewing_deg"][0] + 1.0] + bad["viewing_deg"][1:]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({**doc, "T_camera_lidar": bad}))
    with pytest.raises(CalibError, match="'viewing_deg' disagrees with 'matrix'"):
        load_extrinsics_yaml(tmp_path / "bad.yaml")
    bad = dict(doc["T_camera_lidar"])
    bad["viewing_direction_lidar"] = [0.0, 1.0, 0.0]
    (tmp_path / "bad2.yaml").write_text(yaml.safe_dump({**doc, "T_camera_lidar": bad}))
    with pytest.raises(CalibError, match="'viewing_direction_lidar' disagrees"):
        load_extrinsics_yaml(tmp_path / "bad2.yaml")
    # Values rounded to 6 decimals (by hand) still agree.
    rounded = dict(doc["T_camera_lidar"])
    rounded["viewing_deg"] = [round(x, 6) for x in rounded["viewing_deg"]]
    (tmp_path / "rounded.yaml").write_text(yaml.safe_dump({**doc, "T_camera_lidar": rounded}))
    load_extrinsics_yaml(tmp_path / "rounded.yaml")


def test_yaml_of_a_camera_looking_straight_up(tmp_path):
    from calib_core.io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml

    T = np.eye(4)
    T[:3, :3] = built(0.0, 90.0, 0.0)
    save_extrinsics_yaml(tmp_path / "up.yaml", T)
    doc = load_extrinsics_yaml(tmp_path / "up.yaml")
    az, _, roll = doc["T_camera_lidar_block"]["viewing_deg"]
    assert az is None and roll is None
    np.testing.assert_allclose(doc["T_camera_lidar"], T, atol=1e-15)
