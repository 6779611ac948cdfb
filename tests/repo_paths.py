"""Paths the tests share: the repository root and its committed sample scene (``sample_data/``).

Imported by name (``from repo_paths import SAMPLE``): ``tests/conftest.py`` puts ``tests/`` on ``sys.path``.
"""

from __future__ import annotations

from pathlib import Path

#: The repository root.
REPO = Path(__file__).resolve().parents[1]
#: The committed sample: ``scan.npz``, ``image.png``, ``camera.yaml``, ``ground_truth.yaml``, ``pairs.yaml``.
SAMPLE = REPO / "sample_data"
