"""Edge pairs: a laser point whose pixel lies on a straight image edge and may slide along it.

A laser ring crossing a painted lane line is a precise laser point, but the photo shows only the
line, not the ring: the pixel is known ACROSS the line and hardly at all along it.  Such a pair
states the edge's angle ``a`` (degrees from +u towards +v, in [0, 180)); with ``t = (cos a, sin a)``
the edge direction and ``n = (-sin a, cos a)`` its normal (pixels ``(u, v)``), its click covariance
is, in px^2,

    Sigma_px = sigma^2 (n n^T + k^2 t t^T),     k = EDGE_SLIDE,

so along the edge the click says next to nothing.  The solve whitens the angular residual with the
camera's tangent Jacobian ``A`` (px/rad; :mod:`calib_core.solve.whiten`): replacing ``A`` by
``M^-1 A`` with ``M = n n^T + k t t^T`` (symmetric, ``M^2 = n n^T + k^2 t t^T``) makes the click
term ``sigma^2 (M^-1 A)^-1 (M^-1 A)^-T = sigma^2 A^-1 M^2 A^-T``, exactly the covariance above
carried into the tangent plane, so the laser term, the re-whitening, the covariance and the
outlier test work unchanged.

The pixel error reported for an edge pair is its distance across the edge,
``|(projected - clicked) . n|``: the along-edge offset is not an error.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibError

__all__ = ["EDGE_SLIDE", "check_edge_deg", "edge_frames", "edge_tangent_jacobian", "slide_along_edges",
           "edge_pixel_errors", "edge_click_covariance"]

#: How many times less an edge pair's pixel says along its edge than across it (1-sigma ratio).
EDGE_SLIDE = 30.0


def check_edge_deg(pixel_edge_deg: object, n: int) -> np.ndarray | None:
    """Validate a per-pair edge angle ``(N,)`` in degrees, NaN for an ordinary (corner) pair.

    Returns the angles in [0, 180) with NaN kept, or None when none is given or every one is NaN (no
    edge pair: the solve takes its usual paths).  An infinite value raises one :class:`CalibError` line
    naming the pair's position.
    """
    if pixel_edge_deg is None:
        return None
    try:
        a = np.asarray(pixel_edge_deg, dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibError(f"pixel_edge_deg must be {n} angles in degrees (NaN for a corner pair)") from None
    if a.shape != (n,):
        raise CalibError(f"pixel_edge_deg must hold one angle per pair ({n}), got shape {a.shape}")
    bad = np.flatnonzero(np.isinf(a))
    if bad.size:
        raise CalibError(f"pair {bad[0]}: edge angle must be a finite number of degrees, got {a[bad[0]]!r}")
    if np.isnan(a).all():
        return None
    return np.mod(a, 180.0)


def edge_frames(edge_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit edge directions ``t`` and normals ``n`` ``(N, 2)`` in pixels ``(u, v)`` (NaN rows stay NaN)."""
    a = np.radians(np.asarray(edge_deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    return np.stack([c, s], axis=1), np.stack([-s, c], axis=1)


def edge_tangent_jacobian(A: np.ndarray, edge_deg: np.ndarray, slide: float = EDGE_SLIDE) -> np.ndarray:
    """The camera's tangent Jacobian ``A`` ``(N, 2, 2)`` (px/rad) with every edge pair's row block
    replaced by ``M^-1 A``, ``M^-1 = n n^T + t t^T / slide`` (module docstring); a new array."""
    edge = np.isfinite(edge_deg)
    out = np.array(A, dtype=np.float64, copy=True)
    if edge.any():
        t, nrm = edge_frames(edge_deg[edge])
        M_inv = nrm[:, :, None] * nrm[:, None, :] + t[:, :, None] * t[:, None, :] / float(slide)
        out[edge] = M_inv @ out[edge]
    return np.ascontiguousarray(out)


def slide_along_edges(projected: np.ndarray, pixels: np.ndarray, edge_deg: np.ndarray | None) -> np.ndarray:
    """The clicked ``pixels`` ``(N, 2)`` with each edge pair's moved along its edge to the foot of its
    ``projected`` point (px), so that ``|projected - slid|`` is the distance across the edge; corner pairs,
    and edge pairs whose point does not project, as clicked."""
    pixels = np.asarray(pixels, dtype=np.float64)
    if edge_deg is None:
        return pixels
    edge = np.isfinite(edge_deg)
    if not edge.any():
        return pixels
    out = pixels.copy()
    t, _ = edge_frames(edge_deg[edge])
    d = np.asarray(projected, dtype=np.float64)[edge] - pixels[edge]
    along = np.einsum("ka,ka->k", d, t)
    out[edge] = pixels[edge] + np.where(np.isfinite(along), along, 0.0)[:, None] * t
    return out


def edge_pixel_errors(projected: np.ndarray, pixels: np.ndarray, edge_deg: np.ndarray | None) -> np.ndarray:
    """Pixel errors ``(N,)`` px: ``|projected - clicked|`` for corner pairs, ``|(projected - clicked) . n|``
    (across the edge) for edge pairs; NaN where not finite."""
    projected = np.asarray(projected, dtype=np.float64)
    err = np.linalg.norm(projected - slide_along_edges(projected, pixels, edge_deg), axis=1)
    return np.where(np.isfinite(err), err, np.nan)


def edge_click_covariance(sigma_px: np.ndarray, edge_deg: np.ndarray | None, slide: float = EDGE_SLIDE
                          ) -> np.ndarray:
    """Click covariance ``(N, 2, 2)`` px^2: ``sigma^2 I`` for corner pairs, ``sigma^2 (n n^T + slide^2 t t^T)``
    for edge pairs."""
    s2 = np.asarray(sigma_px, dtype=np.float64) ** 2
    out = s2[:, None, None] * np.eye(2)
    if edge_deg is not None and np.isfinite(edge_deg).any():
        edge = np.isfinite(edge_deg)
        t, nrm = edge_frames(edge_deg[edge])
        out[edge] = s2[edge, None, None] * (nrm[:, :, None] * nrm[:, None, :]
                                           + slide**2 * t[:, :, None] * t[:, None, :])
    return out
