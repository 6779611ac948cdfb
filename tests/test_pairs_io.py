"""Pairs files: parsing, errors, atomic saving, and resolving cells and pixels."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.errors import CalibError
from calib_core.lidar.depth_matrix import DepthMatrix
from calib_core.pairs import Pair, load_pairs_yaml, resolve_pairs, save_pairs_yaml


class _IdentityCamera:
    """A 101x81 pinhole with f = 50 px, centre (50, 40): bearings by hand."""

    model = "test"
    width, height = 101, 81

    def bearing(self, pixels):
        p = np.asarray(pixels, float)
        rays = np.stack([(p[:, 0] - 50) / 50, (p[:, 1] - 40) / 50, np.ones(len(p))], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def _depth():
    rng = np.arange(6, dtype=float).reshape(2, 3) + 1.0
    rng[1, 2] = np.nan
    dirs = np.zeros((2, 3, 3))
    dirs[..., 0] = 1.0
    pts = dirs * rng[..., None]
    return DepthMatrix(rng, dirs, pts, np.isfinite(rng))


def test_round_trip_keeps_every_value(tmp_path):
    pairs = [Pair((1, 2), None, (10.25, 3.5)), Pair(None, (0.1, -2.0, 3.3333333333333335), (0.0, 79.5))]
    path = tmp_path / "p.yaml"
    save_pairs_yaml(path, pairs)
    assert load_pairs_yaml(path) == pairs
    assert not list(tmp_path.glob(".*tmp")), "temporary file left behind"


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("pairs: [\n", "malformed YAML"),
        ("- 1\n- 2\n", "expected a YAML mapping"),
        ("other: []\n", "missing top-level key 'pairs'"),
        ("pairs: {a: 1}\n", "'pairs' must be a list"),
        ("pairs:\n  - pixel: [1, 2]\n", "exactly one of laser_rc or laser_xyz"),
        ("pairs:\n  - laser_rc: [1, 2]\n", "missing pixel"),
        ("pairs:\n  - laser_rc: [1.5, 2]\n    pixel: [1, 2]\n", "whole numbers"),
        ("pairs:\n  - laser_xyz: [1, 2]\n    pixel: [1, 2]\n", "expected 3 numbers"),
        ("pairs:\n  - laser_xyz: [1, .nan, 2]\n    pixel: [1, 2]\n", "finite"),
        ("pairs:\n  - laser_rc: [1, 2]\n    pixel: [a, 2]\n", "expected 2 numbers"),
        ("pairs:\n  - laser_rc: [1, 2]\n    pixel: [1, 2]\n    colour: red\n", "unknown key"),
    ],
)
def test_malformed_files_name_the_problem(tmp_path, text, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CalibError) as err:
        load_pairs_yaml(path)
    assert fragment in str(err.value)
    assert str(path) in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(CalibError, match="pairs file not found"):
        load_pairs_yaml(tmp_path / "nope.yaml")


def test_resolve_uses_cells_points_and_pixel_rays():
    depth = _depth()
    pairs = [Pair((0, 1), None, (50.0, 40.0)), Pair(None, (1.0, 2.0, 3.0), (100.0, 40.0))]
    pts, bearings, pixels = resolve_pairs(pairs, depth, _IdentityCamera())
    np.testing.assert_allclose(pts, [[2.0, 0, 0], [1.0, 2.0, 3.0]])
    # (50, 40) is the principal point: straight ahead.  (100, 40) is 45 deg right.
    np.testing.assert_allclose(bearings[0], [0, 0, 1])
    np.testing.assert_allclose(bearings[1], [np.sqrt(0.5), 0, np.sqrt(0.5)])
    np.testing.assert_allclose(pixels, [[50, 40], [100, 40]])


@pytest.mark.parametrize(
    "pair, fragment",
    [
        (Pair((1, 2), None, (5.0, 5.0)), "has no laser return"),
        (Pair((2, 0), None, (5.0, 5.0)), "outside the 2x3 depth matrix"),
        (Pair((0, 0), None, (100.6, 5.0)), "outside the 101x81 camera image"),
        (Pair((0, 0), None, (5.0, -0.6)), "outside the 101x81 camera image"),
    ],
)
def test_resolve_rejects_bad_picks(pair, fragment):
    with pytest.raises(CalibError, match=fragment):
        resolve_pairs([Pair((0, 0), None, (1.0, 1.0)), pair], _depth(), _IdentityCamera())


def test_cells_without_scan_are_an_error():
    with pytest.raises(CalibError, match="no scan"):
        resolve_pairs([Pair((0, 0), None, (1.0, 1.0))], None, _IdentityCamera())


def test_saved_files_get_ordinary_permissions(tmp_path):
    import os

    path = tmp_path / "p.yaml"
    save_pairs_yaml(path, [Pair((0, 0), None, (1.0, 2.0))])
    umask = os.umask(0)
    os.umask(umask)
    assert (path.stat().st_mode & 0o777) == (0o666 & ~umask)
