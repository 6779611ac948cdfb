"""The app's Verify panel and robotics-format export, driven through app_driver.AppDriver.

Truth is independent of the panels: errors are recomputed here from the
camera model and refits with calib_core.solve, exported files are parsed by
tests/test_extrinsic_formats.py's own format readers, and session files are
read back as plain YAML.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from test_extrinsic_formats import CAMERA, LIDAR, independent_T_camera_lidar

from app.server import CalibrationApp
from app_driver import AppDriver
from app.verify_panel import heat_overlay
from calib_core.io.extrinsic_formats import FORMATS, export_extrinsics
from calib_core.pairs import load_pairs_yaml, resolve_pairs
from calib_core.solve import solve_extrinsics
from calib_core.transforms import rotation_angle_deg
from repo_paths import SAMPLE

PAIRS = (SAMPLE / "pairs.yaml").read_bytes()


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("verify_app")
    a = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                       session_path=tmp / "session.yaml", output_path=tmp / "extrinsics.yaml", port=0)
    yield a
    a.stop()


@pytest.fixture()
def driver(app):
    d = AppDriver(app)
    notes = d.upload_pairs("pairs.yaml", PAIRS, answer="Replace all")
    assert notes and notes[-1][0] == "Pairs imported", notes
    assert d.wait_verified(timeout=120.0)  # generous: the machine is shared
    assert len(app.state.complete_picks()) == 10
    return d


def load_extrinsics_any_text(data: bytes) -> np.ndarray:
    from calib_core.io.extrinsic_formats import parse_extrinsics

    return parse_extrinsics(data.decode()).T_camera_lidar


def _project(camera, T, points):
    uv, ok = camera.project(points @ T[:3, :3].T + T[:3, 3])
    return np.asarray(uv, dtype=np.float64), np.asarray(ok, bool)


def _table_rows(table: str) -> dict[int, tuple[str, float, float]]:
    rows = {}
    for m in re.finditer(r"^\| (\d+) \| (\w+) \| ([0-9.]+|n/a) \| ([0-9.]+|n/a) \|$", table, re.MULTILINE):
        rows[int(m.group(1))] = (m.group(2), float(m.group(3).replace("n/a", "nan")), float(m.group(4).replace("n/a", "nan")))
    return rows


def test_check_pair_is_left_out_and_its_error_is_reported(app, driver, tmp_path):
    pid = app.state.picks[3].id
    assert driver.mark_check_pair(pid) == []
    assert driver.wait_verified()
    pairs = load_pairs_yaml(SAMPLE / "pairs.yaml")
    points, bearings, pixels = resolve_pairs(pairs, app.depth, app.camera)
    keep = np.arange(len(pairs)) != 3
    # The app's pose is the fit without the check pair: its residuals against the other 9 are
    # smaller than those of the fit that includes it, and its error is the check pair's pixel distance.
    T = app.result.T_camera_lidar
    assert app.result.n_pairs == 9
    uv, ok = _project(app.camera, T, points[3:4])
    check_px = float(np.linalg.norm(uv[0] - pixels[3]))
    m = re.search(r"Check pairs: mean ([0-9.]+) px", driver.verify_summary)
    assert m and float(m.group(1)) == pytest.approx(check_px, abs=0.006), driver.verify_summary
    rows = _table_rows(driver.verify_table)
    assert rows[pid][0] == "check" and rows[pid][1] == pytest.approx(check_px, abs=0.006)
    assert f"| {pid} |" in driver.residual_table and "no: check pair" in driver.residual_table
    # A refit on the 9 fit pairs alone puts that pair where the app says.
    alone = solve_extrinsics(points[keep], bearings[keep], camera=app.camera, pixels=pixels[keep]).T_camera_lidar
    uv_alone, _ = _project(app.camera, alone, points[3:4])
    assert np.linalg.norm(uv_alone[0] - pixels[3]) == pytest.approx(check_px, rel=0.05)
    # Saved in the session (plain YAML, additive field), and undoable.
    app.state.flush_session()
    saved = yaml.safe_load(app.session_path.read_text())
    assert [e.get("check", False) for e in saved["pairs"]] == [i == 3 for i in range(10)]
    driver.press_edit("Undo")
    assert not app.state.picks[3].check
    driver.mark_check_pair(pid)
    assert driver.mark_check_pair(pid, check=False) == [] and not app.state.picks[3].check


def test_leave_one_out_is_the_refit_without_the_pair(app, driver):
    pairs = load_pairs_yaml(SAMPLE / "pairs.yaml")
    points, bearings, pixels = resolve_pairs(pairs, app.depth, app.camera)
    rows = _table_rows(driver.verify_table)
    assert len(rows) == 10 and all(r[0] == "fit" for r in rows.values())
    ids = [p.id for p in app.state.picks]
    for i in (0, 5, 9):
        keep = np.arange(10) != i
        Ti = solve_extrinsics(points[keep], bearings[keep], camera=app.camera, pixels=pixels[keep],
                              initial_T_camera_lidar=app.result.T_camera_lidar).T_camera_lidar
        uv, _ = _project(app.camera, Ti, points[i:i + 1])
        assert rows[ids[i]][2] == pytest.approx(np.linalg.norm(uv[0] - pixels[i]), abs=0.006)
        assert rows[ids[i]][2] >= rows[ids[i]][1] - 0.006  # left out errs at least as much as in the fit
    mean = float(np.mean([r[2] for r in rows.values()]))
    m = re.search(r"Leave-one-out: mean ([0-9.]+) px", driver.verify_summary)
    assert m and float(m.group(1)) == pytest.approx(mean, abs=0.01)


def test_plots_show_the_pairs_the_counts_and_the_sigmas(app, driver):
    plots = driver.verify_plots()
    x, under, left = plots["pairs"]
    assert list(x) == [p.id for p in app.state.picks]
    rows = _table_rows(driver.verify_table)
    np.testing.assert_allclose(under, [rows[int(i)][1] for i in x], atol=0.006)
    np.testing.assert_allclose(left, [rows[int(i)][2] for i in x], atol=0.006)
    n, fit_px = plots["count"]  # no check pairs: one series
    assert list(n) == list(range(5, 11))
    assert fit_px[-1] == pytest.approx(app.result.mean_px, rel=0.05)
    k, st, sr = plots["sigma"]
    np.testing.assert_allclose(st, 100 * app.result.sigma_translation_m)
    np.testing.assert_allclose(sr, app.result.sigma_rpy_deg)
    # With a check pair the count plot gains the check pairs' series.
    driver.mark_check_pair(app.state.picks[0].id)
    assert driver.wait_verified()
    n, fit_px, chk_px = driver.verify_plots()["count"]
    assert list(n) == list(range(5, 10)) and np.all(chk_px > 0)


def test_heat_map_is_shown_where_scene_points_project():
    image = np.full((40, 60, 3), 128, np.uint8)
    heat = np.full((4, 6), np.nan)
    heat[0, 0], heat[3, 5] = 0.0, 2.0
    heat[1, 1] = 1.0
    out, top = heat_overlay(image, heat, width=60)
    assert out.shape == (40, 60, 3)
    assert np.array_equal(out[15, 25], image[15, 25])  # no scene point: the image itself
    low, high = out[2, 2].astype(int), out[38, 58].astype(int)
    assert low[2] > low[0] + 30 and high[0] > high[2] + 30  # 0 px blue, the top red
    assert top == pytest.approx(np.percentile([0.0, 1.0, 2.0], 98))


def test_heat_map_in_the_app(app, driver):
    cur = app.verify_panel.current
    assert cur is not None and np.isfinite(cur.heat_px).mean() > 0.05
    assert cur.heat_image.shape[1] == 480 and cur.heat_image.dtype == np.uint8
    assert "Expected reprojection error" in app.verify_panel.heat_text


def test_reference_comparison_in_degrees_cm_and_pixels(app, driver):
    T = app.result.T_camera_lidar
    ref = T.copy()
    ref[:3, :3] = Rotation.from_rotvec(np.radians(0.5) * np.array([0.0, 0.6, 0.8])).as_matrix() @ T[:3, :3]
    ref[:3, 3] += [0.02, 0.0, 0.0]
    text = export_extrinsics(ref, "kitti", "velodyne", "camera")
    notes = driver.upload_reference("ref_calib.txt", text.encode())
    assert notes and notes[0][0] == "Reference imported", notes
    assert driver.wait_verified()
    m = re.search(r"Reference ref\\?_calib\\?\.txt:\*\* rotation ([0-9.]+) deg, translation ([0-9.]+) cm; "
                  r"over the scene ([0-9.]+) px mean", driver.verify_summary)
    assert m, driver.verify_summary
    assert float(m.group(1)) == pytest.approx(rotation_angle_deg(ref[:3, :3], T[:3, :3]), abs=1e-3)
    assert float(m.group(2)) == pytest.approx(2.0, abs=0.005)
    # Half a degree moves the scene by several pixels on a 640-px-wide image.
    uv_a, ok_a = _project(app.camera, T, app.all_points_lidar[::50])
    uv_b, ok_b = _project(app.camera, ref, app.all_points_lidar[::50])
    both = ok_a & ok_b
    expected = float(np.linalg.norm(uv_a[both] - uv_b[both], axis=1).mean())
    assert float(m.group(3)) == pytest.approx(expected, rel=0.05)
    # A broken file: one line, the old reference stays.
    notes = driver.upload_reference("broken.json", b"{not json")
    assert notes and notes[0][0] == "Not accepted" and "broken.json" in notes[0][1] and "\n" not in notes[0][1]
    assert app.verify_panel.reference is not None
    app.verify_panel.set_reference(None)
    assert driver.wait_verified() and "Reference" not in driver.verify_summary


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_export_panel_formats_both_frame_orders(app, driver, fmt):
    T = app.result.T_camera_lidar
    for parent, child in ((LIDAR, CAMERA), (CAMERA, LIDAR)):
        name, data = driver.download_format(fmt, parent, child)
        assert name.endswith(FORMATS[fmt].suffix)
        assert data == export_extrinsics(T, fmt, parent, child).encode()
        back = independent_T_camera_lidar(fmt, data.decode(), parent)
        assert np.abs(back - T).max() < 1e-9
        assert "maps" in driver.export_direction


def test_export_panel_refuses_frames_it_cannot_tell_apart(app, driver):
    with pytest.raises(ValueError, match="cannot tell"):
        driver.download_format("urdf", "base", "sensor")
    assert "cannot tell" in driver.export_direction


def test_yaml_download_and_output_carry_the_verification_block(app, driver):
    pid = app.state.picks[1].id
    driver.mark_check_pair(pid)
    assert driver.wait_verified()
    data = driver.download_extrinsics_yaml()
    doc = yaml.safe_load(data)
    written = yaml.safe_load(app.output_path.read_text())
    for d in (doc, written):
        v = d["verification"]
        assert v["n_fit_pairs"] == 9 and v["n_check_pairs"] == 1 and v["check_pairs"][0]["id"] == pid
    got = load_extrinsics_any_text(data)
    assert np.array_equal(got, app.result.T_camera_lidar)
    rows = _table_rows(driver.verify_table)
    loo = {e["id"]: e["px"] for e in doc["verification"]["leave_one_out"]}
    assert set(loo) == {i for i, r in rows.items() if r[0] == "fit"}
    for i, px in loo.items():
        assert px == pytest.approx(rows[i][2], abs=0.006)


def test_marking_the_last_fit_pairs_is_refused(app, driver):
    ids = [p.id for p in app.state.picks]
    for pid in ids[:6]:
        assert driver.mark_check_pair(pid) == []
    notes = driver.mark_check_pair(ids[6])
    assert notes and "last 4 fit pairs" in notes[0][1]
    assert sum(p.check for p in app.state.picks) == 6
    # Fewer than 4 fit pairs (a pair deleted): not verified, and no stale figures are left on show.
    driver.select_in_dropdown(ids[7])
    driver.press_edit("Delete")
    assert driver.wait_verified()
    assert "Not verified" in driver.verify_summary and driver.verify_table == ""
    assert all(len(a) == 0 for plot in driver.verify_plots().values() for a in plot)
