"""The outcome of a solve: :class:`CalibrationResult` (pose, covariance, residuals, quality).

Apart from :mod:`.extrinsics` so that the modules that only read results need not import the solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .quality import Quality

__all__ = ["CalibrationResult"]


@dataclass
class CalibrationResult:
    """Outcome of :func:`solve_extrinsics`.

    Attributes
    ----------
    T_camera_lidar : (4, 4) ndarray
        Estimated pose, ``X_camera = T_camera_lidar @ X_lidar`` (metres),
        fitted to the inliers only.
    initial_T_camera_lidar : (4, 4) ndarray
        The starting pose of the refinement.
    covariance_6x6 : (6, 6) ndarray
        Covariance of ``(delta, t)``: ``delta`` (rad) is the rotation vector of
        ``R_true @ R_hat^T`` (about the camera axes), ``t`` (m) the
        translation; order :data:`PARAMETER_NAMES`.  inf where undetermined.
    sigma_translation_m : (3,) ndarray
        1-sigma of the translation, metres.
    sigma_rpy_deg : (3,) ndarray
        1-sigma of roll, pitch, yaw, degrees (as in the paper's Table I).
        When the noise is estimated from the residuals, sigmas are widened to
        the 68.27 % Student-t interval with ``2 n_inliers - 6`` degrees of
        freedom, so +-1 sigma covers 68.27 % also for few pairs.
    residual_deg : (N,) ndarray
        Angle between each clicked bearing and its reprojected laser point,
        for every pair (outliers included).
    residual_px : (N,) ndarray
        Pixel distance between each clicked pixel and the projected laser
        point; NaN where the point does not project into the image or there is
        no camera.
    mean_px, std_px, mean_deg, std_deg : float
        Mean and standard deviation of the finite residuals of the inliers
        (NaN if none).
    n_pairs : int
        Pairs given (inliers and outliers).
    warnings : list of str
        The lines of ``quality.reasons``, then notes on the output's form that do not
        lower the quality (roll/pitch/yaw near gimbal lock, or azimuth/roll of the
        viewing direction near lidar +-z: :func:`.quality.orientation_notes`).
    outliers : list of int
        Positions (0-based, in the input arrays) of the pairs left out of the
        fit and the covariance as gross outliers.
    outlier_ids : list of int
        The same pairs by id (``pair_ids`` given to the solve, else positions).
    inliers : (N,) bool ndarray
        Pairs used in the fit.
    quality : Quality
        ``ok`` / ``warning`` / ``unreliable`` and one line per reason.
    iterations : int
        Levenberg-Marquardt iterations (normal-equation evaluations).
    cost_name : str
        ``"angular"``, ``"geodesic"`` or ``"pixel"``.
    initial_method : str
        ``"dlt"``, ``"quan_lan"``, ``"p3p"`` or ``"given"``.
    noise_scale : float
        Estimated sigma per axis of the whitened residuals of the inliers, in
        ``residual_unit``.
    residual_unit : str
        ``"px"`` (whitened by the camera), ``"sigma"`` (also divided by
        ``pixel_sigma``), ``"noise"`` (divided by ``noise_rad``) or ``"rad"``.
    hypotheses : int
        Candidate poses scored by the robust search (0 when it was not needed).
    pair_positions : list of int or None
        Set by :func:`calibrate`: the position in the caller's pair list of each row
        above (check pairs are not in the fit); None: rows are the caller's positions.
    check_positions, check_ids : list of int
        Check pairs (left out of the fit; :func:`calibrate`): positions and ids.
    check_residual_px, check_residual_deg : (M,) ndarray
        Their errors at the estimated pose (px NaN where not projectable).
    """

    T_camera_lidar: np.ndarray
    initial_T_camera_lidar: np.ndarray
    covariance_6x6: np.ndarray
    sigma_translation_m: np.ndarray
    sigma_rpy_deg: np.ndarray
    residual_deg: np.ndarray
    residual_px: np.ndarray
    mean_px: float
    std_px: float
    mean_deg: float
    std_deg: float
    n_pairs: int
    warnings: list[str] = field(default_factory=list)
    outliers: list[int] = field(default_factory=list)
    outlier_ids: list[int] = field(default_factory=list)
    inliers: np.ndarray | None = None
    quality: Quality = field(default_factory=Quality)
    iterations: int = 0
    cost_name: str = "angular"
    initial_method: str = ""
    noise_scale: float = float("nan")
    residual_unit: str = "rad"
    hypotheses: int = 0
    pair_positions: list[int] | None = None
    check_positions: list[int] = field(default_factory=list)
    check_ids: list[int] = field(default_factory=list)
    check_residual_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    check_residual_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
