"""Honest with few pairs (issue 20): no mean error shown where the residuals cannot measure it, one verdict in the
solve, the CLI, the YAML and the panel; and a panel drawn only in characters the page's fonts have.

Truth: the sample's ground truth and simulated clicks with a known noise; the chi-square law of the residuals
(scipy.stats, independent of the project's code); the Unicode database for the characters.
"""

from __future__ import annotations

import math
import unicodedata

import numpy as np
import pytest

from calib_core.pairs import Pair, load_pairs_yaml
from calib_core.solve import calibrate, solve_extrinsics
from calib_core.solve.quality import MIN_PAIRS_FOR_ERROR, NO_ERROR_ESTIMATE, error_estimate_reason
from calib_core.synthetic import load_sample
from app_driver.fakes import FakeGui
from repo_paths import SAMPLE

NO_ESTIMATE_4 = f"{NO_ERROR_ESTIMATE}: 4 pairs fit any pose closely; add pairs"


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


@pytest.fixture(scope="module")
def sample_pairs():
    return load_pairs_yaml(SAMPLE / "pairs.yaml")


def _panel_text(result, n: int) -> str:
    from app.calibration_panel import CalibrationPanel
    from app.ui_common import SolveBundle

    panel = CalibrationPanel(FakeGui())
    bundle = SolveBundle(pick_ids=list(range(1, n + 1)), pairs=[], result=result, pixels=np.zeros((n, 2)),
                         points_camera=np.zeros((n, 3)), edges_camera=np.zeros((0, 3)), seconds=0.01)
    panel.show(bundle, None, False, n)
    return panel.result_text + "\n" + panel.table_text


# --- the threshold, from the maths ------------------------------------------------------------------------------


def test_the_threshold_is_where_the_residuals_chi_square_stops_peaking_at_zero():
    """The residuals' SSR is sigma^2 chi^2(2n - 6): an estimate exists once that law's mode is positive."""
    from scipy.stats import chi2

    assert MIN_PAIRS_FOR_ERROR == 5
    for n in range(3, 12):
        dof = 2 * n - 6
        if dof == 0:
            peaks_at_zero = True  # 3 pairs: an exact fit, the residuals are zero
        else:
            grid = np.linspace(0.0, 5.0 * dof, 20001)
            peaks_at_zero = bool(np.argmax(chi2.pdf(grid, dof)) == 0)
        assert (error_estimate_reason(n) is not None) == peaks_at_zero, n
    # The figures the docstring quotes: sigma's 95 % interval given the residuals, and the RMS-residual shrink.
    lo, hi = math.sqrt(2 / chi2.ppf(0.975, 2)), math.sqrt(2 / chi2.ppf(0.025, 2))
    assert (round(lo, 2), round(hi, 1)) == (0.52, 6.3) and round(hi / lo) == 12
    lo, hi = math.sqrt(4 / chi2.ppf(0.975, 4)), math.sqrt(4 / chi2.ppf(0.025, 4))
    assert (round(lo, 2), round(hi, 2), round(hi / lo, 1)) == (0.60, 2.87, 4.8)


def test_four_pairs_fit_closer_than_the_clicks_are_wrong():
    """Simulated: with 4 pairs the residuals are about half the click error (sqrt(2 / 8)); with 10, 0.84."""
    from calib_core.cameras import PinholeCamera

    cam = PinholeCamera(np.array([[800.0, 0, 639.5], [0, 800, 479.5], [0, 0, 1]]), np.zeros(5), 1280, 960)
    rng = np.random.default_rng(4)
    ratio = {}
    for n in (4, 10):
        shown, true = [], []
        for _ in range(150):
            px = rng.uniform([100, 100], [1180, 860], (n, 2))
            points = cam.bearing(px) * rng.uniform(3, 12, (n, 1))  # camera frame = lidar frame here
            noise = rng.normal(0, 1.0, (n, 2))
            res = solve_extrinsics(points, cam.bearing(px + noise), camera=cam, pixels=px + noise, robust=False)
            shown.append(np.mean(res.residual_px ** 2))
            true.append(np.mean(np.sum(noise ** 2, axis=1)))
        ratio[n] = math.sqrt(np.mean(shown) / np.mean(true))
    print(f"\nRMS residual / RMS click error: 4 pairs {ratio[4]:.2f}, 10 pairs {ratio[10]:.2f}")
    assert abs(ratio[4] - math.sqrt(2 / 8)) < 0.08
    assert abs(ratio[10] - math.sqrt(14 / 20)) < 0.08


# --- the solve, the CLI, the YAML, the panel say the same ------------------------------------------------------


def test_four_pairs_have_no_error_estimate_anywhere(scene, sample_pairs, tmp_path):
    from app.cli import format_summary
    from calib_core.io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml

    pairs = sample_pairs[:4]
    res = calibrate(pairs, scene.depth, scene.camera)
    assert res.outliers == [] and res.quality.status == "warning"
    assert NO_ESTIMATE_4 in res.quality.reasons
    summary = format_summary(res, 4)
    assert f"reprojection error: {NO_ERROR_ESTIMATE} (4 pairs fit any pose closely; add pairs)" in summary
    assert f"  - {NO_ESTIMATE_4}" in summary
    assert "px, " not in summary.split("reprojection error")[1].splitlines()[0]
    save_extrinsics_yaml(tmp_path / "x.yaml", res.T_camera_lidar, res, scene.camera, pairs)
    doc = load_extrinsics_yaml(tmp_path / "x.yaml")
    assert doc["residuals"]["error_estimated"] is False
    assert NO_ESTIMATE_4 in doc["quality"]["reasons"]
    text = _panel_text(res, 4)
    assert f"**Mean error: {NO_ERROR_ESTIMATE}** (4 pairs fit any pose closely; add pairs)" in text
    assert "Mean error: 0" not in text and " px** (std" not in text


def test_five_pairs_show_the_error(scene, sample_pairs, tmp_path):
    from app.cli import format_summary
    from calib_core.io.extrinsics import load_extrinsics_yaml, save_extrinsics_yaml

    res = calibrate(sample_pairs[:5], scene.depth, scene.camera)
    assert not any(NO_ERROR_ESTIMATE in r for r in res.quality.reasons)
    assert f"reprojection error: {res.mean_px:.3f} +/- {res.std_px:.3f} px" in format_summary(res, 5)
    save_extrinsics_yaml(tmp_path / "x.yaml", res.T_camera_lidar, res)
    assert load_extrinsics_yaml(tmp_path / "x.yaml")["residuals"]["error_estimated"] is True
    assert f"**Mean error: {res.mean_px:.3f} px** (std {res.std_px:.3f} px)" in _panel_text(res, 5)


def test_four_pairs_with_a_wrong_one_never_show_zero_error(scene, sample_pairs):
    """The issue's case: 3 of 4 pairs agree (an exact P3P fit: mean error 0.000 px) and the pose is unreliable."""
    pairs = list(sample_pairs[:4])
    u, v = pairs[2].pixel
    pairs[2] = Pair(pairs[2].laser_rc, None, (u + 80.0, v + 40.0))
    res = calibrate(pairs, scene.depth, scene.camera)
    assert res.quality.status == "unreliable" and len(res.outliers) == 1
    assert res.mean_px < 1e-3  # what used to be shown
    assert f"{NO_ERROR_ESTIMATE}: 3 pairs fit any pose closely; add pairs" in res.quality.reasons
    text = _panel_text(res, 4)
    assert f"**Mean error: {NO_ERROR_ESTIMATE}** (3 pairs fit any pose closely; add pairs)" in text
    assert "0.000 px" not in text


def test_the_app_shows_no_error_estimate_for_four_pairs(tmp_path, sample_pairs):
    from browser_helpers import start_sample_app

    app, d = start_sample_app(tmp_path, list(sample_pairs[:4]))
    try:
        panel = d.result_panel
        assert f"Mean error: {NO_ERROR_ESTIMATE}" in panel and "px** (std" not in panel
        assert "Solved with 4 pairs" in panel
    finally:
        app.stop()


# --- the glyph before "Quality:" -------------------------------------------------------------------------------


def _font_safe(ch: str) -> bool:
    from app.calibration_panel import FONT_SAFE

    return ch == "\n" or (" " <= ch <= "~") or ch in FONT_SAFE


def test_the_font_safe_set_is_text_only():
    """Printable ASCII plus the bullet: no symbol (emoji, shapes), private-use or unassigned code point."""
    from app.calibration_panel import FONT_SAFE

    for ch in FONT_SAFE:
        assert unicodedata.category(ch) in ("Po", "Pd", "Pi", "Pf"), (hex(ord(ch)), unicodedata.category(ch))
        assert ord(ch) < 0x2100  # Latin and General Punctuation blocks: in every sans-serif font the page names


def test_the_panel_draws_only_font_safe_characters(scene, sample_pairs):
    """ok, warning (an outlier, notes), unreliable (1 of 4 wrong): every character of the panel is in the set."""
    from app.ui_common import QUALITY_BADGES

    statuses = set()
    cases = [sample_pairs, sample_pairs[:4]]
    wrong = list(sample_pairs)
    wrong[3] = Pair(wrong[3].laser_rc, None, (wrong[3].pixel[0] + 60.0, wrong[3].pixel[1]))
    cases.append(wrong)
    four_wrong = list(sample_pairs[:4])
    four_wrong[2] = Pair(four_wrong[2].laser_rc, None, (four_wrong[2].pixel[0] + 80.0, four_wrong[2].pixel[1] + 40))
    cases.append(four_wrong)
    for pairs in cases:
        res = calibrate(pairs, scene.depth, scene.camera)
        statuses.add(res.quality.status)
        text = _panel_text(res, len(pairs))
        bad = sorted({ch for ch in text if not _font_safe(ch)})
        assert not bad, [f"U+{ord(c):04X} {unicodedata.name(c, '?')}" for c in bad]
        assert f"Quality: {res.quality.status}".lower() in text.lower()
    assert statuses == {"ok", "warning", "unreliable"}
    for badge in QUALITY_BADGES.values():
        assert all(_font_safe(ch) for ch in badge)
