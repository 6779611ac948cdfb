"""Guided picking in the app on a real scan: PJLab auto_calib (64 x 1800 lidar, 1920 x 1200 photo), ../shared/data.

The app starts from the published extrinsic turned by 2 deg and shifted by 20 cm, with no pair.  Issue 20:
proposals from that pose alone are not offered -- the imported extrinsic's 3-sigma ellipses (1 deg and 5 cm a
priori, about 110 px here) do not fit the camera loupe -- and the panel says to do a better rough alignment
first.  The simulated person then makes 5 rough pairs by eye (cells of real_data/pairs/auto_calib_pairs.yaml,
pixels 5-15 px off their projection under the *published* calibration, clicked on the full image), and
presses "Next pair" again; for each proposal they click its true projection -- the proposed cell's laser point
projected with the published calibration (not ground truth, but what careful clicks would match) -- with 0.5 px
noise in the camera loupe.  Where the loupe (framed on the prediction, zoomed out to show the ellipse) does not
show that pixel, the person first clicks the full camera image near it (1 px noise, whole pixels), then places
it in the loupe.  Every guided click and button press counts as an action.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from calib_core.pairs import load_pairs_yaml
from calib_core.transforms import rotation_angle_deg, transform_points

ROOT = Path(__file__).resolve().parents[1]
PJLAB = ROOT.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "auto_calib"
PAIRS = ROOT / "real_data" / "pairs" / "auto_calib_pairs.yaml"
N_GUIDED = 12
#: Fewest guided pairs the screen must offer here (it proposes only clear corners, issue 20).  5 since stop 28:
#: a new cell's 3-sigma ellipse must fit the loupe unzoomed, which on KITTI kept only proposals at a clean photo
#: corner (docs/perf/guide_clean_corners.md); here fewer new cells pass, so more of the guided pairs are re-clicks.
MIN_GUIDED = 5
#: Most actions per guided pair: a new cell takes one click, a re-click "Next pair" and a click.
MAX_ACTIONS_PER_PAIR = 2.0


def rough_extrinsic(T: np.ndarray, degrees: float = 2.0, metres: float = 0.20) -> np.ndarray:
    """``T`` turned by ``degrees`` about a fixed oblique axis and shifted by ``metres``."""
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    shift = np.array([1.0, -1.0, 0.5]) / np.linalg.norm([1.0, -1.0, 0.5])
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(np.radians(degrees) * axis).as_matrix() @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + metres * shift
    return out


@pytest.mark.realdata
@pytest.mark.skipif(not (PJLAB / "calib.pcd").is_file(), reason=f"real data not found at {PJLAB} (../shared/data)")
def test_guided_pairs_on_the_real_scan_from_a_rough_extrinsic(tmp_path):
    from app.server import CalibrationApp
    from app_driver import AppDriver

    doc = json.loads((PJLAB / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    published = np.array(doc["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], float)
    rough_path = tmp_path / "rough.yaml"
    rough_path.write_text(yaml.safe_dump({"T_camera_lidar": {"matrix": rough_extrinsic(published).tolist()}}))
    app = CalibrationApp(PJLAB / "calib.pcd", PJLAB / "calib.png", PJLAB / "center_camera-intrinsic.json",
                         session_path=tmp_path / "session.yaml", port=0, initial_extrinsics_path=rough_path)
    d = AppDriver(app)
    rng = np.random.default_rng(0)
    try:
        # The rough extrinsic alone: no proposal fits the loupe, and the panel says what to do.
        assert d.press_guide("Next pair") == [] and d.wait_guide()
        assert d.guide_proposal is None and app.state.pending() is None
        assert "do a better rough alignment first" in d.guide_panel
        # 5 rough pairs by eye, 5-15 px off.
        for pair in [load_pairs_yaml(PAIRS)[i] for i in rng.choice(11, size=5, replace=False)]:
            uv, _ = app.camera.project(transform_points(published, app.depth.points[pair.laser_rc][None]))
            angle, length = rng.uniform(0, 2 * np.pi), rng.uniform(5.0, 15.0)
            assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == []
            assert d.click_camera(*(uv[0] + length * np.array([np.cos(angle), np.sin(angle)]))) == []
        assert d.wait_idle() and len(app.state.complete_picks()) == 5
        assert d.press_guide("Next pair") == [] and d.wait_guide()
        actions, two_click = 1, 0
        made = 0
        for k in range(N_GUIDED):
            proposal, half = d.guide_proposal, app.state.pending()
            if proposal is None:  # the screen proposes only clear corners: they may run out
                break
            made += 1
            if proposal.replaces is not None and app.state.selected is None:  # run 5: Next pair selects it
                assert d.press_guide("Next pair") == [] and d.wait_guide() and d.guide_proposal == proposal
                actions += 1
            if proposal.replaces is not None:  # a re-click: the pair is selected, the click moves its pixel
                half = app.state.get(app.state.selected)
            assert half is not None and half.laser_rc == tuple(proposal.laser_rc)
            # The camera loupe, framed on the prediction, shows the whole 3-sigma ellipse.
            assert app.loupes.camera_crop.n >= 2 * proposal.radius_3sigma_px
            pix, ok = app.camera.project(transform_points(published, np.asarray(proposal.laser_xyz, float)[None]))
            assert ok[0]
            click = pix[0] + rng.normal(0.0, 0.5, 2)
            if d.loupe_display_pixel("camera", click) is None:  # not in the loupe: find it on the full image
                assert d.click_camera(*np.round(click + rng.normal(0.0, 1.0, 2))) == [] and d.wait_guide()
                actions, two_click = actions + 1, two_click + 1
            assert d.click_loupe_camera(*click) == [] and d.wait_guide()
            actions += 1
            done = app.state.get(half.id)
            # A re-click refines the hand pair: it keeps its source ("clicked"), with the guided click's precision.
            source = "clicked" if proposal.replaces is not None else "guided"
            assert done.complete and done.source == source and done.precision_px == pytest.approx(0.3)
        assert d.wait_idle()
        T = app.result.T_camera_lidar
    finally:
        app.stop()
    rot = rotation_angle_deg(T[:3, :3], published[:3, :3])
    trans = float(np.linalg.norm(T[:3, 3] - published[:3, 3]))
    print(f"\nPJLab auto_calib from 5 rough pairs (5-15 px): {made} guided pairs in {actions} actions "
          f"({actions / max(made, 1):.2f} per pair; {two_click} needed a full-image click first); "
          f"{rot:.3f} deg, {100 * trans:.2f} cm from the published calibration")
    # Issue 9's real-scene target (there with 5 rough + 20 guided pairs): within 0.1 deg and 5 cm.
    assert rot <= 0.1 and trans <= 0.05
    assert made >= MIN_GUIDED and actions / made <= MAX_ACTIONS_PER_PAIR
