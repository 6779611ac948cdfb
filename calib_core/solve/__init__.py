"""Extrinsic pose from laser-point / camera-bearing pairs (paper Sec. IV), robust to wrong pairs.

Pipeline of :func:`solve_extrinsics`:

1. :mod:`.checks` rejects malformed or degenerate input (CalibError).
2. :mod:`.whiten`: the angular residual of each pair is whitened with the
   2x2 pixel-to-tangent Jacobian of the camera at the clicked pixel (and the
   pair's ``pixel_sigma``), so that eq. 7 weighs pairs as the click noise does.
3. Initial pose: a linear DLT on the bearings (:func:`.kernels.dlt_pose`,
   n >= 6, not coplanar) or else Quan & Lan / P3P (:mod:`.bearing_pnp`).
4. Levenberg-Marquardt on the whitened angular cost (compiled,
   :mod:`.kernels`), or, with ``cost="pixel"``, on the pixel error (eq. 6).
5. If any residual is far above the noise scale, :mod:`.robust` finds the
   set of pairs that agree on one pose (LO-MSAC over P3P on bearings, pairs at
   one place in the view sharing one vote); the others are left out of the fit
   and the covariance, and reported.
6. Covariance ``s^2 (J^T J)^-1`` on the pairs in the fit (Student-t
   sigma, or the known noise), and a :class:`.quality.Quality` verdict.

The package's modules, each importing only the ones below it (never this
package): :mod:`.result` (the result), :mod:`.extrinsics` (the pipeline
above), :mod:`.calibrate` (the same from ``Pair`` objects); this module
re-exports their public names.
"""

from .calibrate import calibrate
from .checks import MIN_PAIRS
from .extrinsics import solve_extrinsics, warm_up
from .quality import Quality
from .refine import PARAMETER_NAMES, PoseUncertainty, pose_covariance
from .result import CalibrationResult

__all__ = [
    "CalibrationResult",
    "solve_extrinsics",
    "pose_covariance",
    "PoseUncertainty",
    "PARAMETER_NAMES",
    "MIN_PAIRS",
    "Quality",
    "warm_up",
    "calibrate",
]

