"""The 3-D check view's viewpoint: hand-computed cases."""

import numpy as np
import pytest

from calib_core.viewpoint import viewpoint_behind_camera


def test_camera_looking_along_lidar_x_from_a_mast():
    # Camera at lidar (2, 1, 3), looking along lidar +x (camera z = lidar x, camera x = -lidar y, camera y = -lidar z).
    R_lidar_camera = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T_lidar_camera = np.eye(4)
    T_lidar_camera[:3, :3], T_lidar_camera[:3, 3] = R_lidar_camera, (2.0, 1.0, 3.0)
    eye, look = viewpoint_behind_camera(np.linalg.inv(T_lidar_camera), (0.0, 0.0, 1.0))
    # 1.5 m behind along -x, 0.7 m up; 3 m ahead along +x.
    np.testing.assert_allclose(eye, (0.5, 1.0, 3.7), atol=1e-12)
    np.testing.assert_allclose(look, (5.0, 1.0, 3.0), atol=1e-12)


def test_a_tilted_camera_is_levelled_and_a_vertical_one_gets_a_horizontal_stand_in():
    # Camera at the origin looking 30 deg down from lidar +y: levelled, it looks along +y.
    a = np.radians(30.0)
    z_cam = np.array([0.0, np.cos(a), -np.sin(a)])
    x_cam = np.array([1.0, 0.0, 0.0])
    R_lidar_camera = np.column_stack([x_cam, np.cross(z_cam, x_cam), z_cam])
    T_camera_lidar = np.eye(4)
    T_camera_lidar[:3, :3] = R_lidar_camera.T
    eye, look = viewpoint_behind_camera(T_camera_lidar, (0.0, 0.0, 1.0))
    np.testing.assert_allclose(eye, (0.0, -1.5, 0.7), atol=1e-12)
    np.testing.assert_allclose(look, (0.0, 3.0, 0.0), atol=1e-12)
    # Looking straight down (camera z = lidar -z = -up): no level direction, so up x lidar x = lidar +y stands in.
    R_down = np.column_stack([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    T_down = np.eye(4)
    T_down[:3, :3] = R_down.T
    eye, look = viewpoint_behind_camera(T_down, (0.0, 0.0, 1.0))
    np.testing.assert_allclose(eye, (0.0, -1.5, 0.7), atol=1e-12)
    np.testing.assert_allclose(look, (0.0, 3.0, 0.0), atol=1e-12)


def test_no_calibration_looks_along_lidar_x_from_the_origin():
    eye, look = viewpoint_behind_camera(None, (0.0, 0.0, 1.0))
    np.testing.assert_allclose(eye, (-1.5, 0.0, 0.7))
    np.testing.assert_allclose(look, (3.0, 0.0, 0.0))
