"""The whole fuzz corpus, and the check that CI's part of it keeps every behaviour (issue 22).

CI (``tests/test_fuzz_corpus.py``) runs one case per behaviour of the corpus
(``tests.fuzz.generate.behaviour``: the file kind, the exit code, and the error line with its paths,
quoted values and numbers blanked); the others, listed in ``tests/fuzz/bench_only.txt``, run here.
This runs every case under the same rules, groups the results by behaviour, and checks that each
group holds a case CI runs: a behaviour seen only here (a bench-only case that now ends differently
from its siblings) fails it.  The resource rules too: a case that takes a tenth of the CPU limit or a
quarter of the memory limit (:data:`HEAVY_CPU_S`, :data:`HEAVY_RSS_MB`) must run in CI, whatever its
behaviour.  ``--write`` rewrites ``bench_only.txt`` from this run: in each group the case with the least
CPU stays in CI, and so does every heavy case.

``python -m bench.fuzz_corpus [--workers N] [--write] [--out DIR]`` (35-95 s on 2 cores).  Run it with numba's
cache filled (the test session fills it, or a first run): a kernel a case compiles counts in that case's CPU.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

from .common import REPO

if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from tests.fuzz.generate import (  # noqa: E402
    BENCH_ONLY_FILE, HANG_LIMIT_S, RSS_LIMIT_MB, TIME_LIMIT_S, behaviour, bench_only, build_corpus, check_result,
)
from tests.fuzz.runner import run_cases  # noqa: E402

#: A case this close to a limit checks the resource rules: it runs in CI.  (Every child's peak RSS includes the
#: fork server's own, about 150-200 MiB.)
HEAVY_CPU_S = TIME_LIMIT_S / 10
HEAVY_RSS_MB = RSS_LIMIT_MB / 4

_HEADER = """\
# Fuzz cases that only the full corpus runs (python -m bench.fuzz_corpus, or BA_CALIB_FUZZ_FULL=1 for
# tests/test_fuzz_corpus.py): each has a sibling of the same behaviour (file kind, exit code, error line
# shape: tests.fuzz.generate.behaviour) that CI runs.  Written by python -m bench.fuzz_corpus --write.
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="rewrite tests/fuzz/bench_only.txt from this run")
    ap.add_argument("--out", type=Path, default=None, help="where the corpus is written (default: a temp folder)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="ba-calib-fuzz-") as tmp:
        folder = (args.out or Path(tmp)).resolve()
        cases = build_corpus(folder / "corpus")
        t0 = time.monotonic()
        results = run_cases(cases, folder / "runs", workers=args.workers, timeout=HANG_LIMIT_S,
                            rss_limit_mb=RSS_LIMIT_MB)
        seconds = time.monotonic() - t0
    failures = [f"{r.name}: {why}" for r in results if (why := check_result(r))]
    groups: dict[tuple, list] = defaultdict(list)
    for r in results:
        groups[behaviour(r)].append(r)
    skip = bench_only()
    unknown = sorted(skip - {c.name for c in cases})
    if args.write:
        keep = {min(members, key=lambda r: (r.cpu_seconds, r.name)).name for members in groups.values()}
        keep |= {r.name for r in results if r.cpu_seconds >= HEAVY_CPU_S or r.peak_rss_mb >= HEAVY_RSS_MB}
        skip = frozenset(c.name for c in cases if c.name not in keep)
        BENCH_ONLY_FILE.write_text(_HEADER + "".join(f"{name}\n" for name in sorted(skip)), encoding="utf-8")
        unknown = []
    uncovered = [key for key, members in groups.items() if all(r.name in skip for r in members)]
    heavy_skipped = [r for r in results
                     if r.name in skip and (r.cpu_seconds >= HEAVY_CPU_S or r.peak_rss_mb >= HEAVY_RSS_MB)]
    in_ci = [r for r in results if r.name not in skip]
    codes = Counter(r.returncode for r in results)
    print(f"full corpus: {len(results)} cases in {seconds:.1f} s with {args.workers} workers, "
          f"{len(failures)} broke the rules; exit codes {dict(sorted(codes.items()))}; "
          f"case CPU {sum(r.cpu_seconds for r in results):.1f} s")
    print(f"{len(groups)} behaviours; CI runs {len(in_ci)} cases (case CPU {sum(r.cpu_seconds for r in in_ci):.1f} s); "
          f"behaviours without a CI case: {len(uncovered)}; heavy cases (>= {HEAVY_CPU_S:.0f} s CPU or "
          f">= {HEAVY_RSS_MB:.0f} MiB) not in CI: {len(heavy_skipped)}; "
          f"bench-only names not in the corpus: {len(unknown)}" + ("; bench_only.txt rewritten" if args.write else ""))
    for line in failures:
        print("FAIL", line)
    for kind, code, shape in uncovered:
        examples = ", ".join(r.name for r in groups[kind, code, shape][:3])
        print(f"NOT IN CI {kind} exit {code}: {shape[:160]}  ({examples})")
    for r in heavy_skipped:
        print(f"HEAVY NOT IN CI {r.name}: {r.cpu_seconds:.2f} s CPU, {r.peak_rss_mb:.0f} MiB")
    for name in unknown:
        print("UNKNOWN", name)
    return 1 if failures or uncovered or heavy_skipped or unknown else 0


if __name__ == "__main__":
    sys.exit(main())
