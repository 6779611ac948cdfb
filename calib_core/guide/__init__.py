"""Guided picking: the tool chooses the next pair and predicts its pixel; the person confirms.

Modules (one concept each):

* :mod:`.information` -- Fisher information of the pose, pixel Jacobians, D-optimal gain;
* :mod:`.laser_noise` -- error of a laser point picked as a whole cell;
* :mod:`.candidates` -- corner cells of the scan (depth jumps, plane junctions);
* :mod:`.visibility` -- which laser points the camera sees (z-buffer);
* :mod:`.corner_probability` -- probability that a candidate is a corner the person can click;
* :mod:`.image_corners` -- camera-image corners, the clean-isolated-corner test, sub-pixel refinement;
* :mod:`.pose_state` -- current pose and covariance from pairs or an imported extrinsic;
* :mod:`.evidence` -- the screen: clear, isolated evidence in both views, an ellipse that fits the loupe;
* :mod:`.propose` -- the ranked proposals with predicted pixels and ellipses;
* :mod:`.auto_accept` -- strictly gated acceptance without a click.
"""

from .candidates import KINDS, Candidates, find_candidates
from .evidence import ProposalScreen
from .image_corners import CornerGate, CornerImage, corner_image
from .pose_state import PoseState, current_pose
from .propose import GUIDED_CLICK_SIGMA_PX, Proposal, Proposals, propose, proposals_to_dict, save_proposals_yaml

__all__ = [
    "KINDS",
    "Candidates",
    "find_candidates",
    "CornerGate",
    "CornerImage",
    "corner_image",
    "PoseState",
    "current_pose",
    "GUIDED_CLICK_SIGMA_PX",
    "Proposal",
    "Proposals",
    "ProposalScreen",
    "propose",
    "proposals_to_dict",
    "save_proposals_yaml",
]
