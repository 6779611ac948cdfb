"""Check of the laser pick model against ground truth: ``python -m bench.pick_model``.

The model (:func:`calib_core.solve.whiten.cell_pick_covariance`): a picked
cell's point is off the feature by ``cell_sigma = (row, column)`` cells across
the beam and ``range_sigma_m`` along it.  Its three numbers are fitted by maximum likelihood
to the 3-D errors of :func:`calib_core.synthetic.picks.laser_picks` (the cell
a careful person picks) against the true corners, on two of the four scenes
(the sample, seeds 1-3), and checked on the other two: the errors seen from
the camera (their 2-D tangent-plane part at the true pose, what the solve
weighs) must have a mean squared Mahalanobis distance of 2 and 68.3 % /
95.4 % of them within the 1- and 2-sigma ellipses (chi-square, 2 degrees of
freedom: 2.30 and 6.18).

Two candidates are reported for comparison: the same model with one cell
sigma for both axes (the package's model before), and one that propagates the cell offset along the scanned surface (the
3-D differences of the neighbouring cells' points, the shorter one-sided
difference across a depth edge) instead of the change of the beam direction.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from calib_core.solve.whiten import PICK_CELL_SIGMA, PICK_RANGE_SIGMA_M, cell_pick_covariance


from .common import load_scenes, sigma_coverage

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


def surface_covariance(depth, rc: np.ndarray, cell_sigma, range_sigma_m: float) -> np.ndarray:
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


#: name -> (covariance function, number of cell sigmas: 2 = per axis, 1 = shared).
MODELS = {"beam step, per axis (the package's model)": (cell_pick_covariance, 2),
          "beam step, one value for both axes": (cell_pick_covariance, 1),
          "surface step": (surface_covariance, 1)}


def _cells(x: np.ndarray, k: int):
    return tuple(float(v) for v in np.exp(x[:k])) if k == 2 else float(np.exp(x[0]))


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


def fit(data, model, k: int = 2):
    """Maximum-likelihood ``(cell_sigma, range_sigma_m)``; ``cell_sigma`` a (row, col) pair when ``k == 2``."""
    def f(x):
        cells = _cells(x, k)
        return sum(neg_log_likelihood(e, model(sc.depth, rc, cells, np.exp(x[k]))) for sc, rc, _, e in data)

    x = minimize(f, [np.log(0.5)] * k + [np.log(0.015)], method="Nelder-Mead").x
    return _cells(x, k), float(np.exp(x[k]))


def _fmt_cells(s) -> str:
    return f"({s[0]:.3f}, {s[1]:.3f}) cells" if isinstance(s, tuple) else f"{s:.3f} cells"


#: Scenes of the pooled coverage check: none of them was used to fit the pick model.  Many scenes,
#: because a scene's trials share its fixed pick errors: at 8 scenes the pooled 1-sigma share of
#: one parameter still strayed by 7 points from what 20 scenes gave.
HELD_OUT_SEEDS = tuple(range(4, 24))


def coverage(seeds: tuple[int, ...], trials: int, n: int = 10, cell_sigma=PICK_CELL_SIGMA,
             range_sigma_m: float = PICK_RANGE_SIGMA_M, sample: bool = False, laser: str = "picks") -> dict:
    """Share of trials within 1 and 2 reported sigma, per scene and pooled over the scenes.

    Each trial: ``simulate_pairs`` (n corners, 1 px clicks) on one scene.  ``laser="picks"``: the
    careful whole-cell laser pick (the nearest of the 3x3 cells' points), solved with
    :func:`calib_core.solve.calibrate`.  ``laser="model"``: the same corners and clicks, but each
    laser point is the true corner plus a draw of the pick model's own Gaussian
    (``cell_pick_covariance`` of the picked cell), solved with ``solve_extrinsics`` and that
    covariance: the noise the reported sigma assumes, so any departure from nominal is the
    solve's.  A scan's picked cells and their errors are fixed, and trials on one scene reuse its
    ~120 corners, so one scene's trials are not independent draws of the pick error: the pooled
    share over many scenes is the coverage a user meets; the per-scene spread shows how far a
    single scene can stray from it.

    Returns ``{"n": n, "scenes": [(name, trials, one (6,), two (6,))], "trials": int, "one": (6,), "two": (6,)}``
    with the shares as fractions, parameters roll, pitch, yaw, tx, ty, tz.
    """
    from calib_core.solve import calibrate, solve_extrinsics
    from calib_core.synthetic import simulate_pairs
    from calib_core.synthetic.picks import laser_picks

    from .common import BENCH_SEED, within_sigma

    if laser not in ("picks", "model"):
        raise ValueError(f"laser must be 'picks' or 'model', got {laser!r}")
    scenes = load_scenes(tuple(seeds))
    scenes = scenes if sample else scenes[1:]
    rows, total, total_used = [], np.zeros((2, 6)), 0
    for si, bs in enumerate(scenes):
        sc = bs.scene
        T_true = sc.T_camera_lidar
        within, used = np.zeros((2, 6)), 0
        if laser == "model":
            corners = np.asarray(sc.corners_lidar, dtype=np.float64).reshape(-1, 3)
            corner_of = {tuple(rc): i for i, rc in enumerate(laser_picks(sc.depth, corners)[0])}
        for k in range(trials):
            # One stream per scene and trial: the same stream on every scene would give every scene's
            # k-th trial the same start corner and the same click noise, and the pooled trials would not
            # be independent.
            rng = np.random.default_rng([BENCH_SEED, 179, n, si, k])
            pairs = simulate_pairs(sc, n, rng, pixel_noise_px=1.0)
            if laser == "model":
                rc = np.array([p.laser_rc for p in pairs])
                pix = np.array([p.pixel for p in pairs], dtype=np.float64)
                S = cell_pick_covariance(sc.depth, rc, cell_sigma, range_sigma_m)
                L = np.linalg.cholesky(S + 1e-12 * np.eye(3))
                pts = corners[[corner_of[tuple(r)] for r in rc]] + np.einsum("nij,nj->ni", L,
                                                                             rng.normal(size=(len(rc), 3)))
                res = solve_extrinsics(pts, sc.camera.bearing(pix), camera=sc.camera, pixels=pix, laser_cov_m2=S)
            else:
                res = calibrate(pairs, sc.depth, sc.camera, cell_sigma=cell_sigma, range_sigma_m=range_sigma_m)
            if res.quality.status == "unreliable":
                continue
            within += within_sigma(res, T_true)
            used += 1
        rows.append((bs.name, used, within[0] / max(used, 1), within[1] / max(used, 1)))
        total += within
        total_used += used
    return {"n": n, "scenes": rows, "trials": total_used, "one": total[0] / max(total_used, 1),
            "two": total[1] / max(total_used, 1)}


def print_coverage(cov: dict, label: str) -> None:
    one_nominal, two_nominal = sigma_coverage(cov["n"])
    print(f"Coverage, {label} (roll pitch yaw tx ty tz; nominal {100 * one_nominal:.1f} / {100 * two_nominal:.1f} %):")
    for name, used, one, two in cov["scenes"]:
        print(f"  {name} ({used} trials): 1 sigma " + " ".join(f"{100 * v:.1f}" for v in one)
              + " | 2 sigma " + " ".join(f"{100 * v:.1f}" for v in two))
    print(f"  pooled ({cov['trials']} trials): 1 sigma " + " ".join(f"{100 * v:.1f}" for v in cov["one"])
          + " | 2 sigma " + " ".join(f"{100 * v:.1f}" for v in cov["two"]))


def main() -> None:
    import argparse

    p = argparse.ArgumentParser(prog="python -m bench.pick_model", description=__doc__.splitlines()[0])
    p.add_argument("--coverage", type=int, default=0, metavar="TRIALS",
                   help="instead: the sigma coverage of calibrate(), this many trials per scene, on the held-out "
                        f"scenes (seeds {HELD_OUT_SEEDS[0]}-{HELD_OUT_SEEDS[-1]}) and pooled over them")
    p.add_argument("--seeds", type=int, nargs="+", default=list(HELD_OUT_SEEDS), help="scenes for --coverage")
    p.add_argument("--cell-sigma", type=float, nargs="+", default=list(PICK_CELL_SIGMA),
                   help="pick model for --coverage: cells, one value or row and column")
    p.add_argument("--range-sigma", type=float, default=PICK_RANGE_SIGMA_M, help="pick model for --coverage, metres")
    p.add_argument("--laser", choices=("picks", "model"), default="picks",
                   help="for --coverage: the nearest-cell picks, or laser errors drawn from the pick model")
    args = p.parse_args()
    if args.coverage:
        cells = tuple(args.cell_sigma) if len(args.cell_sigma) == 2 else float(args.cell_sigma[0])
        cov = coverage(tuple(args.seeds), args.coverage, cell_sigma=cells, range_sigma_m=args.range_sigma,
                       laser=args.laser)
        print_coverage(cov, f"{args.coverage} trials per scene, n = 10, laser {args.laser}, pick model "
                            f"{_fmt_cells(cells)}, {100 * args.range_sigma:.1f} cm")
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
    for label, (model, k) in MODELS.items():
        nlls = []
        for train in FOLDS:
            test = [i for i in range(len(data)) if i not in train]
            s, sr = fit([data[i] for i in train], model, k)
            d2 = np.concatenate([camera_d2(data[i][0], data[i][2], data[i][3], model(data[i][0].depth, data[i][1], s, sr))
                                 for i in test])
            nll = sum(neg_log_likelihood(data[i][3], model(data[i][0].depth, data[i][1], s, sr)) for i in test)
            nll /= sum(len(data[i][3]) for i in test)
            nlls.append(nll)
            print(f"  {label}: fit on {[names[i] for i in train]}: {_fmt_cells(s)}, {100 * sr:.2f} cm -> held out "
                  f"{[names[i] for i in test]}: mean d2 {d2.mean():.2f}, {100 * np.mean(d2 <= CHI2_1S):.1f} % / "
                  f"{100 * np.mean(d2 <= CHI2_2S):.1f} %, NLL {nll:.3f}")
        print(f"  {label}: mean held-out NLL per corner {np.mean(nlls):.3f}")
        s, sr = fit(data, model, k)
        print(f"  {label}: fit on all four scenes: {_fmt_cells(s)}, {100 * sr:.2f} cm")
    print(f"\nThe package's values: {_fmt_cells(tuple(PICK_CELL_SIGMA))}, {100 * PICK_RANGE_SIGMA_M:.1f} cm. Per scene:")
    for name, (sc, rc, corners, e) in zip(names, data):
        d2 = camera_d2(sc, corners, e, cell_pick_covariance(sc.depth, rc))
        print(f"  {name}: mean d2 {d2.mean():.2f}, {100 * np.mean(d2 <= CHI2_1S):.1f} % / {100 * np.mean(d2 <= CHI2_2S):.1f} %")
    held = load_scenes(HELD_OUT_SEEDS)[1:]
    d2 = np.concatenate([camera_d2(bs.scene, c, e, cell_pick_covariance(bs.scene.depth, rc))
                         for bs in held for rc, c, e in [pick_errors(bs.scene)]])
    print(f"  held-out seeds {HELD_OUT_SEEDS[0]}-{HELD_OUT_SEEDS[-1]} ({len(d2)} corners): mean d2 {d2.mean():.2f}, "
          f"{100 * np.mean(d2 <= CHI2_1S):.1f} % / {100 * np.mean(d2 <= CHI2_2S):.1f} %")
    for label, s, sr in (("old solve model (uniform in the cell, 2 cm)", 12**-0.5, 0.02),
                         ("old bound model (uniform in the cell, 1 cm)", 12**-0.5, 0.01)):
        d2 = np.concatenate([camera_d2(sc, corners, e, cell_pick_covariance(sc.depth, rc, s, sr))
                             for sc, rc, corners, e in data])
        print(f"  {label}, all scenes: mean d2 {d2.mean():.2f}, {100 * np.mean(d2 <= CHI2_1S):.1f} % / "
              f"{100 * np.mean(d2 <= CHI2_2S):.1f} %")


if __name__ == "__main__":
    main()
