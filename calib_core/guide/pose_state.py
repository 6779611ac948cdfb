"""The current pose and its covariance, from the pairs so far and/or an imported extrinsic.

The covariance is ``F^-1`` with ``F`` the Fisher information of the pairs
(:mod:`.information`: each pair's click noise ``precision_px``, default
:data:`DEFAULT_CLICK_SIGMA_PX`, plus the error of a careful laser pick,
:data:`.laser_noise.PICK_CELL_SIGMA`) and of the prior of an imported extrinsic.
When the pairs' whitened residuals show more noise than modelled, the
covariance is inflated by their variance factor, so the predicted ellipses
stay honest for careless clicks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import CalibError
from ..pairs import Pair, resolve_pairs
from ..solve import MIN_PAIRS, calibrate
from ..solve.calibrate import pair_edge_degrees
from ..solve.edges import slide_along_edges
from ..solve.whiten import pairs_pick_covariance
from .information import fisher_information, information_inverse, pair_noise, pixel_jacobians
from .laser_noise import PICK_CELL_SIGMA

__all__ = ["PoseState", "current_pose", "DEFAULT_CLICK_SIGMA_PX", "DEFAULT_PRIOR_SIGMA"]

#: Click noise of an unguided pair without ``precision_px``, pixels.
DEFAULT_CLICK_SIGMA_PX = 1.0
#: 1-sigma of an imported extrinsic: rotation (deg) and translation (m) per axis.
DEFAULT_PRIOR_SIGMA = (1.0, 0.05)


@dataclass(frozen=True)
class PoseState:
    """Pose estimate and uncertainty the proposals are computed from.

    Attributes
    ----------
    T_camera_lidar : (4, 4) ndarray
    covariance : (6, 6) ndarray
        Of ``(delta [rad], t [m])`` about ``T_camera_lidar`` (:mod:`.information`).
    variance_factor : float
        Whitened residual variance of the pairs (>= 1 applied to ``covariance``; 1 without redundancy).
    n_pairs : int
    source : str
        Where the pose came from.
    quality : calib_core.solve.quality.Quality or None
        The solve's verdict (``status``, ``reasons``); None when the pose is an imported extrinsic alone.
    """

    T_camera_lidar: np.ndarray
    covariance: np.ndarray
    variance_factor: float
    n_pairs: int
    source: str
    quality: Any = None


def pair_sigmas(pairs: Sequence[Pair], default_px: float = DEFAULT_CLICK_SIGMA_PX) -> np.ndarray:
    """Click noise of each pair: its ``precision_px`` or the default, pixels."""
    return np.array([default_px if p.precision_px is None else p.precision_px for p in pairs], dtype=np.float64)


def pose_state_of_fit(camera, T: np.ndarray, points_lidar: np.ndarray, pixels: np.ndarray, sigma_px,
                      laser_cov: np.ndarray, source: str, quality: Any = None,
                      edge_deg: np.ndarray | None = None) -> PoseState:
    """The pose ``T`` and ``F^-1`` of its fit pairs (laser points in metres, clicked pixels, click sigmas in px,
    laser covariances in metres^2, edge pairs' angles in degrees, NaN for corners), inflated by their whitened
    residuals' variance factor when it exceeds 1."""
    predicted, J_pose, J_point = pixel_jacobians(camera, T, points_lidar)
    S = pair_noise(sigma_px, J_point, laser_cov, edge_deg)
    F = fisher_information(J_pose, S)
    factor = 1.0
    dof = 2 * len(points_lidar) - 6
    r = slide_along_edges(predicted, pixels, edge_deg) - predicted  # an edge pair: only across its edge
    if dof > 0 and np.all(np.isfinite(r)):
        factor = max(1.0, float(np.einsum("na,nab,nb->", r, np.linalg.inv(S), r)) / dof)
    return PoseState(T, factor * information_inverse(F), factor, len(points_lidar), source, quality)


def current_pose(
    pairs: Sequence[Pair],
    depth,
    camera,
    T_initial: np.ndarray | None = None,
    prior_sigma: tuple[float, float] = DEFAULT_PRIOR_SIGMA,
) -> PoseState:
    """Solve the pairs (>= 4) or take ``T_initial``, and the pose covariance there.

    Parameters
    ----------
    pairs : sequence of Pair
        Check pairs (``check: true``) are left out.
    depth : DepthMatrix or None
        Needed when pairs name cells.
    camera : CameraModel
    T_initial : (4, 4) ndarray, optional
        Imported extrinsic: the start of the solve; with fewer than 4
        pairs, the pose itself, with ``prior_sigma`` (deg, m per axis).
    prior_sigma : (float, float)
        Used only with fewer than 4 pairs, when the pose is ``T_initial``.

    Raises
    ------
    CalibError
        Fewer than 4 pairs and no ``T_initial``, or a pose the pairs do not determine.
    """
    fit = [p for p in pairs if not p.check]
    if len(fit) < MIN_PAIRS:
        if T_initial is None:
            raise CalibError(f"proposals need at least {MIN_PAIRS} pairs or an initial extrinsic; got {len(fit)} pairs")
        # Too few pairs to solve: the imported pose and its prior alone.
        s_rot, s_t = np.radians(prior_sigma[0]), prior_sigma[1]
        cov = np.diag([s_rot**2] * 3 + [s_t**2] * 3)
        return PoseState(np.asarray(T_initial, dtype=np.float64), cov, 1.0, len(fit), "extrinsics")
    points, _, pixels = resolve_pairs(fit, depth, camera)
    # Weighted by each pair's precision_px and whole-cell laser pick (robust: gross outliers left out).
    solved = calibrate(fit, depth, camera, initial_T_camera_lidar=T_initial)
    laser = pairs_pick_covariance(fit, depth, PICK_CELL_SIGMA)
    laser = np.zeros((len(fit), 3, 3)) if laser is None else laser
    source = "pairs" if T_initial is None else "pairs (started from the extrinsics)"
    return pose_state_of_fit(camera, solved.T_camera_lidar, points, pixels, pair_sigmas(fit), laser, source,
                             solved.quality, pair_edge_degrees(fit))
