"""User-facing errors.

Everything that is the user's fault (a malformed file, a degenerate point set,
a click outside the image) raises :class:`CalibError` with a one-line message
that names the problem.  The CLI turns it into ``error: <message>`` and exit
code 2; the app turns it into a notification.
"""


class CalibError(ValueError):
    """A problem with the user's input, described in one line."""


def one_line(exc: BaseException, limit: int = 160) -> str:
    """``exc``'s message on one line (its type's name when it has none), cut to ``limit`` characters."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def short_repr(value: object) -> str:
    """``repr(value)`` cut to 80 characters, for quoting a bad value in a message."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
