"""Which cells the proposal screen left out, and why (``Proposals.left_out``), from a real by-eye start.

The walkthroughs of docs/by_eye.md ended with "No new corner passes the checks here (N candidates left out: most
for <test>)"; finding out whether those tests were right needs each left-out cell and the first test it failed.
Checked here against the scene itself, from the kept KITTI session of run 1 (``tests/by_eye_sessions``): a cell
left out as "far" is beyond the screen's range in the scan's own ranges, one left out at the "scan edge" lies in
its first or last rows, no proposed cell is left out, and every test's count is its cells' number.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib_core.cameras import load_camera
from calib_core.guide.evidence import RECLICK_SCREEN_KEYS, ProposalScreen
from calib_core.guide.session import GuidedSession
from calib_core.io.images import load_image_rgb
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import load_pairs_yaml

ROOT = Path(__file__).resolve().parents[1]
KITTI = ROOT.parent / "shared" / "data" / "kitti_object_000002"


@pytest.mark.skipif(not (KITTI / "velodyne" / "000002.bin").is_file(), reason=f"KITTI frame not found at {KITTI}")
def test_left_out_cells_name_the_test_they_failed_on_a_real_by_eye_start():
    from app.guide_support import max_ellipse_px_for

    depth = load_scan(KITTI / "velodyne" / "000002.bin")
    camera = load_camera(ROOT / "real_data" / "kitti_000002_camera.yaml")
    image = load_image_rgb(KITTI / "image_2" / "000002.png")
    pairs = load_pairs_yaml(ROOT / "tests" / "by_eye_sessions" / "kitti_run1.yaml")
    screen = replace(ProposalScreen(), max_ellipse_px=max_ellipse_px_for(camera.width, camera.height))
    session = GuidedSession(depth, camera, pairs, image=image, screen=screen)
    props = session.proposals(20)
    rcs, tests = props.left_out
    assert len(rcs) == len(tests) > 100  # the walkthrough's note counted hundreds
    counts = Counter(map(str, tests))
    assert counts == {k: v for k, v in props.screened.items() if v and k not in RECLICK_SCREEN_KEYS}
    H = depth.shape[0]
    ranges = np.linalg.norm(depth.points[rcs[:, 0], rcs[:, 1]], axis=1)
    edge = tests == "scan edge"
    assert edge.any() and np.all((rcs[edge, 0] < screen.scan_edge_rows) | (rcs[edge, 0] >= H - screen.scan_edge_rows))
    # Tests after the scan-edge one see only cells inside the scan's rows.
    assert np.all((rcs[~edge, 0] >= screen.scan_edge_rows) & (rcs[~edge, 0] < H - screen.scan_edge_rows))
    far = tests == "far"
    assert far.any() and np.all(ranges[far] > screen.max_range_m)
    # The far test comes second: every later-failing cell is within the range.
    assert np.all(ranges[~edge & ~far] <= screen.max_range_m)
    proposed = {tuple(p.laser_rc) for p in props if p.replaces is None}
    assert not proposed & set(map(tuple, rcs.tolist()))
    cand = {tuple(rc) for rc in session.candidates.rows_cols.tolist()}
    assert set(map(tuple, rcs.tolist())) <= cand
