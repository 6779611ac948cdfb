"""A simulated person for guided picking on the synthetic scenes (ground truth known).

The person is shown one proposal at a time (:class:`calib_core.guide.session.GuidedSession`).
If the proposed cell is within two rows and columns of a true scene corner's
whole-cell pick (:func:`calib_core.synthetic.picks.laser_picks`: the cell a
careful person picks, the laser model of the Cramer-Rao bound), that corner's
true projection lies inside the proposal's 3-sigma ellipse, and no other such
corner projects inside it elsewhere (:func:`person_accepts`), the person
moves the cell there in the BA loupe when it differs (1 action) and clicks
the corner's true projection plus Gaussian noise (1 action), making a
``guided`` pair; otherwise they press "Not a corner" (1 action, no pair).  A proposal to re-click a
rough starting pair is a click at its corner's true projection (1 action).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib_core.guide.auto_accept import auto_accept
from calib_core.guide.corner_probability import FEATURES
from calib_core.guide.information import fisher_information, pair_noise, pixel_jacobians
from calib_core.guide.laser_noise import PICK_CELL_SIGMA, cell_covariance
from calib_core.guide.pose_state import pair_sigmas
from calib_core.guide.session import GuidedSession
from calib_core.pairs import Pair
from calib_core.solve import calibrate
from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks, simulate_pairs
from calib_core.transforms import transform_points

from .common import pose_error
from .guide_order import expected_rotation_deg, expected_translation_m


#: An auto-accepted pixel farther than this from the true projection is a wrong match, px.
AUTO_WRONG_PX = 2.0


def true_corner_of_cells(scene, rows_cols: np.ndarray, max_cells: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Index of the true corner each cell is on (rule of the module docstring), or -1, and the corners' picks."""
    rc = np.asarray(rows_cols, dtype=np.int64).reshape(-1, 2)
    corners = np.asarray(scene.corners_lidar)
    pick_rc, pick_err = laser_picks(scene.depth, corners)
    cheb = np.abs(rc[:, None, :] - pick_rc[None, :, :]).max(axis=2)
    ok = (cheb <= max_cells) & (pick_err[None, :] <= MAX_LASER_PICK_ERROR_M)
    d = np.where(ok, cheb + 1e-3 * np.linalg.norm(scene.depth.points[rc[:, 0], rc[:, 1]][:, None, :] - corners[None], axis=2), np.inf)
    best = np.argmin(d, axis=1)
    return np.where(np.isfinite(d[np.arange(len(rc)), best]), best, -1), pick_rc


#: Two true corners farther apart than this in the image are different corners to the person, px.
DISTINCT_PX = 2.0


def person_accepts(scene, proposals, corner: np.ndarray, max_cells: int = 2) -> np.ndarray:
    """Whether the simulated person clicks each proposal (module docstring), (N,) bool.

    ``corner`` is :func:`true_corner_of_cells` of the proposals' cells.  The
    person clicks only a true corner whose true projection lies inside the
    proposal's 3-sigma ellipse (what the camera loupe shows) and that is
    unambiguous: no other true corner, also within ``max_cells`` of the
    proposed cell (the BA loupe cannot tell them apart), projects inside the
    ellipse more than :data:`DISTINCT_PX` from it.
    """
    tpix = true_pixels(scene)
    pick_rc, pick_err = laser_picks(scene.depth, np.asarray(scene.corners_lidar))
    usable = pick_err <= MAX_LASER_PICK_ERROR_M
    out = np.zeros(len(proposals), dtype=bool)
    for i, (p, c) in enumerate(zip(proposals, corner)):
        if c < 0:
            continue
        inv = np.linalg.inv(p.pixel_cov)
        d = tpix - p.pixel
        m2 = np.einsum("na,ab,nb->n", d, inv, d)
        if not m2[c] <= 9.0:
            continue
        near_cell = usable & (np.abs(pick_rc - np.asarray(p.laser_rc)).max(axis=1) <= max_cells)
        rivals = near_cell & (m2 <= 9.0) & (np.linalg.norm(tpix - tpix[c], axis=1) > DISTINCT_PX)
        out[i] = not rivals.any()
    return out


def _judge_auto(run, session, scene, gates: dict, lookup, paired, tpix) -> None:
    props = session.proposals(200)
    for name, gate in gates.items():
        passed, auto_px = auto_accept(session.corners, props, gate, image=scene.image, depth=scene.depth,
                                      camera=scene.camera, T_camera_lidar=session.state.T_camera_lidar)
        for p, ok, px in zip(props, passed, auto_px):
            if not ok:
                continue
            corner = lookup.get(tuple(p.laser_rc), -1)
            err = float(np.linalg.norm(px - tpix[corner])) if corner >= 0 and corner not in paired else float("inf")
            run.auto.setdefault(name, []).append((err > AUTO_WRONG_PX, err))


def true_pixels(scene) -> np.ndarray:
    """True projections (N, 2) of the scene's corners."""
    pix, _ = scene.camera.project(transform_points(scene.T_camera_lidar, scene.corners_lidar))
    return np.asarray(pix, dtype=np.float64)


@dataclass
class GuidedRun:
    """Outcome of one simulated guided session."""

    errors: dict = field(default_factory=dict)  # n guided -> (rotation deg, translation m)
    expected: dict = field(default_factory=dict)  # n guided -> expected (rotation deg, translation m) of the pairs
    actions_at: dict = field(default_factory=dict)  # n guided -> actions so far
    actions: int = 0
    shown: int = 0  # proposals shown (new pairs and re-clicks)
    not_a_corner: int = 0
    moves: int = 0  # laser cell moved in the BA loupe
    accepted: int = 0
    reclicks: int = 0  # guided re-clicks of the rough starting pairs (counted in accepted)
    inside_3sigma: list = field(default_factory=list)  # per accepted proposal: true pixel inside the 3-sigma ellipse
    mahalanobis2: list = field(default_factory=list)
    auto: dict = field(default_factory=dict)  # gate name -> per accepted proposal: (wrong, px error or inf)


def guided_run(scene, rng: np.random.Generator, checkpoints=(10, 20, 30, 50), click_sigma_px: float = 0.3,
               starters: list[Pair] | None = None, image: bool = True, max_actions: int = 2000,
               order: str = "d_optimal", auto_gates: dict | None = None, click_z: np.ndarray | None = None,
               count_pairs: bool = False, **propose_options) -> GuidedRun:
    """Start from ``starters`` (default: 4 farthest-point clicks at 1 px) and add guided pairs.

    ``order`` is the proposal order (:func:`calib_core.guide.propose`).  With
    ``auto_gates`` (name -> AutoGate), at every checkpoint all current proposals (up to 200) are
    judged by :func:`calib_core.guide.auto_accept.auto_accept` under each gate; a pass is
    wrong when the cell is on no true corner (or one already paired) or the
    found pixel is more than :data:`AUTO_WRONG_PX` from the corner's true
    projection.  (The person's loop is unchanged, so runs stay comparable.)
    ``propose_options`` go to :func:`calib_core.guide.propose` (e.g. ``corner_weights``).
    ``click_z`` (n_corners, 2): standard-normal click errors per true corner
    (scaled by ``click_sigma_px``), to share them with other arms; drawn from ``rng`` if None.
    At every checkpoint, besides the solve's error, the expected error of the
    pairs so far (:func:`expected_error`) is recorded.  Checkpoints count
    clicks (re-clicks of rough pairs included), or with ``count_pairs`` the
    pairs added to the solve (a re-click replaces a pair and adds none).
    """
    if starters is None:
        starters = simulate_pairs(scene, 4, rng, pixel_noise_px=1.0)
    options = {"order": order, "rng": rng} if order == "random" else {"order": order}
    options.update(propose_options)
    session = GuidedSession(scene.depth, scene.camera, starters, image=scene.image if image else None,
                            click_sigma_px=click_sigma_px, **options)
    truth_idx, pick_rc = true_corner_of_cells(scene, session.candidates.rows_cols)
    pick_lookup = {tuple(rc): i for i, rc in reversed(list(enumerate(pick_rc.tolist())))}
    paired = {pick_lookup[p.laser_rc] for p in starters if p.laser_rc in pick_lookup}
    lookup = {tuple(rc): int(i) for rc, i in zip(session.candidates.rows_cols.tolist(), truth_idx)}
    tpix = true_pixels(scene)
    # One click error per true corner, drawn up front: whatever order the
    # corners come in, a corner is clicked with the same error (fair order comparisons).
    if click_z is None:
        click_z = rng.standard_normal(tpix.shape)
    click_noise = click_sigma_px * np.asarray(click_z)
    run = GuidedRun()
    n_max = max(checkpoints)
    n0 = len(session.pairs)

    def progress() -> int:
        return len(session.pairs) - n0 if count_pairs else run.accepted

    while progress() < n_max and run.actions < max_actions:
        props = session.proposals(1)
        if not props:
            break
        p = props[0]
        run.actions += 1
        run.shown += 1
        if p.replaces is not None:  # re-click of a rough pair: its cell is a corner's pick
            corner = pick_lookup.get(tuple(p.laser_rc), -1)
        else:
            corner = lookup.get(tuple(p.laser_rc), -1)
            corner = -1 if corner in paired else corner
        if corner >= 0:  # ellipse calibration: over every proposal on a true corner
            d = tpix[corner] - p.pixel
            m2 = float(d @ np.linalg.solve(p.pixel_cov, d))
            run.mahalanobis2.append(m2)
            run.inside_3sigma.append(m2 <= 9.0)
        # A re-click is of the person's own earlier pair: they know which corner it is.
        if corner < 0 or (p.replaces is None and not person_accepts(scene, [p], np.array([corner]))[0]):
            session.not_a_corner(p)
            run.not_a_corner += 1
            continue
        click = tpix[corner] + click_noise[corner]
        cell = tuple(int(x) for x in pick_rc[corner])
        if cell != tuple(p.laser_rc):
            run.actions += 1
            run.moves += 1
        session.accept(p, click, laser_rc=cell)
        paired.add(corner)
        run.reclicks += p.replaces is not None
        run.accepted += 1
        n = progress()
        if n not in checkpoints or n in run.errors:
            continue
        if auto_gates and session.corners is not None:
            _judge_auto(run, session, scene, auto_gates, lookup, paired, tpix)
        T = session.solve().T_camera_lidar
        e = pose_error(T, scene.T_camera_lidar)
        run.errors[n] = (e.rotation_deg, e.translation_norm_m)
        run.expected[n] = expected_error(scene, session.pairs)
        run.actions_at[n] = run.actions
    return run


def expected_error(scene, pairs) -> tuple[float, float]:
    """Expected (mean) rotation (deg) and translation (m) error of a solve of ``pairs``, from their
    Fisher information at the true pose: each pair's ``precision_px`` (1 px if unset) and whole-cell laser pick."""
    rc = np.array([p.laser_rc for p in pairs], dtype=np.int64)
    pts = scene.depth.points[rc[:, 0], rc[:, 1]]
    _, J_pose, J_point = pixel_jacobians(scene.camera, scene.T_camera_lidar, pts)
    S = pair_noise(pair_sigmas(pairs), J_point, cell_covariance(scene.depth, rc, PICK_CELL_SIGMA))
    F = fisher_information(J_pose, S)
    return expected_rotation_deg(F), expected_translation_m(F)


def unguided_run(scene, starters: list[Pair], click_z: np.ndarray, checkpoints, click_sigma_px: float) -> GuidedRun:
    """The person without guidance: after ``starters``, more true corners chosen by farthest-point
    sampling of their camera bearings (continuing from the starters' corners, as
    :func:`calib_core.synthetic.picks.simulate_pairs` chooses), clicked at the true projection plus
    ``click_sigma_px * click_z`` of that corner; solved (each pair weighted by its precision) after
    each number of added corners in ``checkpoints``."""
    corners = np.asarray(scene.corners_lidar, dtype=np.float64)
    pick_rc, err = laser_picks(scene.depth, corners)
    usable = err <= MAX_LASER_PICK_ERROR_M
    Pc = transform_points(scene.T_camera_lidar, corners)
    bear = Pc / np.linalg.norm(Pc, axis=1, keepdims=True)
    lookup = {tuple(rc): i for i, rc in reversed(list(enumerate(pick_rc.tolist())))}
    start = [lookup[p.laser_rc] for p in starters]
    max_cos = np.where(usable, (bear @ bear[start].T).max(axis=1), np.inf)
    max_cos[start] = np.inf
    tpix = true_pixels(scene)
    pairs = list(starters)
    run = GuidedRun()
    for n in range(1, max(checkpoints) + 1):
        c = int(np.argmin(max_cos))
        if not np.isfinite(max_cos[c]):
            break
        max_cos = np.maximum(max_cos, bear @ bear[c])
        max_cos[c] = np.inf
        px = tpix[c] + click_sigma_px * click_z[c]
        pairs.append(Pair((int(pick_rc[c, 0]), int(pick_rc[c, 1])), None, (float(px[0]), float(px[1])),
                          precision_px=click_sigma_px))
        run.accepted = run.actions = run.shown = n
        if n in checkpoints:
            run.actions_at[n] = n
            e = pose_error(calibrate(pairs, scene.depth, scene.camera).T_camera_lidar, scene.T_camera_lidar)
            run.errors[n] = (e.rotation_deg, e.translation_norm_m)
            run.expected[n] = expected_error(scene, pairs)
    return run


#: Ranking by the gain alone (information per click) instead of gain x P (per action), without re-clicks.
PER_CLICK = {"corner_weights": (0.0, (0.0,) * len(FEATURES)), "reclicks": False}
#: Arms of the order comparison: name -> (kind, propose order or None, click noise px, session options).
ORDER_ARMS = {
    "guided D-optimal (shipped), 0.3 px": ("guided", "d_optimal", 0.3, {}),
    "guided D-optimal (shipped), 0.3 px, counting pairs (re-clicks free)": ("guided pairs", "d_optimal", 0.3, {}),
    "guided, farthest order over the same proposals, 0.3 px": ("guided", "farthest", 0.3, {}),
    "unguided farthest-point corners, 1 px (issue's model)": ("unguided", None, 1.0, {}),
    "unguided farthest-point corners, 0.3 px (same noise)": ("unguided", None, 0.3, {}),
    "guided D-optimal per click (gain only, no re-clicks), 0.3 px": ("guided", "d_optimal", 0.3, PER_CLICK),
}


def order_trial(scene, rng: np.random.Generator, checkpoints=(6, 10), arms=tuple(ORDER_ARMS)) -> dict:
    """One trial of the order comparison: every arm starts from the same 4 rough pairs (farthest-point
    corners from a random start, 1 px clicks) and adds clicks (errors recorded after each number in
    ``checkpoints``; a guided re-click counts as a click); a corner clicked in several arms gets the same
    standard-normal error (scaled by the arm's click noise).  Returns arm -> GuidedRun."""
    starters = simulate_pairs(scene, 4, rng, pixel_noise_px=1.0)
    z = rng.standard_normal((len(scene.corners_lidar), 2))
    out = {}
    for name in arms:
        kind, order, sigma, options = ORDER_ARMS[name]
        if kind.startswith("guided"):
            out[name] = guided_run(scene, rng, checkpoints=tuple(checkpoints), click_sigma_px=sigma,
                                   starters=starters, order=order, click_z=z, max_actions=300,
                                   count_pairs=kind == "guided pairs", **options)
        else:
            out[name] = unguided_run(scene, starters, z, tuple(checkpoints), sigma)
    return out
