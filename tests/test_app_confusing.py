"""The "Confusing" items of issue 11: one pair id, import asks, Clear all is undoable, --port, file references."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from app_driver import AppDriver
from calib_core.errors import CalibError
from calib_core.pairs import Pair, load_pairs_yaml, resolve_pairs, save_pairs_yaml
from browser_helpers import free_port
from repo_paths import SAMPLE

ROOT = SAMPLE.parent


@pytest.fixture
def driver(tmp_path):
    from app.server import CalibrationApp

    app = CalibrationApp(SAMPLE / "scan.npz", SAMPLE / "image.png", SAMPLE / "camera.yaml",
                         session_path=tmp_path / "session.yaml", output_path=tmp_path / "out" / "extrinsics.yaml",
                         port=free_port())
    try:
        yield AppDriver(app)
    finally:
        app.stop()


def ends(picks):
    return [(p.laser_rc, p.pixel) for p in picks]


def file_bytes(tmp_path, pairs, name="pairs.yaml"):
    path = tmp_path / name
    save_pairs_yaml(path, pairs)
    return path.read_bytes()


def test_import_asks_append_or_replace_and_skips_exact_duplicates(driver, tmp_path):
    app = driver.app
    sample = load_pairs_yaml(SAMPLE / "pairs.yaml")
    notes = driver.upload_pairs("first.yaml", file_bytes(tmp_path, sample[:6]))
    assert driver.open_question is None  # nothing to replace: no question
    assert [t for t, _ in notes] == ["Pairs imported"] and len(app.state.picks) == 6
    first = ends(app.state.picks)

    # The same file again: asked, and appending adds nothing (all 6 are exact duplicates).
    notes = driver.upload_pairs("first.yaml", file_bytes(tmp_path, sample[:6]), answer=None)
    question = driver.open_question
    assert question is not None and "Append" in question and "Replace all" in question
    assert "6 exact duplicates" in question
    assert len(app.state.picks) == 6  # nothing changes until answered
    notes = driver.answer_question("Append")
    assert driver.open_question is None
    assert ends(app.state.picks) == first
    assert "6 exact duplicates skipped" in notes[-1][1]

    # Overlapping file: only the new pairs are appended.
    notes = driver.upload_pairs("more.yaml", file_bytes(tmp_path, sample[4:9]), answer="Append")
    assert ends(app.state.picks) == first + ends(Pair(p.laser_rc, None, p.pixel) for p in sample[6:9])
    assert "3 pairs added" in notes[-1][1] and "2 exact duplicates skipped" in notes[-1][1]

    # Cancel changes nothing; Replace all replaces, and Undo brings the old pairs back.
    before = ends(app.state.picks)
    driver.upload_pairs("last.yaml", file_bytes(tmp_path, sample[8:]), answer="Cancel")
    assert ends(app.state.picks) == before
    notes = driver.upload_pairs("last.yaml", file_bytes(tmp_path, sample[8:]), answer="Replace all")
    assert ends(app.state.picks) == [(p.laser_rc, p.pixel) for p in sample[8:]]
    assert "replaced" in notes[-1][1]
    driver.press_edit("Undo")
    assert ends(app.state.picks) == before


def test_clear_all_says_it_can_be_undone_and_undo_restores(driver, tmp_path):
    app = driver.app
    driver.upload_pairs("p.yaml", file_bytes(tmp_path, load_pairs_yaml(SAMPLE / "pairs.yaml")[:5]))
    before = app.state.picks
    notes = driver.press_clear_all()
    assert app.state.picks == ()
    assert notes and notes[-1][0] == "Pairs cleared" and "Undo" in notes[-1][1] and "5 pairs" in notes[-1][1]
    driver.press_edit("Undo")
    assert app.state.picks == before  # same ids, same ends
    driver.press_clear_all()
    assert driver.press_clear_all()[-1][0] == "Not accepted"  # nothing to clear: said, not silent
    driver.press_edit("Undo")  # the refused clear made no undo step: this undoes the first clear
    assert app.state.picks == before


def test_one_pair_id_in_the_table_the_files_and_the_messages(driver, tmp_path):
    app = driver.app
    sample = load_pairs_yaml(SAMPLE / "pairs.yaml")
    # A file with its own ids: they are kept, and they are what the table and the files show.
    ids = [31, 7, 12, 40, 5, 26]
    with_ids = [Pair(p.laser_rc, None, p.pixel, id=i) for p, i in zip(sample, ids)]
    driver.upload_pairs("ids.yaml", file_bytes(tmp_path, with_ids))
    assert [p.id for p in app.state.picks] == ids
    assert driver.wait_idle() and app.result is not None
    for i in ids:
        assert f"| {i} |" in driver.residual_table or f"| **{i}** |" in driver.residual_table
    out = tmp_path / "export.yaml"
    app.state.export_pairs_file(out)
    assert [p.id for p in load_pairs_yaml(out)] == ids
    data, written = driver.app.export_panel.export_extrinsics()
    doc = yaml.safe_load(data)
    assert [int(e["id"]) for e in doc["pairs"]] == ids
    # Messages about a pair name its id.
    hole = np.argwhere(~app.depth.valid)[0]
    bad = [Pair((int(hole[0]), int(hole[1])), None, (1.0, 1.0), id=17)]
    with pytest.raises(CalibError, match=r"^pair 17: "):
        resolve_pairs(bad, app.depth, app.camera)


def test_camera_file_is_referenced_from_the_yaml_folder_and_the_download_is_self_contained(driver, tmp_path):
    from calib_core.cameras.io import camera_from_dict

    app = driver.app
    driver.upload_pairs("p.yaml", (SAMPLE / "pairs.yaml").read_bytes())
    assert driver.wait_idle() and app.result is not None
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    old = os.getcwd()
    os.chdir(elsewhere)  # the process's folder must not matter
    try:
        data, written = app.export_panel.export_extrinsics()
    finally:
        os.chdir(old)
    assert written == tmp_path / "out" / "extrinsics.yaml"
    block = yaml.safe_load(written.read_text())["camera"]
    assert (written.parent / block["file"]).resolve() == (SAMPLE / "calib_results.txt").resolve()
    # The download lands in a folder we do not know: no file reference, the model inline.
    inline = yaml.safe_load(data)["camera"]
    assert "file" not in inline
    cam = camera_from_dict(inline, base_dir=tmp_path / "nowhere")
    px = np.array([[100.0, 80.0], [320.0, 240.0]])
    np.testing.assert_allclose(cam.project(cam.bearing(px))[0], app.camera.project(app.camera.bearing(px))[0],
                               atol=1e-6)


def test_no_command_takes_port_and_host_like_serve():
    from app.cli import build_parser, with_default_command

    parser = build_parser()
    args = parser.parse_args(with_default_command(parser, ["--port", "8300", "--host", "127.0.0.2"]))
    assert (args.command, args.port, args.host) == ("serve", 8300, "127.0.0.2")
    args = parser.parse_args(with_default_command(parser, ["--debug"]))
    assert (args.command, args.port, args.host, args.debug) == ("serve", 8080, "127.0.0.1", True)
    args = parser.parse_args(with_default_command(parser, ["serve", "--port", "8301"]))
    assert (args.command, args.port) == ("serve", 8301)
    args = parser.parse_args(with_default_command(parser, ["solve", "--camera", "c.yaml", "--pairs", "p.yaml",
                                                           "-o", "o.yaml"]))
    assert args.command == "solve"


def test_ba_calib_with_only_a_port_serves_there(tmp_path):
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "--port", str(port), "--host", "127.0.0.1"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        seen = []
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            seen.append(line)
            if "ba-calib: open" in line:
                break
        assert any(f"http://127.0.0.1:{port}" in s and "ba-calib: open" in s for s in seen), "".join(seen)
        with socket.create_connection(("127.0.0.1", port), timeout=10):
            pass
    finally:
        proc.terminate()
        proc.wait(timeout=30)
