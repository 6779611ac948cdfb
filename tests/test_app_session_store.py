"""The session journal: compaction keeps pace with a burst without running all the time."""

from __future__ import annotations

import time

import yaml

from app import session_store
from app.session_store import SessionStore


def session(k: int) -> dict:
    return {"format": "ba-calib-session", "version": 1, "next_id": k + 2,
            "pairs": [{"id": i + 1, "laser_rc": [i, i], "laser_xyz": None, "pixel": [float(i), 1.0]}
                      for i in range(k % 50)], "view": {}}


def test_a_burst_that_never_pauses_is_compacted_a_bounded_number_of_times(tmp_path):
    store = SessionStore(tmp_path / "s.yaml")
    n = 3 * session_store.COMPACT_RECORDS
    t0 = time.perf_counter()
    for k in range(n):
        store.append(session(k))
    burst_s = time.perf_counter() - t0
    # One compaction per COMPACT_RECORDS appends (the YAML dump is slow: it must not loop while appends go on).
    assert store.compactions <= n // session_store.COMPACT_RECORDS + 1, (store.compactions, burst_s)
    store.close()
    assert yaml.safe_load((tmp_path / "s.yaml").read_text())["next_id"] == n + 1
    assert not (tmp_path / "s.yaml.journal").exists()
    restored, from_yaml = SessionStore(tmp_path / "s.yaml").load()
    assert from_yaml and restored["pairs"] == session(n - 1)["pairs"]
