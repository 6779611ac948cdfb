"""Build the fuzz corpus: every ``tests/fuzz/cases_*.py`` module writes its hostile files.

As a script::

    python -m tests.fuzz.generate OUT_DIR          # write the corpus and OUT_DIR/cases.json
    python -m tests.fuzz.generate OUT_DIR --run    # ... and run it, printing one line per failure

As a library: :func:`case_modules`, :func:`build_corpus`, :func:`check_result`, :func:`ci_cases`,
:func:`behaviour`.

CI (``tests/test_fuzz_corpus.py``) runs one case per behaviour (:func:`behaviour`: the file kind, the
exit code, the error line with its paths, quoted values and numbers blanked): the cases named in
``bench_only.txt`` have a sibling of the same behaviour in CI and run only in the full corpus
(``--run`` here, ``python -m bench.fuzz_corpus``, or ``BA_CALIB_FUZZ_FULL=1`` for the test).  A new
case runs in CI until that list names it.
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import re
import sys
import time
from pathlib import Path
from types import ModuleType

from .case import FuzzCase

PACKAGE = __package__ or "tests.fuzz"

#: What a case may end in (see the package docstring): CPU seconds (not wall time, which a shared
#: machine's other jobs inflate) and peak memory.
TIME_LIMIT_S = 10.0
RSS_LIMIT_MB = 1024.0
#: Wall seconds after which a case counts as hung and is killed.
HANG_LIMIT_S = 60.0


def case_modules() -> list[ModuleType]:
    """Every ``cases_*`` module of this package, by name."""
    package = importlib.import_module(PACKAGE)
    names = sorted(m.name for m in pkgutil.iter_modules(package.__path__) if m.name.startswith("cases_"))
    return [importlib.import_module(f"{PACKAGE}.{n}") for n in names]


def build_corpus(folder: str | Path) -> list[FuzzCase]:
    """Write every module's files under ``folder/<module>/`` and return all cases.

    Raises
    ------
    ValueError
        Two cases share a name.
    """
    folder = Path(folder).resolve()
    cases: list[FuzzCase] = []
    for module in case_modules():
        sub = folder / module.__name__.rsplit(".", 1)[1]
        sub.mkdir(parents=True, exist_ok=True)
        cases.extend(module.make_cases(sub))
    names = [c.name for c in cases]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"duplicate fuzz case names: {dupes[:10]}")
    return cases


#: The cases that only the full corpus runs, one name a line (``#`` comments): written by
#: ``python -m bench.fuzz_corpus --write``, which keeps in CI the cheapest case of each behaviour.
BENCH_ONLY_FILE = Path(__file__).with_name("bench_only.txt")


def bench_only() -> frozenset[str]:
    """The case names of :data:`BENCH_ONLY_FILE`."""
    lines = BENCH_ONLY_FILE.read_text(encoding="utf-8").splitlines() if BENCH_ONLY_FILE.exists() else []
    return frozenset(line.strip() for line in lines if line.strip() and not line.startswith("#"))


def ci_cases(cases: list[FuzzCase]) -> list[FuzzCase]:
    """``cases`` without those of :func:`bench_only` (each has a sibling of the same :func:`behaviour` kept)."""
    skip = bench_only()
    return [c for c in cases if c.name not in skip]


def file_kind(name: str) -> str:
    """What a case feeds the CLI, from its name: ``config/<file>`` (with the command for outputs and
    arguments, the mutated file for mutations), or ``<group>/<format>`` for scans and images
    (``scan/pcd_ascii``, ``mutant/ply``, ``image/.png``, ``special/fifo``)."""
    parts = name.split("/")
    if parts[0] == "config":
        if parts[1] == "mutation":
            return "config/mutation/" + re.sub(r"_\d+$", "", parts[2])
        if parts[1] in ("output", "args") and len(parts) > 3:
            return f"config/{parts[1]}/{parts[2]}"
        return "config/" + parts[1]
    base = re.sub(r"^m\d+_", "", parts[-1])  # a mutant of the file it names
    if parts[0] == "image" or base.startswith("img_"):
        return f"{parts[0]}/image{Path(base).suffix}"
    return f"{parts[0]}/" + re.match(r"pcd_binary_compressed|pcd_ascii|pcd_binary|[a-z0-9]+", base).group(0)


def error_shape(text: str) -> str:
    """A message with its paths, quoted values and numbers replaced by ``<path>``, ``<q>``, ``<n>``."""
    text = re.sub(r"(/[^\s:'\"(),]+)+", "<path>", text.strip())
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "<q>", text)
    return re.sub(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", "<n>", text)


def behaviour(result) -> tuple[str, int, str]:
    """``(file kind, exit code, error shape)`` of a :class:`~tests.fuzz.runner.CaseResult` (no shape for exit 0):
    the cases of one behaviour take the same path through the code to the same kind of end."""
    return file_kind(result.name), result.returncode, error_shape(result.stderr) if result.returncode else ""


def check_result(result) -> str | None:
    """``None`` when a :class:`~tests.fuzz.runner.CaseResult` keeps the corpus rules, else why not.

    Rules: exit 0 (a clean result; 3 is ``solve``'s "result is unreliable", also a clean
    result), or exit 2 with exactly one stderr line, starting ``error: ``; never a traceback;
    at most :data:`TIME_LIMIT_S` of CPU and :data:`RSS_LIMIT_MB`; killed after :data:`HANG_LIMIT_S` wall seconds.
    """
    if result.killed:
        return f"killed ({result.killed}) after {result.seconds:.1f} s at {result.peak_rss_mb:.0f} MiB"
    if "Traceback (most recent call last)" in result.stderr:
        return "traceback: " + result.stderr.strip().splitlines()[-1][:200]
    if result.cpu_seconds > TIME_LIMIT_S:
        return f"took {result.cpu_seconds:.1f} s of CPU ({result.seconds:.1f} s wall)"
    if result.peak_rss_mb > RSS_LIMIT_MB:
        return f"peak RSS {result.peak_rss_mb:.0f} MiB"
    if result.returncode in (0, 3):
        return None
    lines = result.stderr.strip().splitlines()
    if result.returncode != 2:
        return f"exit {result.returncode}: {' | '.join(lines)[:300]}"
    if len(lines) != 1 or not lines[0].startswith("error: "):
        return f"exit 2 but stderr is not one error line: {' | '.join(lines)[:300]}"
    return None


def _write_manifest(folder: Path, cases: list[FuzzCase]) -> Path:
    path = folder / "cases.json"
    data = [{"name": c.name, "argv": c.argv, "stdin": c.stdin.hex() if c.stdin else None} for c in cases]
    path.write_text(json.dumps(data, indent=1, ensure_ascii=True))
    return path


def main(argv: list[str] | None = None) -> int:
    from .runner import run_cases

    ap = argparse.ArgumentParser(prog="python -m tests.fuzz.generate", description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="where the corpus is written")
    ap.add_argument("--run", action="store_true", help="run every case and report the failures")
    ap.add_argument("--workers", type=int, default=3)
    ap.add_argument("--only", default="", help="run only cases whose name contains this")
    args = ap.parse_args(argv)
    cases = build_corpus(args.folder)
    manifest = _write_manifest(args.folder.resolve(), cases)
    counts: dict[str, int] = {}
    for c in cases:
        kind = "mutation" if "/mutation/" in f"/{c.name}" else "hostile"
        counts[kind] = counts.get(kind, 0) + 1
    print(f"{len(cases)} cases ({counts.get('hostile', 0)} hostile, {counts.get('mutation', 0)} mutations); manifest {manifest}")
    if not args.run:
        return 0
    chosen = [c for c in cases if args.only in c.name]
    t0 = time.monotonic()
    results = run_cases(chosen, args.folder.resolve() / "_runs", workers=args.workers, timeout=HANG_LIMIT_S, rss_limit_mb=RSS_LIMIT_MB)
    (args.folder / "results.json").write_text(json.dumps([r.__dict__ for r in results], indent=1))
    failures = [(r, why) for r in results if (why := check_result(r))]
    for r, why in failures:
        print(f"FAIL {r.name}: {why}")
    codes: dict[int, int] = {}
    for r in results:
        codes[r.returncode] = codes.get(r.returncode, 0) + 1
    slowest = max(results, key=lambda r: r.cpu_seconds)
    biggest = max(results, key=lambda r: r.peak_rss_mb)
    print(
        f"ran {len(results)} cases in {time.monotonic() - t0:.1f} s with {args.workers} workers: "
        f"{len(results) - len(failures)} ok, {len(failures)} failed; exit codes {dict(sorted(codes.items()))}; "
        f"slowest {slowest.cpu_seconds:.2f} s of CPU ({slowest.name}); largest {biggest.peak_rss_mb:.0f} MiB ({biggest.name})"
    )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
