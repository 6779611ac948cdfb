"""User-facing errors.

Everything that is the user's fault (a malformed file, a degenerate point set,
a click outside the image) raises :class:`CalibError` with a one-line message
that names the problem.  The CLI turns it into ``error: <message>`` and exit
code 2; the app turns it into a notification.
"""


class CalibError(ValueError):
    """A problem with the user's input, described in one line."""
