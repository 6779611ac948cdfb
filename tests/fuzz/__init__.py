"""A generated corpus of hostile inputs for every reader and every file the CLI takes.

Each ``cases_*.py`` module here defines ``make_cases(folder: Path) -> list[FuzzCase]``: it writes its
hostile files into ``folder`` and returns the ``ba-calib`` invocations that read them.  Every case must
end in exit 0 (a clean result) or exit 2 with exactly one ``error:`` line on stderr, within 10 s and
1 GB peak RSS: no traceback, no hang.
"""
