"""The synthetic sample scene: an office room, a rotating scanner and an
omnidirectional camera with known extrinsics (``sample_data/``).

* :func:`make_sample_scene` -- ray-cast a scene for a seed;
* :func:`write_sample` / :func:`load_sample` -- the ``sample_data/`` folder;
* :func:`simulate_pairs` -- user clicks at scene corners, with realistic errors.

Modules: :mod:`.scene` (layout, mesh, corners, rig), :mod:`.raycast`
(first-hit casting), :mod:`.render` (scan and image), :mod:`.picks`
(visibility, clicks), :mod:`.sample` (generation and files).
"""

from .picks import simulate_pairs
from .sample import SampleScene, load_sample, make_sample_scene, write_sample

__all__ = ["SampleScene", "load_sample", "make_sample_scene", "simulate_pairs", "write_sample"]
