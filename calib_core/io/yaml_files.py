"""Reading YAML and JSON files safely, with one-line errors that name the file.

``yaml.safe_load`` alone does not bound what a file can cost: a "billion
laughs" document (aliases of aliases) expands without limit, and nesting a
few thousand levels deep overflows the stack (PyYAML's C loader crashes on
it).  :func:`parse_yaml_text` therefore first walks the YAML *events* (an
iterative parser, cheap) and counts the nesting depth, the aliases and the
number of values the document expands to; only a document within every limit
is then loaded with the safe loader.  JSON gets the same depth limit.
"""

from __future__ import annotations

import json
import numbers
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import CalibError, short_repr
from .input_files import read_input_text, with_article

#: Deepest nesting of lists/mappings accepted (real files nest fewer than 10 levels).
MAX_DEPTH = 64
#: Most aliases (``*name``) accepted in one document.
MAX_ALIASES = 1000
#: Most values (scalars plus collections, aliases expanded) a document may hold by default.
#: Loading costs about 10-30 us per value, so this bounds the time too.
MAX_VALUES = 100_000

_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Limit(Exception):
    pass


def _check_yaml_events(text: str, max_values: int) -> None:
    """Walk the YAML events and raise :class:`_Limit` when a limit is exceeded.

    Each open collection keeps (values so far, deepest level below it, anchor);
    an alias adds the expanded size and depth of the node it names.
    """
    anchors: dict[str, tuple[int, int]] = {}  # anchor -> (values, depth) of its node
    stack: list[list] = [[0, 0, None]]
    aliases = 0
    for event in yaml.parse(text, Loader=_SAFE_LOADER):
        if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            if len(stack) > MAX_DEPTH:
                raise _Limit(f"nested deeper than {MAX_DEPTH} levels")
            stack.append([1, 1, event.anchor])
        elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            values, depth, anchor = stack.pop()
            if anchor is not None:
                anchors[anchor] = (values, depth)
            _add(stack, values, depth, max_values)
        elif isinstance(event, yaml.ScalarEvent):
            if event.anchor is not None:
                anchors[event.anchor] = (1, 0)
            _add(stack, 1, 0, max_values)
        elif isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_ALIASES:
                raise _Limit(f"more than {MAX_ALIASES} aliases")
            values, depth = anchors.get(event.anchor, (1, 0))
            _add(stack, values, depth, max_values)
        elif isinstance(event, yaml.DocumentEndEvent):
            stack = [[0, 0, None]]


def _add(stack: list[list], values: int, depth: int, max_values: int) -> None:
    top = stack[-1]
    top[0] += values
    top[1] = max(top[1], depth + (1 if len(stack) > 1 else 0))
    if len(stack) + depth > MAX_DEPTH + 1:
        raise _Limit(f"nested deeper than {MAX_DEPTH} levels (aliases expanded)")
    if sum(level[0] for level in stack) > max_values:
        raise _Limit(f"holds more than {max_values:,} values (aliases expanded)")


def parse_yaml_text(text: str, where: str, max_values: int = MAX_VALUES, limit_hint: str = "") -> Any:
    """``yaml.safe_load`` of ``text`` within the depth, alias and size limits.

    Parameters
    ----------
    text : str
        The document.
    where : str
        Names the file in errors.
    max_values : int
        Most values (scalars and collections, aliases expanded) accepted.
    limit_hint : str
        Appended to the message when ``max_values`` is exceeded (e.g. which option raises it).

    Raises
    ------
    CalibError
        Malformed YAML, or a limit exceeded; one line naming ``where``.
    """
    try:
        _check_yaml_events(text, max_values)
        return yaml.load(text, Loader=_SAFE_LOADER)  # noqa: S506 - the C or Python *safe* loader
    except _Limit as exc:
        hint = f"; {limit_hint}" if limit_hint and "values" in str(exc) else ""
        raise CalibError(f"{where}: YAML {exc}{hint}") from None
    except yaml.YAMLError as exc:
        if "nesting depth" in str(getattr(exc, "problem", "")):
            # PyYAML >= 6.0.4 stops deep flow nesting itself, before our event walk does:
            # the promise is one message whichever layer notices first.
            raise CalibError(f"{where}: YAML nested deeper than {MAX_DEPTH} levels") from None
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise CalibError(f"{where}: malformed YAML{at}: {' '.join(str(problem).split())}") from None
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        # The constructors' own errors: a date like 2001-13-45, an integer of 10,000 digits.
        raise CalibError(f"{where}: malformed YAML: {' '.join(str(exc).split())[:200]}") from None


def read_yaml_mapping(
    path: str | os.PathLike,
    what: str,
    max_bytes: int = 4 << 20,
    max_values: int = MAX_VALUES,
    limit_hint: str = "",
) -> dict[str, Any]:
    """Load a YAML file, within limits, and check that it is a mapping.

    Parameters
    ----------
    path : path-like
        The YAML file (a regular file of at most ``max_bytes``).
    what : str
        What the file should be (e.g. ``"pairs file"``), for error messages.
    max_bytes, max_values : int
        Limits on the file size and the number of values (see :func:`parse_yaml_text`).
    limit_hint : str
        Says how to raise ``max_values``, for the message.
    """
    path = Path(path)
    text = read_input_text(path, what, max_bytes, limit_hint)
    data = parse_yaml_text(text, str(path), max_values, limit_hint)
    if not isinstance(data, dict):
        raise CalibError(f"{path}: expected a YAML mapping for {with_article(what)}, got {type(data).__name__}")
    return data


def parse_json_text(text: str, where: str) -> Any:
    """``json.loads`` with the same nesting limit as YAML; one-line errors naming ``where``."""
    depth = 0
    in_string = escaped = False
    # A bracket count outside strings bounds the depth before parsing (json recurses per level).
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                raise CalibError(f"{where}: JSON nested deeper than {MAX_DEPTH} levels")
        elif ch in "]}":
            depth -= 1
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise CalibError(f"{where}: malformed JSON at line {exc.lineno}: {exc.msg}") from None
    except (ValueError, RecursionError) as exc:
        raise CalibError(f"{where}: malformed JSON: {' '.join(str(exc).split())[:200]}") from None


def finite_vector(value: Any, length: int, where: str, max_abs: float = 1e9) -> list[float]:
    """``value`` as a list of ``length`` finite floats of at most ``max_abs``, or a :class:`CalibError`.

    Booleans are refused (YAML's ``true`` is not the number 1).
    """
    if not isinstance(value, (list, tuple, np.ndarray)) or np.ndim(value) != 1:
        raise CalibError(f"{where}: expected {length} numbers, got {short_repr(value)}")
    if len(value) != length:
        raise CalibError(f"{where}: expected {length} numbers, got {len(value)}")
    if any(isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real) for x in value):
        raise CalibError(f"{where}: expected {length} numbers, got {short_repr(value)}")
    try:
        out = [float(x) for x in value]
    except OverflowError:
        raise CalibError(f"{where}: number too large, got {short_repr(value)}") from None
    if not all(x == x and abs(x) != float("inf") for x in out):
        raise CalibError(f"{where}: numbers must be finite, got {out}")
    if any(abs(x) > max_abs for x in out):
        raise CalibError(f"{where}: numbers must be at most {max_abs:g} in size, got {out}")
    return out
