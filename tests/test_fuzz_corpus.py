"""The fuzz corpus: every case of every ``tests/fuzz/cases_*.py`` module keeps the rules.

Each case runs as ``python -m app.cli ARGV`` in a process forked from a worker that has imported the
package (tests/fuzz/runner.py), three workers at a time (two cores, plus one to fill the waits on
fsync and on the polling of the others; one fewer per other pytest-xdist worker).  A case must end
in exit 0 (or 3 from solve: a result marked unreliable), or exit 2 with exactly one ``error:`` line
on stderr; never a traceback; within 10 s of CPU and 1 GiB peak RSS (killed as hung after 60 s wall).  ``python -m tests.fuzz.generate OUT
--run`` does the same by hand.

CI runs one case per behaviour (file kind, exit code, error line shape: ``tests.fuzz.generate.behaviour``) and
every case near a resource limit, 620 of the 972 cases; ``BA_CALIB_FUZZ_FULL=1`` runs them all, and ``python -m
bench.fuzz_corpus`` runs them all and checks that every behaviour they show has a case in CI (docs/testing.md).
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # tests/ is not a package: make ``tests.fuzz`` importable
    sys.path.insert(0, str(REPO))

from tests.fuzz.generate import (  # noqa: E402
    HANG_LIMIT_S, RSS_LIMIT_MB, bench_only, build_corpus, case_modules, check_result, ci_cases, file_kind,
)
from tests.fuzz.runner import run_cases  # noqa: E402


def _fuzz_workers() -> int:
    """Three on two cores (one fills the waits); one fewer per other pytest-xdist worker, which keeps a core busy
    too (the cases' limit is CPU time, so the load changes only how long the corpus takes)."""
    other_test_workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) - 1
    return max(1, min(3, (os.cpu_count() or 2) + 1 - other_test_workers))


def test_every_fuzz_case_ends_cleanly(tmp_path):
    cases = build_corpus(tmp_path / "corpus")
    kinds = Counter("mutation" if "/mutation/" in f"/{c.name}" else "hostile" for c in cases)
    modules = [m.__name__.rsplit(".", 1)[1] for m in case_modules()]
    assert "cases_config" in modules
    # The bench-only list names cases of this corpus, and leaves cases of every file kind in CI.
    assert not bench_only() - {c.name for c in cases}, sorted(bench_only() - {c.name for c in cases})[:10]
    run = cases if os.environ.get("BA_CALIB_FUZZ_FULL") == "1" else ci_cases(cases)
    assert {file_kind(c.name) for c in run} == {file_kind(c.name) for c in cases}
    results = run_cases(run, tmp_path / "runs", workers=_fuzz_workers(), timeout=HANG_LIMIT_S,
                        rss_limit_mb=RSS_LIMIT_MB)
    failures = [f"{r.name}: {why}" for r in results if (why := check_result(r))]
    codes = Counter(r.returncode for r in results)
    slowest = max(results, key=lambda r: r.cpu_seconds)
    biggest = max(results, key=lambda r: r.peak_rss_mb)
    print(
        f"fuzz corpus from {', '.join(modules)}: {len(cases)} cases ({kinds['hostile']} hostile, {kinds['mutation']} mutations), "
        f"{len(run)} run; exit codes {dict(sorted(codes.items()))}; slowest {slowest.cpu_seconds:.2f} s of CPU ({slowest.name}); "
        f"largest {biggest.peak_rss_mb:.0f} MiB ({biggest.name})"
    )
    assert not failures, f"{len(failures)} of {len(run)} cases broke the rules:\n" + "\n".join(failures)
    # The corpus (CI runs part of it): the config cases alone; the rest of the target (300 hostile, 50 mutations)
    # comes with the scan cases.
    config = Counter("mutation" if "/mutation/" in c.name else "hostile" for c in cases if c.name.startswith("config/"))
    assert config["hostile"] >= 300 and config["mutation"] >= 50, config


def test_forked_cases_end_as_real_processes_do(tmp_path):
    """The fork server is a shortcut: a few cases run both ways must end the same."""
    wanted = ("config/valid/pinhole_yaml", "config/camera_yaml/generic/fifo", "config/pairs/generic/dev_zero",
              "config/camera_json/generic/json_deep_100k", "config/pairs/generic/billion_laughs",
              "config/args/solve/image_size_1e9", "config/output/solve/folder")
    cases = [c for c in build_corpus(tmp_path / "corpus") if c.name in wanted]
    assert len(cases) == len(wanted)
    forked = run_cases(cases, tmp_path / "runs", workers=2, timeout=60.0, rss_limit_mb=RSS_LIMIT_MB)
    for case, result in zip(cases, forked):
        work = tmp_path / "real" / case.name.replace("/", "_")
        work.mkdir(parents=True)
        real = subprocess.run([sys.executable, "-m", "app.cli", *case.argv], capture_output=True, timeout=120, cwd=work,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
        assert result.returncode == real.returncode, case.name
        assert result.stderr == real.stderr.decode("utf-8", "replace"), case.name


def test_the_time_rule_counts_cpu_not_the_machines_load():
    """A case that waited 30 s of wall time on a busy machine but used 2 s of CPU keeps the rules; 11 s of CPU
    breaks them, and so does a case killed as hung."""
    from tests.fuzz.runner import CaseResult

    def result(wall, cpu, killed=None):
        return CaseResult(name="x", returncode=2, stdout="", stderr="error: x.yaml: not a mapping\n", seconds=wall,
                          peak_rss_mb=100.0, killed=killed, cpu_seconds=cpu)

    assert check_result(result(30.0, 2.0)) is None
    assert check_result(result(11.0, 11.0)) == "took 11.0 s of CPU (11.0 s wall)"
    assert check_result(result(HANG_LIMIT_S, 0.1, killed="timeout")).startswith("killed (timeout)")
