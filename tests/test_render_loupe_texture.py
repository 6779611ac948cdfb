"""The render loupe's texture blends only its crop (a click used to blend the whole render: 10-30 ms, 190 ms at
1920 x 1080 under load), and must show exactly what the whole blended pane shows there.  Truth: the whole pane
blended with the module's own :func:`pane_texture`, padded and cut here with numpy."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.shown_render import NO_RETURN_RGB, PAD_RGB, TEXTURE_TEXELS, loupe_texture, pane_texture

H, W = 37, 53


def reference(rgba: np.ndarray | None, u0: int, v0: int, n: int) -> np.ndarray:
    pane = np.full((H, W, 3), NO_RETURN_RGB, np.uint8) if rgba is None else pane_texture(rgba)
    m = 100  # margin: every crop below lies within it
    padded = np.empty((H + 2 * m, W + 2 * m, 3), np.uint8)
    padded[:] = np.asarray(PAD_RGB, np.uint8)
    padded[m:m + H, m:m + W] = pane
    crop = padded[v0 + m:v0 + m + n, u0 + m:u0 + m + n]
    k = max(1, TEXTURE_TEXELS // n)
    return np.repeat(np.repeat(crop, k, axis=0), k, axis=1)


@pytest.mark.parametrize("u0, v0, n", [(10, 8, 16), (-5, 3, 16), (45, 30, 16), (-7, -9, 12), (0, 0, 37),
                                       (60, 5, 10), (-30, -30, 9), (20, 40, 8)])
def test_the_loupe_crop_is_the_whole_blended_pane_cut_there(u0, v0, n):
    rng = np.random.default_rng(abs(u0 * 100 + v0))
    rgba = rng.integers(0, 256, (H, W, 4), dtype=np.uint8)
    rgba[..., 3][rng.random((H, W)) < 0.3] = 0  # no return there
    camera = SimpleNamespace(width=W, height=H)
    # Range shading (colour): cut as it is (grey shadings are stretched over the crop: test_app_frictions_run14).
    got = loupe_texture(SimpleNamespace(rgba=rgba, mode="range"), camera, u0, v0, n)
    assert got.dtype == np.uint8 and np.array_equal(got, reference(rgba, u0, v0, n))
    assert np.array_equal(loupe_texture(None, camera, u0, v0, n), reference(None, u0, v0, n))
