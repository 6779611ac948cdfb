"""The proposals' clear-evidence screen (calib_core.guide.evidence, issue 20) on the sample and two real frames.

Every proposal is checked here against measures written in this file, not the
screen's vectorised code: a plane fitted (SVD) to each support cell's
same-surface 3 x 3 block, the cell footprint from projecting the neighbouring
beams at the cell's range, the 3-sigma box from the covariance's diagonal, the
image corners' local maxima from scipy's maximum filter.  Real data:
``../shared/data`` (KITTI object 000002 and PJLab manual_calib, with the
committed real_data pairs' cells clicked 5-15 px off, as by eye).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from calib_core.cameras import load_camera
from calib_core.guide.corner_probability import scan_range_noise_m
from calib_core.guide.evidence import REASON_ROUGH_ALIGNMENT, ProposalScreen
from calib_core.guide.session import GuidedSession
from calib_core.io.images import load_image_rgb
from calib_core.io.kitti_calib import read_kitti_camera2
from calib_core.io.scan_readers import load_scan
from calib_core.pairs import Pair, load_pairs_yaml
from calib_core.synthetic import load_sample, simulate_pairs
from calib_core.transforms import transform_points
from repo_paths import SAMPLE

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
KITTI = DATA / "kitti_object_000002"
MANUAL = DATA / "pjlab_opencalib_lidar2camera" / "manual_calib"


# ------------------------------------------------------------------ independent measures
def planar_support_share(depth, rc, tol_m: float, screen: ProposalScreen) -> float:
    """Share of the window's support (near side of a >= 5 % depth step, else all valid cells) whose same-surface
    3 x 3 block fits a plane (SVD, one cell at a time) within ``tol_m`` RMS and spans two rows and two columns."""
    H, W = depth.shape
    wrap = depth.meta.get("wrap_cols", False)
    h = screen.plane_half
    cells = [(r, c % W if wrap else c) for r in range(rc[0] - h, rc[0] + h + 1) for c in range(rc[1] - h, rc[1] + h + 1)]
    cells = [(r, c) for r, c in cells if 0 <= r < H and 0 <= c < W and depth.valid[r, c]]
    if not cells:
        return 0.0
    log_r = np.log([depth.range_m[r, c] for r, c in cells])
    if log_r.max() - log_r.min() >= 0.05:
        mid = 0.5 * (log_r.max() + log_r.min())
        cells = [cell for cell, lr in zip(cells, log_r) if lr < mid]
    planar = 0
    for r, c in cells:
        block = []
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if wrap:
                    cc %= W
                if 0 <= rr < H and 0 <= cc < W and depth.valid[rr, cc] and \
                        abs(depth.range_m[rr, cc] - depth.range_m[r, c]) <= screen.same_surface_rel * depth.range_m[r, c]:
                    block.append((dr, dc, depth.points[rr, cc]))
        if len(block) < screen.min_plane_neighbours or len({b[0] for b in block}) < 2 or len({b[1] for b in block}) < 2:
            continue
        P = np.array([b[2] for b in block])
        rms = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(P))
        planar += rms <= tol_m
    return planar / len(cells)


def footprint_px(depth, camera, T, rc) -> float:
    """Image length of one cell step: the cell's range along the row and column neighbours' beams, projected."""
    H, W = depth.shape
    r, c = rc
    rho = depth.range_m[r, c]
    out = 0.0
    for a, b in (((min(r + 1, H - 1), c), (max(r - 1, 0), c)), ((r, (c + 1) % W), (r, (c - 1) % W))):
        uv, ok = camera.project(transform_points(T, rho * np.array([depth.directions[a], depth.directions[b]])))
        steps = abs(a[0] - b[0]) + abs(a[1] - b[1])
        if ok.all() and np.isfinite(uv).all():
            out = max(out, float(np.linalg.norm(uv[0] - uv[1])) / steps)
    return out


def corner_maxima(lam_min: np.ndarray, window: int) -> np.ndarray:
    """``lam_min`` where it is the largest of its window-sized neighbourhood (scipy maximum filter), else 0."""
    peaks = (lam_min == ndimage.maximum_filter(lam_min, size=2 * window + 1, mode="constant")) & (lam_min > 0)
    return np.where(peaks, lam_min, 0.0)


def top_two_corners(maxima: np.ndarray, pixel, cov, min_search_px: float) -> tuple[float, float]:
    """The two largest :func:`corner_maxima` inside the 3-sigma ellipse (or the ``min_search_px`` disc)."""
    u0, v0 = int(np.rint(pixel[0])), int(np.rint(pixel[1]))
    r = int(np.ceil(max(3.0 * np.sqrt(np.linalg.eigvalsh(cov).max()), min_search_px))) + 1
    H, W = maxima.shape
    vs, us = np.mgrid[max(v0 - r, 0):min(v0 + r + 1, H), max(u0 - r, 0):min(u0 + r + 1, W)]
    d = np.stack([us - u0, vs - v0], axis=-1).astype(np.float64)
    m2 = np.einsum("hwa,ab,hwb->hw", d, np.linalg.inv(cov), d)
    inside = (m2 <= 9.0) | ((d**2).sum(-1) <= min_search_px**2)
    values = np.sort(maxima[vs, us][inside])[::-1]
    return (float(values[0]) if len(values) else 0.0), (float(values[1]) if len(values) > 1 else 0.0)


def check_screen(props, depth, camera, T, corners, screen: ProposalScreen) -> None:
    """Every screened proposal (not a re-click) passes each test, measured here; ``T`` is the pose they were
    computed at."""
    tol = screen.max_plane_rms_noise * scan_range_noise_m(depth)
    maxima = corner_maxima(corners.lam_min, corners.window)
    for p in props:
        cov = np.asarray(p.pixel_cov)
        # The 3-sigma ellipse fits the loupe, and its box keeps the margin from the border.
        assert 3.0 * np.sqrt(np.linalg.eigvalsh(cov).max()) <= screen.max_ellipse_px + 1e-9
        half_box = 3.0 * np.sqrt(np.diag(cov))
        lo, hi = p.pixel - half_box, p.pixel + half_box
        assert lo.min() >= screen.border_margin_px
        assert hi[0] <= camera.width - 1 - screen.border_margin_px and hi[1] <= camera.height - 1 - screen.border_margin_px
        if p.replaces is not None:
            continue
        # Not on the scan's first or last rows: there the scan ends, not the object.
        assert screen.scan_edge_rows <= p.laser_rc[0] < depth.shape[0] - screen.scan_edge_rows
        assert np.linalg.norm(p.laser_xyz) <= screen.max_range_m
        # Resolution: pose from the pairs (the session's), footprint computed by projecting the neighbours.
        assert footprint_px(depth, camera, T, p.laser_rc) <= 1.05 * screen.max_footprint_px
        assert planar_support_share(depth, p.laser_rc, tol, screen) >= screen.min_planar_share
        first, second = top_two_corners(maxima, p.pixel, cov, screen.min_search_px)
        assert first >= screen.min_corner_strength and first >= screen.min_corner_dominance * second


def proposals_of(session: GuidedSession, n: int, screen: ProposalScreen | None):
    session.propose_options["screen"] = screen
    return session.proposals(n)


# ------------------------------------------------------------------ the sample
@pytest.fixture(scope="module")
def sample():
    return load_sample(SAMPLE)


def test_screen_on_the_sample(sample):
    session = GuidedSession(sample.depth, sample.camera, simulate_pairs(sample, 6, np.random.default_rng(3), 1.0),
                            image=sample.image)
    screen = ProposalScreen(max_ellipse_px=20.0)
    props = proposals_of(session, 60, screen)
    assert len(props) >= 10 and props.reason is None
    check_screen(props, sample.depth, sample.camera, session.state.T_camera_lidar, session.corners, screen)
    # The independent measures can fail: without the screen some proposals fail the plane test or the
    # dominant-corner test.
    tol = screen.max_plane_rms_noise * scan_range_noise_m(sample.depth)
    loose = [p for p in proposals_of(session, 200, None) if p.replaces is None]
    flat = [planar_support_share(sample.depth, p.laser_rc, tol, screen) >= screen.min_planar_share for p in loose]
    dominant = []
    maxima = corner_maxima(session.corners.lam_min, session.corners.window)
    for p in loose:
        first, second = top_two_corners(maxima, p.pixel, p.pixel_cov, 4.0)
        dominant.append(first >= 0.01 and first >= 2 * second)
    assert not all(flat) and not all(dominant)


def test_ellipses_larger_than_the_loupe_ask_for_a_better_rough_alignment(sample, tmp_path, capsys):
    """From 4 pairs clicked 8 px off (a careless rough alignment) no ellipse fits a 3 px loupe: no proposal, and
    the reason says what to do (the Proposals object, and the CLI's output)."""
    from app.cli import main as cli_main
    from calib_core.pairs import save_pairs_yaml

    pairs = simulate_pairs(sample, 4, np.random.default_rng(2), 8.0)
    session = GuidedSession(sample.depth, sample.camera, pairs, image=sample.image)
    big = proposals_of(session, 20, ProposalScreen(max_ellipse_px=60.0))
    assert len(big) > 0 and min(p.radius_3sigma_px for p in big) > 3.0
    none = proposals_of(session, 20, ProposalScreen(max_ellipse_px=3.0))
    assert list(none) == [] and "do a better rough alignment first" in none.reason
    assert none.reason == REASON_ROUGH_ALIGNMENT.format(limit=3.0, smallest=float(none.reason.split("smallest is ")[1]
                                                                                   .split(" px")[0]))
    save_pairs_yaml(tmp_path / "pairs.yaml", pairs)
    args = ["propose", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
            "--pairs", str(tmp_path / "pairs.yaml"), "--image", str(SAMPLE / "image.png"), "-o", str(tmp_path / "p.yaml")]
    assert cli_main(args + ["--max-ellipse-px", "3"]) == 0
    assert "do a better rough alignment first" in capsys.readouterr().out
    assert cli_main(args + ["--max-ellipse-px", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "max_ellipse_px" in err[0]


# ------------------------------------------------------------------ real frames
def by_eye(pairs, depth, camera, T, rng, n: int = 5) -> list[Pair]:
    out = []
    for i in rng.choice(len(pairs), size=n, replace=False):
        rc = pairs[i].laser_rc
        uv, _ = camera.project(transform_points(T, depth.points[rc[0], rc[1]][None]))
        a, length = rng.uniform(0, 2 * np.pi), rng.uniform(5.0, 15.0)
        out.append(Pair(rc, None, tuple(float(x) for x in uv[0] + length * np.array([np.cos(a), np.sin(a)]))))
    return out


def _kitti():
    _, T = read_kitti_camera2(KITTI / "calib" / "000002.txt")
    return (load_scan(KITTI / "velodyne" / "000002.bin"), load_camera(ROOT / "real_data" / "kitti_000002_camera.yaml"),
            load_image_rgb(KITTI / "image_2" / "000002.png"), T,
            load_pairs_yaml(ROOT / "real_data" / "pairs" / "kitti_000002_pairs.yaml"))


def _manual():
    doc = json.loads((MANUAL / "top_center_lidar-to-center_camera-extrinsic.json").read_text())
    T = np.array(doc["top_center_lidar-to-center_camera-extrinsic"]["param"]["sensor_calib"]["data"], dtype=float)
    return (load_scan(MANUAL / "0.pcd", beams=64),
            load_camera(MANUAL / "center_camera-intrinsic.json", image_size=(1920, 1200)),
            load_image_rgb(MANUAL / "0.png"), T, load_pairs_yaml(ROOT / "real_data" / "pairs" / "manual_calib_pairs.yaml"))


@pytest.mark.realdata
@pytest.mark.parametrize("name, loader, present", [
    ("kitti", _kitti, (KITTI / "velodyne" / "000002.bin").is_file()),
    ("manual_calib", _manual, (MANUAL / "0.pcd").is_file()),
])
def test_screen_on_real_frames(name, loader, present):
    if not present:
        pytest.skip(f"real data for {name} not found under {DATA}")
    from app.guide_support import max_ellipse_px_for

    depth, camera, image, T, pairs = loader()
    screen = ProposalScreen(max_ellipse_px=max_ellipse_px_for(camera.width, camera.height))
    shown = 0
    for seed in (0, 1):
        session = GuidedSession(depth, camera, by_eye(pairs, depth, camera, T, np.random.default_rng(seed)),
                                image=image)
        props = proposals_of(session, 20, screen)
        shown += len(props)
        check_screen(props, depth, camera, session.state.T_camera_lidar, session.corners, screen)
        assert props or props.reason  # nothing proposed: the person is told why
    # Not a vacuous check.  (10 before re-clicks were limited to the pairs where they clearly help: each trial
    # then offered a re-click of every one of its 5 rough pairs.)
    assert shown >= 4
