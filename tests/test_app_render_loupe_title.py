"""By-eye runs 11 and 12 (docs/by_eye.md): after a pair was made in the render loupe, a photo click starting the
next pair re-framed the render loupe, but its title still named the last pair's cell ("r12 c1228 · 9.69 m") until
the next laser click.  Driven through :class:`app_driver.AppDriver` on the committed sample; truth is the render's
own cell map (``cell_rc``) at the crop's centre."""

from __future__ import annotations

import numpy as np

from app_driver import AppDriver


def _uniform_pixels(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels whose 3 x 3 neighbourhood shows one cell (no doubt which cell a title should name there)."""
    c = cells[..., 0].astype(np.int64) * 100_000 + cells[..., 1]
    ok = cells[..., 0] >= 0
    same = np.ones_like(ok)
    for dv in range(-1, 2):
        for du in range(-1, 2):
            same &= np.roll(np.roll(c, dv, axis=0), du, axis=1) == c
    same[:1], same[-1:], same[:, :1], same[:, -1:] = False, False, False, False
    return np.nonzero(ok & same)


def test_a_photo_click_for_the_next_pair_names_the_render_loupes_new_centre(app):
    d = AppDriver(app)
    assert d.wait_render()
    cells = d.render_shown.render.cell_rc
    vs, us = _uniform_pixels(cells)
    _, shown = app.display_from_pixels(np.c_[us, vs].astype(np.float64))  # pixels the camera view shows
    order = np.argsort(np.hypot(us - app.camera.width / 2, vs - app.camera.height / 2))
    order = order[np.asarray(shown, dtype=bool)[order]]
    vs, us = vs[order], us[order]
    assert len(us) > 100
    # Pair 1: a photo click, then a click at the centre of the render loupe (its laser end).
    assert d.click_camera(float(us[0]), float(vs[0])) == [] and app.loupes.shows_render
    rc = app.loupes.render_crop
    assert d.click("loupe_ba", (float(rc.n // 2), float(rc.n // 2))) == []
    first = app.state.picks[-1].laser_rc
    assert first is not None and f"r{first[0]} c{first[1]}" in d.loupe_title("ba")
    # Pair 2 starts on the photo far away, on a pixel whose cell differs from pair 1's.
    k = next(i for i in range(len(us)) if abs(int(us[i]) - int(us[0])) > 100
             and tuple(int(x) for x in cells[vs[i], us[i]]) != tuple(first))
    assert d.click_camera(float(us[k]), float(vs[k])) == [] and app.state.pending() is not None
    centre = tuple(int(x) for x in cells[vs[k], us[k]])
    title = d.loupe_title("ba")
    assert f"r{first[0]} c{first[1]} " not in title + " ", title
    assert f"r{centre[0]} c{centre[1]}" in title and f"{app.depth.range_m[centre]:.2f} m" in title, (centre, title)
