"""calib_core.transforms against hand-computed rotations and transforms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calib_core.errors import CalibError
from calib_core.transforms import (
    R_from_quat_xyzw,
    R_from_rpy_deg,
    invert_T,
    make_T,
    quat_xyzw_from_R,
    rotation_angle_deg,
    rpy_deg_from_R,
    transform_points,
)

S45 = np.sqrt(0.5)


def Rx(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def Ry(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def Rz(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_yaw_90_maps_x_to_y():
    np.testing.assert_allclose(R_from_rpy_deg([0, 0, 90]) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_pitch_90_maps_z_to_x_and_roll_90_maps_y_to_z():
    np.testing.assert_allclose(R_from_rpy_deg([0, 90, 0]) @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(R_from_rpy_deg([90, 0, 0]) @ [0, 1, 0], [0, 0, 1], atol=1e-15)


def test_rpy_order_is_rz_ry_rx():
    # Roll 90 then pitch 90 (Rx first, applied to the vector first):
    # x -> x -> -z and y -> z -> x.
    R = R_from_rpy_deg([90, 90, 0])
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(R @ [0, 1, 0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(R_from_rpy_deg([10, -20, 30]), Rz(30) @ Ry(-20) @ Rx(10), atol=1e-15)


def test_rpy_from_hand_matrix():
    np.testing.assert_allclose(rpy_deg_from_R(Rz(166.95) @ Ry(-1.24) @ Rx(0.64)), [0.64, -1.24, 166.95], atol=1e-12)
    np.testing.assert_allclose(rpy_deg_from_R(Rz(-120) @ Ry(45) @ Rx(-170)), [-170, 45, -120], atol=1e-12)


def test_quaternions_by_hand():
    np.testing.assert_allclose(quat_xyzw_from_R(Rz(90)), [0, 0, S45, S45], atol=1e-15)
    np.testing.assert_allclose(R_from_quat_xyzw([1, 0, 0, 0]), np.diag([1.0, -1, -1]), atol=1e-15)
    # Not normalised on input: same rotation.
    np.testing.assert_allclose(R_from_quat_xyzw([0, 0, 2, 2]), Rz(90), atol=1e-15)
    # 270 deg about z = -90 deg; returned with w >= 0.
    np.testing.assert_allclose(quat_xyzw_from_R(Rz(270)), [0, 0, -S45, S45], atol=1e-15)


def test_make_invert_transform_points_by_hand():
    T = make_T(Rz(90), [1, 2, 3])
    np.testing.assert_allclose(transform_points(T, [[1, 0, 0], [0, 0, 0]]), [[1, 3, 3], [1, 2, 3]], atol=1e-15)
    Ti = invert_T(T)
    np.testing.assert_allclose(Ti[:3, 3], [-2, 1, -3], atol=1e-15)
    np.testing.assert_allclose(Ti @ T, np.eye(4), atol=1e-15)
    np.testing.assert_allclose(transform_points(Ti, [[1, 3, 3]]), [[1, 0, 0]], atol=1e-15)


def test_rotation_angle_deg():
    assert rotation_angle_deg(Rz(30), Rz(75)) == pytest.approx(45, abs=1e-12)
    assert rotation_angle_deg(Rx(170), Rx(-170)) == pytest.approx(20, abs=1e-12)
    assert rotation_angle_deg(Ry(10), Ry(10)) == pytest.approx(0, abs=1e-6)


@pytest.mark.parametrize(
    "call, fragment",
    [
        (lambda: make_T(np.eye(3), [1, 2]), "t must have shape"),
        (lambda: make_T(np.eye(2), [1, 2, 3]), "R must have shape"),
        (lambda: invert_T(np.full((4, 4), np.nan)), "NaN"),
        (lambda: transform_points(np.eye(4), np.zeros((3, 2))), "(N, 3)"),
        (lambda: R_from_quat_xyzw([0, 0, 0, 0]), "zero length"),
        (lambda: R_from_rpy_deg([1, 2]), "rpy_deg"),
    ],
)
def test_bad_input_raises_calib_error(call, fragment):
    with pytest.raises(CalibError, match=None) as info:
        call()
    assert fragment in str(info.value)


angles = st.floats(-179.9, 179.9)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(roll=angles, pitch=st.floats(-89.0, 89.0), yaw=angles)
def test_rpy_and_quaternion_round_trips(roll, pitch, yaw):
    R = Rz(yaw) @ Ry(pitch) @ Rx(roll)
    np.testing.assert_allclose(R_from_rpy_deg([roll, pitch, yaw]), R, atol=1e-12)
    np.testing.assert_allclose(rpy_deg_from_R(R), [roll, pitch, yaw], atol=1e-8)
    q = quat_xyzw_from_R(R)
    assert q[3] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
    np.testing.assert_allclose(R_from_quat_xyzw(q), R, atol=1e-12)
    assert rotation_angle_deg(R, R_from_quat_xyzw(-q)) == pytest.approx(0, abs=1e-5)
