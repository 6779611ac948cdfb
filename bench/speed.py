"""Speed of every live step: median wall time of repeated runs.

Inputs are built once, outside the timed region, from the committed sample
(its OCam camera, image, scan and true pose) and seeded random draws.  Times
are single-process wall clock on whatever machine runs the benchmark; the
report prints the CPU it ran on.
"""

from __future__ import annotations

import copy
import cProfile
import io
import pstats
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from calib_core.transforms import transform_points

from .common import BENCH_SEED, BenchScene, log, time_median


@dataclass
class Timing:
    """One timed step.

    Attributes
    ----------
    group, label : str
        What was timed (``group`` names the table, ``label`` the row).
    median_s : float
    runs : int
    detail : str
        Input description.
    min_s : float
        Fastest run.
    """

    group: str
    label: str
    median_s: float
    runs: int
    detail: str = ""
    min_s: float = float("nan")


@dataclass
class SpeedReport:
    timings: list[Timing] = field(default_factory=list)
    #: Step name -> callable that re-runs it once, for profiling a missed target.
    steps: dict[str, Callable[[], Any]] = field(default_factory=dict)
    click_breakdown: list[Timing] = field(default_factory=list)
    click_note: str = ""
    solve_breakdown: list[Timing] = field(default_factory=list)

    def get(self, group: str, label: str) -> Timing | None:
        for t in self.timings:
            if t.group == group and t.label == label:
                return t
        return None


def timed(rep: "SpeedReport", group: str, label: str, fn: Callable[[], Any], repeats: int, detail: str = "",
          warmup: int = 1, min_total_s: float = 0.0, step: str | None = None) -> Timing:
    """Time ``fn`` into ``rep``; a step that raises is recorded as failed (NaN) with its message."""
    try:
        med, runs, best = time_median(fn, repeats, warmup=warmup, min_total_s=min_total_s)
    except Exception as exc:  # noqa: BLE001 -- the report must show the failure, not stop
        msg = str(exc).strip().splitlines()
        med, runs, best = float("nan"), 0, float("nan")
        detail = f"FAILED: {type(exc).__name__}: {msg[-1] if msg else ''}"[:300]
        log(f"  {group} {label}: {detail}")
    t = Timing(group, label, med, runs, detail, best)
    rep.timings.append(t)
    if step is not None:
        rep.steps[step] = fn
    return t


# ------------------------------------------------------------------ inputs
def spherical_room_depth(rows: int, cols: int, seed: int = 0):
    """A spinning-lidar depth matrix (common beam origin) of a furnished box room.

    Rows span elevation +15 .. -25 deg, columns a full turn (``wrap_cols``);
    ranges are the distance to the walls, floor and ceiling of a 7 x 5 x 2.8 m
    room with a few boxes, plus 1 cm noise; 3 % of the cells have no return.
    """
    from calib_core.lidar import spherical_depth, spherical_directions

    rng = np.random.default_rng([BENCH_SEED, rows, cols, seed])
    el = np.radians(np.linspace(15.0, -25.0, rows))
    az = np.linspace(0.0, 2 * np.pi, cols, endpoint=False)
    d = spherical_directions(el[:, None], az[None, :]).reshape(-1, 3)
    lo, hi = np.array([-3.2, -2.3, -1.2]), np.array([3.8, 2.7, 1.6])
    with np.errstate(divide="ignore", invalid="ignore"):
        t_far = np.where(d > 0, hi / d, np.where(d < 0, lo / d, np.inf))
    rng_m = t_far.min(axis=1)
    # A few boxes: slab intersection, nearest hit wins.
    for _ in range(6):
        c = rng.uniform([-2.5, -1.8, -1.2], [3.0, 2.2, -0.6])
        h = rng.uniform(0.2, 0.6, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (c - h) / d, (c + h) / d
        tn = np.nanmax(np.minimum(t1, t2), axis=1)
        tf = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (tn <= tf) & (tn > 0.1)
        rng_m = np.where(hit, np.minimum(rng_m, tn), rng_m)
    rng_m = rng_m.reshape(rows, cols) + rng.normal(0, 0.01, (rows, cols))
    rng_m[rng.random((rows, cols)) < 0.03] = np.nan
    return spherical_depth(rng_m, el, az, wrap_cols=True)


def solve_inputs(bs: BenchScene, n: int, rng: np.random.Generator):
    """``n`` scan points visible in the image, clicked with 1 px noise: solver input."""
    sc = bs.scene
    pts = sc.depth.points[sc.depth.valid]
    uv, ok = sc.camera.project(transform_points(sc.T_camera_lidar, pts))
    idx = rng.choice(np.flatnonzero(ok), n, replace=False)
    px = uv[idx] + rng.normal(0, 1.0, (n, 2))
    px = np.clip(px, -0.5, [sc.camera.width - 0.5, sc.camera.height - 0.5])
    return pts[idx], sc.camera.bearing(px), px


def dense_cloud(bs: BenchScene, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points like a dense scan of the sample room: scan points plus 1 cm jitter."""
    pts = bs.scene.depth.points[bs.scene.depth.valid]
    idx = rng.integers(0, len(pts), n)
    return pts[idx] + rng.normal(0, 0.01, (n, 3))


# ----------------------------------------------------------------- profile
def profile_text(fn: Callable[[], Any], runs: int = 5, top: int = 12) -> str:
    """cProfile of ``runs`` calls as Markdown: the package's functions by cumulative time
    (where a fix goes) and all functions by own time (where the time is spent)."""
    try:
        fn()
    except Exception as exc:  # noqa: BLE001
        return f"Not profiled: the step fails with `{type(exc).__name__}: {str(exc).strip().splitlines()[-1]}`."
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(runs):
        fn()
    prof.disable()
    st = pstats.Stats(prof, stream=io.StringIO())
    total = st.total_tt
    repo = str(Path(__file__).resolve().parents[1]) + "/"
    rows = []
    for (file, line, func), (cc, nc, tt, ct, _) in st.stats.items():  # type: ignore[attr-defined]
        where = file.replace(repo, "")
        if "site-packages/" in where:
            where = where.split("site-packages/")[1]
        name = f"`{where}:{line} {func}`" if line else f"`{func}`"
        ours = file.startswith(repo) and not where.startswith("bench/")
        rows.append((tt, ct, nc, name, ours))

    def table(sel, key, title):
        out = [f"{title}\n", "| own time | cumulative | calls | function |", "|---:|---:|---:|---|"]
        for tt, ct, nc, name, _ in sorted(sel, key=key)[:top]:
            out.append(f"| {1e3 * tt / runs:.2f} ms | {1e3 * ct / runs:.2f} ms | {nc / runs:.0f} | {name} |")
        return "\n".join(out)

    parts = [
        table([r for r in rows if r[4]], lambda r: -r[1], "Package functions by cumulative time (per call of the step):"),
        table(rows, lambda r: -r[0], "All functions by own time (per call of the step):"),
        f"Total profiled time per call: {1e3 * total / runs:.1f} ms (cProfile adds overhead).",
    ]
    return "\n\n".join(parts)


# ------------------------------------------------------------------ steps
def run_speed(bs: BenchScene, quick: bool = False) -> SpeedReport:
    """Time every live step on the sample scene ``bs``."""
    from calib_core.bearing_angle import bearing_angle_images
    from calib_core.overlays import colorize_points
    from calib_core.panorama import Panorama
    from calib_core.solve import solve_extrinsics

    rep = SpeedReport()
    rng = np.random.default_rng([BENCH_SEED, 9])
    sc = bs.scene
    scale = 0.3 if quick else 1.0
    reps = lambda n: max(3, int(n * scale))  # noqa: E731

    # --- BA images, 4 directions.
    ba_inputs = [
        ("180x720", sc.depth, "the sample scan: rotating 2-D scanner, beams with offsets (eq. 3)"),
        ("180x720 spherical", spherical_room_depth(180, 720), "spherical model, common beam origin"),
        ("64x1800", spherical_room_depth(64, 1800), "spherical model, common beam origin"),
        ("128x2048", spherical_room_depth(128, 2048), "spherical model, common beam origin"),
    ]
    for label, depth, what in ba_inputs:
        # Warm: the beam geometry of this depth matrix is cached (every later call in the app).
        t = timed(rep, "ba", label, lambda d=depth: bearing_angle_images(d), reps(30), what + "; geometry cached",
                  warmup=2, min_total_s=0.5 * scale, step=f"ba {label}")
        # Cold: a shallow copy is a new DepthMatrix, so its geometry is computed again (first call on a scan).
        c = timed(rep, "ba", label + " (first call)", lambda d=depth: bearing_angle_images(copy.copy(d)), reps(10),
                  what + "; geometry computed in the call", warmup=1)
        log(f"  BA images {label}: {1e3 * t.median_s:.2f} ms (first call {1e3 * c.median_s:.2f} ms)")

    # --- solve: initial pose + LM + covariance.
    for n in (10, 100, 1000):
        pts, brg, px = solve_inputs(bs, n, rng)
        f = lambda p=pts, b=brg, x=px: solve_extrinsics(p, b, camera=sc.camera, pixels=x)  # noqa: E731
        t = timed(rep, "solve", f"{n} pairs", f, reps(40) if n < 1000 else 3,
                  "angular cost, OCam camera, 1 px click noise", warmup=2 if n < 1000 else 1,
                  min_total_s=0.5 * scale if n < 1000 else 0.0, step=f"solve {n}")
        log(f"  solve {n} pairs: {1e3 * t.median_s:.2f} ms")

    solve_parts(bs, rep, reps)

    # --- colourise with the occlusion test.
    for n, label in ((100_000, "100k"), (1_000_000, "1M"), (2_000_000, "2M")):
        cloud = dense_cloud(bs, n, rng)
        f = lambda c=cloud: colorize_points(c, sc.image, sc.camera, sc.T_camera_lidar, occlusion=True)  # noqa: E731
        t = timed(rep, "colorize", f"{label} points", f, reps(10 if n <= 1_000_000 else 5),
                  "OCam 640x480, occlusion test on", step=f"colorize {label}")
        log(f"  colorize {label}: {1e3 * t.median_s:.1f} ms")
        del cloud

    # --- panorama.
    t0 = time.perf_counter()
    pano = Panorama.for_camera(sc.camera)
    build_s = time.perf_counter() - t0
    rep.timings.append(Timing("panorama", "build maps (once per camera)", build_s, 1,
                              f"Panorama.for_camera, {pano.width}x{pano.height}", build_s))
    t = timed(rep, "panorama", "render (per image)", lambda: pano.render(sc.image), reps(50),
              f"{pano.width}x{pano.height} from 640x480", warmup=2, min_total_s=0.3 * scale, step="panorama render")
    log(f"  panorama render: {1e3 * t.median_s:.2f} ms")

    # --- click to updated error and overlays.
    click_time(bs, rep, reps)
    return rep


def solve_parts(bs: BenchScene, rep: SpeedReport, reps: Callable[[int], int], n: int = 10) -> None:
    """Time the stages of ``solve_extrinsics`` for ``n`` pairs through the package's own functions."""
    import numpy as np

    from calib_core import solve as S
    from calib_core.solve import refine

    sc = bs.scene
    pts, brg, px = solve_inputs(bs, n, np.random.default_rng([BENCH_SEED, 10]))
    T0, _, _ = S.initial_pose(pts, brg)
    T, _ = refine.refine_pose(T0, pts, brg, cost="angular")
    E = refine.tangent_basis(brg)
    x_opt = np.concatenate([np.zeros(3), T[:3, 3]])
    parts = [
        ("whole solve_extrinsics", lambda: S.solve_extrinsics(pts, brg, camera=sc.camera, pixels=px)),
        ("validate_pairs (input checks)", lambda: S.validate_pairs(pts, brg)),
        ("initial_pose (Quan-Lan + P3P candidates)", lambda: S.initial_pose(pts, brg)),
        ("  of which quan_lan_pose", lambda: S.bearing_pnp.quan_lan_pose(pts, brg)),
        ("refine_pose, angular LM (scipy least_squares)", lambda: refine.refine_pose(T0, pts, brg, cost="angular")),
        ("Jacobian + covariance", lambda: refine.covariance_from_jacobian(
            refine.angular_jacobian(x_opt, T[:3, :3], pts, brg, E), 0.01, T[:3, :3])),
        ("pixel residuals (camera.project)", lambda: sc.camera.project(pts @ T[:3, :3].T + T[:3, 3])),
    ]
    sub = SpeedReport()
    for label, fn in parts:
        rep.solve_breakdown.append(timed(sub, "solve parts", label, fn, reps(40), warmup=2))


def click_time(bs: BenchScene, rep: SpeedReport, reps: Callable[[int], int]) -> None:
    """Server-side time from a click to the updated error and overlays.

    Uses the app's own handler when ``app.server`` exposes one; otherwise
    times the core steps the app runs on a click (see ``rep.click_note``).
    """
    from app.state import AnnotationState
    from calib_core.bearing_angle import bearing_angle_images
    from calib_core.overlays import ba_edge_points, colorize_points, project_lidar_points
    from calib_core.pairs import load_pairs_yaml, resolve_pairs
    from calib_core.solve import solve_extrinsics

    from .common import SAMPLE_DIR

    sc = bs.scene
    pairs = load_pairs_yaml(SAMPLE_DIR / "pairs.yaml")
    tmp = Path(tempfile.mkdtemp(prefix="ba-calib-bench-"))
    state = AnnotationState(sc.depth.valid, (sc.camera.width, sc.camera.height), session_path=tmp / "session.yaml")
    ids = state.import_pairs(pairs)
    # Cached once per scan, as the app does: BA images and their edge points.
    ba = bearing_angle_images(sc.depth)
    edge_pts = np.concatenate([ba_edge_points(img, sc.depth)[0] for img in ba.values()])
    scan_pts = sc.depth.points[sc.depth.valid]
    pick = ids[0]
    u0, v0 = pairs[0].pixel
    counter = [0]

    def step_click():
        counter[0] += 1
        state.move_pixel(pick, u0 + 0.25 * (counter[0] % 2), v0)

    def step_resolve():
        return resolve_pairs(state.pairs(), sc.depth, sc.camera)

    inp = step_resolve()

    def step_solve():
        return solve_extrinsics(*inp[:2], camera=sc.camera, pixels=inp[2])

    res = step_solve()

    def step_edges():
        return project_lidar_points(res.T_camera_lidar, sc.camera, edge_pts)

    def step_table():
        return [f"{i:3d} {r_px:7.2f} px {r_deg:7.3f} deg" for i, (r_px, r_deg) in enumerate(zip(res.residual_px, res.residual_deg))]

    def step_colour():
        return colorize_points(scan_pts, sc.image, sc.camera, res.T_camera_lidar, occlusion=True)

    steps = [
        ("record the click (AnnotationState.move_pixel, atomic session save)", step_click),
        ("resolve pairs (calib_core.pairs.resolve_pairs)", step_resolve),
        ("solve: initial + LM + covariance (solve_extrinsics)", step_solve),
        (f"reproject BA-edge points ({len(edge_pts)} points, project_lidar_points)", step_edges),
        ("residual table (per-pair strings)", step_table),
        (f"recolour the scan ({len(scan_pts)} points, colorize_points with occlusion)", step_colour),
    ]
    total = 0.0
    sub = SpeedReport()
    for label, fn in steps:
        t = timed(sub, "click", label, fn, reps(30), warmup=2)
        rep.click_breakdown.append(t)
        total += t.median_s

    def whole():
        step_click()
        r, b, p = resolve_pairs(state.pairs(), sc.depth, sc.camera)
        s = solve_extrinsics(r, b, camera=sc.camera, pixels=p)
        project_lidar_points(s.T_camera_lidar, sc.camera, edge_pts)
        [f"{x:.2f}" for x in s.residual_px]
        colorize_points(scan_pts, sc.image, sc.camera, s.T_camera_lidar, occlusion=True)

    t = timed(rep, "click", "click to updated error and overlays", whole, reps(30),
              f"{len(pairs)} pairs on the sample; sum of the step medians {1e3 * total:.1f} ms", warmup=2, step="click")
    rep.click_note = (
        "`app.server` exposes no click handler that can be called without a browser, so this times the "
        "core steps the app runs on a click, in order, with the app's `AnnotationState` (session saved to a "
        "temporary file) and the BA images and their edge points computed once per scan, as the app caches them."
    )
    log(f"  click to update: {1e3 * t.median_s:.1f} ms")

