"""OCamCalib model on real calibrations from Scaramuzza's and Urban's toolboxes.

Truth: the checkerboard corners the toolbox detected in real images, the board
poses the toolbox estimated, and a calib_results.txt the toolbox exported
(shared/data/ocamcalib_checkerboards, see its README.txt).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from calib_core.cameras import OCamCamera, load_camera
from calib_core.cameras.ocam import R_CV_OCAM

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ocamcalib_checkerboards"
EXAMPLE = DATA / "calib_results_toolbox_example.txt"
SETS = ("Fisheye1", "Fisheye2", "MiniOmni", "VMRImage")

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(not DATA.exists(), reason=f"OCamCalib real data not found at {DATA}"),
]


def ocam_to_cv(points_ocam: np.ndarray) -> np.ndarray:
    """X_cv = y_oc, Y_cv = x_oc, Z_cv = -z_oc (written out here, not taken from the code)."""
    return np.column_stack([points_ocam[:, 1], points_ocam[:, 0], -points_ocam[:, 2]])


def reference_world2cam_invpol(points_ocam: np.ndarray, invpol, xc, yc, c, d, e) -> np.ndarray:
    """The toolbox's C world2cam (with invpol), as in math.md; returns (row, col)."""
    x, y, z = points_ocam.T
    n = np.hypot(x, y)
    theta = np.arctan(z / n)
    rho = np.polynomial.polynomial.polyval(theta, invpol)
    xs, ys = x * rho / n, y * rho / n
    return np.column_stack([c * xs + d * ys + xc, e * xs + ys + yc])


@pytest.mark.parametrize("name", SETS)
def test_reprojects_detected_corners(name):
    data = json.loads((DATA / f"{name}_ocam_calib.json").read_text())
    m = data["ocam_model_matlab"]
    camera = OCamCamera(
        m["ss_a0_to_a4"], None,
        m["xc_row_1based"] - 1.0, m["yc_col_1based"] - 1.0,  # MATLAB 1-based -> 0-based
        m["c"], m["d"], m["e"],
        int(m["width_as_stored"]), int(m["height_as_stored"]),
    )
    board = np.array([data["board"]["Xt"], data["board"]["Yt"], np.ones(len(data["board"]["Xt"]))])
    errors, behind = [], 0
    for image in data["images"]:
        M = np.asarray(image["RRfin_r1_r2_t"], dtype=float) @ board  # OCam frame, (3, N)
        pixels, valid = camera.project(ocam_to_cv(M.T))
        assert valid.all(), f"{name} image {image['index_1based']}: {np.count_nonzero(~valid)} corners not projected"
        behind += int(np.count_nonzero(M[2] > 0))
        detected = np.column_stack([image["Yp_abs_col_1based"], image["Xp_abs_row_1based"]]) - 1.0  # (u, v)
        errors.append(np.linalg.norm(pixels - detected, axis=1))
    err = np.concatenate(errors)
    print(
        f"\n{name}: {err.size} corners in {len(data['images'])} images, {behind} beyond 90 deg: "
        f"mean {err.mean():.3f} px, median {np.median(err):.3f} px, max {err.max():.3f} px"
    )
    assert err.mean() <= 0.4


def test_parses_toolbox_calib_results():
    camera = load_camera(EXAMPLE)
    assert isinstance(camera, OCamCamera)
    # values read by eye from the file
    np.testing.assert_array_equal(camera.pol, [-2.063866e02, 0.0, 2.165610e-03, -4.495456e-06, 1.810639e-08])
    assert camera.invpol.size == 12 and camera.invpol[0] == 293.052431 and camera.invpol[-1] == 0.865190
    assert (camera.xc, camera.yc) == (241.019976, 385.783141)
    assert (camera.c, camera.d, camera.e) == (0.998881, -0.042038, 0.045079)
    assert (camera.width, camera.height) == (748, 480)


def test_pol_and_invpol_agree_over_the_image():
    camera = OCamCamera.from_calib_results(EXAMPLE)
    # 1e-4 px inside the edges: exactly on an edge, round-off may step outside
    u, v = np.meshgrid(np.linspace(-0.4999, 747.4999, 75), np.linspace(-0.4999, 479.4999, 49))
    pixels = np.column_stack([u.ravel(), v.ravel()])
    rays_cv = camera.bearing(pixels)
    assert np.isfinite(rays_cv).all()
    rays_ocam = ocam_to_cv(rays_cv)  # the frame change is its own inverse
    rows_cols = reference_world2cam_invpol(
        rays_ocam, camera.invpol, camera.xc, camera.yc, camera.c, camera.d, camera.e
    )
    # sensor-plane radius (math.md's cam2world) of each pixel
    dr, dq = pixels[:, 1] - camera.xc, pixels[:, 0] - camera.yc
    det = camera.c - camera.d * camera.e
    rho = np.hypot((dr - camera.d * dq) / det, (-camera.e * dr + camera.c * dq) / det)
    # The toolbox fits invpol out to hypot(W, H) / 2 = 444.4 px; the image
    # corners of this off-centre camera reach 454.7 px.
    fitted = (rho > 1.0) & (rho <= math.hypot(748, 480) / 2)  # rho = 0 is 0/0 in world2cam
    invpol_err = np.hypot(rows_cols[:, 1] - pixels[:, 0], rows_cols[:, 0] - pixels[:, 1])
    assert fitted.mean() > 0.99
    assert invpol_err[fitted].max() < 0.01
    # our exact root solving agrees with the toolbox's invpol to the same tolerance
    projected, valid = camera.project(rays_cv)
    assert valid.all()
    assert np.max(np.abs(projected[fitted] - rows_cols[fitted][:, ::-1])) < 0.01
    np.testing.assert_allclose(projected, pixels, atol=1e-6)  # while ours is exact everywhere
    print(
        f"\ntoolbox example: pol/invpol max disagreement {invpol_err[fitted].max():.4f} px within the fit "
        f"radius, {invpol_err[rho > 1.0].max():.4f} px including the corners"
    )


def test_round_trip_including_rays_beyond_90_degrees():
    camera = OCamCamera.from_calib_results(EXAMPLE)
    assert camera.max_angle_rad > math.radians(120)  # pol turns positive inside the image
    rng = np.random.default_rng(0)
    rays = rng.normal(size=(4000, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    pixels, valid = camera.project(rays)
    angle = np.arccos(np.clip(rays[:, 2], -1, 1))
    assert not valid[angle > camera.max_angle_rad + 1e-9].any()
    back = camera.bearing(pixels[valid])
    beyond = rays[valid, 2] < 0
    assert beyond.sum() > 100  # many valid rays more than 90 deg from the axis
    np.testing.assert_allclose(back, rays[valid], atol=1e-9)
    u, v = np.meshgrid(np.linspace(0, 747, 60), np.linspace(0, 479, 40))
    pixels = np.column_stack([u.ravel(), v.ravel()])
    again, valid = camera.project(camera.bearing(pixels))
    assert valid.all() and np.max(np.abs(again - pixels)) < 1e-6


def test_frame_change_is_a_proper_rotation():
    camera = OCamCamera.from_calib_results(EXAMPLE)
    centre = np.array([camera.yc, camera.xc])  # (u, v)
    b_centre, b_right, b_down = camera.bearing(np.array([centre, centre + [50, 0], centre + [0, 50]]))
    assert b_right[0] > 0.1 and abs(b_right[1]) < 0.05  # right in the image -> +X
    assert b_down[1] > 0.1 and abs(b_down[0]) < 0.05  # down in the image -> +Y
    assert b_centre[2] > 0.999  # optical axis -> +Z
    # right, down, forward form a right-handed triple, as OpenCV's x, y, z do
    assert np.linalg.det(np.array([b_right - b_centre, b_down - b_centre, b_centre])) > 0
    assert np.linalg.det(R_CV_OCAM) == pytest.approx(1.0)
    np.testing.assert_array_equal(R_CV_OCAM @ R_CV_OCAM.T, np.eye(3))


def test_example_file_write_round_trip(tmp_path):
    camera = OCamCamera.from_calib_results(EXAMPLE)
    camera.write_calib_results(tmp_path / "calib_results.txt")
    again = OCamCamera.from_calib_results(tmp_path / "calib_results.txt")
    np.testing.assert_array_equal(again.pol, camera.pol)
    np.testing.assert_array_equal(again.invpol, camera.invpol)
    assert (again.xc, again.yc, again.c, again.d, again.e, again.width, again.height) == (
        camera.xc, camera.yc, camera.c, camera.d, camera.e, camera.width, camera.height,
    )


def test_bulk_float32_rays_land_on_their_pixels():
    # The colouring path: many float32 points, column-major, with unprojectable rows among them.
    camera = OCamCamera.from_calib_results(EXAMPLE)
    u, v = np.meshgrid(np.linspace(0, 747, 60), np.linspace(0, 479, 40))
    pixels = np.column_stack([u.ravel(), v.ravel()])
    points = camera.bearing(pixels) * np.linspace(0.5, 30.0, len(pixels))[:, None]
    points[[0, 255, 256, 1000]] = [[np.nan, 0.0, 1.0], [0.0, 0.0, 0.0], [np.inf, 0.0, 1.0], [0.0, np.nan, 0.0]]
    projected, valid = camera.project(np.asfortranarray(points, dtype=np.float32))
    assert projected.dtype == np.float32
    good = np.ones(len(points), bool)
    good[[0, 255, 256, 1000]] = False
    assert valid[good].all() and not valid[~good].any() and np.isnan(projected[~good]).all()
    assert np.max(np.abs(projected[good] - pixels[good])) < 5e-4  # float32 points and pixels
