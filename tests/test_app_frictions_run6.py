"""By-eye frictions of runs 5 and 6 (docs/by_eye.md), driven through :class:`app_driver.AppDriver` on the committed
sample: Escape (Cancel pair) with nothing pending, a skipped lone marking proposal, the pair bar's Guided line."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.synthetic import load_sample, simulate_pairs

from app_driver import AppDriver, sample_app
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


@pytest.fixture
def app(tmp_path):
    a = sample_app(tmp_path / "session.yaml")
    yield a
    a.stop()


def test_cancel_pair_with_nothing_pending_gives_no_warning(app, scene):
    d = AppDriver(app)
    # Nothing at all: Escape / Cancel pair changes nothing and says nothing (run 6: a red "Not accepted").
    assert d.press_pair_action("Cancel pair") == [] and len(app.state.picks) == 0 and app.state.selected is None
    pair = simulate_pairs(scene, 1, np.random.default_rng(3), pixel_noise_px=0.0)[0]
    assert d.click_cell(app.ba_keys[0], *pair.laser_rc) == [] and d.click_camera(*pair.pixel) == []
    assert d.wait_idle()
    done = app.state.picks
    assert len(done) == 1 and app.state.pending() is None
    # A finished pair and no selection: still nothing to cancel, still silent, the pair stays.
    assert d.press_pair_action("Cancel pair") == [] and app.state.picks == done
    # A half-made pair is still dropped, a selection still ended.
    assert d.click_camera(330.0, 250.0) == [] and app.state.pending() is not None
    assert d.press_pair_action("Cancel pair") == [] and app.state.picks == done
    app.state.select(done[0].id)
    assert d.press_pair_action("Cancel pair") == [] and app.state.selected is None and app.state.picks == done
