"""How much can the choice of corners alone lower the rotation error?  ``python -m bench.guide_order``.

An oracle analysis of the proposal order (issue 9's "D-optimal ordering"
target), free of detection and of the simulated person: the pool is the
scene's true corners (whole-cell laser picks the camera sees), every chosen
corner is clicked, and the expected error of a design is computed from its
Fisher information at the true pose (:mod:`calib_core.guide.information`),
not from one noisy draw.  The expected rotation error is ``E ||delta||`` with
``delta ~ N(0, C_rot)``, the rotation block of ``F^-1`` (Monte Carlo, fixed
draws shared by all designs), in degrees.

Every design starts from the same 4 rough pairs (farthest-point corners from
a random start, 1 px clicks, :func:`calib_core.synthetic.picks.simulate_pairs`)
and adds ``k`` corners clicked at ``sigma`` px:

* ``farthest`` -- the corner whose camera bearing is farthest from those
  chosen so far (the person spreading clicks);
* ``greedy D`` -- one at a time, the largest increase of ``log det F``
  (the shipped ranking without the corner probability);
* ``exchange D`` -- ``greedy D`` improved by Fedorov exchanges (swap a chosen
  corner for an unchosen one while ``log det F`` grows): the batch D-optimum;
* ``greedy rot`` -- one at a time, the smallest ``trace C_rot``;
* ``exchange rot`` -- the same improved by exchanges on ``trace C_rot``: a
  near-optimal design for the rotation error itself, i.e. about the lowest
  rotation error any order can reach from this pool;
* ``... + re-clicks`` -- as above, but a click may also re-click one of the 4
  rough pairs at ``sigma`` (what the guided session proposes when it adds
  more information than a new corner); each re-click costs one of the ``k`` clicks;
* ``..., detected corners only`` -- the pool restricted to the true corners
  that a laser corner candidate (:func:`calib_core.guide.find_candidates`)
  lies within two cells of: what the proposals can offer at best.
"""

from __future__ import annotations

import argparse

import numpy as np

from calib_core.guide.candidates import find_candidates
from calib_core.guide.information import pair_noise, pixel_jacobians
from calib_core.guide.laser_noise import WHOLE_CELL_SIGMA, cell_covariance
from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks, simulate_pairs
from calib_core.transforms import transform_points

from .common import BENCH_SEED, load_scenes, log

DESIGNS = ("farthest", "greedy D", "exchange D", "greedy rot", "exchange rot", "greedy D + re-clicks",
           "exchange rot + re-clicks", "greedy D, detected corners only", "exchange rot, detected corners only")
#: Fixed standard-normal draws for E||delta|| (shared by every design: differences are not MC noise).
_Z = np.random.default_rng(BENCH_SEED).standard_normal((4000, 3))


def expected_rotation_deg(F: np.ndarray) -> float:
    """``E ||delta||`` in degrees for ``delta ~ N(0, (F^-1)_rot)``."""
    C = np.linalg.inv(F)[:3, :3]
    L = np.linalg.cholesky(0.5 * (C + C.T))
    return float(np.degrees(np.linalg.norm(_Z @ L.T, axis=1).mean()))


def expected_translation_m(F: np.ndarray) -> float:
    C = np.linalg.inv(F)[3:, 3:]
    L = np.linalg.cholesky(0.5 * (C + C.T))
    return float(np.linalg.norm(_Z @ L.T, axis=1).mean())


def corner_pool(scene):
    """Usable, visible true corners: their pick cells, per-pair information blocks and camera bearings."""
    corners = np.asarray(scene.corners_lidar, dtype=np.float64)
    rc, err = laser_picks(scene.depth, corners)
    pts = scene.depth.points[rc[:, 0], rc[:, 1]]
    pix, J_pose, J_point = pixel_jacobians(scene.camera, scene.T_camera_lidar, pts)
    ok = (err <= MAX_LASER_PICK_ERROR_M) & np.all(np.isfinite(J_pose), axis=(1, 2))
    Pc = transform_points(scene.T_camera_lidar, corners)
    bear = Pc / np.linalg.norm(Pc, axis=1, keepdims=True)
    laser = cell_covariance(scene.depth, rc, WHOLE_CELL_SIGMA)
    return rc, ok, J_pose, J_point, laser, bear


def blocks(J_pose, J_point, laser, sigma) -> np.ndarray:
    """Per-pair information ``J^T S^-1 J`` (N, 6, 6)."""
    S = pair_noise(sigma, J_point, laser)
    return np.einsum("nai,nab,nbj->nij", J_pose, np.linalg.inv(S), J_pose)


def _score(F, crit):
    if crit == "D":
        s, ld = np.linalg.slogdet(F)
        return ld if s > 0 else -np.inf
    try:
        return -float(np.trace(np.linalg.inv(F)[:3, :3]))
    except np.linalg.LinAlgError:
        return -np.inf


def greedy(F0, B, pool, k, crit):
    chosen, F = [], F0.copy()
    for _ in range(k):
        cand = [i for i in pool if i not in chosen]
        best = max(cand, key=lambda i: _score(F + B[i], crit))
        chosen.append(best)
        F = F + B[best]
    return chosen


def exchange(F0, B, pool, chosen, crit, sweeps=5):
    chosen = list(chosen)
    F = F0 + B[chosen].sum(axis=0)
    cur = _score(F, crit)
    for _ in range(sweeps):
        improved = False
        for j in range(len(chosen)):
            Fm = F - B[chosen[j]]
            out = [i for i in pool if i not in chosen]
            scores = [_score(Fm + B[i], crit) for i in out]
            b = int(np.argmax(scores))
            if scores[b] > cur + 1e-9:
                chosen[j], F, cur, improved = out[b], Fm + B[out[b]], scores[b], True
        if not improved:
            break
    return chosen


def farthest(bear, pool, start, k):
    chosen = []
    max_cos = (bear[pool] @ bear[start].T).max(axis=1)
    pool = np.asarray(pool)
    for _ in range(k):
        j = int(np.argmin(np.where(np.isin(pool, chosen), np.inf, max_cos)))
        chosen.append(int(pool[j]))
        max_cos = np.maximum(max_cos, bear[pool] @ bear[pool[j]])
    return chosen


def detected_corners(scene) -> np.ndarray:
    """Mask of the true corners with a laser corner candidate within two cells of their whole-cell pick."""
    from .guide_sim import true_corner_of_cells

    idx, _ = true_corner_of_cells(scene, find_candidates(scene.depth).rows_cols)
    mask = np.zeros(len(scene.corners_lidar), dtype=bool)
    mask[idx[idx >= 0]] = True
    return mask


def trial(scene, rng, k: int, sigma: float, start_sigma: float = 1.0, detected: np.ndarray | None = None) -> dict:
    rc, ok, J_pose, J_point, laser, bear = corner_pool(scene)
    starters = simulate_pairs(scene, 4, rng, pixel_noise_px=start_sigma)
    lookup = {tuple(r): i for i, r in reversed(list(enumerate(rc.tolist())))}
    start = [lookup[p.laser_rc] for p in starters]
    B1 = blocks(J_pose, J_point, laser, start_sigma)
    B = blocks(J_pose, J_point, laser, sigma)
    F0 = B1[start].sum(axis=0)
    pool = [i for i in np.flatnonzero(ok) if i not in start]
    # Re-click items: index len(B) + j re-clicks starter j (its information rises from B1 to B).
    Bx = np.concatenate([B, B[start] - B1[start]])
    pool_x = pool + [len(B) + j for j in range(len(start))]
    gdx = greedy(F0, Bx, pool_x, k, "D")
    grx = exchange(F0, Bx, pool_x, greedy(F0, Bx, pool_x, k, "rot"), "rot")
    gd = greedy(F0, B, pool, k, "D")
    gr = greedy(F0, B, pool, k, "rot")
    sets = {"farthest": farthest(bear, pool, start, k), "greedy D": gd, "exchange D": exchange(F0, B, pool, gd, "D"),
            "greedy rot": gr, "exchange rot": exchange(F0, B, pool, gr, "rot")}
    out = {}
    for name, s in sets.items():
        F = F0 + B[s].sum(axis=0)
        out[name] = (expected_rotation_deg(F), expected_translation_m(F), _score(F, "D"))
    if detected is not None:
        pool_d = [i for i in pool if detected[i]]
        sets_d = {"greedy D, detected corners only": greedy(F0, B, pool_d, k, "D"),
                  "exchange rot, detected corners only": exchange(F0, B, pool_d, greedy(F0, B, pool_d, k, "rot"), "rot")}
        for name, s in sets_d.items():
            F = F0 + B[s].sum(axis=0)
            out[name] = (expected_rotation_deg(F), expected_translation_m(F), _score(F, "D"))
    for name, s in (("greedy D + re-clicks", gdx), ("exchange rot + re-clicks", grx)):
        F = F0 + Bx[s].sum(axis=0)
        out[name] = (expected_rotation_deg(F), expected_translation_m(F), _score(F, "D"))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.guide_order", description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=20, help="random starts per scene")
    p.add_argument("--seeds", type=int, nargs="*", default=[1, 2], help="extra scenes besides the sample")
    p.add_argument("--k", type=int, nargs="*", default=[6, 10], help="corners added to the 4 starting pairs")
    p.add_argument("--sigma", type=float, nargs="*", default=[0.3, 1.0], help="click noise of the added corners, px")
    a = p.parse_args(argv)
    scenes = load_scenes(tuple(a.seeds))
    detected = [detected_corners(bs.scene) for bs in scenes]
    print("Detected true corners (a candidate within 2 cells): "
          + ", ".join(f"{bs.name} {int(d.sum())} of {len(d)}" for bs, d in zip(scenes, detected)) + "\n")
    print(f"Oracle design comparison (`python -m bench.guide_order --trials {a.trials} --seeds "
          f"{' '.join(map(str, a.seeds))}`): expected errors from the Fisher information at the true pose; "
          f"{a.trials} random 4-pair starts per scene on {', '.join(s.name for s in scenes)}.\n")
    print("| 4 starters + k | click px | design | E rotation (mean over trials) | vs farthest | E translation | log det F vs farthest |")
    print("|---|---:|---|---|---:|---|---:|")
    for k in a.k:
        for sigma in a.sigma:
            rows = []
            for si, bs in enumerate(scenes):
                for t in range(a.trials):
                    rows.append(trial(bs.scene, np.random.default_rng([BENCH_SEED, 13, si, t]), k, sigma,
                                      detected=detected[si]))
            far_r = np.mean([r["farthest"][0] for r in rows])
            far_ld = np.mean([r["farthest"][2] for r in rows])
            for name in DESIGNS:
                rot = np.mean([r[name][0] for r in rows])
                tr = np.mean([r[name][1] for r in rows])
                ld = np.mean([r[name][2] for r in rows])
                print(f"| 4 + {k} | {sigma} | {name} | {rot:.3f} deg | {100 * (rot / far_r - 1):+.0f} % | "
                      f"{100 * tr:.2f} cm | {ld - far_ld:+.2f} |")
            log(f"k={k} sigma={sigma} done")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
