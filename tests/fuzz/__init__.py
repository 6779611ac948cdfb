"""A generated corpus of hostile inputs for every reader and every file the CLI takes.

Each ``cases_*.py`` module here defines ``make_cases(folder: Path) -> list[FuzzCase]``: it writes its
hostile files into ``folder`` and returns the ``ba-calib`` invocations that read them.  Every case must
end in exit 0 (a clean result) or exit 2 with exactly one ``error:`` line on stderr, within 10 s of CPU
and 1 GB peak RSS: no traceback, no hang (a case still running after 60 s of wall time is killed and fails).

Inputs are absolute paths into ``folder``; outputs should be relative (``-o out.yaml``): each case runs
in its own empty working folder.  Never name a real device as an output: make a private node (see
``cases_config.py``), so that a regression cannot replace the machine's ``/dev/null``.

``generate.py`` builds the corpus (``python -m tests.fuzz.generate OUT [--run]``), ``runner.py`` runs
it in fork-server workers that have imported the package, and ``tests/test_fuzz_corpus.py`` checks it.
"""
