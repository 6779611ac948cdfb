"""Benchmarks of ba-calib: accuracy against ground truth and speed of every live step.

Run everything with ``python -m bench`` (a few minutes on two cores); it writes
``docs/performance.md`` and the plots in ``docs/perf/``.  Nothing here is part
of the test suite.

Modules
-------
common
    Scenes (the committed sample and cached generated seeds), seeded trials,
    pose-error measures, timing helpers.
accuracy
    Error against the number of pairs (paper Fig. 6, Fig. 7, Table I) and the
    Cramer-Rao check.
compare
    Angular cost (eq. 7) vs pixel cost (eq. 6) vs OpenCV SQPnP + LM.
speed
    Median run time of each live step, against the targets of issue 5.
report
    Markdown and PNG output.
"""
