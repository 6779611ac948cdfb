"""Guided picking across shots (issue 21): from the joint rough solve of the two PJLab road scenes of one rig,
20 guided pairs, each the top proposal over both scenes.

A trial (one noise draw):

1. The joint rough solve: 3 pairs per scene (:func:`bench.shots.rough_pairs`: the cells of
   tools/make_real_pairs.py's fixed rule, pixel = the published calibration's projection + N(0, 1 px)),
   solved together (:func:`calib_core.shots.solve_shots`).
2. Proposals across both scenes (:func:`calib_core.shots.propose_shots`, what ``ba-calib propose --shot``
   runs), the simulated click at 0.5 px declared (``click_sigma_px``, the pair's ``precision_px``).
3. The simulated person clicks the top proposal: the proposed laser cell, pixel = the published
   calibration's projection of that cell's point + N(0, 0.5 px) per axis.  A proposal whose projection is off
   the picture cannot be clicked: the next one is taken (counted).  A re-click proposal replaces the rough pair
   it names.  Back to 2 until 20 guided clicks; then the joint solve against the published calibration.

What the simulated click assumes (the benchmark's main limit): the person finds, at the proposed cell, an image
feature whose pixel is exactly the projection of that cell's laser point under the published calibration.  So
(a) the published calibration is the truth the clicks are made from (it is not independent ground truth: the
figures say the guide converges to the calibration the clicks came from); (b) every proposal is clickable (no
vegetation, no hidden corner; in the ``exact`` and ``jitter`` arms the photos are not used: ``propose_shots``
runs without ``--image-for-shot``; the ``exact, photos`` arm gives them);
(c) the laser cell has no offset from the clicked feature.  The solve still models a whole-cell pick
(its laser covariance).  The ``jitter`` arm (left out with ``--no-jitter``) drops (c): the clicked feature
is the cell's point moved by a draw of that same whole-cell covariance
(:func:`calib_core.solve.whiten.cell_pick_covariance`), the solve's own model of where in the cell the feature is.

Ellipses: for every clicked proposal, whether the projection that was clicked (before the click noise) lies
inside the proposal's 3-sigma ellipse (``pixel_cov``: pose uncertainty plus one cell of pick offset), and, more
strictly, inside the ellipse of the pose uncertainty alone (``J_pose C J_pose^T``).

Run::

    python -m bench.shots_guided            # 10 draws per arm, about 5 minutes on 2 shared cores
    python -m bench.shots_guided --quick    # 3 draws, a smoke run
    python -m bench.shots_guided --write    # also replaces its section in docs/performance.md

Frames and units: ``T_camera_lidar`` maps lidar points into the camera frame, metres; the rotation error is the
angle of ``R_published^T R_est`` in degrees, the translation error the norm of the difference of the translations.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field

import numpy as np

from bench.common import BENCH_SEED, log
from bench.shots import load_two_scenes, rough_pairs, write_section
from calib_core.guide import ProposalScreen, find_candidates
from calib_core.guide.evidence import local_plane_residual_m
from calib_core.guide.information import pixel_jacobians, pose_pixel_covariance
from calib_core.pairs import Pair
from calib_core.shots import Shot, propose_shots, solve_shots
from calib_core.solve.whiten import cell_pick_covariance
from calib_core.transforms import rotation_angle_deg, transform_points

SECTION = "## Guided picking across shots (issue 21, `bench.shots_guided`)"
#: Click noise of the simulated guided pair, px per axis (the issue's simulated person).
GUIDED_CLICK_PX = 0.5
N_GUIDED = 20
#: The issue's target after 20 guided pairs: rotation (deg) and translation (cm) errors.
TARGET_DEG, TARGET_CM = 0.05, 2.0
#: Proposals asked for per step: the simulated person takes the first it can click.
N_PROPOSALS = 5
#: A click needs its 3-sigma noise on the picture (px from the border).
PICTURE_MARGIN_PX = 1.5
CHECKPOINTS = (0, 5, 10, 20)


@dataclass
class GuidedTrial:
    """One draw: errors against the published calibration after the rough solve and the guided clicks."""

    errors: dict = field(default_factory=dict)  # guided clicks -> (rotation deg, translation cm)
    shot_of_click: list = field(default_factory=list)  # scene (0 or 1) of each guided click
    reclicks: int = 0  # guided clicks that re-clicked a rough pair (replacing it)
    off_picture: int = 0  # proposals skipped: the projection is off the picture
    range_m: list = field(default_factory=list)  # range of each clicked cell's point
    inside_3sigma: list = field(default_factory=list)  # clicked projection inside the proposal's 3-sigma ellipse
    inside_pose_3sigma: list = field(default_factory=list)  # ... inside the pose-only 3-sigma ellipse
    mahalanobis2: list = field(default_factory=list)  # squared Mahalanobis distances (proposal's, pose-only)
    pick_px: list = field(default_factory=list)  # 1-sigma (minor, major) px of a whole-cell pick at each clicked cell
    status: str = ""  # quality status of the final joint solve
    sigma: tuple = (float("nan"), float("nan"))  # final solve's expected RMS error: rotation deg, translation cm
    T_final: np.ndarray | None = None  # the final joint solve's T_camera_lidar
    seconds: float = 0.0


def scan_caches(scenes, person_screen: bool = True) -> dict[int, dict]:
    """Per scene, what :func:`calib_core.guide.propose` would compute anew on every call from the scan alone
    (its candidates, the default screen's plane residuals), for ``propose_shots(shot_options=...)``.

    ``person_screen=False`` also turns the clear-evidence screen off (``screen=None``): every candidate, as a
    simulated click needs no checking by eye.  With it on (the default of the app and ``propose``) only cells a
    person can check are proposed, and a trial stops when none is left.
    """
    screen = ProposalScreen()
    out = {k: {"candidates": find_candidates(depth),
               "plane_residual": local_plane_residual_m(depth, screen.same_surface_rel, screen.min_plane_neighbours)}
           for k, (depth, _, _) in enumerate(scenes)}
    if not person_screen:
        for options in out.values():
            options["screen"] = None
    return out


def _on_picture(camera, uv: np.ndarray) -> bool:
    m = PICTURE_MARGIN_PX
    return bool(np.all(np.isfinite(uv)) and m <= uv[0] <= camera.width - 1 - m and m <= uv[1] <= camera.height - 1 - m)


def _errors(T: np.ndarray, T_pub: np.ndarray) -> tuple[float, float]:
    return rotation_angle_deg(T[:3, :3], T_pub[:3, :3]), float(100 * np.linalg.norm(T[:3, 3] - T_pub[:3, 3]))


def guided_trial(scenes, rule, draw: int, rng: np.random.Generator, caches: dict | None = None,
                 n_guided: int = N_GUIDED, click_px: float = GUIDED_CLICK_PX, jitter: bool = False,
                 images: dict | None = None) -> GuidedTrial:
    """The rough joint solve of draw ``draw`` (:func:`bench.shots.rough_pairs`), then ``n_guided`` guided clicks
    (module docstring); ``rng`` draws the click noise (and with ``jitter`` the feature's place in its cell);
    ``images`` (scene -> photo) go to the proposer (``--image-for-shot``)."""
    t0 = time.perf_counter()
    camera = scenes[0][1]
    T_pub = scenes[0][2]
    pairs = rough_pairs(scenes, rule, draw)
    out = GuidedTrial()

    def shots() -> list[Shot]:
        return [Shot.from_pairs(p, scenes[k][0], camera, name=f"scene{k + 1}") for k, p in enumerate(pairs)]

    while True:
        props, state = propose_shots(shots(), camera, N_PROPOSALS, click_sigma_px=click_px, shot_options=caches,
                                     images=images)
        made = len(out.shot_of_click)
        if made in CHECKPOINTS:
            out.errors[made] = _errors(state.T_camera_lidar, T_pub)
        if made >= n_guided or not props:
            break
        for sp in props:
            p = sp.proposal
            point = np.asarray(p.laser_xyz, dtype=np.float64)
            if jitter:
                cov = cell_pick_covariance(scenes[sp.shot][0], np.array([p.laser_rc]))[0]
                point = point + rng.multivariate_normal(np.zeros(3), cov)
            uv, ok = camera.project(transform_points(T_pub, point[None]))
            if ok[0] and _on_picture(camera, uv[0]):
                break
            out.off_picture += 1
        else:
            break  # nothing clickable among the proposals
        d = uv[0] - p.pixel  # the clicked feature about the prediction: pose and cell offset
        m2 = float(d @ np.linalg.solve(p.pixel_cov, d))
        out.inside_3sigma.append(m2 <= 9.0)
        # The pose part alone: the published projection of the cell's own point about the prediction.
        _, J_pose, J_point = pixel_jacobians(camera, state.T_camera_lidar, np.asarray(p.laser_xyz)[None])
        pick_cov = cell_pick_covariance(scenes[sp.shot][0], np.array([p.laser_rc]))[0]
        out.pick_px.append(np.sqrt(np.maximum(np.linalg.eigvalsh(J_point[0] @ pick_cov @ J_point[0].T), 0.0)).tolist())
        pose_cov = pose_pixel_covariance(J_pose, state.covariance)[0]
        d_cell = camera.project(transform_points(T_pub, np.asarray(p.laser_xyz)[None]))[0][0] - p.pixel
        m2_pose = float(d_cell @ np.linalg.solve(pose_cov, d_cell))
        out.inside_pose_3sigma.append(m2_pose <= 9.0)
        out.mahalanobis2.append((m2, m2_pose))
        click = uv[0] + rng.normal(0.0, click_px, 2)
        new = Pair(tuple(int(x) for x in p.laser_rc), None, (float(click[0]), float(click[1])), precision_px=click_px)
        if p.replaces is not None:
            pairs[sp.shot][p.replaces] = new
            out.reclicks += 1
        else:
            pairs[sp.shot].append(new)
        out.shot_of_click.append(sp.shot)
        out.range_m.append(float(np.linalg.norm(p.laser_xyz)))
    final = solve_shots(shots(), camera).result
    out.errors[len(out.shot_of_click)] = _errors(final.T_camera_lidar, T_pub)
    out.status = final.quality.status
    # sqrt(trace) of the covariance blocks: the RMS of the rotation angle and of the translation error it predicts.
    cov = np.asarray(final.covariance_6x6)
    out.sigma = (float(np.degrees(np.sqrt(np.trace(cov[:3, :3])))), float(100 * np.sqrt(np.trace(cov[3:, 3:]))))
    out.T_final = final.T_camera_lidar
    out.seconds = time.perf_counter() - t0
    return out


def run_arm(scenes, rule, caches, draws: int, jitter: bool, n_guided: int = N_GUIDED,
            images: dict | None = None) -> list[GuidedTrial]:
    """``draws`` trials (draw ``d``: rough pairs of :func:`bench.shots.rough_pairs`, clicks from
    ``default_rng((BENCH_SEED, d, jitter))``)."""
    trials = []
    for d in range(draws):
        t = guided_trial(scenes, rule, d, np.random.default_rng((BENCH_SEED, d, int(jitter))), caches,
                         n_guided=n_guided, jitter=jitter, images=images)
        r, c = t.errors[len(t.shot_of_click)]
        r0, c0 = t.errors[0]
        log(f"  draw {d}{' (jitter)' if jitter else ''}: rough {r0:.3f} deg / {c0:.2f} cm -> {len(t.shot_of_click)} "
            f"guided: {r:.4f} deg / {c:.2f} cm; clicks per scene {np.bincount(t.shot_of_click, minlength=2).tolist()}, "
            f"re-clicks {t.reclicks}, {t.seconds:.0f} s")
        trials.append(t)
    return trials


def screen_counts(scenes, rule, caches, photos: dict, n: int = 40) -> list[dict]:
    """Per scene, at the joint rough solve of draw 0: how many of ``n`` asked proposals
    (:func:`calib_core.guide.propose` under the joint pose) pass the screen without and with the photo, and how many
    cells the photo's test left out (``screened["no dominant image corner"]``)."""
    from calib_core.guide import corner_image, propose
    from calib_core.shots import joint_pose_state

    camera = scenes[0][1]
    shots = [Shot.from_pairs(p, scenes[k][0], camera) for k, p in enumerate(rough_pairs(scenes, rule, 0))]
    state = joint_pose_state(shots, camera)
    out = []
    for k, shot in enumerate(shots):
        used = [p.laser_rc for p in shot.pairs]
        plain = propose(shot.depth, camera, state, n, exclude_rc=used, click_sigma_px=GUIDED_CLICK_PX, **caches[k])
        seen = propose(shot.depth, camera, state, n, exclude_rc=used, click_sigma_px=GUIDED_CLICK_PX,
                       corner_image=corner_image(photos[k]), **caches[k])
        out.append({"without": len(plain), "with": len(seen),
                    "no_corner": int(seen.screened.get("no dominant image corner", 0))})
    return out


def summary(trials: list[GuidedTrial], n_guided: int = N_GUIDED) -> dict:
    """Medians, maxima and shares within the target, clicks per scene, ellipse coverage."""
    full = [t for t in trials if len(t.shot_of_click) == n_guided]
    # A trial that ran out of proposals is judged where it stopped.
    rot = np.array([t.errors[len(t.shot_of_click)][0] for t in trials])
    tra = np.array([t.errors[len(t.shot_of_click)][1] for t in trials])
    per_scene = np.array([np.bincount(t.shot_of_click, minlength=2)[:2] for t in trials])
    out = {"draws": len(trials), "complete": len(full),
           "rot_median": float(np.median(rot)), "rot_max": float(rot.max()),
           "trans_median": float(np.median(tra)), "trans_max": float(tra.max()),
           "rot_within": float(np.mean(rot <= TARGET_DEG)), "trans_within": float(np.mean(tra <= TARGET_CM)),
           "within": float(np.mean((rot <= TARGET_DEG) & (tra <= TARGET_CM))),
           "clicks_scene": per_scene.sum(axis=0).tolist(), "min_per_scene": int(per_scene.min()),
           "both_scenes": float(np.mean(per_scene.min(axis=1) > 0)),
           "reclicks": int(sum(t.reclicks for t in trials)), "off_picture": int(sum(t.off_picture for t in trials)),
           "range_median": float(np.median(np.concatenate([t.range_m for t in trials]))),
           "range_max": float(np.max(np.concatenate([t.range_m for t in trials]))),
           "inside": float(np.mean(np.concatenate([t.inside_3sigma for t in trials]))),
           "inside_pose": float(np.mean(np.concatenate([t.inside_pose_3sigma for t in trials]))),
           "n_ellipses": int(sum(len(t.inside_3sigma) for t in trials)),
           "pick_px": np.median(np.concatenate([np.reshape(t.pick_px, (-1, 2)) for t in trials]), axis=0).tolist(),
           "mean_m2": np.mean(np.concatenate([np.reshape(t.mahalanobis2, (-1, 2)) for t in trials]), axis=0).tolist(),
           "statuses": sorted({t.status for t in trials}),
           "sigma_rot": float(np.median([t.sigma[0] for t in trials])),
           "sigma_trans": float(np.median([t.sigma[1] for t in trials])),
           "clicks_median": float(np.median([len(t.shot_of_click) for t in trials])),
           "seconds_per_draw": float(np.mean([t.seconds for t in trials]))}
    out["checkpoints"] = {n: (float(np.median([t.errors[n][0] for t in trials if n in t.errors])),
                              float(np.median([t.errors[n][1] for t in trials if n in t.errors])))
                          for n in CHECKPOINTS if all(n in t.errors for t in trials)}
    return out


def report(arms: dict, command: str, seconds: float) -> str:
    lines = [SECTION, "",
             f"Command: `{command}` ({seconds:.0f} s on this 2-core machine shared with other jobs).  Data: "
             "`../shared/data/pjlab_opencalib_two_scenes` (two road scenes, one rig, one published calibration).  "
             "Per draw: the joint rough solve of 3 + 3 pairs (the cells of `tools/make_real_pairs.py`'s rule, "
             "pixel = published projection + N(0, 1 px); the draws of the `bench.shots` PJLab table), then "
             f"{N_GUIDED} guided clicks, each on the top proposal of `calib_core.shots.propose_shots` over both scenes "
             f"(what `ba-calib propose --shot` runs; {GUIDED_CLICK_PX} px declared), pixel = the published "
             f"calibration's projection of the proposed cell's point + N(0, {GUIDED_CLICK_PX} px); a proposal off the "
             "picture is passed over for the next; a re-click proposal replaces its rough pair.  Errors against the "
             "published calibration.", "",
             "**What the simulated click assumes.**  The person finds, at every proposed cell, an image feature "
             "whose pixel is exactly the published projection of that cell's laser point: every proposal is "
             "clickable (in the `exact` and `jitter` rows no image is given to the proposer and the clear-evidence "
             "screen is off, `screen=None`: a simulated click needs no checking by eye), the cell has no offset from the feature, and the published calibration is the "
             "truth the clicks come from (it is not independent ground truth).  The `exact, person screen` row keeps the "
             "screen on, as the app and `propose` do by default (only cells a person can check), and stops when "
             "nothing passes it; its error is taken where it stopped.  The `exact, photos` row also gives the "
             "proposer the two photos (`--image-for-shot`): proposals then need an image corner near their pixel and "
             "are ranked by gain x the probability of a clickable corner; the click is still the exact projection.  "
             "The `jitter` row drops the no-offset assumption: the clicked feature is the cell's point moved by a "
             "draw of the solve's own whole-cell pick covariance.", "",
             f"| clicks | draws | rotation median (max), deg | translation median (max), cm | within {TARGET_DEG} deg "
             f"| within {TARGET_CM:g} cm | both | target | the solve's own expected RMS error (sqrt of the "
             "covariance's trace), median: rotation deg; translation cm |",
             "|---|---:|---:|---:|---:|---:|---:|---|---|"]
    for name, s in arms.items():
        ok = s["within"] >= 0.95 and s["both_scenes"] == 1.0 and s["complete"] == s["draws"]
        lines.append(f"| {name} | {s['complete']} of {s['draws']} reach {N_GUIDED} (median {s['clicks_median']:.0f} clicks) | {s['rot_median']:.4f} ({s['rot_max']:.4f}) | "
                     f"{s['trans_median']:.2f} ({s['trans_max']:.2f}) | {100 * s['rot_within']:.0f} % | "
                     f"{100 * s['trans_within']:.0f} % | {100 * s['within']:.0f} % | {'PASS' if ok else 'MISS'} | "
                     f"{s['sigma_rot']:.4f}; {s['sigma_trans']:.2f} |")
    lines += ["", "Target: after 20 guided pairs within 0.05 deg and 2 cm (judged here as >= 95 % of draws within "
              "both), with clicks in both scenes in every draw.", "",
              "| clicks | median error after 0 / 5 / 10 / 20 guided (deg; cm) | guided clicks in scene 1 / scene 2 "
              "(fewest in one scene in a draw) | re-clicks | passed over (off the picture) | range of the clicked "
              "cells, median (max), m | inside the 3-sigma ellipse | inside the pose-only 3-sigma ellipse | mean "
              "squared Mahalanobis distance, proposal's ellipse; pose-only (2 when calibrated) | final status | "
              "s per draw |",
              "|---|---|---|---:|---:|---|---:|---:|---|---|---:|"]
    for name, s in arms.items():
        cp = s["checkpoints"]
        steps = " / ".join(f"{cp[n][0]:.3f}" for n in cp) + "; " + " / ".join(f"{cp[n][1]:.2f}" for n in cp)
        lines.append(f"| {name} | {steps} | {s['clicks_scene'][0]} / {s['clicks_scene'][1]} ({s['min_per_scene']}) | "
                     f"{s['reclicks']} | {s['off_picture']} | {s['range_median']:.1f} ({s['range_max']:.1f}) | "
                     f"{100 * s['inside']:.1f} % of {s['n_ellipses']} | {100 * s['inside_pose']:.1f} % | "
                     f"{s['mean_m2'][0]:.3f}; {s['mean_m2'][1]:.2f} | "
                     f"{', '.join(s['statuses'])} | {s['seconds_per_draw']:.0f} |")
    lines += ["", "The 3-sigma ellipse of a proposal is the pose uncertainty plus one cell of pick offset "
              "(`calib_core.guide.propose`); on this 64-beam scan the cell term dominates (radii of about 35-40 px), "
              "so its coverage says little; the pose-only ellipse (the published projection of the cell's own point "
              "about the prediction) is the stricter check of the joint pose covariance.", ""]
    if "jitter" in arms:
        e, j = arms["exact"], arms["jitter"]
        lines += [
            f"Reading: with exact clicks the 20 guided pairs reach the target in {100 * e['within']:.0f} % of the "
            f"draws, with clicks in both scenes in {100 * e['both_scenes']:.0f} %.  With the feature jittered in its "
            f"cell the errors (median {j['rot_median']:.3f} deg, {j['trans_median']:.2f} cm) are of the size the "
            f"solve itself expects of such pairs ({j['sigma_rot']:.3f} deg, {j['sigma_trans']:.2f} cm RMS): a "
            f"whole-cell pick on this 64-beam scan moves a pair's pixel by {j['pick_px'][0]:.1f} x "
            f"{j['pick_px'][1]:.1f} px (1 sigma, median over the clicked cells), several times the 0.5 px click, so "
            f"20 such pairs reach 0.05 deg / 2 cm in only {100 * j['within']:.0f} % of the draws.  As simulated, "
            "the target holds for a person whose click lands on the laser cell's own point, not for one who clicks "
            "the image corner wherever it lies within the cell.  The pose-only ellipses are conservative with exact "
            f"clicks (mean squared distance {e['mean_m2'][1]:.2f} against 2: the joint covariance counts the "
            f"whole-cell pick the exact clicks do not have); with the jitter it is {j['mean_m2'][1]:.2f}.", ""]
    if "exact, photos" in arms:
        ph = arms["exact, photos"]
        lines += [f"With the photos given to the proposer the guided clicks reach the target in "
                  f"{100 * ph['within']:.0f} % of the draws (median {ph['rot_median']:.4f} deg, "
                  f"{ph['trans_median']:.2f} cm), with clicks in both scenes in {100 * ph['both_scenes']:.0f} % "
                  f"({ph['clicks_scene'][0]} / {ph['clicks_scene'][1]} in all).  Why scene 1 gets few clicks: "
                  "at the rough solve of draw 0, of 40 proposals asked per scene, "
                  + "; ".join(f"scene {k + 1}: {c['without']} pass the screen without its photo, {c['with']} with it "
                              f"({c['no_corner']} cells left out for no dominant image corner in the ellipse)"
                              for k, c in enumerate(ph["screen"]))
                  + f".  The solve's own expected error with these pairs ({ph['sigma_rot']:.3f} deg, "
                  f"{ph['sigma_trans']:.2f} cm RMS) is close to the target, so a share of the draws misses it; more "
                  "guided pairs, or a screen that keeps more of scene 1, may close the gap (not tried here; the "
                  "screen is `calib_core.guide.evidence`'s).", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 draws (a smoke run)")
    ap.add_argument("--draws", type=int, default=None, help="noise draws per arm (default 10, 3 with --quick)")
    ap.add_argument("--no-jitter", action="store_true", help="skip the arm with the feature jittered in its cell")
    ap.add_argument("--no-photos", action="store_true", help="skip the arm with the photos given to the proposer")
    ap.add_argument("--write", action="store_true", help="replace this section in docs/performance.md")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    loaded = load_two_scenes()
    if loaded is None:
        log("no ../shared/data/pjlab_opencalib_two_scenes: nothing to measure")
        return 1
    scenes, rule = loaded
    draws = args.draws or (3 if args.quick else 10)
    caches = scan_caches(scenes)
    open_caches = scan_caches(scenes, person_screen=False)
    arms = {}
    log(f"exact clicks, every candidate, {draws} draws")
    arms["exact"] = summary(run_arm(scenes, rule, open_caches, draws, jitter=False))
    log(f"exact clicks, the person screen on, {draws} draws")
    arms["exact, person screen"] = summary(run_arm(scenes, rule, caches, draws, jitter=False))
    if not args.no_photos:
        from bench.shots import TWO_SCENES
        from calib_core.io.images import load_image_rgb

        photos = {k: load_image_rgb(TWO_SCENES / name / "calib.jpg") for k, name in enumerate(("scene1", "scene2"))}
        log(f"exact clicks, the photos given to the proposer, {draws} draws")
        arms["exact, photos"] = summary(run_arm(scenes, rule, caches, draws, jitter=False, images=photos))
        arms["exact, photos"]["screen"] = screen_counts(scenes, rule, caches, photos)
    if not args.no_jitter:
        log(f"feature jittered in its cell, {draws} draws")
        arms["jitter"] = summary(run_arm(scenes, rule, open_caches, draws, jitter=True))
    command = "python -m bench.shots_guided" + (f" --draws {args.draws}" if args.draws else "") + \
        (" --quick" if args.quick and not args.draws else "") + (" --no-jitter" if args.no_jitter else "") + \
        (" --no-photos" if args.no_photos else "") + " --write"
    text = report(arms, command, time.perf_counter() - t0)
    print(text)
    if args.write:
        write_section(text, section=SECTION)
        log("wrote the section into docs/performance.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
