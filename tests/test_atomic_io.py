"""Outputs never destroy what they replace: devices, FIFOs, folders and links (calib_core.io.atomic).

Device cases use a private node of /dev/full's device (made with mknod, as root): a regression must not
replace the machine's own /dev/full, as the code before this test did.
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from calib_core.errors import CalibError
from calib_core.io.atomic import TEMP_PREFIX, remove_stale_temp_files, write_bytes_atomic, write_yaml_atomic
from repo_paths import REPO, SAMPLE


def _no_temp_files(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.startswith(TEMP_PREFIX)]


def _full_device(folder: Path) -> Path:
    """A private node of /dev/full's device (1, 7): a regression here must not replace the machine's own."""
    node = folder / "full"
    try:
        os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    except OSError as exc:
        pytest.skip(f"cannot make a device node here ({exc.strerror}); needs root")
    return node


def test_a_device_is_refused_and_left_a_device(tmp_path):
    full = _full_device(tmp_path)
    before = os.stat(full)
    with pytest.raises(CalibError) as err:
        write_bytes_atomic(full, b"x")
    assert str(err.value).startswith(f"{full}: is a device")
    after = os.stat(full)
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev and after.st_ino == before.st_ino
    assert _no_temp_files(tmp_path)


def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "out.yaml"
    os.mkfifo(fifo)
    with pytest.raises(CalibError, match=r"out\.yaml: is a FIFO"):
        write_yaml_atomic(fifo, {"a": 1})
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert _no_temp_files(tmp_path)


def test_a_folder_is_refused_with_the_users_path(tmp_path):
    folder = tmp_path / "results"
    folder.mkdir()
    with pytest.raises(CalibError) as err:
        write_bytes_atomic(folder, b"x")
    msg = str(err.value)
    assert msg.startswith(f"{folder}: is a folder")
    assert TEMP_PREFIX not in msg and ".tmp" not in msg
    assert folder.is_dir() and _no_temp_files(folder) and _no_temp_files(tmp_path)


def test_a_symlink_is_written_through_and_stays_a_link(tmp_path):
    target = tmp_path / "real" / "extrinsics.yaml"
    target.parent.mkdir()
    target.write_text("old\n")
    link = tmp_path / "link.yaml"
    link.symlink_to(target)
    write_bytes_atomic(link, b"new\n")
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text() == "new\n"
    assert _no_temp_files(tmp_path) and _no_temp_files(target.parent)


def test_a_chain_of_links_and_a_dangling_link(tmp_path):
    target = tmp_path / "t.yaml"
    (tmp_path / "b").symlink_to(target)  # dangling until written
    (tmp_path / "a").symlink_to(tmp_path / "b")
    write_bytes_atomic(tmp_path / "a", b"1")
    assert target.read_bytes() == b"1"
    assert (tmp_path / "a").is_symlink() and (tmp_path / "b").is_symlink()


def test_a_link_to_a_device_is_refused_and_names_both(tmp_path):
    full = _full_device(tmp_path)
    link = tmp_path / "out.yaml"
    link.symlink_to(full)
    with pytest.raises(CalibError) as err:
        write_bytes_atomic(link, b"x")
    assert str(err.value).startswith(f"{link}: is a device (via the link to {full})")
    assert link.is_symlink() and stat.S_ISCHR(os.stat(full).st_mode)


def test_a_link_loop_is_a_one_line_error(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(CalibError, match=str(tmp_path / "a")):
        write_bytes_atomic(tmp_path / "a", b"x")


def test_a_parent_that_is_a_file_names_the_users_path(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(CalibError) as err:
        write_bytes_atomic(tmp_path / "f" / "out.yaml", b"x")
    assert str(err.value).startswith(f"{tmp_path / 'f' / 'out.yaml'}: cannot write")


def test_replacing_keeps_the_files_permissions(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("a")
    path.chmod(0o640)
    write_bytes_atomic(path, b"b")
    assert path.read_bytes() == b"b" and stat.S_IMODE(path.stat().st_mode) == 0o640


def test_temporary_files_sit_next_to_the_target_with_the_prefix(tmp_path, monkeypatch):
    seen = []
    real_replace = os.replace

    def spy(src, dst):
        seen.append((Path(src), Path(dst)))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    write_bytes_atomic(tmp_path / "sub" / "x.yaml", b"1")
    (src, dst), = seen
    assert src.parent == dst.parent == tmp_path / "sub"
    assert src.name.startswith(f"{TEMP_PREFIX}{os.getpid()}-")


def test_stale_temp_files_of_dead_processes_are_removed(tmp_path):
    # A process that has exited: its pid is free (or reused by another process, which is left alone).
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = tmp_path / f"{TEMP_PREFIX}{dead_pid}-abc"
    stale.write_text("half a file")
    old = time.time() - 3600
    os.utime(stale, (old, old))
    in_flight = tmp_path / f"{TEMP_PREFIX}1-xyz"  # pid 1 always runs
    in_flight.write_text("another process is writing")
    os.utime(in_flight, (old, old))
    young = tmp_path / f"{TEMP_PREFIX}{dead_pid}-new"
    young.write_text("written after this process started")
    unrelated = tmp_path / ".notes.txt.abcd1234.tmp"
    unrelated.write_text("another program's temporary file")
    os.utime(unrelated, (old, old))
    legacy = tmp_path / ".session.yaml.k3j_9xq2.tmp"  # what the code before this left behind
    legacy.write_text("half a session")
    os.utime(legacy, (old, old))
    alive = os.path.exists(f"/proc/{dead_pid}")
    removed = remove_stale_temp_files(tmp_path, legacy_for=["session.yaml"])
    assert sorted(removed) == sorted([legacy] + ([] if alive else [stale]))
    assert in_flight.exists() and young.exists() and unrelated.exists()


def test_the_cli_removes_stale_temp_files_next_to_its_output(tmp_path):
    stale = tmp_path / f"{TEMP_PREFIX}999999999-abc"  # above any pid_max: never a live process
    stale.write_text("left by a killed run")
    old = time.time() - 3600
    os.utime(stale, (old, old))
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
         "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(tmp_path / "e.yaml")],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )
    assert proc.returncode in (0, 3), proc.stderr
    assert not stale.exists()
    assert (tmp_path / "e.yaml").is_file()


def test_the_cli_refuses_a_device_in_one_line(tmp_path):
    full = _full_device(tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "solve", "--scan", str(SAMPLE / "scan.npz"), "--camera", str(SAMPLE / "camera.yaml"),
         "--pairs", str(SAMPLE / "pairs.yaml"), "-o", str(full)],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [f"error: {full}: is a device; refusing to write over anything but a regular file"]
    assert stat.S_ISCHR(os.stat(full).st_mode)


def test_ba_images_into_an_existing_file_is_one_line(tmp_path):
    existing = tmp_path / "notes.txt"
    existing.write_text("keep")
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "ba-images", "--scan", str(SAMPLE / "scan.npz"), "-o", str(existing)],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1
    assert proc.stderr.startswith(f"error: {existing}: exists and is not a folder")
    assert existing.read_text() == "keep"
