"""A failing ``ba-calib`` command prints exactly one ``error:`` line and exits 2, whatever the
libraries print on the way (libpng writes to file descriptor 2 directly) and however the input fails
(argparse, RecursionError-deep files, undecodable paths)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from repo_paths import REPO, SAMPLE


def run_cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], capture_output=True, timeout=300, cwd=cwd)


def one_error_line(proc: subprocess.CompletedProcess) -> str:
    err = proc.stderr.decode("utf-8", "replace")
    assert proc.returncode == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


def test_libpng_messages_are_folded_into_the_one_error_line(tmp_path):
    png = (SAMPLE / "image.png").read_bytes()
    cut = tmp_path / "cut.png"
    cut.write_bytes(png[: len(png) // 3])  # libpng prints "libpng error: ..." on fd 2 while decoding
    proc = run_cli("colorize", "--scan", str(SAMPLE / "scan.npz"), "--image", str(cut), "--camera", str(SAMPLE / "camera.yaml"),
                   "--extrinsics", str(SAMPLE / "ground_truth.yaml"), "-o", str(tmp_path / "c.ply"))
    line = one_error_line(proc)
    assert "cut.png" in line and "libpng error" in line


def test_argument_errors_are_one_line():
    line = one_error_line(run_cli("solve", "--camera", "c.yaml", "--pairs", "p.yaml", "-o", "e.yaml", "--image-size", "1e9", "1e9"))
    assert "--image-size" in line and "invalid int value: '1e9'" in line and "--help" in line
    line = one_error_line(run_cli("solve", "--camera", "c.yaml", "--pairs", "p.yaml", "-o", "e.yaml", "--image-size", "100000", "100000"))
    assert "--image-size" in line and "65536" in line


def test_a_camera_nested_100k_deep_is_one_line_not_a_recursion_error(tmp_path):
    cam = tmp_path / "cam.yaml"
    cam.write_text("[" * 100_000 + "]" * 100_000)
    line = one_error_line(run_cli("solve", "--camera", str(cam), "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(tmp_path / "e.yaml")))
    assert "cam.yaml" in line and "nested deeper than" in line


def test_a_fifo_camera_does_not_block(tmp_path):
    fifo = tmp_path / "cam.yaml"
    os.mkfifo(fifo)
    line = one_error_line(run_cli("solve", "--camera", str(fifo), "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(tmp_path / "e.yaml")))
    assert "cam.yaml: is a FIFO" in line


def test_an_output_name_with_undecodable_bytes_is_written_and_printed(tmp_path):
    name = os.fsdecode(b"e-\xff\xfe.yaml")
    proc = run_cli("solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
                   "--pairs", str(SAMPLE / "pairs.yaml"), "-o", name, cwd=tmp_path)
    assert proc.returncode in (0, 3), proc.stderr
    assert b"Traceback" not in proc.stderr
    assert (tmp_path / name).is_file()
    assert b"wrote e-\\udcff\\udcfe.yaml" in proc.stdout


def test_a_clean_run_prints_nothing_on_stderr(tmp_path):
    proc = run_cli("ba-images", "--scan", str(SAMPLE / "scan.npz"), "-o", str(tmp_path / "ba"))
    assert proc.returncode == 0 and proc.stderr == b""


# main() itself, with a stand-in command: what it does with library noise and with the errors that
# input can provoke deep inside a library (RecursionError, MemoryError).
import warnings  # noqa: E402

import pytest  # noqa: E402

import app.cli as cli  # noqa: E402
from calib_core.errors import CalibError  # noqa: E402


def _noisy_command(outcome):
    def command(args):
        warnings.warn("a library is unhappy", UserWarning)
        os.write(2, b"libfoo warning: written straight to fd 2\n")  # as libpng does, past sys.stderr
        if isinstance(outcome, BaseException):
            raise outcome
        print("result")
        return 0

    return command


def test_noise_is_folded_into_the_error_line(monkeypatch, capfd):
    monkeypatch.setattr(cli, "cmd_ba_images", _noisy_command(CalibError("x.pcd: no valid point")))
    assert cli.main(["ba-images", "--scan", "x.pcd", "-o", "out"]) == 2
    out, err = capfd.readouterr()
    assert err == ("error: x.pcd: no valid point [libraries said: UserWarning: a library is unhappy; "
                   "libfoo warning: written straight to fd 2]\n")


def test_noise_of_a_successful_command_follows_as_warnings(monkeypatch, capfd):
    monkeypatch.setattr(cli, "cmd_ba_images", _noisy_command(None))
    assert cli.main(["ba-images", "--scan", "x.pcd", "-o", "out"]) == 0
    out, err = capfd.readouterr()
    assert out == "result\n"
    assert err == "warning: UserWarning: a library is unhappy\nwarning: libfoo warning: written straight to fd 2\n"


@pytest.mark.parametrize("exc, text", [(RecursionError("maximum recursion depth exceeded"), "nested too deeply"),
                                       (MemoryError(), "out of memory")])
def test_recursion_and_memory_errors_are_one_line(monkeypatch, capfd, exc, text):
    monkeypatch.setattr(cli, "cmd_ba_images", _noisy_command(exc))
    assert cli.main(["ba-images", "--scan", "x.pcd", "-o", "out"]) == 2
    err = capfd.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and text in err
