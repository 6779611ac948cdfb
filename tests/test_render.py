"""The scan seen from the camera (calib_core.render, ``ba-calib render``) against independent truth.

Truth:
* a plane scanned by a synthetic spherical lidar, with the distance along every pixel's ray computed
  analytically here, for the three camera models (distorted pinhole, fisheye, OCam);
* KITTI 000002 under its published calibration: an independent z-buffer written in this file (every valid
  point projected with ``K``, nearest wins per pixel, no footprint);
* the sample scene: rays cast from the true camera centre through every pixel's bearing into the room's
  mesh (the mesh the scan was simulated from).

Run with ``-s`` to see the measured figures.
"""

from __future__ import annotations

import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from calib_core.alignment import focal_px_estimate, preset_T
from calib_core.bearing_angle import bearing_angle_images
from calib_core.cameras.fisheye import FisheyeCamera
from calib_core.cameras.io import load_camera
from calib_core.cameras.pinhole import PinholeCamera
from calib_core.errors import CalibError
from calib_core.io.extrinsic_formats import load_extrinsics_any
from calib_core.io.scan_readers import load_scan
from calib_core.lidar.depth_matrix import DepthMatrix
from calib_core.render import CameraRender, render_from_camera, shade_render
from kitti_reference import KITTI, KITTI_CALIB, kitti_K_T
from repo_paths import REPO, SAMPLE

KITTI_BIN = KITTI / "velodyne" / "000002.bin"
KITTI_CAMERA = REPO / "real_data" / "kitti_000002_camera.yaml"
needs_kitti = pytest.mark.skipif(not KITTI_BIN.is_file(), reason=f"KITTI frame not found at {KITTI}")


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], capture_output=True, text=True, timeout=300,
                          cwd=REPO)


# ------------------------------------------------------------------ a scanned plane, every camera model
PLANE_X_M = 6.0
ROW_STEP_DEG, COL_STEP_DEG = 0.4, 0.2
EL_DEG = np.arange(20.0, -20.0 - 1e-9, -ROW_STEP_DEG)  # rows top to bottom
AZ_DEG = np.arange(70.0, -70.0 - 1e-9, -COL_STEP_DEG)  # columns left to right (lidar y is left)


def plane_scan() -> DepthMatrix:
    """A lidar at the origin scanning the plane x = 6 m over +-20 deg elevation, +-70 deg azimuth."""
    el, az = np.meshgrid(np.radians(EL_DEG), np.radians(AZ_DEG), indexing="ij")
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=2)
    rng = PLANE_X_M / dirs[..., 0]
    return DepthMatrix(rng, dirs, dirs * rng[..., None], np.ones(rng.shape, bool), {"wrap_cols": False})


def plane_pose() -> np.ndarray:
    T = preset_T("+x")
    T[:3, 3] = [0.05, -0.10, 0.20]  # the camera is off the lidar origin: parallax
    return T


CAMERAS = {
    "pinhole": lambda: PinholeCamera(np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]),
                                     np.array([-0.25, 0.08, 0.001, -0.0005, 0.0]), 640, 480),
    "fisheye": lambda: FisheyeCamera(np.array([[260.0, 0, 320.0], [0, 260.0, 240.0], [0, 0, 1]]),
                                     np.array([0.02, -0.01, 0.0, 0.0]), 640, 480),
    "ocam": lambda: load_camera(SAMPLE / "camera.yaml"),
}


@pytest.mark.parametrize("model", sorted(CAMERAS))
def test_plane_render_matches_the_analytic_distance(model):
    camera = CAMERAS[model]()
    depth, T = plane_scan(), plane_pose()
    r = render_from_camera(depth, camera, T)
    assert isinstance(r, CameraRender)
    h, w = camera.height, camera.width
    assert r.range_m.shape == (h, w) and r.range_m.dtype == np.float32
    assert r.camera_depth_m.shape == (h, w) and r.camera_depth_m.dtype == np.float32
    assert r.cell_rc.shape == (h, w, 2) and r.cell_rc.dtype == np.int32
    assert r.edge.shape == (h, w) and r.edge.dtype == bool

    # Every pixel's ray, in the lidar frame, from the camera centre.
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays_cam = camera.bearing(np.stack([u.ravel(), v.ravel()], axis=1)).reshape(h, w, 3)
    R, t = T[:3, :3], T[:3, 3]
    centre = -R.T @ t
    rays = rays_cam @ R  # R.T @ ray per pixel
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (PLANE_X_M - centre[0]) / rays[..., 0]  # distance to the plane along a unit ray
        hit = centre + s[..., None] * rays
        el = np.degrees(np.arcsin(hit[..., 2] / np.linalg.norm(hit, axis=2)))
        az = np.degrees(np.arctan2(hit[..., 1], hit[..., 0]))
    ray_ok = np.isfinite(rays).all(axis=2) & (s > 0)
    margin = 1.0  # deg, a few beams: the footprint may cover this much beyond the scanned box, never more
    well_inside = ray_ok & (np.abs(el) < 20 - margin) & (np.abs(az) < 70 - margin)
    outside = ~ray_ok | (np.abs(el) > 20 + margin) | (np.abs(az) > 70 + margin)
    shown = r.has_return

    coverage = shown[well_inside].mean()
    rel = np.abs(r.camera_depth_m[shown & well_inside] - s[shown & well_inside]) / s[shown & well_inside]
    print(f"\nplane, {model}: coverage {100 * coverage:.2f} %, camera distance vs analytic: median "
          f"{100 * np.median(rel):.3f} %, max {100 * rel.max():.2f} %; pixels outside the scan shown: "
          f"{int((shown & outside).sum())}")
    assert well_inside.sum() > 0.03 * h * w  # the OCam's 165 deg field makes the plane small
    assert coverage > 0.995
    # A pixel shows a return up to ~1.5 px off its ray; on the plane, seen up to 70 deg off its normal
    # (tan 70 deg = 2.75), that changes the distance by up to ~2.75 * 1.5 * sqrt(2) pixel angles.
    px_rad = 1.0 / focal_px_estimate(camera)
    assert np.median(rel) < 2 * px_rad and rel.max() < 6 * px_rad
    assert not (shown & outside).any()
    # No-return pixels: NaN and -1 everywhere together.
    assert np.array_equal(np.isfinite(r.range_m), shown) and np.array_equal(np.isfinite(r.camera_depth_m), shown)
    assert (r.cell_rc[~shown] == -1).all() and (r.cell_rc[shown] >= 0).all()

    # The cell shown at a pixel is within about a beam spacing of that pixel's ray (seen from the camera).
    rc = r.cell_rc[shown]
    to_cell = depth.points[rc[:, 0], rc[:, 1]] - centre
    cos = np.einsum("ij,ij->i", to_cell / np.linalg.norm(to_cell, axis=1, keepdims=True), rays[shown])
    off_deg = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    # Half a beam spacing plus the footprint's rounding up (< 1 px) and the centre's (0.5 px), on both axes.
    px_deg = np.degrees(px_rad)
    bound = np.sqrt(2) * (ROW_STEP_DEG / 2 + 1.5 * px_deg)
    print(f"  angle between a pixel's ray and its cell: 99th pct {np.percentile(off_deg, 99):.3f} deg, max "
          f"{off_deg.max():.3f} deg (bound {bound:.3f} deg; a pixel is {px_deg:.3f} deg)")
    assert np.percentile(off_deg, 99) < bound and off_deg.max() < 1.5 * bound
    # range_m is the distance of that cell's point from the lidar origin.
    np.testing.assert_allclose(r.range_m[shown], depth.range_m[rc[:, 0], rc[:, 1]], rtol=1e-6)
    # A plane has no depth edge inside; the edge pixels are the scan's outline (4-neighbours).
    interior = cv2.erode(shown.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))) > 0
    assert not (r.edge & interior).any()
    assert r.edge[shown & ~interior].all()


def test_nearest_wins_and_the_footprint_stops_at_a_step():
    """A near square in front of the plane: it shows in full, and the plane never paints over it."""
    depth = plane_scan()
    near = (np.abs(EL_DEG)[:, None] <= 5.0) & (np.abs(AZ_DEG)[None, :] <= 10.0)
    rng = np.where(near, 0.5 * depth.range_m, depth.range_m)
    depth = DepthMatrix(rng, depth.directions, depth.directions * rng[..., None], depth.valid, depth.meta)
    camera, T = CAMERAS["pinhole"](), preset_T("+x")  # the camera at the lidar origin: no parallax
    r = render_from_camera(depth, camera, T)
    shown = r.has_return
    near_px = shown & near[r.cell_rc[..., 0].clip(0), r.cell_rc[..., 1].clip(0)]
    # The square's outline as the test projects it: +-5 deg elevation, +-10 deg azimuth at x = 3 m.
    K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5]])
    corners = np.array([[3.0, np.tan(np.radians(10)) * 3, np.tan(np.radians(5)) * 3]])
    x_cam = -corners[0, 1] / corners[0, 0]
    y_cam = -corners[0, 2] / corners[0, 0]
    u0, u1 = sorted([K[0, 0] * x_cam + K[0, 2], -K[0, 0] * x_cam + K[0, 2]])
    v0, v1 = sorted([K[1, 1] * y_cam + K[1, 2], -K[1, 1] * y_cam + K[1, 2]])
    rows, cols = np.nonzero(near_px)
    # (Distortion moves the box a little: allow a few pixels.)
    print(f"\nnear square rendered over u {cols.min()}..{cols.max()} v {rows.min()}..{rows.max()}; "
          f"undistorted box u {u0:.0f}..{u1:.0f} v {v0:.0f}..{v1:.0f}")
    # Inside the square, well away from its outline, only the square shows (the far plane never wins).
    inner = np.zeros_like(shown)
    inner[int(v0) + 12:int(v1) - 12, int(u0) + 12:int(u1) - 12] = True
    assert near_px[inner].all()
    # Its footprints do not bleed more than a few pixels (half a beam spacing) past its outline.
    bleed_u = max(u0 - cols.min(), cols.max() - u1)
    bleed_v = max(v0 - rows.min(), rows.max() - v1)
    assert bleed_u < 15 and bleed_v < 15  # distortion included; a beam spacing is 3.5 px here
    # Its outline is a depth edge.
    outline = near_px & ~(cv2.erode(near_px.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
    assert r.edge[outline].mean() > 0.95


def test_footprint_px_fixed_and_bad_arguments():
    depth, T, camera = plane_scan(), plane_pose(), CAMERAS["pinhole"]()
    one = render_from_camera(depth, camera, T, footprint_px=1)
    # One pixel per return: every shown pixel holds the return projecting into it (centre within 0.5 px).
    rc = one.cell_rc[one.has_return]
    pts = depth.points[rc[:, 0], rc[:, 1]]
    px, _ = camera.project(pts @ T[:3, :3].T + T[:3, 3])
    rr, cc = np.nonzero(one.has_return)
    # (The renderer projects float32 camera-frame points: pixels within 1e-3 px of this float64 projection.)
    assert np.abs(px - np.stack([cc, rr], axis=1)).max() <= 0.5 + 1e-3
    # Far returns dropped by max_range_m.
    capped = render_from_camera(depth, camera, T, max_range_m=6.5)
    assert np.nanmax(capped.range_m) <= 6.5
    assert capped.has_return.sum() < render_from_camera(depth, camera, T).has_return.sum()
    with pytest.raises(CalibError, match="footprint_px"):
        render_from_camera(depth, camera, T, footprint_px=0)
    with pytest.raises(CalibError, match="max_range_m"):
        render_from_camera(depth, camera, T, max_range_m=-1)
    with pytest.raises(CalibError):
        render_from_camera(depth, camera, np.eye(3))


def test_shade_render_modes():
    depth = plane_scan()
    intensity = np.tile(np.linspace(0.0, 1.0, depth.shape[1]), (depth.shape[0], 1))  # grows to the right (lidar)
    depth = DepthMatrix(depth.range_m, depth.directions, depth.points, depth.valid,
                        {**depth.meta, "field_images": {"intensity": intensity}})
    camera, T = CAMERAS["pinhole"](), preset_T("+x")
    r = render_from_camera(depth, camera, T)
    shown = r.has_return
    ba = bearing_angle_images(depth)["vertical"]
    for mode, kwargs in (("range", {}), ("intensity", {}), ("ba", {"ba_image": ba})):
        rgba = shade_render(r, depth, mode, **kwargs)
        assert rgba.shape == (camera.height, camera.width, 4) and rgba.dtype == np.uint8
        assert (rgba[~shown] == 0).all()  # fully transparent, never grey
        assert (rgba[shown, 3] == 255).all()
        assert (rgba[r.edge & shown, :3] == 255).all()
    # Intensity: grey grows with the cell's intensity (lidar columns run right to left in the image here).
    grey = shade_render(r, depth, "intensity")[..., 0].astype(float)
    row = camera.height // 2
    ok = shown[row] & ~r.edge[row]
    values = intensity[r.cell_rc[row, ok, 0], r.cell_rc[row, ok, 1]]
    assert np.all(np.diff(grey[row, ok][np.argsort(values)]) >= 0)
    # Range: TURBO of log range: the plane's nearest point (image centre) is blue, the far corners redder.
    rgb = shade_render(r, depth, "range")
    centre = rgb[camera.height // 2, camera.width // 2, :3].astype(int)
    assert centre[2] > centre[0]
    with pytest.raises(CalibError, match="unknown shading mode"):
        shade_render(r, depth, "colour")
    with pytest.raises(CalibError, match="BA image"):
        shade_render(r, depth, "ba")
    bare = plane_scan()
    with pytest.raises(CalibError, match="no intensity"):
        shade_render(render_from_camera(bare, camera, T), bare, "intensity")


# ------------------------------------------------------------------ KITTI 000002, published calibration
def independent_zbuffer(points: np.ndarray, K: np.ndarray, T: np.ndarray, width: int, height: int):
    """Per pixel the index of the nearest projected point (no footprint) and its distance from the camera."""
    p = points @ T[:3, :3].T + T[:3, 3]
    z = p[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = (p @ K.T)[:, :2] / z[:, None]
    col, row = np.floor(uv[:, 0] + 0.5), np.floor(uv[:, 1] + 0.5)
    ok = (z > 0) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    idx = np.nonzero(ok)[0]
    flat = (row[idx] * width + col[idx]).astype(np.int64)
    dist = np.linalg.norm(p[idx], axis=1)
    order = np.lexsort((dist, flat))
    first = np.unique(flat[order], return_index=True)[1]
    winners = idx[order[first]]
    owner = np.full(height * width, -1, np.int64)
    owner[flat[order[first]]] = winners
    best = np.full(height * width, np.nan)
    best[flat[order[first]]] = dist[order[first]]
    return owner.reshape(height, width), best.reshape(height, width), uv


@pytest.fixture(scope="module")
def kitti():
    if not KITTI_BIN.is_file():
        pytest.skip(f"KITTI frame not found at {KITTI}")
    depth = load_scan(KITTI_BIN)
    camera = load_camera(KITTI_CAMERA)
    K, T = kitti_K_T()
    np.testing.assert_allclose(camera.K if hasattr(camera, "K") else K, K)
    return depth, camera, K, T


@needs_kitti
def test_kitti_render_against_an_independent_zbuffer(kitti):
    depth, camera, K, T = kitti
    rows, cols = np.nonzero(depth.valid)
    points = depth.points[rows, cols]
    owner, best_dist, uv = independent_zbuffer(points, K, T, camera.width, camera.height)
    covered = owner >= 0

    render_from_camera(depth, camera, T)  # compile / load the kernel
    t0 = time.perf_counter()
    r = render_from_camera(depth, camera, T)
    seconds = time.perf_counter() - t0
    shown = r.has_return

    # (a) ranges agree where the independent projection has a point.
    both = covered & shown
    ref_range = np.linalg.norm(points[owner[both]], axis=1)
    rel = np.abs(r.range_m[both] - ref_range) / ref_range
    coverage = both.sum() / covered.sum()
    print(f"\nKITTI 000002: {covered.sum()} pixels hold a projected point, {shown.sum()} shown by the render "
          f"({100 * shown.mean():.1f} % of the image); coverage of the projected pixels {100 * coverage:.2f} %; "
          f"median relative range difference {100 * np.median(rel):.3f} % "
          f"(90th pct {100 * np.percentile(rel, 90):.2f} %);"
          f" render {1000 * seconds:.0f} ms")
    assert coverage >= 0.90
    assert np.median(rel) < 0.02
    # Nearest wins: a pixel never shows a return farther than the nearest one projecting into it.
    assert (r.camera_depth_m[both] <= best_dist[both] * (1 + 1e-6)).all()
    assert seconds < 2.0  # the app needs well under 0.5 s; generous here for a loaded test machine

    # (b) the cell shown is one whose point projects within the footprint of that pixel: half a beam
    # spacing (rows up to 0.9 deg apart, one missing row bridged) and within 1 px of rounding.
    lut = np.full(depth.shape, -1, np.int64)
    lut[rows, cols] = np.arange(rows.size)
    which = lut[r.cell_rc[shown, 0], r.cell_rc[shown, 1]]
    assert (which >= 0).all()
    pr, pc = np.nonzero(shown)
    off = np.abs(uv[which] - np.stack([pc, pr], axis=1))
    row_step = np.diff(np.nanmedian(np.degrees(np.arcsin(depth.points[..., 2] / depth.range_m)), axis=1))
    half_v = K[1, 1] * np.tan(np.radians(2 * np.abs(row_step).max())) / 2 + 1
    half_u = K[0, 0] * np.tan(np.radians(2 * 360.0 / depth.shape[1])) / 2 * 2.5 + 1  # 1/cos^2 at the image edges
    print(f"cell projection vs pixel: 99th pct |du| {np.percentile(off[:, 0], 99):.2f} px, |dv| "
          f"{np.percentile(off[:, 1], 99):.2f} px; bounds {half_u:.1f}, {half_v:.1f} px")
    assert (off[:, 0] <= half_u).all() and (off[:, 1] <= half_v).all()
    # With a fixed 5 px footprint the bound is exact: 2 px plus the rounding of the centre.
    r5 = render_from_camera(depth, camera, T, footprint_px=5)
    w5 = lut[r5.cell_rc[r5.has_return, 0], r5.cell_rc[r5.has_return, 1]]
    pr5, pc5 = np.nonzero(r5.has_return)
    assert np.abs(uv[w5] - np.stack([pc5, pr5], axis=1)).max() <= 2.5 + 1e-3

    # One pixel per return: exactly the independent z-buffer.
    r1 = render_from_camera(depth, camera, T, footprint_px=1)
    same = (r1.has_return == covered).mean()
    agree = (lut[r1.cell_rc[covered, 0], r1.cell_rc[covered, 1]] == owner[covered]).mean()
    print(f"footprint 1 px: same pixels shown {100 * same:.3f} %, same cell {100 * agree:.3f} %")
    assert same > 0.9999 and agree > 0.999

    # (c) the sky above the top beam: no return there.
    top_el = np.nanmax(np.degrees(np.arcsin(depth.points[..., 2] / depth.range_m)))
    v_sky = int(K[1, 2] - K[1, 1] * np.tan(np.radians(top_el + 2.0)))
    assert v_sky > 50
    assert not shown[:v_sky].any() and np.isnan(r.range_m[:v_sky]).all() and (r.cell_rc[:v_sky] == -1).all()


@needs_kitti
def test_kitti_cli_npz_png_and_errors(kitti, tmp_path):
    depth, camera, K, T = kitti
    common = ["render", "--scan", str(KITTI_BIN), "--camera", str(KITTI_CAMERA), "--extrinsics", str(KITTI_CALIB)]
    npz = tmp_path / "view.npz"
    run = run_cli(*common, "-o", str(npz))
    assert run.returncode == 0, run.stderr
    with np.load(npz) as data:
        assert set(data.files) == {"range_m", "cell_rc", "camera_depth_m"}
        rng, cells, cam = data["range_m"], data["cell_rc"], data["camera_depth_m"]
    assert rng.shape == (375, 1242) and rng.dtype == np.float32
    assert cells.shape == (375, 1242, 2) and cells.dtype == np.int32
    assert cam.shape == (375, 1242) and cam.dtype == np.float32
    # load_extrinsics_any reads a KITTI calib file's Tr_velo_to_cam (what --extrinsics promises).
    T_file = load_extrinsics_any(KITTI_CALIB)
    in_process = render_from_camera(depth, camera, T_file)
    np.testing.assert_array_equal(cells, in_process.cell_rc)
    np.testing.assert_array_equal(np.isnan(rng), cells[..., 0] < 0)

    png = tmp_path / "view.png"
    run = run_cli(*common, "--mode", "intensity", "-o", str(png))
    assert run.returncode == 0, run.stderr
    bgra = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    assert bgra.shape == (375, 1242, 4)
    np.testing.assert_array_equal(bgra[..., 3] == 0, cells[..., 0] < 0)  # no return: alpha 0
    assert (bgra[cells[..., 0] < 0] == 0).all()
    run = run_cli(*common, "--mode", "ba", "--ba-direction", "vertical", "-o", str(tmp_path / "ba.png"))
    assert run.returncode == 0, run.stderr

    for bad, fragment in ((["-o", str(tmp_path / "view.jpg")], ".png"),
                          (["-o", str(tmp_path / "v.npz"), "--extrinsics", str(tmp_path / "none.yaml")],
                           "not found")):
        run = run_cli(*common, *bad)
        assert run.returncode == 2, run.stderr
        lines = [ln for ln in run.stderr.splitlines() if ln.startswith("error:")]
        assert len(lines) == 1 and fragment in lines[0], run.stderr
        assert "Traceback" not in run.stderr


# ------------------------------------------------------------------ the sample: OCam, against the room's mesh
def test_sample_render_against_the_scene_mesh(tmp_path):
    from calib_core.synthetic.render import cast
    from calib_core.synthetic.sample import load_sample

    scene = load_sample(SAMPLE)
    camera, T, depth = scene.camera, scene.T_camera_lidar, scene.depth
    t0 = time.perf_counter()
    r = render_from_camera(depth, camera, T)
    seconds = time.perf_counter() - t0

    step = 2
    v, u = np.mgrid[0:camera.height:step, 0:camera.width:step]
    rays_cam = camera.bearing(np.stack([u.ravel(), v.ravel()], axis=1).astype(float))
    # Inside the image circle (230 px) and in front: where the photo sees the room.
    radius = np.hypot(u.ravel() - 318.6, v.ravel() - 242.3)
    use = np.isfinite(rays_cam).all(axis=1) & (rays_cam[:, 2] > 0.2) & (radius < 225)
    R, t = T[:3, :3], T[:3, 3]
    T_wl = scene.T_world_lidar
    centre_w = T_wl[:3, :3] @ (-R.T @ t) + T_wl[:3, 3]
    dirs_w = rays_cam[use] @ (T_wl[:3, :3] @ R.T).T
    dist, face = cast(scene.room, np.repeat(centre_w[None], use.sum(), axis=0), dirs_w)
    truth = np.full(u.size, np.nan)
    truth[np.nonzero(use)[0]] = np.where(face >= 0, dist, np.nan)
    got = r.camera_depth_m[v.ravel(), u.ravel()]
    has_truth = np.isfinite(truth)
    both = has_truth & np.isfinite(got)
    rel = np.abs(got[both] - truth[both]) / truth[both]
    coverage = both.sum() / has_truth.sum()
    print(f"\nsample (OCam): coverage inside the image circle {100 * coverage:.2f} %, camera distance vs mesh: "
          f"median {100 * np.median(rel):.3f} %, within 5 %: {100 * (rel < 0.05).mean():.1f} %; "
          f"render {1000 * seconds:.0f} ms")
    assert coverage > 0.97
    assert np.median(rel) < 0.02
    assert (rel < 0.05).mean() > 0.95

    # The CLI on the sample (OCam path): NPZ and PNG agree with each other.
    npz, png = tmp_path / "s.npz", tmp_path / "s.png"
    common = ["render", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
              "--extrinsics", str(SAMPLE / "ground_truth.yaml")]
    for out in (npz, png):
        run = run_cli(*common, "-o", str(out))
        assert run.returncode == 0, run.stderr
    with np.load(npz) as data:
        cells = data["cell_rc"]
    bgra = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    assert cells.shape == (480, 640, 2) and bgra.shape == (480, 640, 4)
    np.testing.assert_array_equal(bgra[..., 3] == 0, cells[..., 0] < 0)
