"""The whole pipeline recovers the sample's ground truth from simulated clicks.

Clicks are simulated as a user makes them (calib_core.synthetic.simulate_pairs):
at real corners of the scene, spread over the view, the camera click with
1 px Gaussian noise per axis and the BA pick rounded to a whole depth-matrix
cell.  As in the paper's Table I, a calibration uses 10 pairs and the figures
are taken over 10 trials with different pairs.

What is asserted, and why
-------------------------
* Mean reprojection error <= 1.6 px (the paper reports 1.6 +/- 1.2 px).
* Mean translation error <= 2 cm.
* Every trial's error is consistent with the covariance the solver reports
  (Mahalanobis distance of the 6-D pose error below the 99.9 % chi-square
  quantile): the quoted sigmas can be trusted.
* Mean rotation error <= 0.6 deg, and the pose averaged over the trials
  (the paper's Table I protocol) is within 0.3 deg and 1 cm.

Issue 2 asks for <= 0.2 deg rotation error per calibration.  This sample
cannot give that to one calibration of 10 pairs, whatever the solver: the
camera images 120 deg over a 230 px radius (0.52 deg per pixel), so the 1 px
click noise alone is 0.5 deg per ray, and whole-cell BA picks add up to
0.25 x 0.5 deg.  The covariance at the optimum -- the Cramer-Rao bound our
estimator reaches (bench/) -- puts one calibration's rotation sigma at about
0.25-0.4 deg.  The test keeps the bounds the noise permits and prints the
measured errors.
"""

from __future__ import annotations


import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.solve import calibrate
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import rotation_angle_deg
from repo_paths import SAMPLE

TRIALS = 10
PAIRS = 10


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


@pytest.fixture(scope="module")
def trials(scene):
    out = []
    for k in range(TRIALS):
        pairs = simulate_pairs(scene, PAIRS, np.random.default_rng(1000 + k), pixel_noise_px=1.0)
        # As the CLI and the app do: ids, whole-cell laser picks modelled, robust solve.
        out.append(calibrate(pairs, scene.depth, scene.camera))
    return out


def _errors(result, truth):
    T = result.T_camera_lidar
    return rotation_angle_deg(T[:3, :3], truth[:3, :3]), float(np.linalg.norm(T[:3, 3] - truth[:3, 3]))


def test_ground_truth_file_matches_the_scene(scene):
    truth = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    np.testing.assert_allclose(truth, scene.T_camera_lidar, atol=1e-12)


def test_ten_pairs_recover_ground_truth(scene, trials):
    truth = scene.T_camera_lidar
    rot, trans, px = [], [], []
    for k, res in enumerate(trials):
        r, t = _errors(res, truth)
        rot.append(r), trans.append(t), px.append(res.mean_px)
        print(f"trial {k}: rotation {r:.3f} deg, translation {100 * t:.2f} cm, "
              f"reprojection {res.mean_px:.2f} +/- {res.std_px:.2f} px")
    R_mean = Rotation.from_matrix([res.T_camera_lidar[:3, :3] for res in trials]).mean().as_matrix()
    t_mean = np.mean([res.T_camera_lidar[:3, 3] for res in trials], axis=0)
    rot_avg = rotation_angle_deg(R_mean, truth[:3, :3])
    trans_avg = float(np.linalg.norm(t_mean - truth[:3, 3]))
    print(f"mean over {TRIALS} trials: rotation {np.mean(rot):.3f} deg (max {np.max(rot):.3f}), "
          f"translation {100 * np.mean(trans):.2f} cm (max {100 * np.max(trans):.2f}), "
          f"reprojection {np.mean(px):.2f} px; averaged pose: rotation {rot_avg:.3f} deg, "
          f"translation {100 * trans_avg:.2f} cm")
    assert np.mean(px) <= 1.6
    assert np.mean(trans) <= 0.02
    assert np.mean(rot) <= 0.6
    assert rot_avg <= 0.3 and trans_avg <= 0.01


def test_reported_uncertainty_covers_the_error(scene, trials):
    truth = scene.T_camera_lidar
    limit = chi2.ppf(0.999, 6)
    for res in trials:
        T = res.T_camera_lidar
        # Solver parameters: rotation vector delta with R = exp(delta) R_hat, then translation.
        delta = Rotation.from_matrix(truth[:3, :3] @ T[:3, :3].T).as_rotvec()
        err = np.concatenate([delta, truth[:3, 3] - T[:3, 3]])
        d2 = float(err @ np.linalg.solve(res.covariance_6x6, err))
        assert d2 <= limit, f"pose error is {np.sqrt(d2):.1f} sigma from the reported covariance"
