"""Guided picking in the app (issue 9), driven through :class:`app_driver.AppDriver` on the committed sample.

The simulated person clicks, for each proposal, its true projection -- the
proposed cell's laser point projected with the sample's ground-truth
extrinsic (sample_data/ground_truth.yaml) -- plus 0.3 px Gaussian noise per
axis, the click noise issue 9 assumes for a magnified, known target.
"""

from __future__ import annotations


import numpy as np
import pytest
import yaml

from calib_core.errors import CalibError
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks
from calib_core.transforms import rotation_angle_deg, transform_points

from app.state import AnnotationState
from app_driver import AppDriver, sample_app
from repo_paths import SAMPLE

N_GUIDED = 10
CLICK_SIGMA_PX = 0.3
# Issue 9's Cramer-Rao bound for the sample at 10 pairs of 0.3 px clicks (whole-cell laser picks): 0.22 deg and
# 0.83 cm.  Here the 10 guided clicks leave at least 10 pairs of 0.3 px or better (the 4 clicked at true pixels,
# some re-clicked in the loupe, and the new guided ones, whose laser points are the clicked cells' own), so the
# bound is no larger; one run's error exceeds twice the bound's RMS with < 1 % probability (chi-square, 3 dof:
# P(> 12) = 0.7 %).
MAX_ROT_DEG = 2 * 0.22
MAX_TRANS_M = 2 * 0.0083


def pose_error(T, truth) -> tuple[float, float]:
    return float(rotation_angle_deg(T[:3, :3], truth[:3, :3])), float(np.linalg.norm(T[:3, 3] - truth[:3, 3]))


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


@pytest.fixture(scope="module")
def truth():
    return load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]


@pytest.fixture
def app(tmp_path):
    a = sample_app(tmp_path / "session.yaml")
    yield a
    a.stop()


def true_click(scene, truth, proposal, rng) -> np.ndarray:
    """The simulated person's click: the proposed laser point's true projection + 0.3 px noise."""
    pix, ok = scene.camera.project(transform_points(truth, np.asarray(proposal.laser_xyz, dtype=float)[None]))
    assert ok[0], f"proposal {proposal.laser_rc} does not project into the image"
    return np.asarray(pix[0], dtype=float) + rng.normal(0.0, CLICK_SIGMA_PX, 2)


def shown_target(app, d: AppDriver) -> int:
    """The pick the next camera click goes to, checked against the shown proposal: a new pair's guided half pick
    at the proposed cell, or for a re-click the rough pair (selected) at that cell."""
    proposal = d.guide_proposal
    assert proposal is not None
    if proposal.replaces is not None and app.state.selected is None:  # run 5: Next pair selects it
        assert d.press_guide("Next pair") == [] and d.wait_guide() and d.guide_proposal == proposal
    if proposal.replaces is not None:
        rid = app.state.selected
        assert rid is not None and app.state.pending() is None
        assert app.state.get(rid).laser_rc == tuple(proposal.laser_rc)
        return rid
    half = app.state.pending()
    assert half is not None and half.laser_rc == tuple(proposal.laser_rc)
    assert half.source == "guided" and half.pixel is None
    return half.id


def skip_reclicks(d: AppDriver) -> None:
    """Press Skip until the shown proposal is a new pair (re-clicks are tested in the first test)."""
    for _ in range(N_PROPOSALS_MAX):
        if d.guide_proposal.replaces is None:
            return
        assert d.press_guide("Skip") == [] and d.wait_guide()
    pytest.fail("only re-click proposals")


N_PROPOSALS_MAX = 20


def click_start_pairs(driver: AppDriver, scene) -> None:
    """4 clicks at ground-truth corner pairs: the cell nearest each corner and its true pixel."""
    for pair in simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=0.0):
        assert driver.click_cell(driver.app.ba_keys[0], *pair.laser_rc) == []
        assert driver.click_camera(*pair.pixel) == []


def test_guided_pairs_beat_the_start_and_keep_their_tags(app, scene, truth, tmp_path):
    d = AppDriver(app)
    rng = np.random.default_rng(11)
    click_start_pairs(d, scene)
    assert d.wait_idle() and d.wait_guide()
    err4 = pose_error(app.result.T_camera_lidar, truth)

    assert d.press_guide("Next pair") == []
    assert d.wait_guide()
    cells, reclicked, sides = [], set(), []
    for k in range(N_GUIDED):
        proposal = d.guide_proposal
        assert proposal is not None
        if proposal.replaces is not None and app.state.selected is None:  # run 5: Next pair selects it
            assert d.press_guide("Next pair") == [] and d.wait_guide() and d.guide_proposal == proposal
        cells.append(tuple(proposal.laser_rc))
        # The loupes are framed on the cell and on the predicted pixel; the camera loupe shows the whole
        # 3-sigma ellipse (zoomed out when it is larger), which the screen keeps within the app's limit.
        assert tuple(d.loupe_view("ba")["center"]) == tuple(proposal.laser_rc)
        assert np.allclose(d.loupe_view("camera")["center"], proposal.pixel, atol=0.5)
        radius = 3.0 * np.sqrt(np.linalg.eigvalsh(proposal.pixel_cov).max())
        assert d.loupe_view("camera")["size"] >= 2 * radius and radius <= app.guide.screen.max_ellipse_px
        # The zoom stays steady between proposals: the loupe's side grows only when an ellipse needs more.
        sides.append(d.loupe_view("camera")["size"])
        assert sides[-1] >= max(sides[:-1], default=0)
        if len(sides) > 1 and sides[-1] > sides[-2]:
            assert 2 * radius + 4.0 > sides[-2]
        click = true_click(scene, truth, proposal, rng)
        if proposal.replaces is not None:
            # A re-click of a rough pair: that pair is selected, and the click moves its pixel.
            rid = app.state.selected
            assert rid is not None and app.state.pending() is None
            assert app.state.get(rid).laser_rc == tuple(proposal.laser_rc) and f"re-click of pair {rid}" in d.guide_panel
            assert d.click_loupe_camera(*click) == [] and d.wait_guide()
            target = app.state.get(rid)
            reclicked.add(rid)
            # Deselected, also when the next proposal is another re-click (Next pair selects it).
            assert app.state.selected is None
        else:
            # "Next pair" (then each finished pair) started a guided half pick at the shown proposal's cell.
            half = app.state.pending()
            assert half is not None and half.laser_rc == tuple(proposal.laser_rc) and half.pixel is None
            assert half.source == "guided" and f"cell (row {proposal.laser_rc[0]}, col {proposal.laser_rc[1]})" in d.guide_panel
            # One click in the camera loupe completes the pair.
            assert d.click_loupe_camera(*click) == [] and d.wait_guide()
            target = app.state.get(half.id)
        # A re-click refines a hand pair: it keeps its source ("clicked") and gets the guided click's precision.
        source = "clicked" if proposal.replaces is not None else "guided"
        assert target.complete and target.source == source and target.precision_px == pytest.approx(CLICK_SIGMA_PX)
        assert np.allclose(target.pixel, click, atol=0.05)
    assert d.wait_idle()
    err = pose_error(app.result.T_camera_lidar, truth)
    print(f"\nerror after 4 clicks: {err4[0]:.3f} deg, {100 * err4[1]:.2f} cm; after {N_GUIDED} guided clicks: "
          f"{err[0]:.3f} deg, {100 * err[1]:.2f} cm (bound {MAX_ROT_DEG:.2f} deg, {100 * MAX_TRANS_M:.2f} cm)")
    # For the record: how many proposed cells a person would find on a real scene corner (within 2 cells of a
    # corner's whole-cell pick); the others would cost a "Not a corner" press in practice.
    pick_rc, pick_err = laser_picks(scene.depth, np.asarray(scene.corners_lidar))
    usable = pick_rc[pick_err <= MAX_LASER_PICK_ERROR_M]
    on_corner = sum(bool((np.abs(usable - c).max(axis=1) <= 2).any()) for c in cells)
    print(f"{on_corner} of {N_GUIDED} proposed cells lie within 2 cells of a true scene corner")
    assert err[0] < err4[0] and err[1] < err4[1]
    assert err[0] <= MAX_ROT_DEG and err[1] <= MAX_TRANS_M

    # Tags reach the solve's pairs and survive a reload of the session file.
    complete = app.state.complete_picks()
    n_new = N_GUIDED - len(reclicked)
    print(f"{N_GUIDED} guided clicks: {n_new} new pairs, {len(reclicked)} re-clicks of the 4 clicked pairs")
    assert len(complete) == 4 + n_new >= N_GUIDED
    assert [p.source for p in complete] == ["clicked"] * 4 + ["guided"] * n_new
    again = f" ({len(reclicked)} re-clicked by guidance)" if reclicked else ""
    assert f"Pairs: 4 clicked{again}, {n_new} guided" in d.guide_panel
    assert all(p.precision_px == pytest.approx(CLICK_SIGMA_PX) for p in complete
               if p.source == "guided" or p.id in reclicked)
    assert [(p.source, p.precision_px) for p in app.state.pairs()] == [(p.source, p.precision_px) for p in complete]
    before = {p.id: (p.source, p.precision_px, p.laser_rc, p.pixel) for p in app.state.picks}
    valid, size = app.depth.valid, (app.camera.width, app.camera.height)
    app.stop()
    again = AnnotationState(valid, size, tmp_path / "session.yaml")
    try:
        assert {p.id: (p.source, p.precision_px, p.laser_rc, p.pixel) for p in again.picks} == before
    finally:
        again.close()


def test_skip_not_a_corner_undo(app, scene, truth):
    d = AppDriver(app)
    # Before a calibration exists the panel refuses and says why.
    notes = d.press_guide("Next pair")
    assert notes and "4 pairs" in notes[0][1]
    click_start_pairs(d, scene)
    assert d.wait_guide()
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    skip_reclicks(d)
    first = d.guide_proposal
    half_id = shown_target(app, d)

    # Skip: the next proposal is framed (a new pair moves the same half pick); the skipped one comes back last.
    assert d.press_guide("Skip") == [] and d.wait_guide()
    second = d.guide_proposal
    assert tuple(second.laser_rc) != tuple(first.laser_rc)
    assert shown_target(app, d) == half_id or second.replaces is not None
    # Not a corner: that cell is dropped for good (also after the proposals are recomputed).
    assert d.press_guide("Not a corner") == [] and d.wait_guide()
    skip_reclicks(d)
    third = d.guide_proposal
    assert tuple(third.laser_rc) not in (tuple(first.laser_rc), tuple(second.laser_rc))
    shown_target(app, d)

    # Complete it, then undo: the guided tag stays with the half pick the undo brings back.
    assert d.click_loupe_camera(*true_click(scene, truth, third, np.random.default_rng(0))) == [] and d.wait_guide()
    assert tuple(second.laser_rc) not in [tuple(p.laser_rc) for p in app.guide.proposals]
    n_complete = len(app.state.complete_picks())
    while app.state.pending() is not None:  # the next guided half, started by itself
        assert d.press_edit("Undo") == []
    assert d.press_edit("Undo") == [] and d.wait_guide()
    assert len(app.state.complete_picks()) == n_complete - 1
    back = app.state.pending()
    assert back.laser_rc == tuple(third.laser_rc) and back.pixel is None and back.source == "guided"

    # Stop removes the half pick, the proposal's ellipse and its text, and leaves the pairs.
    assert app.loupes.camera_crop.cov_px2 is not None and "Proposal " in d.guide_panel
    assert d.press_guide("Stop") == [] and d.wait_guide()
    assert app.state.pending() is None and len(app.state.complete_picks()) == n_complete - 1
    assert app.loupes.camera_crop.cov_px2 is None and len(d.drawn_segment_pixels("/annot/loupe/ellipse",
                                                                                  "loupe_camera")) == 0
    assert "Proposal " not in d.guide_panel and "Next pair" in d.guide_panel


def test_sessions_without_tags_load_and_bad_tags_are_refused(tmp_path):
    valid = np.ones((10, 20), dtype=bool)
    old = {"format": "ba-calib-session", "version": 1, "next_id": 3, "view": {},
           "pairs": [{"id": 1, "laser_rc": [2, 3], "laser_xyz": None, "pixel": [10.0, 20.0]},
                     {"id": 2, "laser_rc": [4, 5], "laser_xyz": None, "pixel": None}]}
    path = tmp_path / "old.yaml"
    path.write_text(yaml.safe_dump(old))
    state = AnnotationState(valid, (100, 80), path)
    try:
        assert [(p.source, p.precision_px) for p in state.picks] == [("clicked", None), ("clicked", None)]
        assert state.pairs()[0].source == "clicked" and state.pairs()[0].precision_px is None
    finally:
        state.close()
    for bad, word in (({"source": "magic"}, "source"), ({"precision_px": -1.0}, "precision_px")):
        doc = dict(old, pairs=[dict(old["pairs"][0], **bad)])
        path.write_text(yaml.safe_dump(doc))
        with pytest.raises(CalibError, match=word) as info:
            AnnotationState(valid, (100, 80), path)
        assert "\n" not in str(info.value)


def test_auto_accept_tags_pairs_and_an_undo_sticks(app, scene, truth):
    from calib_core.guide.auto_accept import AutoGate
    from calib_core.guide.image_corners import CornerGate

    d = AppDriver(app)
    click_start_pairs(d, scene)
    assert d.wait_guide()
    # The shipped strict gate accepts no proposal on the sample (docs/guide_performance.md), so the plumbing is
    # exercised with bench/guide.py's "loose" gate; its matches are often wrong, which is why it is not shipped.
    app.guide.auto_gate = AutoGate(max_ellipse_px=9.0, min_laser_strength=0.5, min_contrast=0.0,
                                   corner=CornerGate(min_strength=0.01, min_ratio=0.3, isolation=0.3,
                                                     isolation_radius_px=6.0))
    assert d.set_auto_accept(True) == [] and d.wait_guide()
    auto = [p for p in app.state.complete_picks() if p.source == "auto"]
    assert auto, "the loose gate accepted nothing"
    assert all(p.precision_px is not None and p.precision_px > CLICK_SIGMA_PX for p in auto)
    app.state.flush_session()
    saved = yaml.safe_load(app.session_path.read_text())["pairs"]
    assert sorted(e["id"] for e in saved if e.get("source") == "auto") == sorted(p.id for p in auto)
    n = len(app.state.complete_picks())
    # One undo removes the last auto batch, and the same cells are not accepted again.
    assert d.press_edit("Undo") == [] and d.wait_guide()  # the undo is a change: the proposals were recomputed
    left = app.state.complete_picks()
    print(f"\nloose gate: {len(auto)} pairs auto-accepted, {len(left)} pairs left after one undo")
    assert 4 <= len(left) < n


def test_guided_from_an_imported_initial_extrinsic(app, scene, truth, tmp_path):
    from calib_core.io.extrinsics import save_extrinsics_yaml
    from calib_core.transforms import R_from_rpy_deg

    d = AppDriver(app)
    # A rough start: the truth turned by 0.5 deg about each axis and moved 3 cm.
    rough = truth.copy()
    rough[:3, :3] = R_from_rpy_deg(np.array([0.5, -0.5, 0.5])) @ truth[:3, :3]
    rough[:3, 3] += [0.03, -0.01, 0.01]
    save_extrinsics_yaml(tmp_path / "rough.yaml", rough)
    assert not [n for n in d.upload_initial_extrinsics("rough.yaml", (tmp_path / "rough.yaml").read_bytes())
                if n[0] != "Initial extrinsics imported"]
    # No pair yet: the import alone makes guided picking available (the panel says so, no button pressed).
    assert d.wait_guide() and "Starts after" not in d.guide_panel and "Next pair" in d.guide_panel
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    rng = np.random.default_rng(2)
    for k in range(6):
        proposal, target = d.guide_proposal, shown_target(app, d)
        assert d.click_loupe_camera(*true_click(scene, truth, proposal, rng)) == [] and d.wait_guide()
        assert app.state.get(target).precision_px == pytest.approx(CLICK_SIGMA_PX)
    assert d.wait_idle()
    picks = app.state.complete_picks()
    assert len(picks) >= 4 and all(p.source == "guided" for p in picks)
    err = pose_error(app.result.T_camera_lidar, truth)
    print(f"\nfrom a 0.87 deg / 3.3 cm initial extrinsic, 6 guided pairs: {err[0]:.3f} deg, {100 * err[1]:.2f} cm")
    assert err[0] < pose_error(rough, truth)[0] and err[1] < pose_error(rough, truth)[1]


def test_a_full_image_click_waits_for_the_loupe(app, scene, truth):
    d = AppDriver(app)
    click_start_pairs(d, scene)
    assert d.wait_guide() and d.press_guide("Next pair") == [] and d.wait_guide()
    skip_reclicks(d)
    proposal, half = d.guide_proposal, app.state.pending()
    click = true_click(scene, truth, proposal, np.random.default_rng(4))
    # A click on the full camera image completes the pair, but only at the default precision, and the next
    # proposal waits: the loupe (now on the click) is where the pixel is placed precisely.
    assert d.click_camera(*np.round(click)) == [] and d.wait_guide()
    pick = app.state.get(half.id)
    assert pick.complete and pick.source == "guided" and pick.precision_px is None
    assert app.state.pending() is None and f"Pair {half.id}: refine" in d.guide_panel
    # The click in the camera loupe refines the same pair (0.3 px again) and the next pair is framed.
    assert d.click_loupe_camera(*click) == [] and d.wait_guide()
    pick = app.state.get(half.id)
    assert np.allclose(pick.pixel, click, atol=0.05) and pick.precision_px == pytest.approx(CLICK_SIGMA_PX)
    assert shown_target(app, d) != half.id


def test_guided_picking_waits_for_a_reliable_calibration(app, scene, truth):
    """While the live solve's verdict is "unreliable", "Next pair" refuses and the panel says why; once the
    pairs are fixed, guided picking starts."""
    from calib_core.solve import calibrate

    d = AppDriver(app)
    pairs = simulate_pairs(scene, 4, np.random.default_rng(3), pixel_noise_px=0.0)
    wrong = np.asarray(pairs[3].pixel) + [60.0, 40.0]  # a click 72 px off its corner
    for k, pair in enumerate(pairs):
        assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == []
        assert d.click_camera(*(wrong if k == 3 else pair.pixel)) == []
    assert d.wait_idle()
    # The verdict of these pairs, solved here: 3 agree, the fourth is left out, so it cannot be trusted.
    expected = calibrate(app.state.pairs(), scene.depth, scene.camera).quality
    assert expected.status == "unreliable" and app.result.quality.status == "unreliable"
    notes = d.press_guide("Next pair")
    assert len(notes) == 1 and "reliable calibration" in notes[0][1] and expected.reasons[0] in notes[0][1]
    assert d.wait_guide() and app.state.pending() is None and d.guide_proposal is None
    assert "UNRELIABLE" in d.guide_panel and expected.reasons[0] in d.guide_panel
    # The wrong click undone and made at the corner: the calibration can be trusted, guided picking starts.
    assert d.press_edit("Undo") == [] and d.click_camera(*pairs[3].pixel) == [] and d.wait_idle()
    assert app.result.quality.status != "unreliable"
    assert d.press_guide("Next pair") == [] and d.wait_guide()
    half = app.state.pending()
    assert d.guide_proposal is not None and "UNRELIABLE" not in d.guide_panel
    assert (half is not None and half.laser_rc == tuple(d.guide_proposal.laser_rc)) or app.state.selected is not None


def test_the_camera_loupe_draws_the_ellipse_inside_itself(app, scene, truth):
    """An ellipse larger than the loupe's view (a proposal's ellipse grown to a 3-sigma radius of 0.65 times the
    loupe's side) is drawn only where the loupe shows it, not across the page."""
    d = AppDriver(app)
    click_start_pairs(d, scene)
    assert d.wait_guide() and d.press_guide("Next pair") == [] and d.wait_guide()
    p = d.guide_proposal
    n = d.loupe_view("camera")["size"]
    app.loupes.frame_camera(*p.pixel, cov_px2=(0.65 * n / p.radius_3sigma_px) ** 2 * np.asarray(p.pixel_cov))
    crop = app.loupes.camera_crop
    # The ellipse (computed here from the covariance) reaches beyond the crop the loupe shows now.
    w, V = np.linalg.eigh(np.asarray(crop.cov_px2))
    t = np.linspace(0, 2 * np.pi, 200)
    outline = np.asarray(crop.center) + (3 * np.sqrt(w) * np.stack([np.cos(t), np.sin(t)], 1)) @ V.T
    local = outline - [crop.u0, crop.v0]
    assert ((local < -0.5) | (local > crop.n - 0.5)).any()
    drawn = d.drawn_segment_pixels("/annot/loupe/ellipse", "loupe_camera").reshape(-1, 2)
    assert len(drawn) > 0
    assert np.all((drawn >= -0.5 - 1e-6) & (drawn <= crop.n - 0.5 + 1e-6))
