"""Fit the corner-probability weights (calib_core.guide.corner_probability): ``python -m bench.guide_fit``.

Training data: the committed sample (seed 0) only.  For several starting
states (4, 10 and 20 farthest-point clicks at 1 px, a few draws each) every
proposal the guide makes (up to 400, D-optimal order without the
probability) is labelled by the simulated person's rule
(:func:`bench.guide_sim.true_corner_of_cells`: within two cells of a true
corner's whole-cell pick, the corner's true projection inside the 3-sigma
ellipse); a logistic regression with a mild L2 penalty gives the weights.
``--eval`` prints the precision of the top proposals on the held-out scenes
(seeds 1 and 2) too.  Paste the printed ``WEIGHTS`` into the module.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import minimize

from calib_core.guide.corner_probability import FEATURES, corner_features, corner_probability, laser_features, scan_range_noise_m
from calib_core.guide.session import GuidedSession
from calib_core.synthetic.picks import simulate_pairs

from .common import BENCH_SEED, load_scenes
from .guide_sim import person_accepts, true_corner_of_cells


def samples(scene, draws: int = 3, starts=(4, 10, 20)) -> tuple[np.ndarray, np.ndarray]:
    """Features and labels of every proposal at several starting states of ``scene``."""
    X, y = [], []
    noise = scan_range_noise_m(scene.depth)
    for n0 in starts:
        for d in range(draws):
            rng = np.random.default_rng([BENCH_SEED, 21, n0, d])
            s = GuidedSession(scene.depth, scene.camera, simulate_pairs(scene, n0, rng, 1.0), image=scene.image,
                              corner_weights=(0.0, (0.0,) * len(FEATURES)))
            props = [p for p in s.proposals(400) if p.replaces is None]
            if not props:
                continue
            rc = np.array([p.laser_rc for p in props])
            keep = np.array([np.flatnonzero((s.candidates.rows_cols == r).all(axis=1))[0] for r in rc])
            lf = laser_features(scene.depth, s.candidates.subset(keep), noise)
            X.append(corner_features(lf, s.corners, np.array([p.pixel for p in props]),
                                     np.array([p.pixel_cov for p in props])))
            corner, _ = true_corner_of_cells(scene, rc)
            y.append(person_accepts(scene, props, corner))
    return np.concatenate(X), np.concatenate(y).astype(np.float64)


def fit(X: np.ndarray, y: np.ndarray, l2: float = 1.0) -> tuple[float, tuple[float, ...]]:
    """Logistic regression on standardised features; weights returned for the raw features."""
    mu, sd = X.mean(axis=0), X.std(axis=0) + 1e-9
    Z = np.column_stack([np.ones(len(X)), (X - mu) / sd])

    def loss(w):
        z = Z @ w
        return np.sum(np.logaddexp(0.0, z) - y * z) + 0.5 * l2 * np.sum(w[1:] ** 2)

    def grad(w):
        p = 1.0 / (1.0 + np.exp(-(Z @ w)))
        g = Z.T @ (p - y)
        g[1:] += l2 * w[1:]
        return g

    w = minimize(loss, np.zeros(Z.shape[1]), jac=grad, method="L-BFGS-B").x
    raw = w[1:] / sd
    return float(w[0] - raw @ mu), tuple(float(x) for x in raw)


def top_precision(p: np.ndarray, y: np.ndarray, share: float) -> float:
    k = max(1, int(round(share * len(p))))
    return float(y[np.argsort(-p)[:k]].mean())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.guide_fit", description=__doc__.splitlines()[0])
    ap.add_argument("--eval", action="store_true", help="also report precision on the held-out seeds 1 and 2")
    args = ap.parse_args(argv)
    scenes = load_scenes((1, 2) if args.eval else ())
    X, y = samples(scenes[0].scene)
    weights = fit(X, y)
    print(f"sample (training): {len(y)} proposals, {100 * y.mean():.1f} % clickable corners")
    print("WEIGHTS = (" + f"{weights[0]:.4g}, (" + ", ".join(f"{w:.4g}" for w in weights[1]) + "))")
    print("  features: " + ", ".join(FEATURES))
    for bs in scenes if args.eval else scenes[:1]:
        Xs, ys = (X, y) if bs is scenes[0] else samples(bs.scene)
        p = corner_probability(Xs, weights)
        print(f"{bs.name}: {len(ys)} proposals, all {100 * ys.mean():.1f} %, top 10 % {100 * top_precision(p, ys, 0.1):.1f} %, "
              f"top 25 % {100 * top_precision(p, ys, 0.25):.1f} %, top 50 % {100 * top_precision(p, ys, 0.5):.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
