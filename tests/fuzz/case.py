"""One entry of the fuzz corpus."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FuzzCase:
    """A ``ba-calib`` invocation on a hostile input.

    Attributes
    ----------
    name : str
        Unique, says what is hostile (e.g. ``"pcd/count3_on_x"``).
    argv : list of str
        The CLI arguments, without the program name.
    stdin : bytes or None
        What the command reads on standard input, if anything.
    """

    name: str
    argv: list[str]
    stdin: bytes | None = None
