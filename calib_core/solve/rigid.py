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

Here: Arun's SVD with Umeyama's determinant fix, batched over leading axes.
"""

from __future__ import annotations

import numpy as np


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
    mu_src = src.mean(axis=-2, keepdims=True)
    mu_dst = dst.mean(axis=-2, keepdims=True)
    # Cross-covariance H = sum (p_src - mu_src)(p_dst - mu_dst)^T.
    H = np.swapaxes(src - mu_src, -1, -2) @ (dst - mu_dst)
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    # Umeyama: flip the least-significant axis if the SVD gives a reflection.
    sign = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    sign = np.where(sign == 0, 1.0, sign)
    D = np.broadcast_to(np.eye(3), H.shape).copy()
    D[..., 2, 2] = sign
    R = V @ D @ np.swapaxes(U, -1, -2)
    t = mu_dst[..., 0, :] - (R @ mu_src[..., 0, :, None])[..., 0]
    T = np.zeros(H.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T
