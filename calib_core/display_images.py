"""Grey images of per-cell laser values (intensity, range) and a contrast control, for display only.

Gray 0 is kept for cells without a value, as in :func:`calib_core.bearing_angle.ba_to_display`.
"""

from __future__ import annotations

import numpy as np

#: Names a scan's reflectance field goes by (lower case), best first.
INTENSITY_FIELDS = ("intensity", "reflectance", "remission", "reflectivity", "i", "signal")


def field_to_gray(values: np.ndarray, min_gray: int = 32, low_pct: float = 1.0, high_pct: float = 99.0,
                  log: bool = False) -> np.ndarray:
    """Grey levels ``(H, W) uint8`` of a per-cell value image: a linear stretch of its ``low_pct``..``high_pct``
    percentiles onto ``min_gray..255``; 0 where the value is NaN.

    Parameters
    ----------
    values : (H, W) float
        E.g. intensity (sensor units) or range (metres); NaN where the cell has no value.
    log : bool
        Stretch ``log(values)`` (for range: near and far both keep detail); values <= 0 count as missing.
    """
    v = np.asarray(values, dtype=np.float64)
    if log:
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(v > 0, np.log(np.where(v > 0, v, 1.0)), np.nan)
    ok = np.isfinite(v)
    out = np.zeros(v.shape, np.uint8)
    if not ok.any():
        return out
    lo, hi = np.percentile(v[ok], [low_pct, high_pct])
    span = hi - lo if hi > lo else 1.0
    scaled = np.clip((v[ok] - lo) / span, 0.0, 1.0)
    out[ok] = np.round(min_gray + scaled * (255 - min_gray)).astype(np.uint8)
    return out


def apply_contrast(gray: np.ndarray, contrast: float, min_gray: int = 1) -> np.ndarray:
    """``gray`` with its contrast scaled by ``contrast`` about the median of the non-zero levels.

    ``contrast`` 1 returns the image unchanged; 2 doubles every level's distance from the median
    (clipped to ``min_gray..255``); 0 stays 0 (no return).
    """
    g = np.asarray(gray)
    c = float(contrast)
    if c == 1.0:
        return g
    ok = g > 0
    if not ok.any():
        return g
    mid = float(np.median(g[ok]))
    out = np.zeros_like(g, dtype=np.uint8)
    out[ok] = np.clip(np.round(mid + (g[ok].astype(np.float64) - mid) * c), min_gray, 255).astype(np.uint8)
    return out


def find_intensity(field_images: dict | None) -> tuple[str, np.ndarray] | None:
    """The scan's reflectance image ``(name, (H, W) float)`` among per-cell field images, or None."""
    if not field_images:
        return None
    by_lower = {str(k).lower(): (k, v) for k, v in field_images.items()}
    for name in INTENSITY_FIELDS:
        if name in by_lower:
            key, values = by_lower[name]
            values = np.asarray(values, dtype=np.float64)
            if np.isfinite(values).any():
                return str(key), values
    return None
