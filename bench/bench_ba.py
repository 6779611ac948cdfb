"""Time the four Bearing Angle images on depth matrices of common sizes.

Usage::

    python bench/bench_ba.py [--repeats 30]

Scenes are a box-shaped room (6 x 4 x 3 m around the scanner) with 1 cm
range noise and 5 % missing returns, so every code path (NaN masking,
wrap-around) is exercised.  For each depth matrix the table gives the median
time of ``bearing_angle_images`` (all four traces) once the beam geometry is
cached ("warm"), the median of first calls on fresh depth matrices ("cold",
geometry included), and, for reference, a plain float32 numpy version with
``np.arccos`` and the same precomputed ``cos dphi``.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from calib_core.bearing_angle import BA_DIRECTIONS, PREVIOUS_NEIGHBOUR, bearing_angle_images
from calib_core.lidar import rotating_scanner_beams, rotating_scanner_depth, spherical_depth
from calib_core.lidar.spherical import spherical_directions

ROOM_HALF_EXTENT_M = np.array([3.0, 2.0, 1.5])


def room_range(origins: np.ndarray, directions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Range along each beam to the walls of an axis-aligned box room, noisy, 5 % dropped."""
    with np.errstate(divide="ignore"):
        wall = np.where(directions > 0, ROOM_HALF_EXTENT_M, -ROOM_HALF_EXTENT_M)
        t = (wall - origins) / directions
    rho = np.min(np.where(t > 0, t, np.inf), axis=-1) + rng.normal(0.0, 0.01, directions.shape[:-1])
    rho[rng.random(rho.shape) < 0.05] = np.nan
    return rho


def make_depths(rng: np.random.Generator):
    # The paper's scanner: theta per row (1 deg), phi per column (0.5 deg), full turn.
    theta = np.deg2rad(np.arange(89.5, -90.0, -1.0))[:, None]
    phi = np.deg2rad(np.arange(720) * 0.5)
    for dx, dz in ((0.0, 0.0), (0.05, 0.03)):
        origins, directions = rotating_scanner_beams(theta, phi, dx, dz)
        label = "rotating_2d" + (f" dx={dx} dz={dz}" if dx or dz else "")
        yield label, rotating_scanner_depth(room_range(origins, directions, rng), theta, phi, dx, dz, wrap_cols=True)
    # Spinning multi-beam lidars: 64 x 1800 (0.2 deg) and 128 x 2048.
    for n_rows, n_cols, top, bottom in ((64, 1800, 2.0, -24.9), (128, 2048, 22.5, -22.5)):
        elevation = np.deg2rad(np.linspace(top, bottom, n_rows))
        azimuth = np.pi - (np.arange(n_cols) + 0.5) * 2.0 * np.pi / n_cols
        directions = spherical_directions(elevation[:, None], azimuth[None, :])
        rho = room_range(np.zeros(3), directions, rng)
        yield "spherical", spherical_depth(rho, elevation, azimuth, wrap_cols=True)


def plain_numpy_ba(depth, cos_dphi: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Reference: the law-of-cosines arccos in float32, neighbours by padding."""
    n_rows, n_cols = depth.shape
    padded = np.full((n_rows + 2, n_cols + 2), np.nan, np.float32)
    padded[1:-1, 1:-1] = depth.range_m
    padded[1:-1, 0], padded[1:-1, -1] = padded[1:-1, -2], padded[1:-1, 1]
    cur = padded[1:-1, 1:-1]
    images = {}
    for name, (d_row, d_col) in PREVIOUS_NEIGHBOUR.items():
        prev = padded[1 + d_row : 1 + d_row + n_rows, 1 + d_col : 1 + d_col + n_cols]
        c = cos_dphi[name]
        with np.errstate(invalid="ignore", divide="ignore"):
            arg = (cur - prev * c) / np.sqrt(cur * cur + prev * prev - 2 * cur * prev * c)
            images[name] = np.arccos(np.clip(arg, -1, 1))
    return images


def median_ms(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    rng = np.random.default_rng(0)

    print(f"{'depth matrix':>12}  {'model':<28} {'warm ms':>8} {'cold ms':>8} {'plain np ms':>12}")
    for label, depth in make_depths(rng):
        bearing_angle_images(depth)  # fills the geometry cache
        warm = median_ms(lambda: bearing_angle_images(depth), args.repeats)
        # A shallow copy is a new DepthMatrix object: its geometry is not cached yet.
        cold = median_ms(lambda: bearing_angle_images(copy.copy(depth)), max(3, args.repeats // 5))
        wrap = np.concatenate([depth.directions[:, -1:], depth.directions, depth.directions[:, :1]], axis=1)
        pad = np.full((depth.shape[0] + 2,) + wrap.shape[1:], np.nan)
        pad[1:-1] = wrap
        cos_dphi = {}
        for name, (d_row, d_col) in PREVIOUS_NEIGHBOUR.items():
            prev = pad[1 + d_row : 1 + d_row + depth.shape[0], 1 + d_col : 1 + d_col + depth.shape[1]]
            cos_dphi[name] = np.sum(depth.directions * prev, axis=2).astype(np.float32)
        plain = median_ms(lambda: plain_numpy_ba(depth, cos_dphi), args.repeats)
        shape = f"{depth.shape[0]}x{depth.shape[1]}"
        print(f"{shape:>12}  {label:<28} {warm:8.2f} {cold:8.2f} {plain:12.2f}")
    print(f"(four traces: {', '.join(BA_DIRECTIONS)}; median of {args.repeats} repeats)")


if __name__ == "__main__":
    main()
