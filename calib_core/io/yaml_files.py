"""Reading YAML files safely, with one-line errors that name the file."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from ..errors import CalibError


def read_yaml_mapping(path: str | os.PathLike, what: str) -> dict[str, Any]:
    """Load ``path`` with ``yaml.safe_load`` and check that it is a mapping.

    Parameters
    ----------
    path : path-like
        The YAML file.
    what : str
        What the file should be (e.g. ``"pairs file"``), for error messages.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CalibError(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise CalibError(f"{path}: is a folder, expected a {what}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibError(f"{path}: cannot read {what}: {exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise CalibError(f"{path}: malformed YAML{where}: {problem}") from None
    if not isinstance(data, dict):
        raise CalibError(f"{path}: expected a YAML mapping for a {what}, got {type(data).__name__}")
    return data


def finite_vector(value: Any, length: int, where: str) -> list[float]:
    """``value`` as a list of ``length`` finite floats, or a :class:`CalibError`."""
    try:
        out = [float(x) for x in value]
    except (TypeError, ValueError):
        raise CalibError(f"{where}: expected {length} numbers, got {value!r}") from None
    if len(out) != length:
        raise CalibError(f"{where}: expected {length} numbers, got {len(out)}")
    if not all(map(lambda x: x == x and abs(x) != float("inf"), out)):
        raise CalibError(f"{where}: numbers must be finite, got {out}")
    return out
