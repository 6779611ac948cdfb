"""Proposals a person can check, measured without a person: ``python -m bench.guide_by_eye [--trials N] [--write]``.

Issue 20, item 3: a by-eye user found the guided proposals unusable on real
scans (3-sigma ellipses larger than the loupe, cells on vegetation, far
background and the image border).  This benchmark starts where that user
started and measures what the user saw, on two real frames with their
published calibrations (not ground truth, but correct to a few pixels):

* KITTI object 000002 (``../shared/data/kitti_object_000002``, camera
  ``real_data/kitti_000002_camera.yaml``, pose from its calib file);
* PJLab OpenCalib manual_calib (``../shared/data/pjlab_opencalib_lidar2camera/manual_calib``,
  64 beams by elevation, the 1920 x 1200 image).

A trial: 5 rough pairs as a person makes them by eye -- laser cells at real
corners (the committed ``real_data/pairs`` cells: foreground corners chosen
by a fixed rule), each pixel off its projection under the published pose by
5-15 px (uniform length, uniform direction), no ``precision_px`` (the app's
default) -- then the 20 proposals of a :class:`GuidedSession` with the camera
image, once without the screen (``screen=None``) and once with the app's
:class:`calib_core.guide.evidence.ProposalScreen` (``max_ellipse_px`` set to
the app's limit for that image).  ``--before FILE`` adds the rows of a run on
older code (run this file with that code on the path), so one table shows
before and after.

Each proposal is judged from its laser point projected with the *published*
pose, by this module's own measures (none of them is the proposal code):

* **corner**: an OpenCV Harris corner (``cv2.goodFeaturesToTrack``) within
  :data:`ON_CORNER_PX` and isolated (at most :data:`MAX_RIVALS` others within
  :data:`ISOLATION_PX`), the laser window explained by at most two RANSAC
  planes (not vegetation), not on a RANSAC ground plane, not beyond
  :data:`FAR_M`; also reported: a Harris corner within 3 px, within one cell
  footprint (measured by projecting the neighbouring beams);
* **3-sigma radius**, **fits the loupe** at zoom 1 (half the camera loupe's
  side) and within the app's limit (:func:`app.guide_support.max_ellipse_px_for`);
* **off vegetation**, **off far background** (range > :data:`FAR_M`), **off
  the ground**.

``--sessions`` starts instead from the by-eye walkthroughs' own pairs
(``tests/by_eye_sessions/*.yaml`` and any ``--session SCENE=FILE``, SCENE
``kitti`` or ``pjlab``): the proposals the app would offer next, judged as
above, and for every test of the screen how many candidates it left out and
how many of those the judge calls a corner -- at 3 px and, as a whole-cell
pick can do no better, within one cell footprint (:func:`session_rows`).

``--crops DIR`` saves, for the first trial with the screen, the photo and the
scan rendered from the camera under the published pose side by side around
each proposal's true projection: what a person judging it looks at.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from calib_core.cameras import load_camera
from calib_core.guide.evidence import ProposalScreen
from calib_core.guide.session import GuidedSession
from calib_core.io.images import load_image_rgb
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import Pair, load_pairs_yaml
from calib_core.transforms import transform_points

from .common import BENCH_SEED, REPO, log
from .guide_real import KITTI, RealScene, kitti_available, load_kitti

MANUAL = REPO.parent / "shared" / "data" / "pjlab_opencalib_lidar2camera" / "manual_calib"
MANUAL_PAIRS = REPO / "real_data" / "pairs" / "manual_calib_pairs.yaml"
#: Rough pairs per trial, and the range of their pixel error (px): a by-eye click on the full image.
N_ROUGH = 5
ROUGH_PX = (5.0, 15.0)
N_PROPOSALS = 20
#: Laser range (m) beyond which a proposal is on far background.
FAR_M = 30.0
#: Share of a window's near-side points that at most two planes must explain (else: vegetation-like).
MIN_EXPLAINED = 0.7
#: Plane tolerance of that test, in range-noise units.
PLANE_TOL_NOISE = 3.0


def manual_available() -> bool:
    return (MANUAL / "0.pcd").is_file() and MANUAL_PAIRS.is_file()


def load_manual() -> RealScene:
    """manual_calib: 0.pcd organised into 64 beams by elevation; its JSON claims 1920 x 1080 but the image
    is 1920 x 1200 (real_data/README.md); the published matrix from the dataset's JSON."""
    doc = json.loads((MANUAL / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    T = np.array(doc["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], dtype=float)
    return RealScene(load_scan(MANUAL / "0.pcd", beams=64),
                     load_camera(MANUAL / "center_camera-intrinsic.json", image_size=(1920, 1200)),
                     load_image_rgb(MANUAL / "0.png"), T, load_pairs_yaml(MANUAL_PAIRS))


def loupe_side_px(width: int, height: int) -> int:
    """The app's camera loupe side at zoom 1 (original-image px)."""
    from app.loupes import default_camera_crop_px

    return default_camera_crop_px(width, height)


def app_screen(width: int, height: int) -> ProposalScreen:
    """The screen the app uses for an image of this size (app/guide_support.py)."""
    from app.guide_support import max_ellipse_px_for

    return replace(ProposalScreen(), max_ellipse_px=max_ellipse_px_for(width, height))


def by_eye_pairs(scene: RealScene, rng: np.random.Generator, n: int = N_ROUGH) -> list[Pair]:
    """``n`` of the committed pairs' cells, pixels off their published projection by 5-15 px."""
    pick = rng.choice(len(scene.pairs), size=n, replace=False)
    out = []
    for i in pick:
        rc = scene.pairs[i].laser_rc
        uv, _ = scene.camera.project(transform_points(scene.T_published, scene.depth.points[rc[0], rc[1]][None]))
        angle, length = rng.uniform(0.0, 2 * np.pi), rng.uniform(*ROUGH_PX)
        uv = np.clip(uv[0] + length * np.array([np.cos(angle), np.sin(angle)]), 0,
                     [scene.camera.width - 1, scene.camera.height - 1])
        out.append(Pair(rc, None, (float(uv[0]), float(uv[1]))))
    return out


# ------------------------------------------------------------------ the measures (independent of the screen)
def range_noise_m(depth, step: int = 4) -> float:
    """Median RMS of plane fits (SVD) to the valid points of 3 x 3 blocks on a grid of cells, metres."""
    H, W = depth.shape
    r0, c0 = np.meshgrid(np.arange(1, H - 1, step), np.arange(1, W - 1, step), indexing="ij")
    off = np.array([(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)])
    rows, cols = r0.reshape(-1, 1) + off[:, 0], c0.reshape(-1, 1) + off[:, 1]
    full = depth.valid[rows, cols].all(axis=1)
    P = depth.points[rows[full], cols[full]]
    D = P - P.mean(axis=1, keepdims=True)
    rms = np.sqrt(np.linalg.eigvalsh(np.einsum("nki,nkj->nij", D, D) / 9.0)[:, 0].clip(0))
    return float(np.median(rms))


def explained_by_two_planes(depth, rc, tol_m: float, rng: np.random.Generator, half: int = 2) -> float:
    """Share of the near-side points of the cell's window that lie within ``tol_m`` of at most two RANSAC planes."""
    H, W = depth.shape
    r, c = int(rc[0]), int(rc[1])
    rows = np.arange(max(r - half, 0), min(r + half + 1, H))
    cols = np.mod(np.arange(c - half, c + half + 1), W)
    ok = depth.valid[np.ix_(rows, cols)]
    P = depth.points[np.ix_(rows, cols)][ok]
    rng_m = np.linalg.norm(P, axis=1)
    if len(P) < 4:
        return 0.0
    lo, hi = np.log(rng_m.min()), np.log(rng_m.max())
    if hi - lo >= 0.05:  # a depth step: the near side is the object whose corner is proposed
        P = P[np.log(rng_m) < 0.5 * (lo + hi)]
    left = np.ones(len(P), dtype=bool)
    for _ in range(2):
        Q = P[left]
        if len(Q) < 3:
            break
        idx = rng.integers(0, len(Q), size=(300, 3))
        normal = np.cross(Q[idx[:, 1]] - Q[idx[:, 0]], Q[idx[:, 2]] - Q[idx[:, 0]])
        norm = np.linalg.norm(normal, axis=1)
        good = norm > 1e-9
        if not good.any():
            break
        normal = normal[good] / norm[good, None]
        # Distance of every point from every hypothesis plane: |n . (q - a)|.
        d = np.abs(normal @ Q.T - np.einsum("hj,hj->h", normal, Q[idx[good, 0]])[:, None])
        best = int(np.argmax((d <= tol_m).sum(axis=1)))
        inl = d[best] <= tol_m
        if inl.sum() < 3:
            break
        sub = np.flatnonzero(left)
        left[sub[inl]] = False
    return float(1.0 - left.mean()) if len(P) else 0.0


def footprint_px(scene: RealScene, rc) -> float:
    """Image length (px) of one cell step: the cell's range along the neighbouring beams, projected (published pose)."""
    depth = scene.depth
    H, W = depth.shape
    r, c = int(rc[0]), int(rc[1])
    rho = float(depth.range_m[r, c])
    steps = []
    for a, b in (((min(r + 1, H - 1), c), (max(r - 1, 0), c)), ((r, (c + 1) % W), (r, (c - 1) % W))):
        d = np.array([depth.directions[a], depth.directions[b]])
        if not np.isfinite(d).all():
            continue
        uv, ok = scene.camera.project(transform_points(scene.T_published, rho * d))
        if ok.all():
            steps.append(float(np.linalg.norm(uv[0] - uv[1])) / max(abs(a[0] - b[0]) + abs(a[1] - b[1]), 1))
    return max(steps) if steps else np.nan


# Independent image-corner and ground measures (OpenCV's Harris detector and a RANSAC ground plane written here,
# not the proposal code's structure tensor or planes).
#: Harris corners: relative quality, minimum spacing (px), block size (px).
HARRIS_QUALITY, HARRIS_MIN_DIST, HARRIS_BLOCK = 0.01, 3, 5
#: A proposal's true projection is on a corner when a Harris corner lies within this many px...
ON_CORNER_PX = 3.0
#: ...and the corner is isolated when at most this many other Harris corners lie within ISOLATION_PX of it.
ISOLATION_PX, MAX_RIVALS = 10.0, 2
#: A point within this distance (m) of the scan's ground plane is on the ground.
GROUND_TOL_M = 0.15


def harris_corners(image: np.ndarray) -> np.ndarray:
    """(M, 2) ``(u, v)`` of OpenCV's Harris corners (goodFeaturesToTrack) of an RGB image."""
    import cv2

    gray = cv2.cvtColor(np.asarray(image), cv2.COLOR_RGB2GRAY)
    c = cv2.goodFeaturesToTrack(gray, 20000, HARRIS_QUALITY, HARRIS_MIN_DIST, blockSize=HARRIS_BLOCK,
                                useHarrisDetector=True, k=0.04)
    return np.zeros((0, 2)) if c is None else c.reshape(-1, 2).astype(np.float64)


def harris_verdict(corners_uv: np.ndarray, uv: np.ndarray) -> tuple[bool, bool]:
    """(a Harris corner within ON_CORNER_PX of ``uv``, and that corner isolated)."""
    if not np.all(np.isfinite(uv)) or len(corners_uv) == 0:
        return False, False
    d = np.linalg.norm(corners_uv - np.asarray(uv, dtype=np.float64).reshape(1, 2), axis=1)
    k = int(np.argmin(d))
    if d[k] > ON_CORNER_PX:
        return False, False
    rivals = int((np.linalg.norm(corners_uv - corners_uv[k], axis=1) <= ISOLATION_PX).sum()) - 1
    return True, rivals <= MAX_RIVALS


def ground_plane(depth, rng: np.random.Generator, hypotheses: int = 400) -> tuple[np.ndarray, float]:
    """The scan's ground: the RANSAC plane (unit normal ``n``, offset ``d``: ``n . x = d``) with the most
    points within GROUND_TOL_M among planes tilted at most 20 deg from the lidar's xy plane."""
    P = depth.points[depth.valid]
    P = P[rng.choice(len(P), size=min(len(P), 20000), replace=False)]
    idx = rng.integers(0, len(P), size=(hypotheses, 3))
    n = np.cross(P[idx[:, 1]] - P[idx[:, 0]], P[idx[:, 2]] - P[idx[:, 0]])
    norm = np.linalg.norm(n, axis=1)
    good = norm > 1e-9
    n = n[good] / norm[good, None]
    n *= np.sign(n[:, 2:3] + 1e-12)
    n, a = n[n[:, 2] >= np.cos(np.radians(20.0))], P[idx[good, 0]][n[:, 2] >= np.cos(np.radians(20.0))]
    d = np.einsum("hj,hj->h", n, a)
    count = (np.abs(P @ n.T - d[None]) <= GROUND_TOL_M).sum(axis=0)
    best = int(np.argmax(count))
    return n[best], float(d[best])


def on_ground(depth, rc, plane: tuple[np.ndarray, float], half: int = 2) -> bool:
    """The cell's point and most of its window's valid points lie on the ground plane."""
    n, d = plane
    H, W = depth.shape
    r, c = int(rc[0]), int(rc[1])
    rows = np.arange(max(r - half, 0), min(r + half + 1, H))
    cols = np.mod(np.arange(c - half, c + half + 1), W)
    P = depth.points[np.ix_(rows, cols)][depth.valid[np.ix_(rows, cols)]]
    here = abs(float(depth.points[r, c] @ n) - d) <= GROUND_TOL_M
    return bool(here and len(P) and np.mean(np.abs(P @ n - d) <= GROUND_TOL_M) >= 0.6)


@dataclass
class Judged:
    """Measures of one trial's proposals (one entry per proposal)."""

    reclick: list
    harris: list
    harris_footprint: list
    corner: list
    radius_px: list
    fits_loupe: list
    fits_zoomed: list
    vegetation: list
    far: list
    ground: list
    painted: list
    clean: list = None
    reason: str | None = None


def judge(scene: RealScene, harris: np.ndarray, plane, props, noise_m: float, loupe_px: int,
          max_ellipse_px: float, rng: np.random.Generator) -> Judged:
    """The benchmark's own verdict on each proposal (module docstring), from its true projection."""
    out = Judged([], [], [], [], [], [], [], [], [], [], [], [], getattr(props, "reason", None))
    for p in props:
        uv, ok = scene.camera.project(transform_points(scene.T_published, np.asarray(p.laser_xyz)[None]))
        near, isolated = harris_verdict(harris, uv[0]) if ok[0] else (False, False)
        foot = max(ON_CORNER_PX, np.nan_to_num(footprint_px(scene, p.laser_rc), nan=ON_CORNER_PX))
        d = np.linalg.norm(harris - uv[0], axis=1) if len(harris) and ok[0] else np.array([np.inf])
        veg = explained_by_two_planes(scene.depth, p.laser_rc, PLANE_TOL_NOISE * noise_m, rng) < MIN_EXPLAINED
        ground = on_ground(scene.depth, p.laser_rc, plane)
        far = float(np.linalg.norm(p.laser_xyz)) > FAR_M
        out.reclick.append(p.replaces is not None)
        out.harris.append(bool(near))
        out.harris_footprint.append(bool(d.min() <= foot))
        out.corner.append(bool(near and isolated and not veg and not ground and not far))
        out.clean.append(bool(near and isolated))
        out.radius_px.append(p.radius_3sigma_px)
        out.fits_loupe.append(p.radius_3sigma_px <= loupe_px / 2)
        out.fits_zoomed.append(p.radius_3sigma_px <= max_ellipse_px)
        out.vegetation.append(veg)
        out.far.append(far)
        out.ground.append(ground)
        out.painted.append(bool(ground and painted_corner(scene, harris, p.laser_rc, p.laser_xyz)))
    return out


def candidate_ceiling(scene: RealScene, harris: np.ndarray, plane, noise_m: float) -> tuple[int, float, float]:
    """Every laser candidate the camera sees under the published pose: their number, the share whose true
    projection is a corner by the benchmark's verdict (what any choice among them can reach) and their median
    cell footprint (px)."""
    from calib_core.guide.candidates import find_candidates
    from calib_core.guide.visibility import visible_in_camera

    cand = find_candidates(scene.depth)
    scan_points, _ = scene.depth.valid_points()
    uv, seen = visible_in_camera(scene.camera, scene.T_published, scan_points, cand.points_lidar)
    rng = np.random.default_rng(BENCH_SEED)
    verdict, feet = [], []
    for i in np.flatnonzero(seen):
        rc = cand.rows_cols[i]
        feet.append(footprint_px(scene, rc))
        near, isolated = harris_verdict(harris, uv[i])
        verdict.append(near and isolated and not on_ground(scene.depth, rc, plane)
                       and np.linalg.norm(cand.points_lidar[i]) <= FAR_M
                       and explained_by_two_planes(scene.depth, rc, PLANE_TOL_NOISE * noise_m, rng) >= MIN_EXPLAINED)
    return len(verdict), float(np.mean(verdict)), float(np.nanmedian(feet))


ARMS = {"none": "no screen", "screen": "screen"}


def run_scene(name: str, scene: RealScene, trials: int) -> dict:
    """Each arm over ``trials`` trials: arm -> list of Judged."""
    noise = range_noise_m(scene.depth)
    loupe = loupe_side_px(scene.camera.width, scene.camera.height)
    screen = app_screen(scene.camera.width, scene.camera.height)
    screens = {"none": None, "screen": screen}
    harris = harris_corners(scene.image)
    plane = ground_plane(scene.depth, np.random.default_rng(BENCH_SEED))
    out: dict = {arm: [] for arm in ARMS}
    out.update({"loupe_px": loupe, "max_ellipse_px": screen.max_ellipse_px, "noise_m": noise,
                "ceiling": candidate_ceiling(scene, harris, plane, noise), "props": []})
    session = None
    for k in range(trials):
        rng = np.random.default_rng([BENCH_SEED, k])
        pairs = by_eye_pairs(scene, rng)
        if session is None:
            session = GuidedSession(scene.depth, scene.camera, pairs, image=scene.image)
        else:  # the scan's candidates and corners are computed once
            session.pairs = list(pairs)
            session._update_state()
        for arm, scr in screens.items():
            session.propose_options["screen"] = scr
            props = session.proposals(N_PROPOSALS)
            out[arm].append(judge(scene, harris, plane, props, noise, loupe, screen.max_ellipse_px,
                                  np.random.default_rng([BENCH_SEED, k, 1])))
            if arm == "screen":
                out["props"].append(list(props))
        log(f"{name} trial {k + 1}/{trials}: " + ", ".join(f"{len(out[a][-1].radius_px)} {a}" for a in ARMS))
    return out


def _share(judged: list, attr: str, new_only: bool = False) -> tuple[float, int]:
    values = [v for j in judged for v, re in zip(getattr(j, attr), j.reclick) if not (new_only and re)]
    return (float(np.mean(values)) if values else float("nan")), len(values)


def table(results: dict, trials: int) -> list[str]:
    """The arms' table (markdown)."""
    pct = (lambda x: "-" if not np.isfinite(x) else f"{100 * x:.0f} %")  # noqa: E731
    lines = [
        f"| scene | proposals | shown ({trials} trials, at most 20 each) | of them re-clicks | corner (bench verdict) | "
        "corner, new cells only | painted-marking corner, new cells | Harris corner within 3 px | "
        "Harris within one cell footprint | "
        "median 3-sigma radius | fits the loupe at zoom 1 | fits the app's limit | off vegetation | "
        f"off far background (> {FAR_M:.0f} m) | off the ground | trials with none |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, res in results.items():
        for arm, label in ARMS.items():
            js = res[arm]
            corner, n = _share(js, "corner")
            corner_new, n_new = _share(js, "corner", new_only=True)
            radii = [v for j in js for v in j.radius_px]
            med = f"{np.median(radii):.1f} px" if radii else "-"
            empty = sum(1 for j in js if not j.radius_px)
            lines.append(
                f"| {name} (loupe {res['loupe_px']} px, limit {res['max_ellipse_px']:.0f} px) | {label} | {n} | "
                f"{n - n_new} | {pct(corner)} | {pct(corner_new)} ({n_new}) | "
                f"{pct(_share(js, 'painted', new_only=True)[0])} | {pct(_share(js, 'harris')[0])} | "
                f"{pct(_share(js, 'harris_footprint')[0])} | {med} | {pct(_share(js, 'fits_loupe')[0])} | "
                f"{pct(_share(js, 'fits_zoomed')[0])} | {pct(1 - _share(js, 'vegetation')[0])} | "
                f"{pct(1 - _share(js, 'far')[0])} | {pct(1 - _share(js, 'ground')[0])} | {empty} |")
        n_all, share_all, _ = res["ceiling"]
        lines.append(f"| {name} | every laser candidate the camera sees (published pose) | {n_all} | | "
                     f"{pct(share_all)} | | | | | | | | | | | |")
    return lines


def save_crops(scene: RealScene, props: list, folder: Path, half: int = 40, scale: int = 4) -> list[Path]:
    """For each proposal a PNG: the photo (left) and the scan rendered from the camera under the *published*
    calibration (right, range-shaded; intensity-shaded for a ``marking``), both cropped around the proposal's
    true projection (a green cross) and
    magnified ``scale`` times -- what a person judging "is this a corner?" looks at."""
    import cv2

    from calib_core.render import render_from_camera, shade_render

    folder.mkdir(parents=True, exist_ok=True)
    render = render_from_camera(scene.depth, scene.camera, scene.T_published)
    shades = {}
    for mode in ("range", "intensity"):  # markings show in the scan's intensity, not its range
        try:
            rgba = shade_render(render, scene.depth, mode)
        except Exception:  # noqa: BLE001 - a scan without intensity: range only
            continue
        shades[mode] = np.where(rgba[..., 3:4] > 0, rgba[..., :3], 40).astype(np.uint8)
    H, W = scene.image.shape[:2]
    out = []
    for k, p in enumerate(props):
        uv, ok = scene.camera.project(transform_points(scene.T_published, np.asarray(p.laser_xyz)[None]))
        if not ok[0]:
            continue
        u, v = np.rint(uv[0]).astype(int)
        tiles = []
        shaded = shades.get("intensity" if p.kind == "marking" else "range", shades["range"])
        for img in (scene.image, shaded):
            pad = np.pad(img, ((half, half), (half, half), (0, 0)))
            tile = cv2.resize(pad[v:v + 2 * half + 1, u:u + 2 * half + 1], None, fx=scale, fy=scale,
                              interpolation=cv2.INTER_NEAREST)
            c = half * scale + scale // 2
            cv2.drawMarker(tile, (c, c), (0, 255, 0), cv2.MARKER_CROSS, 24, 1)
            tiles.append(tile)
        name = folder / f"p{k:02d}_{'reclick' if p.replaces is not None else p.kind}_r{p.laser_rc[0]}_c{p.laser_rc[1]}.png"
        cv2.imwrite(str(name), cv2.cvtColor(np.concatenate([tiles[0], np.full((tiles[0].shape[0], 8, 3), 255,
                                                                               np.uint8), tiles[1]], axis=1),
                                           cv2.COLOR_RGB2BGR))
        out.append(name)
    return out


DOC = REPO / "docs" / "guide_performance.md"
START, END = "<!-- bench.guide_by_eye: start -->", "<!-- bench.guide_by_eye: end -->"


def section_of(path: Path = DOC) -> str:
    """The by-eye section (with its markers) of a guide_performance.md, or "" (bench/guide.py keeps it when it
    rewrites the file)."""
    text = path.read_text() if path.is_file() else ""
    i, j = text.find(START), text.find(END)
    return text[i:j + len(END)] + "\n" if 0 <= i < j else ""


def write_section(body: str, path: Path = DOC) -> None:
    """Put ``body`` between the markers of ``path`` (replacing the old section, else appended)."""
    text = path.read_text() if path.is_file() else ""
    block = f"{START}\n{body.rstrip()}\n{END}\n"
    old = section_of(path)
    text = text.replace(old, block) if old else text.rstrip("\n") + "\n\n" + block
    path.write_text(text)


def markdown(results: dict, trials: int, seconds: float, load: tuple) -> str:
    """The section: how it was made, the table, the reasons shown when a trial had no proposal."""
    lines = [
        "## Proposals a person can check (issue 20)",
        "",
        f"Generated by `python -m bench.guide_by_eye --trials {trials} --write` (bench/guide_by_eye.py) in "
        f"{seconds:.0f} s; load average at the start and the end {load[0]:.2f}, {load[1]:.2f} (2 cores, shared). "
        "Each trial: 5 rough pairs made by eye (cells of the committed real_data pairs, pixels 5-15 px off their "
        "projection under the published calibration, no precision given), then the first 20 proposals with the "
        "camera image: without a screen (`screen=None`) and with the app's screen (`ProposalScreen`, "
        "`max_ellipse_px` = the app's limit, `app.guide_support.max_ellipse_px_for`). The verdict is the benchmark's own, from each proposal's laser point projected with the "
        "*published* calibration: *corner* = an OpenCV Harris corner (`goodFeaturesToTrack`, quality "
        f"{HARRIS_QUALITY}, block {HARRIS_BLOCK}) within {ON_CORNER_PX:.0f} px with at most {MAX_RIVALS} other "
        f"Harris corners within {ISOLATION_PX:.0f} px of it, and the laser window explained by at most two RANSAC "
        f"planes (>= {100 * MIN_EXPLAINED:.0f} % of its near-side points within {PLANE_TOL_NOISE:.0f} range noise: "
        "not vegetation), not on the ground (a RANSAC ground plane fitted here, +-"
        f"{GROUND_TOL_M:.2f} m) and not beyond {FAR_M:.0f} m. Re-clicks of the rough pairs are proposals too "
        "and are counted; the column *new cells only* leaves them out. *Painted-marking corner*: a new cell on that "
        "ground plane with an isolated Harris corner within one cell footprint and the scan's raw intensity in its "
        "5 x 5 window spanning 3x or more (90th over 10th percentile: paint against asphalt).",
        "",
    ]
    lines += table(results, trials)
    ceil = {name: res["ceiling"] for name, res in results.items()}
    if ceil:
        lines += ["", "The limit (measured here): of every laser candidate the camera sees, "
                  + ", ".join(f"{100 * c[1]:.0f} % ({name})" for name, c in ceil.items())
                  + " are a corner by this verdict at their true projection; their median cell footprint is "
                  + ", ".join(f"{c[2]:.1f} px ({name})" for name, c in ceil.items()) + "."]
    reasons = sorted({j.reason for res in results.values() for j in res["screen"] if j.reason})
    if reasons:
        lines += ["", "Reasons shown when a trial had no proposal: " + "; ".join(f"\"{r}\"" for r in reasons) + "."]
    return "\n".join(lines)


def with_rows_before(md: str, before: str, label: str) -> str:
    """``md`` with the proposal rows of an older run's table (``before``) inserted after its own table, their
    proposals column prefixed with ``label``."""
    rows = [line for line in before.splitlines() if line.startswith("| ") and "| scene |" not in line
            and "every laser candidate" not in line]
    rows = [line.replace(" | no screen | ", f" | {label}: no screen | ").replace(" | screen | ", f" | {label}: screen | ")
            for line in rows]
    lines = md.splitlines()
    last = max(i for i, line in enumerate(lines) if line.startswith("|"))
    return "\n".join(lines[:last + 1] + rows + lines[last + 1:])


SESSIONS = REPO / "tests" / "by_eye_sessions"


def session_pairs(path: Path) -> list[Pair]:
    """The complete pairs (a laser cell and a pixel) of a by-eye session or kept-session file, as the app has them."""
    from calib_core.io.yaml_files import read_yaml_mapping

    doc = read_yaml_mapping(path, "session file")
    return [Pair(tuple(e["laser_rc"]), None, tuple(e["pixel"]), id=e.get("id"), precision_px=e.get("precision_px"))
            for e in doc.get("pairs", []) if e.get("pixel") is not None and e.get("laser_rc") is not None]


def corner_within_footprint(scene: RealScene, harris: np.ndarray, plane, noise_m: float, rc, xyz,
                            rng: np.random.Generator) -> tuple[bool, bool]:
    """The judge's corner verdict for one cell at 3 px, and with "within one cell footprint" instead of 3 px
    (:func:`footprint_px`; a whole-cell pick's own error is up to about a footprint)."""
    uv, ok = scene.camera.project(transform_points(scene.T_published, np.asarray(xyz, dtype=np.float64)[None]))
    if not ok[0] or len(harris) == 0 or np.linalg.norm(xyz) > FAR_M or on_ground(scene.depth, rc, plane):
        return False, False
    d = np.linalg.norm(harris - uv[0], axis=1)
    k = int(np.argmin(d))
    isolated = int((np.linalg.norm(harris - harris[k], axis=1) <= ISOLATION_PX).sum()) - 1 <= MAX_RIVALS
    if not isolated or explained_by_two_planes(scene.depth, rc, PLANE_TOL_NOISE * noise_m, rng) < MIN_EXPLAINED:
        return False, False
    foot = max(ON_CORNER_PX, np.nan_to_num(footprint_px(scene, rc), nan=ON_CORNER_PX))
    return bool(d[k] <= ON_CORNER_PX), bool(d[k] <= foot)


def painted_corner(scene: RealScene, harris: np.ndarray, rc, xyz, contrast: float = 3.0, half: int = 2) -> bool:
    """A ground cell at a painted marking's corner, by this module's own measures: an isolated Harris corner within
    one cell footprint of its true projection, and the scan's raw intensity in its window spanning at least
    ``contrast`` times (90th over 10th percentile: paint against asphalt)."""
    from calib_core.display_images import find_intensity

    found = find_intensity(scene.depth.meta.get("field_images"))
    uv, ok = scene.camera.project(transform_points(scene.T_published, np.asarray(xyz, dtype=np.float64)[None]))
    if found is None or not ok[0] or len(harris) == 0 or np.linalg.norm(xyz) > FAR_M:
        return False
    d = np.linalg.norm(harris - uv[0], axis=1)
    k = int(np.argmin(d))
    foot = max(ON_CORNER_PX, np.nan_to_num(footprint_px(scene, rc), nan=ON_CORNER_PX))
    isolated = int((np.linalg.norm(harris - harris[k], axis=1) <= ISOLATION_PX).sum()) - 1 <= MAX_RIVALS
    H, W = scene.depth.shape
    r, c = int(rc[0]), int(rc[1])
    rows, cols = np.arange(max(r - half, 0), min(r + half + 1, H)), np.arange(max(c - half, 0), min(c + half + 1, W))
    values = np.asarray(found[1], dtype=np.float64)[np.ix_(rows, cols)][scene.depth.valid[np.ix_(rows, cols)]]
    if d[k] > foot or not isolated or len(values) < 4:
        return False
    lo, hi = np.percentile(values, [10, 90])
    return bool(hi >= contrast * max(lo, 1e-6))


#: Steps of a continued session (:func:`walk_session`).
WALK_STEPS = 15


def walk_session(scene: RealScene, session: GuidedSession, pairs: list[Pair], harris, plane, noise_m: float,
                 screen: ProposalScreen, steps: int = WALK_STEPS) -> list[tuple]:
    """Go on from ``pairs`` as a person who clicks every proposal's true corner: each step takes the first
    proposal (a re-click or a new cell), clicked at its laser point's projection under the published pose plus
    0.5 px noise, and the session re-ranks.  Returns one ``(kind, rc, corner at 3 px, corner within a footprint,
    painted corner, 3-sigma radius px, fits the loupe limit)`` per *new* cell offered at a step."""
    rng = np.random.default_rng(BENCH_SEED)
    session.pairs, session.skipped, session.dropped = list(pairs), [], []
    session._update_state()
    session.propose_options["screen"] = screen
    offered = []
    for _ in range(steps):
        props = session.proposals(N_PROPOSALS)
        if not props:
            break
        p = props[0]
        uv, ok = scene.camera.project(transform_points(scene.T_published, np.asarray(p.laser_xyz)[None]))
        if not ok[0]:
            session.not_a_corner(p)
            continue
        if p.replaces is None:
            c3, cf = corner_within_footprint(scene, harris, plane, noise_m, p.laser_rc, p.laser_xyz, rng)
            painted = painted_corner(scene, harris, p.laser_rc, p.laser_xyz)
            clean = harris_verdict(harris, uv[0])
            offered.append((p.kind, tuple(p.laser_rc), c3, cf, painted, p.radius_3sigma_px,
                            p.radius_3sigma_px <= screen.max_ellipse_px, bool(clean[0] and clean[1])))
        session.accept(p, uv[0] + rng.normal(0.0, 0.5, 2))
    return offered


def session_rows(name: str, scene: RealScene, paths: list[Path]) -> list[str]:
    """From each by-eye session's pairs: the app's next proposals (new cells judged) and the screen's left-out
    cells per test with how many the judge calls a corner (markdown lines)."""
    from collections import Counter

    screen = app_screen(scene.camera.width, scene.camera.height)
    harris = harris_corners(scene.image)
    plane = ground_plane(scene.depth, np.random.default_rng(BENCH_SEED))
    noise = range_noise_m(scene.depth)
    lines = [f"### {name}: from the by-eye sessions", "",
             "| session | pairs | proposals | new cells | new: corner at 3 px | new: corner within a footprint | "
             "new: median 3-sigma radius | note |", "|---|---:|---:|---:|---:|---:|---:|---|"]
    left, judged3, judgedf = Counter(), Counter(), Counter()
    session = None
    for path in paths:
        pairs = session_pairs(path)
        if session is None:
            session = GuidedSession(scene.depth, scene.camera, pairs, image=scene.image)
        else:
            session.pairs = list(pairs)
            session._update_state()
        session.propose_options["screen"] = screen
        props = session.proposals(N_PROPOSALS)
        rng = np.random.default_rng(BENCH_SEED)
        new = [p for p in props if p.replaces is None]
        verdicts = [corner_within_footprint(scene, harris, plane, noise, p.laser_rc, p.laser_xyz, rng) for p in new]
        radius = f"{np.median([p.radius_3sigma_px for p in new]):.1f} px" if new else "-"
        lines.append(f"| {path.name if path.parent == SESSIONS else path} | {len(pairs)} | {len(props)} | {len(new)} | "
                     f"{sum(v[0] for v in verdicts)} | {sum(v[1] for v in verdicts)} | {radius} | {props.note or ''} |")
        for rc, test in zip(*props.left_out):
            c3, cf = corner_within_footprint(scene, harris, plane, noise, rc, scene.depth.points[rc[0], rc[1]], rng)
            left[str(test)] += 1
            judged3[str(test)] += c3
            judgedf[str(test)] += cf
    lines += ["", f"Left out by the screen, summed over the {len(paths)} sessions: test: cells (of them a corner by "
              "the judge at 3 px / within a footprint): "
              + "; ".join(f"{t}: {n} ({judged3[t]} / {judgedf[t]})" for t, n in left.most_common()) + "."]
    lines += ["", f"Continued {WALK_STEPS} steps from each session (:func:`walk_session`: the first proposal "
              "clicked at its true corner each step):", "",
              "| session | new cells offered | corner at 3 px | corner within a footprint | painted-marking corner | "
              "either | median 3-sigma radius | within the loupe limit | cells |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for path in paths:
        walk = walk_session(scene, session, session_pairs(path), harris, plane, noise, screen)
        n = len(walk)
        either = sum(1 for w in walk if w[3] or w[4])
        radius = f"{np.median([w[5] for w in walk]):.1f} px" if walk else "-"
        lines.append(f"| {path.name if path.parent == SESSIONS else path} | {n} | {sum(w[2] for w in walk)} | "
                     f"{sum(w[3] for w in walk)} | {sum(w[4] for w in walk)} | {either} | {radius} | "
                     f"{sum(w[6] for w in walk)} | {' '.join(f'{w[0]}{list(w[1])}' for w in walk)} |")
    return lines


def summary_rows(name: str, scene: RealScene, trials: int, paths: list[Path]) -> list[str]:
    """The figure issue guide9 improves, one markdown row per start: of the *new* cells proposed with the app's
    screen, the share whose laser point, projected with the published pose, lands within :data:`ON_CORNER_PX` of an
    isolated Harris corner (a clean photo corner: what the person will click), the median 3-sigma radius and the
    share whose ellipse fits the camera loupe at zoom 1 (half its side).  Starts: ``trials`` seeds of 5 rough
    pairs 5-15 px off (:func:`by_eye_pairs`), and each by-eye session continued :data:`WALK_STEPS` steps
    (:func:`walk_session`)."""
    res = run_scene(name, scene, trials)
    loupe = res["loupe_px"]
    pct = (lambda x: "-" if not np.isfinite(x) else f"{100 * x:.0f} %")  # noqa: E731
    new = [(c, r) for j in res["screen"] for c, r, re in zip(j.clean, j.radius_px, j.reclick) if not re]
    rows = [f"| {name} | {trials} rough starts | {len(new)} | {sum(c for c, _ in new)} | "
            f"{pct(np.mean([c for c, _ in new]) if new else np.nan)} | "
            f"{np.median([r for _, r in new]):.1f} px | " if new else
            f"| {name} | {trials} rough starts | 0 | 0 | - | - | ",
            ]
    rows[0] += f"{pct(np.mean([r <= loupe / 2 for _, r in new]) if new else np.nan)} |"
    screen = app_screen(scene.camera.width, scene.camera.height)
    harris = harris_corners(scene.image)
    plane = ground_plane(scene.depth, np.random.default_rng(BENCH_SEED))
    noise = range_noise_m(scene.depth)
    session = GuidedSession(scene.depth, scene.camera, session_pairs(paths[0]), image=scene.image) if paths else None
    walked = []
    for path in paths:
        walked += walk_session(scene, session, session_pairs(path), harris, plane, noise, screen)
    if paths:
        rows.append(f"| {name} | {len(paths)} by-eye sessions, {WALK_STEPS} steps each | {len(walked)} | "
                    f"{sum(w[7] for w in walked)} | {pct(np.mean([w[7] for w in walked]) if walked else np.nan)} | "
                    + (f"{np.median([w[5] for w in walked]):.1f} px | " if walked else "- | ")
                    + f"{pct(np.mean([w[5] <= loupe / 2 for w in walked]) if walked else np.nan)} |")
    kinds = sorted({w[0] for w in walked})
    rows.append(f"| {name} | (walk cells: {' '.join(f'{w[0]}{list(w[1])}' for w in walked) or 'none'}) | | | | | |"
                if kinds or paths else "")
    return [r for r in rows if r]


def ring_crossing_rows(name: str, scene: RealScene) -> list[str]:
    """Does the paint's corner rebuilt from the rings' crossings of its edges
    (:func:`bench.ring_crossing.ring_crossing_corner`) lie closer to the photo's corner than the
    ``marking`` cell does?  Every marking candidate the camera sees under the published pose, within
    :data:`FAR_M`, with an isolated Harris corner within 20 px of the cell: the distance (published pose) from that
    corner of the cell, of the rebuilt corner and of the cell nearest the rebuilt corner (markdown rows)."""
    from calib_core.guide.candidates import KINDS, find_candidates
    from calib_core.guide.marking_corner import edge_width_cells
    from bench.ring_crossing import point_at, ring_crossing_corner
    from calib_core.guide.visibility import visible_in_camera

    harris = harris_corners(scene.image)
    rivals = np.array([(np.linalg.norm(harris - h, axis=1) <= ISOLATION_PX).sum() - 1 for h in harris])
    clean = harris[rivals <= MAX_RIVALS]
    cand = find_candidates(scene.depth)
    scan_points, _ = scene.depth.valid_points()
    _, seen = visible_in_camera(scene.camera, scene.T_published, scan_points, cand.points_lidar)
    m = seen & (cand.kind == KINDS.index("marking")) & (np.linalg.norm(cand.points_lidar, axis=1) <= FAR_M)
    rc = cand.rows_cols[m]

    def dist(points: np.ndarray) -> np.ndarray:
        out = np.full(len(points), np.nan)
        ok = np.isfinite(points).all(axis=1)
        uv, _ = scene.camera.project(transform_points(scene.T_published, points[ok]))
        out[ok] = np.linalg.norm(clean[None] - uv[:, None], axis=2).min(axis=1)
        return out

    corner = ring_crossing_corner(scene.depth, rc)
    rebuilt = point_at(scene.depth, corner)
    nearest = np.rint(np.nan_to_num(corner)).astype(np.int64)
    nearest_pts = np.where(np.isfinite(rebuilt).all(axis=1)[:, None],
                           scene.depth.points[nearest[:, 0], nearest[:, 1]], np.nan)
    d_cell, d_rebuilt, d_nearest = dist(cand.points_lidar[m]), dist(rebuilt), dist(nearest_pts)
    sel = (d_cell <= 20.0) & np.isfinite(d_rebuilt)
    width = edge_width_cells(scene.depth, rc)
    rows = []
    for label, d in (("the marking cell", d_cell), ("the rebuilt corner", d_rebuilt),
                     ("the cell nearest the rebuilt corner", d_nearest)):
        dd = d[sel]
        rows.append(f"| {name} | {label} | {len(dd)} | {np.median(dd):.1f} px | "
                    f"{100 * np.mean(dd <= ON_CORNER_PX):.0f} % |" if len(dd) else f"| {name} | {label} | 0 | - | - |")
    rows.append(f"| {name} | (of the {int(m.sum())} markings, {int(np.isfinite(corner).all(axis=1).sum())} rebuilt; "
                f"edge smeared over more than one cell: {int((width > 1.0).sum())}, at most one: "
                f"{int((width <= 1.0).sum())}) | | | |")
    return rows


def main(argv=None) -> int:
    import os

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=5, help="trials per scene (default 5)")
    ap.add_argument("--crops", type=Path, default=None,
                    help="save photo | render crops around each proposal of the first trial (with the screen) here")
    ap.add_argument("--before", type=Path, default=None,
                    help="the printed output of this benchmark run on older code: its table rows are added, "
                         "labelled with --before-label")
    ap.add_argument("--before-label", default="before",
                    help="label of the --before rows (e.g. the commit they were measured on)")
    ap.add_argument("--sessions", action="store_true",
                    help="start from the by-eye walkthroughs' pairs (tests/by_eye_sessions and --session) instead")
    ap.add_argument("--session", action="append", default=[], metavar="SCENE=FILE",
                    help="another by-eye session file (SCENE kitti or pjlab), with --sessions; may be repeated")
    ap.add_argument("--write", action="store_true",
                    help="write the section into docs/guide_performance.md (between its markers)")
    ap.add_argument("--summary", action="store_true",
                    help="print only the clean-corner figure per scene (:func:`summary_rows`)")
    ap.add_argument("--ring-crossing", action="store_true",
                    help="measure the painted corners rebuilt from ring crossings (:func:`ring_crossing_rows`)")
    args = ap.parse_args(argv)
    if args.ring_crossing:
        lines = ["| scene | distance to the nearest clean photo corner (published pose) of | markings | median | "
                 "within 3 px |", "|---|---|---:|---:|---:|"]
        if kitti_available():
            lines += ring_crossing_rows("KITTI 000002", load_kitti())
        if manual_available():
            lines += ring_crossing_rows("PJLab manual_calib", load_manual())
        print("\n".join(lines))
        return 0
    if args.summary:
        lines = ["| scene | start | new cells proposed | at a clean photo corner (3 px) | share | "
                 "median 3-sigma radius | fits the loupe (zoom 1) |", "|---|---|---:|---:|---:|---:|---:|"]
        if kitti_available():
            lines += summary_rows("KITTI 000002", load_kitti(), args.trials, sorted(SESSIONS.glob("kitti_*.yaml")))
        if manual_available():
            lines += summary_rows("PJLab manual_calib", load_manual(), args.trials,
                                  sorted(SESSIONS.glob("pjlab_*.yaml")))
        print("\n".join(lines))
        return 0
    if args.sessions:
        extra = {"kitti": [], "pjlab": []}
        for item in args.session:
            scene_name, _, file = item.partition("=")
            if scene_name not in extra or not file:
                ap.error(f"--session wants kitti=FILE or pjlab=FILE, got {item!r}")
            extra[scene_name].append(Path(file))
        lines = []
        if kitti_available():
            lines += session_rows("KITTI 000002", load_kitti(), sorted(SESSIONS.glob("kitti_*.yaml")) + extra["kitti"])
        if manual_available():
            lines += [""] + session_rows("PJLab manual_calib", load_manual(),
                                         sorted(SESSIONS.glob("pjlab_*.yaml")) + extra["pjlab"])
        print("\n".join(lines))
        return 0
    t0 = time.time()
    load0 = os.getloadavg()[0]
    results = {}
    if kitti_available():
        scene = load_kitti()
        results["KITTI 000002"] = run_scene("KITTI 000002", scene, args.trials)
        if args.crops:
            save_crops(scene, results["KITTI 000002"]["props"][0], args.crops / "kitti")
    else:
        log(f"KITTI data not found at {KITTI}; skipped")
    if manual_available():
        scene = load_manual()
        results["PJLab manual_calib"] = run_scene("PJLab manual_calib", scene, args.trials)
        if args.crops:
            save_crops(scene, results["PJLab manual_calib"]["props"][0], args.crops / "pjlab")
    else:
        log(f"manual_calib data not found at {MANUAL}; skipped")
    md = markdown(results, args.trials, time.time() - t0, (load0, os.getloadavg()[0]))
    if args.before is not None:
        md = with_rows_before(md, args.before.read_text(), args.before_label)
    print(md)
    if args.write:
        write_section(md)
        log(f"wrote the section into {DOC}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
