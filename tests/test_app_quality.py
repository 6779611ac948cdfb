"""The solve's quality verdict and its excluded pairs are shown on the page (issue 8)."""

from __future__ import annotations

import re

from app.ui_common import md_escape
from calib_core.pairs import Pair, load_pairs_yaml
from browser_helpers import start_sample_app
from repo_paths import SAMPLE


def table_rows(table: str) -> dict[int, str]:
    """Pair id -> its table row."""
    out = {}
    for line in table.splitlines():
        m = re.match(r"\|\s*\**(\d+)\**\s*\|", line)
        if m:
            out[int(m.group(1))] = line
    return out


def test_a_wrong_pair_is_shown_excluded_by_its_id_with_the_verdict(tmp_path):
    pairs = load_pairs_yaml(SAMPLE / "pairs.yaml")
    assert len(pairs) == 10
    bad = 3  # its pixel moved 60 px: far beyond click noise, the solve must leave it out
    u, v = pairs[bad].pixel
    pairs[bad] = Pair(pairs[bad].laser_rc, None, (u + 60.0, v))
    app, d = start_sample_app(tmp_path, pairs)
    try:
        bad_id = app.state.picks[bad].id
        r = app.result
        assert r.outlier_ids == [bad_id]  # named by the id the page shows
        rows = table_rows(d.residual_table)
        assert sorted(rows) == sorted(p.id for p in app.state.picks)
        assert "excluded" in rows[bad_id]
        assert all("excluded" not in row for pid, row in rows.items() if pid != bad_id)
        panel = d.result_panel
        assert r.quality.status in ("warning", "unreliable")  # a pair left out is never "ok"
        assert f"Quality: {r.quality.status}".lower() in panel.lower()
        assert f"Left out of the fit: pair {bad_id}" in panel
        for reason in r.quality.reasons:
            assert md_escape(reason) in panel
    finally:
        app.stop()


def test_clean_pairs_show_ok_and_every_pair_in_the_fit(tmp_path):
    app, d = start_sample_app(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml"))
    try:
        assert app.result.outlier_ids == []
        rows = table_rows(d.residual_table)
        assert len(rows) == 10 and all(row.rstrip().endswith("yes |") for row in rows.values())
        status = app.result.quality.status
        assert f"Quality: {status}".lower() in d.result_panel.lower()
        assert "🔴" not in d.result_panel or status == "unreliable"
    finally:
        app.stop()


def test_user_text_in_reasons_is_escaped():
    from app.ui_common import md_escape

    assert "<" not in md_escape("<img src=x onerror=alert(1)>")
