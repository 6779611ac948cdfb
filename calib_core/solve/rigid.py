"""Closed-form rigid 3-D / 3-D registration (least squares, SVD).

The paper recovers R and T from the camera-frame points ``d_i * bearing_i`` and
the laser points with Zhang's motion estimation (Zhang 1992, ref. [24]); the
closed form is the same as

* B. K. P. Horn, "Closed-form solution of absolute orientation using unit
  quaternions", JOSA A 4(4), 1987;
* K. S. Arun, T. S. Huang, S. D. Blostein, "Least-squares fitting of two 3-D
  point sets", IEEE PAMI 9(5), 1987;
* S. Umeyama, "Least-squares estimation of transformation parameters between
  two point patterns", IEEE PAMI 13(4), 1991 (the reflection correction).

Here: Arun's SVD with Umeyama's determinant fix, batched over leading axes, compiled
(:func:`calib_core.solve.kernels.rigid_fit_batch`).
"""

from __future__ import annotations

import numpy as np

from .kernels import rigid_fit_batch


def rigid_fit(points_src: np.ndarray, points_dst: np.ndarray) -> np.ndarray:
    """Rigid transform ``T_dst_src`` minimising ``sum |T p_src - p_dst|^2``.

    Parameters
    ----------
    points_src : (..., N, 3) ndarray
        Points in the source frame, metres (``N >= 3``, not collinear, for a
        unique answer).
    points_dst : (..., N, 3) ndarray
        Corresponding points in the destination frame, metres.

    Returns
    -------
    (..., 4, 4) ndarray
        ``T_dst_src``, a proper rotation (det = +1) and a translation.  For a
        degenerate (collinear) set the rotation about the line is arbitrary;
        callers check their input first.
    """
    src = np.asarray(points_src, dtype=np.float64)
    dst = np.asarray(points_dst, dtype=np.float64)
    lead = src.shape[:-2]
    n = src.shape[-2]
    T = rigid_fit_batch(
        np.ascontiguousarray(src.reshape(-1, n, 3)), np.ascontiguousarray(dst.reshape(-1, n, 3))
    )
    return T.reshape(lead + (4, 4))
