"""Snapping a click to a sub-pixel image corner, only where that cannot make it worse.

The click stands unless the strongest image corner within the click's
3-sigma disc passes the clean-isolated-corner test
(:func:`calib_core.guide.image_corners.clean_corner`) and
``cv2.cornerSubPix`` from that corner stays within the disc.  Sub-pixel
refinement drifts by a few tenths of a pixel even on a good corner, so
snapping only pays for clicks noisier than that: ``min_click_sigma_px``
(measured in bench/guide.py on the sample's corners).
"""

from __future__ import annotations

import numpy as np

from calib_core.guide.image_corners import CornerGate, CornerImage, clean_corner, refine_subpixel, strongest_near

__all__ = ["snap_clicks", "SNAP_MIN_CLICK_SIGMA_PX", "SNAP_GATE"]

#: Clicks at least this noisy (1-sigma px) are snapped; finer clicks stand.
SNAP_MIN_CLICK_SIGMA_PX = 1.0
#: The gate used for snapping.
SNAP_GATE = CornerGate(min_strength=0.02, min_ratio=0.4, isolation=0.2, isolation_radius_px=6.0)


def snap_clicks(
    ci: CornerImage,
    clicks: np.ndarray,
    click_sigma_px: float,
    gate: CornerGate = SNAP_GATE,
    min_click_sigma_px: float = SNAP_MIN_CLICK_SIGMA_PX,
) -> tuple[np.ndarray, np.ndarray]:
    """Snapped clicks (module docstring).

    Parameters
    ----------
    ci : CornerImage
    clicks : (N, 2) array_like
        Clicked ``(u, v)``.
    click_sigma_px : float
        1-sigma of the clicks, px.

    Returns
    -------
    pixels : (N, 2) ndarray
        The snapped corner where the gate passed, else the click.
    snapped : (N,) bool
    """
    c = np.asarray(clicks, dtype=np.float64).reshape(-1, 2)
    if click_sigma_px < min_click_sigma_px or len(c) == 0:
        return c.copy(), np.zeros(len(c), dtype=bool)
    radius = max(1.5, 3.0 * float(click_sigma_px))
    peak, _ = strongest_near(ci, c, radius)
    ok = clean_corner(ci, peak, gate)
    refined = np.full_like(c, np.nan)
    if ok.any():
        refined[ok] = refine_subpixel(ci, peak[ok])
    ok &= np.all(np.isfinite(refined), axis=1)
    ok &= np.linalg.norm(np.where(ok[:, None], refined, c) - c, axis=1) <= radius
    return np.where(ok[:, None], refined, c), ok
