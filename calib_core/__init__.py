"""ba-calib core: maths and I/O for camera / 3D-lidar extrinsic calibration.

Conventions used everywhere in this package
------------------------------------------
* Pixels are ``(u, v) = (column, row)``; the *centre* of the top-left pixel is
  ``(0, 0)``, as in OpenCV and in OCamCalib's C export.  An image of width W
  covers ``u`` in ``[-0.5, W - 0.5]``.
* Camera frame: OpenCV (x right, y down, z forward), metres.
* ``T_camera_lidar`` is a 4x4 homogeneous matrix with
  ``X_camera = T_camera_lidar @ X_lidar``.
* Angles in APIs are radians unless a name ends in ``_deg``.
* Roll, pitch, yaw: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.

Data flows one way:
scan -> depth matrix -> BA images -> picks -> pairs -> solve -> extrinsics
-> overlays and export.  This package never imports the UI.
"""

import os as _os

# Our matrix products are tall and thin ((N, 3) @ (3, 3)).  A multi-threaded
# BLAS gains nothing on them and, on a busy machine, can be 20x slower
# (measured: 400 ms instead of 9 ms for 1M points).  Set before numpy loads;
# a value the user exported wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
