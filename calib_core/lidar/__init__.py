"""Laser models: every scanner becomes a :class:`DepthMatrix` (paper Sec. II-B, III).

* :func:`rotating_scanner_depth` -- the paper's 2-D scanner on a rotating
  support (eq. 3, with axis offsets); :func:`rotating_scanner_beams` gives its
  beams for ray casting.
* :func:`spherical_depth` -- per-row elevation, per-column azimuth.
* :func:`organized_cloud_depth` -- any organized point cloud.
* :func:`save_depth_npz` / :func:`load_depth_npz` -- the native scan file.
* :func:`organize_cloud` -- an unorganized or organized point cloud as a
  depth matrix (ring field, scan order, elevations or spherical bins), with
  an :class:`OrganizeReport` of what it kept.
"""

from .depth_matrix import DepthMatrix
from .npz_format import load_depth_npz, save_depth_npz
from .organize_cloud import organize_cloud
from .organized import organized_cloud_depth
from .report import OrganizeReport
from .rotating_scanner import rotating_scanner_beams, rotating_scanner_depth
from .spherical import spherical_depth, spherical_directions

__all__ = [
    "DepthMatrix",
    "OrganizeReport",
    "load_depth_npz",
    "organize_cloud",
    "organized_cloud_depth",
    "rotating_scanner_beams",
    "rotating_scanner_depth",
    "save_depth_npz",
    "spherical_depth",
    "spherical_directions",
]
