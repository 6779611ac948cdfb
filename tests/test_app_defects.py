"""Defects met in the by-eye trial (issue 20, item 5), driven without a browser.

* Pair numbers stay consecutive when guided proposals were declined (a pick started, then dropped or undone).
* "Hide marks" takes every mark off the images (the loupes keep theirs), and is saved with the view settings.
* A refining click inside a loupe: the loupe's title names that click, not the rough one before it.
* A check pair whose laser point projects outside the image: a reason instead of "n/a", and no numpy warning.

Truth: the sample's ground truth (which cells project off the image, the cells' ranges), hand-counted numbers,
and the clicks the test itself makes.  The browser half (number boxes, Verify plots, layout on resize, folder
order) is in ``tests/test_e2e_defects.py``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from app_driver import sample_app
from calib_core.pairs import Pair, save_pairs_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import transform_points
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


# ---------------------------------------------------------------------------------------------- pair numbers
def test_pair_numbers_stay_consecutive_after_declined_proposals(tmp_path):
    from app.state import AnnotationState

    valid = np.ones((20, 40), bool)
    session = tmp_path / "session.yaml"
    s = AnnotationState(valid, (320, 240), session_path=session)
    for k in range(3):  # three pairs by hand: 1, 2, 3
        s.add_laser(2 + k, 2)
        s.add_pixel(10.0 * k, 5.0)
    # Three guided proposals declined: each started as a half pick, then dropped ("Stop", a re-click) or undone.
    s.delete(s.start_pick(8, 8, source="guided"))
    s.start_pick(9, 9, source="guided")
    assert s.undo()
    s.delete(s.start_pick(10, 10, source="guided"))
    # The next pair made by hand is number 4, as a person counting the pairs expects.
    assert s.add_laser(11, 11) == 4 and s.add_pixel(50.0, 50.0) == 4
    assert [p.id for p in s.picks] == [1, 2, 3, 4]
    # An accepted proposal continues the count; a declined one after it leaves no gap either.
    assert s.start_pick(12, 12, source="guided") == 5 and s.add_pixel(60.0, 60.0) == 5
    s.delete(s.start_pick(13, 13, source="guided"))
    s.close()
    # After a restart (the session file holds the numbering) the next number is still 6.
    t = AnnotationState(valid, (320, 240), session_path=session)
    assert [p.id for p in t.picks] == [1, 2, 3, 4, 5]
    assert t.add_laser(14, 14) == 6
    # Deleting a pair below the highest keeps every other pair's number (markers and colours stay put).
    t.delete(2)
    assert t.add_pixel(70.0, 70.0) == 6 and t.add_laser(15, 15) == 7
    assert [p.id for p in t.picks] == [1, 3, 4, 5, 6, 7]
    t.close()


# ---------------------------------------------------------------------------------------------- hide marks
#: Marks inside the loupes: "Hide marks" leaves them (by-eye run 4: they are where a pair is refined).
LOUPE_INSIDE = ("/annot/loupe/ba_marks", "/annot/loupe/camera_marks", "/annot/loupe/camera_centre")
MARK_LINES = ("/annot/loupe/ba_marks", "/annot/loupe/camera_marks", "/annot/loupe/ba_outline",
              "/annot/loupe/camera_outline", "/annot/loupe/camera_centre", "/annot/overlay/residuals",
              "/annot/overlay/predicted")


def test_hide_marks_hides_every_mark_and_is_saved(tmp_path, scene):
    from app_driver import AppDriver

    pairs = simulate_pairs(scene, 6, np.random.default_rng(5), pixel_noise_px=0.5)
    pairs_file = tmp_path / "pairs.yaml"
    save_pairs_yaml(pairs_file, pairs)
    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        app.state.set_view(show_edges=True)  # off by default since stop 28: every kind of mark is on before
        assert [t for t, _ in d.upload_pairs("pairs.yaml", pairs_file.read_bytes())] == ["Pairs imported"]
        assert d.wait_idle() and app.result is not None
        row, col = pairs[0].laser_rc
        assert d.click_cell("horizontal", row, col) == []  # a pending pick: a prediction cross and the loupes on it
        d.select_in_dropdown(2)
        images = (*app.ba_keys, d.camera_key)

        def shown() -> dict[str, int]:
            """How many marks of each kind the scene shows."""
            out = {f"markers {k}": len(d.drawn_marker_pixels(k)) for k in images}
            out |= {f"selected {k}": d.selection_drawn(k) for k in images}
            out |= {name: len(app.nodes.segments(name)) for name in MARK_LINES}
            out["reprojected"] = len(d.drawn_points("/annot/overlay/reprojected")[0])
            out["edges"] = len(d.drawn_points("/annot/overlay/edges")[0])
            out["labels"] = len(d.drawn_labels())
            return out

        before = shown()
        # Every kind of mark is on the page before (else hiding it would prove nothing).
        assert all(n > 0 for n in before.values()), before
        assert before[f"markers {d.camera_key}"] == 6 and before["markers horizontal"] == 7
        def hidden() -> bool:
            """Every mark off the images; the loupes' own marks still drawn."""
            now = shown()
            return all(now[k] == 0 for k in now if k not in LOUPE_INSIDE) and all(now[k] > 0 for k in LOUPE_INSIDE)

        assert d.set_hide_marks(True) == []
        assert hidden(), shown()
        assert app.state.view.hide_marks
        # Clicks still work while hidden (and draw nothing); the pairs themselves are untouched.
        assert d.press_edit("Deselect") == []
        u, v = pairs[0].pixel
        assert d.click_camera(u, v) == [] and len(app.state.complete_picks()) == 7
        assert hidden(), shown()
        assert d.set_hide_marks(False) == []
        after = shown()
        # Back: the markers (now 7 on the camera too), numbers, overlays and loupe marks; no selection, no
        # pending pick any more, so no selection ring and no prediction.
        assert after[f"markers {d.camera_key}"] == 7 and after["markers horizontal"] == 7
        back = {k: n for k, n in after.items() if not k.startswith("selected") and k != "/annot/overlay/predicted"}
        assert all(n > 0 for n in back.values()), after
    finally:
        app.stop()
    # Saved in the session's view settings like the other toggles: a restart keeps the marks hidden.
    again = sample_app(tmp_path / "session.yaml")
    try:
        assert again.state.view.hide_marks is False
        AppDriver(again).set_hide_marks(True)
    finally:
        again.stop()
    third = sample_app(tmp_path / "session.yaml")
    try:
        assert third.state.view.hide_marks is True
        assert len(AppDriver(third).drawn_marker_pixels("horizontal")) == 0 and len(third.state.picks) == 7
    finally:
        third.stop()


# ---------------------------------------------------------------------------------------------- loupe title
def test_the_loupe_title_names_the_latest_click(tmp_path, scene):
    from app_driver import AppDriver

    pair = simulate_pairs(scene, 1, np.random.default_rng(4), pixel_noise_px=0.0)[0]
    row, col = pair.laser_rc
    u, v = pair.pixel
    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        rough = (row + 2, col - 3)
        assert d.click_cell("vertical", *rough) == []
        assert f"r{rough[0]} c{rough[1]} ·" in d.loupe_title("ba")
        assert d.click_loupe_cell(row, col) == []  # the refining click, inside the loupe
        assert app.state.picks[0].laser_rc == (row, col)
        title = d.loupe_title("ba")
        # The cell clicked last, and that cell's range (read from the scan here, not from the app's title code).
        assert f"r{row} c{col} · {scene.depth.range_m[row, col]:.2f} m" in title, title
        assert f"r{rough[0]} c{rough[1]} ·" not in title
        # The camera loupe likewise: a rough click, then a sub-pixel refinement inside the loupe.
        assert d.click_camera(u + 4.0, v - 3.0) == []
        assert f"({u + 4.0:.1f}, {v - 3.0:.1f})" in d.loupe_title("camera")
        assert d.click_loupe_camera(u + 0.3, v - 0.2) == []
        assert app.state.picks[0].pixel == pytest.approx((u + 0.3, v - 0.2))
        assert f"({u + 0.3:.1f}, {v - 0.2:.1f})" in d.loupe_title("camera"), d.loupe_title("camera")
        # Framing the loupe somewhere else (a click on the full image) names that place again.
        assert d.click_cell("vertical", *rough) == []
        assert f"r{rough[0]} c{rough[1]} ·" in d.loupe_title("ba")
    finally:
        app.stop()


# ---------------------------------------------------------------------------------------------- check pair off the image
def off_image_cell(scene) -> tuple[int, int]:
    """A scan cell whose point lies behind the camera under the ground truth (found here, from the sample)."""
    rc = np.argwhere(scene.depth.valid)
    pts = transform_points(scene.T_camera_lidar, scene.depth.cell_points(rc))
    behind = pts[:, 2] / np.linalg.norm(pts, axis=1)
    cell = tuple(int(x) for x in rc[int(np.argmin(behind))])
    _, ok = scene.camera.project(transform_points(scene.T_camera_lidar, scene.depth.cell_points(np.array([cell]))))
    assert behind.min() < -0.9 and not ok[0]
    return cell


def test_a_check_pair_off_the_image_says_why_without_a_numpy_warning(tmp_path, scene):
    from calib_core.verify import verification_to_dict, verify_pairs

    fit = simulate_pairs(scene, 8, np.random.default_rng(3))
    fit = [Pair(p.laser_rc, None, p.pixel, id=i + 1) for i, p in enumerate(fit)]
    inside = simulate_pairs(scene, 1, np.random.default_rng(9), pixel_noise_px=0.0)[0]
    checks = [Pair(inside.laser_rc, None, inside.pixel, check=True, id=9),
              Pair(off_image_cell(scene), None, (320.0, 240.0), check=True, id=10)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "Mean of empty slice" and friends fail the test
        rep = verify_pairs(fit + checks, scene.depth, scene.camera)
        only_off = verify_pairs(fit + checks[1:], scene.depth, scene.camera)
        doc = verification_to_dict(only_off)
    assert list(rep.check_outside) == [False, True]
    assert np.isfinite(rep.check_px[0]) and rep.check_px[0] < 3.0 and np.isnan(rep.check_px[1])
    assert any(w.startswith("check pair 10: its laser point projects outside the image") for w in rep.warnings)
    assert not any(w.startswith("check pair 9:") for w in rep.warnings)
    # With every check pair off the image the per-count curve has no check error (NaN, not a warning) ...
    assert np.isnan(only_off.pairs_vs_count["check_px"]).all() and np.isfinite(only_off.pairs_vs_count["fit_px"]).all()
    assert doc["check_mean_px"] is None and any("projects outside the image" in w for w in doc["warnings"])

    # ... and the app's panels give the reason where they gave "n/a".
    from app_driver import AppDriver

    pairs_file = tmp_path / "pairs.yaml"
    save_pairs_yaml(pairs_file, fit + checks)
    app = sample_app(tmp_path / "session.yaml")
    try:
        d = AppDriver(app)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert [t for t, _ in d.upload_pairs("pairs.yaml", pairs_file.read_bytes())] == ["Pairs imported"]
            assert d.wait_verified()
        assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
        row = next(r for r in d.verify_table.splitlines() if r.startswith("| 10 |"))
        assert "projects outside the image" in row and "n/a" not in row, row
        row9 = next(r for r in d.verify_table.splitlines() if r.startswith("| 9 |"))
        assert "n/a" not in row9 and "projects outside" not in row9
        assert "1 projects outside the image" in d.verify_summary and "n/a" not in d.verify_summary
        calib_row = next(r for r in d.residual_table.splitlines() if r.startswith("| 10 |"))
        assert "projects outside the image" in calib_row and "n/a" not in calib_row
    finally:
        app.stop()


def test_plot_data_never_holds_nan():
    """What the Verify plots are sent: finite float arrays; a column with nothing to show is left out whole."""
    from app.verify_panel import finite_plot

    x = np.array([1.0, 2.0, 3.0, 4.0])
    under = np.array([0.5, np.nan, 0.7, 0.9])
    left = np.full(4, np.nan)  # e.g. leave-one-out with 4 fit pairs: not computable
    series, data = finite_plot({"label": "x"}, x, [({"label": "under"}, under), ({"label": "left"}, left)])
    assert [s["label"] for s in series] == ["x", "under"]
    np.testing.assert_array_equal(data[0], [1.0, 3.0, 4.0])
    np.testing.assert_array_equal(data[1], [0.5, 0.7, 0.9])
    left[[0, 3]] = [0.6, 1.1]
    series, data = finite_plot({"label": "x"}, x, [({"label": "under"}, under), ({"label": "left"}, left)])
    assert [s["label"] for s in series] == ["x", "under", "left"]
    assert [list(a) for a in data] == [[1.0, 4.0], [0.5, 0.9], [0.6, 1.1]]
    assert all(a.dtype == np.float64 for a in data)
    _, data = finite_plot({"label": "x"}, np.full(3, np.nan), [({"label": "y"}, np.ones(3))])
    assert [len(a) for a in data] == [0, 0]


def test_a_typed_number_is_passed_on_once_typed():
    """settled(): of the updates one per keystroke ("8", "80", "800"), only the last is passed on, once the box
    has kept it for the delay; the app's own writes (no client) pass at once and do not cancel a typed value."""
    import asyncio
    from types import SimpleNamespace

    from app.settled_updates import settled

    box = SimpleNamespace(value=0)
    got: list[tuple] = []

    async def record(event) -> None:
        got.append((event.client, box.value))

    on_update = settled(record, delay=0.2)

    async def person_types() -> None:
        tasks = []
        for text in ("8", "80", "800"):
            box.value = int(text)
            tasks.append(asyncio.create_task(on_update(SimpleNamespace(client="tab", target=box))))
            await asyncio.sleep(0.05)  # a keystroke every 50 ms, well inside the delay
        await on_update(SimpleNamespace(client=None, target=box))  # the app writes meanwhile: passed at once
        assert got == [(None, 800)]
        await asyncio.gather(*tasks)
        box.value = 9  # a later change, after a pause: passed on too
        await on_update(SimpleNamespace(client="tab", target=box))

    asyncio.run(person_types())
    assert got == [(None, 800), ("tab", 800), ("tab", 9)]
