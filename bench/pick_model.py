"""Check of the laser pick model against ground truth: ``python -m bench.pick_model``.

The model (:func:`calib_core.solve.whiten.cell_pick_covariance`): a picked
cell's point is off the feature by ``cell_sigma`` cells across the beam and
``range_sigma_m`` along it.  Its two numbers are fitted by maximum likelihood
to the 3-D errors of :func:`calib_core.synthetic.picks.laser_picks` (the cell
a careful person picks) against the true corners, on two of the four scenes
(the sample, seeds 1-3), and checked on the other two: the errors seen from
the camera (their 2-D tangent-plane part at the true pose, what the solve
weighs) must have a mean squared Mahalanobis distance of 2 and 68.3 % /
95.4 % of them within the 1- and 2-sigma ellipses (chi-square, 2 degrees of
freedom: 2.30 and 6.18).

A second candidate propagates the cell offset along the scanned surface (the
3-D differences of the neighbouring cells' points, the shorter one-sided
difference across a depth edge) instead of the change of the beam direction;
it is reported for comparison.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from calib_core.solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M, cell_pick_covariance

from .common import load_scenes

#: chi-square quantiles, 2 degrees of freedom, of 68.27 % and 95.45 %.
CHI2_1S, CHI2_2S = 2.296, 6.180
FOLDS = ((0, 1), (2, 3), (0, 2), (1, 3))


def pick_errors(scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Picked cells ``(N, 2)``, true corners ``(N, 3)`` and errors ``(N, 3)`` (cell point minus corner, metres)."""
    from calib_core.synthetic.picks import MAX_LASER_PICK_ERROR_M, laser_picks

    corners = np.asarray(scene.corners_lidar, dtype=np.float64).reshape(-1, 3)
    rc, err = laser_picks(scene.depth, corners)
    ok = err <= MAX_LASER_PICK_ERROR_M
    rc, corners = rc[ok], corners[ok]
    return rc, corners, scene.depth.points[rc[:, 0], rc[:, 1]] - corners


def surface_covariance(depth, rc: np.ndarray, cell_sigma: float, range_sigma_m: float) -> np.ndarray:
    """The surface candidate: the offset along the 3-D steps to the neighbouring cells' points."""
    H, W = depth.shape
    wrap = bool(depth.meta.get("wrap_cols", False))
    r, c = rc[:, 0], rc[:, 1]
    p0 = depth.points[r, c]
    steps = []
    for dr, dc in ((1, 0), (0, 1)):
        ends = []
        for sgn in (1, -1):
            rr, cc = r + sgn * dr, c + sgn * dc
            cc = cc % W if wrap else cc
            ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            rr, cc = np.clip(rr, 0, H - 1), np.clip(cc, 0, W - 1)
            ok &= depth.valid[rr, cc]
            d = sgn * (depth.points[rr, cc] - p0)
            ends.append((d, np.where(ok, np.linalg.norm(d, axis=1), np.inf)))
        (fwd, nf), (bwd, nb) = ends
        both = np.isfinite(nf) & np.isfinite(nb) & (np.maximum(nf, nb) <= 2 * np.minimum(nf, nb))
        g = np.where(both[:, None], (fwd + bwd) / 2, np.where((nf <= nb)[:, None], fwd, bwd))
        steps.append(np.where(np.isfinite(g), g, 0.0))
    b = depth.directions[r, c]
    outer = lambda a: a[:, :, None] * a[:, None, :]  # noqa: E731
    return cell_sigma**2 * (outer(steps[0]) + outer(steps[1])) + range_sigma_m**2 * outer(b)


MODELS = {"beam step (the package's model)": cell_pick_covariance, "surface step": surface_covariance}


def neg_log_likelihood(e: np.ndarray, S: np.ndarray) -> float:
    S = S + 1e-10 * np.eye(3)
    d2 = np.einsum("ni,ni->n", e, np.linalg.solve(S, e[:, :, None])[:, :, 0])
    return float(np.sum(np.linalg.slogdet(S)[1] + d2))


def camera_d2(scene, corners: np.ndarray, e: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances of the errors' camera tangent-plane parts (2 degrees of freedom)."""
    R, t = scene.T_camera_lidar[:3, :3], scene.T_camera_lidar[:3, 3]
    pc = corners @ R.T + t
    rng_m = np.linalg.norm(pc, axis=1)
    u = pc / rng_m[:, None]
    across = (np.eye(3)[None] - u[:, :, None] * u[:, None, :]) @ R  # lidar error -> across the line of sight
    r = np.einsum("nij,nj->ni", across, e)
    C = np.einsum("nij,njk,nlk->nil", across, S, across) + 1e-12 * u[:, :, None] * u[:, None, :]
    return np.einsum("ni,ni->n", r, np.linalg.solve(C, r[:, :, None])[:, :, 0])


def fit(data, model) -> tuple[float, float]:
    def f(x):
        return sum(neg_log_likelihood(e, model(sc.depth, rc, np.exp(x[0]), np.exp(x[1]))) for sc, rc, _, e in data)

    x = minimize(f, [np.log(0.5), np.log(0.015)], method="Nelder-Mead").x
    return float(np.exp(x[0])), float(np.exp(x[1]))


def coverage_by_scene(trials: int, cell_sigma: float = PICK_CELL_SIGMA, range_sigma_m: float = PICK_RANGE_SIGMA_M,
                      n: int = 10) -> None:
    """Share of ``calibrate`` trials (``simulate_pairs``, n pairs) within 1 and 2 reported sigma, per scene.

    The picked cells and their errors are fixed in each scan, and trials reuse the same corners: the
    scene-to-scene spread shows how far one scene's coverage can be from nominal for that reason alone.
    """
    import calib_core.solve.whiten as whiten
    from calib_core.solve import calibrate
    from calib_core.synthetic import simulate_pairs
    from calib_core.transforms import rpy_deg_from_R

    from .common import BENCH_SEED, wrap_deg

    defaults = whiten.cell_pick_covariance.__defaults__
    whiten.cell_pick_covariance.__defaults__ = (cell_sigma, range_sigma_m)  # the model calibrate() uses
    try:
        print(f"Coverage, {trials} trials per scene, n = {n}, pick model {cell_sigma:.3f} cells, "
              f"{100 * range_sigma_m:.1f} cm (roll pitch yaw tx ty tz; nominal 68.3 / 95.4 %):")
        for bs in load_scenes((1, 2, 3)):
            sc = bs.scene
            T_true = sc.T_camera_lidar
            rpy_true = rpy_deg_from_R(T_true[:3, :3])
            within, used = np.zeros((2, 6)), 0
            for k in range(trials):
                pairs = simulate_pairs(sc, n, np.random.default_rng([BENCH_SEED, 179, n, k]), pixel_noise_px=1.0)
                res = calibrate(pairs, sc.depth, sc.camera)
                if res.quality.status == "unreliable":
                    continue
                err = np.concatenate([wrap_deg(rpy_deg_from_R(res.T_camera_lidar[:3, :3]) - rpy_true),
                                      res.T_camera_lidar[:3, 3] - T_true[:3, 3]])
                sig = np.concatenate([res.sigma_rpy_deg, res.sigma_translation_m])
                within += np.abs(err) <= np.array([[1.0], [2.0]]) * sig
                used += 1
            one, two = 100 * within / used
            print(f"  {bs.name} ({used} trials): 1 sigma " + " ".join(f"{v:.1f}" for v in one)
                  + " | 2 sigma " + " ".join(f"{v:.1f}" for v in two))
    finally:
        whiten.cell_pick_covariance.__defaults__ = defaults


def main() -> None:
    import argparse

    p = argparse.ArgumentParser(prog="python -m bench.pick_model", description=__doc__.splitlines()[0])
    p.add_argument("--coverage", type=int, default=0, metavar="TRIALS",
                   help="also the sigma coverage of calibrate() per scene, this many trials each")
    p.add_argument("--cell-sigma", type=float, default=PICK_CELL_SIGMA, help="pick model for --coverage, cells")
    p.add_argument("--range-sigma", type=float, default=PICK_RANGE_SIGMA_M, help="pick model for --coverage, metres")
    args = p.parse_args()
    if args.coverage:
        coverage_by_scene(args.coverage, args.cell_sigma, args.range_sigma)
        return
    scenes = load_scenes((1, 2, 3))
    data = [(bs.scene,) + pick_errors(bs.scene) for bs in scenes]
    names = [bs.name for bs in scenes]
    print("Pick errors (cell point - true corner):")
    for name, (sc, rc, _, e) in zip(names, data):
        b = sc.depth.directions[rc[:, 0], rc[:, 1]]
        along = np.einsum("ni,ni->n", e, b)
        across = np.linalg.norm(e - along[:, None] * b, axis=1)
        print(f"  {name}: {len(e)} corners, median |error| {100 * np.median(np.linalg.norm(e, axis=1)):.2f} cm, "
              f"RMS along the beam {100 * np.sqrt(np.mean(along**2)):.2f} cm, across {100 * np.sqrt(np.mean(across**2)):.2f} cm")
    print("\nHeld-out check (fit on two scenes, test on the other two): mean d2 (2), within 1 sigma (68.3 %), "
          "2 sigma (95.4 %), held-out negative log-likelihood per corner (lower is better)")
    for label, model in MODELS.items():
        nlls = []
        for train in FOLDS:
            test = [i for i in range(len(data)) if i not in train]
            s, sr = fit([data[i] for i in train], model)
            d2 = np.concatenate([camera_d2(data[i][0], data[i][2], data[i][3], model(data[i][0].depth, data[i][1], s, sr))
                                 for i in test])
            nll = sum(neg_log_likelihood(data[i][3], model(data[i][0].depth, data[i][1], s, sr)) for i in test)
            nll /= sum(len(data[i][3]) for i in test)
            nlls.append(nll)
            print(f"  {label}: fit on {[names[i] for i in train]}: {s:.3f} cells, {100 * sr:.2f} cm -> held out "
                  f"{[names[i] for i in test]}: mean d2 {d2.mean():.2f}, {100 * np.mean(d2 <= CHI2_1S):.1f} % / "
                  f"{100 * np.mean(d2 <= CHI2_2S):.1f} %, NLL {nll:.3f}")
        print(f"  {label}: mean held-out NLL per corner {np.mean(nlls):.3f}")
    print(f"\nThe package's values: {PICK_CELL_SIGMA} cells, {100 * PICK_RANGE_SIGMA_M:.1f} cm. Per scene:")
    for name, (sc, rc, corners, e) in zip(names, data):
        d2 = camera_d2(sc, corners, e, cell_pick_covariance(sc.depth, rc))
        print(f"  {name}: mean d2 {d2.mean():.2f}, {100 * np.mean(d2 <= CHI2_1S):.1f} % / {100 * np.mean(d2 <= CHI2_2S):.1f} %")
    for label, s, sr in (("old solve model (uniform in the cell, 2 cm)", 12**-0.5, 0.02),
                         ("old bound model (uniform in the cell, 1 cm)", 12**-0.5, 0.01)):
        d2 = np.concatenate([camera_d2(sc, corners, e, cell_pick_covariance(sc.depth, rc, s, sr))
                             for sc, rc, corners, e in data])
        print(f"  {label}, all scenes: mean d2 {d2.mean():.2f}, {100 * np.mean(d2 <= CHI2_1S):.1f} % / "
              f"{100 * np.mean(d2 <= CHI2_2S):.1f} %")


if __name__ == "__main__":
    main()
