"""Re-click proposals that help, once each, and a plain note when no new corner passes the screen (issue 20:
on PJLab every proposal was "re-click of pair N", cycling through the pairs and back after a Skip)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calib_core.guide.evidence import ProposalScreen
from calib_core.guide.session import GuidedSession
from calib_core.synthetic import load_sample
from calib_core.synthetic.picks import simulate_pairs
from repo_paths import SAMPLE


@pytest.fixture(scope="module")
def scene():
    return load_sample(SAMPLE)


def _reclicked(props) -> set[int]:
    return {p.replaces for p in props if p.replaces is not None}


def test_a_skipped_reclick_is_not_proposed_again(scene):
    """Skip on a re-click: it is gone from the whole ranked list (before: it came back last, and the app cycled
    to it again)."""
    session = GuidedSession(scene.depth, scene.camera, simulate_pairs(scene, 4, np.random.default_rng(0), 1.0),
                            image=scene.image)
    reclicks = [p for p in session.proposals(200) if p.replaces is not None]
    assert len(reclicks) >= 2
    session.skip(reclicks[0])
    again = session.proposals(200)
    assert reclicks[0].replaces not in _reclicked(again)
    assert _reclicked(again) == _reclicked(reclicks) - {reclicks[0].replaces}  # the others stay offered


def test_reclicks_are_offered_for_the_pair_that_is_off_not_for_every_rough_pair(scene):
    """10 spread pairs clicked 0.5 px off their true corners, one of them 15 px off: a re-click is offered for that
    one, and not for the pairs the others pin down (before: every rough pair was offered)."""
    rng = np.random.default_rng(3)
    pairs = simulate_pairs(scene, 10, rng, 0.5)
    bad = 4
    u, v = pairs[bad].pixel
    pairs[bad] = replace(pairs[bad], pixel=(u + 12.0, v - 9.0))  # 15 px off: the person's rough click
    session = GuidedSession(scene.depth, scene.camera, pairs, image=scene.image)
    offered = _reclicked(session.proposals(200))
    assert bad in offered
    assert len(offered) <= 4, offered  # the pairs the pose does not rest on are left alone
    # Independent check of "clearly helps": with the bad pair moved back to its true corner, the pairs agree and
    # only high-leverage pairs (if any) remain.
    fixed = list(pairs)
    fixed[bad] = replace(pairs[bad], pixel=(u, v))
    calm = _reclicked(GuidedSession(scene.depth, scene.camera, fixed, image=scene.image).proposals(200))
    assert bad not in calm or len(calm) < len(offered)


def test_no_reclick_before_the_pairs_enter_a_solve(scene):
    """2 pairs and an imported extrinsic: the pose is the extrinsic; re-clicking the 2 pairs was all the app
    offered on PJLab.  No re-click then."""
    pairs = simulate_pairs(scene, 2, np.random.default_rng(1), 1.0)
    session = GuidedSession(scene.depth, scene.camera, pairs, T_initial=scene.T_camera_lidar, image=scene.image)
    assert not _reclicked(session.proposals(200))


def test_no_new_corner_says_so_with_the_main_reason(scene):
    """A screen no cell passes (nothing within 0.5 m of the lidar: every candidate is farther, checked here) leaves
    only re-clicks: the note says so, with the count and the test that left most out."""
    session = GuidedSession(scene.depth, scene.camera, simulate_pairs(scene, 4, np.random.default_rng(0), 1.0),
                            image=scene.image, screen=ProposalScreen(max_range_m=0.5))
    assert np.linalg.norm(session.candidates.points_lidar, axis=1).min() > 0.5
    props = session.proposals(20)
    assert all(p.replaces is not None for p in props)
    note = props.note
    assert note is not None and note.startswith("No new corner to propose here; pick the next pairs by hand: of ")
    assert note.endswith("are too far away to place")
    n = int(note.split("of ")[1].split()[0])
    assert n == props.screened["far"] + sum(v for k, v in props.screened.items()
                                            if k not in ("far", "reclick ellipse or border"))
    for p in props:  # every re-click skipped: the list empties and the note is its reason
        session.skip(p)
    empty = session.proposals(20)
    assert not empty and empty.reason == empty.note
    # With the app's screen some new corners pass on the sample: no note.
    ok = GuidedSession(scene.depth, scene.camera, session.pairs, image=scene.image).proposals(20)
    assert any(p.replaces is None for p in ok) and ok.note is None
