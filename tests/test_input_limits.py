"""Every non-scan input is bounded and checked: regular files only, size, YAML/JSON depth and alias
limits, pair caps, and numbers that are whole, finite and sane."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest
import yaml

from calib_core.cameras import load_camera
from calib_core.errors import CalibError
from calib_core.io.extrinsics import load_extrinsics_yaml
from calib_core.io.input_files import read_input_bytes
from calib_core.io.session_file import SESSION_VERSION, parse_session
from calib_core.io.yaml_files import MAX_DEPTH, parse_json_text, parse_yaml_text
from calib_core.pairs import MAX_PAIRS, load_pairs_yaml
from repo_paths import REPO


def _in_thread(fn, timeout: float = 20.0):
    """Run ``fn`` in a thread; fail (instead of hanging the suite) when it does not return in time."""
    out: dict = {}

    def run():
        try:
            out["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed back to the test
            out["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(timeout)
    assert not t.is_alive(), f"did not return within {timeout} s"
    if "error" in out:
        raise out["error"]
    return out.get("value")


# ---------------------------------------------------------------- regular files, sizes
@pytest.mark.parametrize("loader", [load_camera, load_pairs_yaml, load_extrinsics_yaml])
def test_a_fifo_is_refused_without_blocking(tmp_path, loader):
    fifo = tmp_path / "input.yaml"
    os.mkfifo(fifo)
    with pytest.raises(CalibError, match=r"input\.yaml: is a FIFO"):
        _in_thread(lambda: loader(fifo))


@pytest.mark.parametrize("loader", [load_camera, load_pairs_yaml, load_extrinsics_yaml])
@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_endless_devices_are_refused_before_reading(loader, device):
    if not Path(device).exists():
        pytest.skip(f"no {device}")
    with pytest.raises(CalibError, match=f"{device}: is a device"):
        _in_thread(lambda: loader(device))


def test_an_ocam_yaml_naming_dev_zero_is_refused(tmp_path):
    cam = tmp_path / "cam.yaml"
    cam.write_text("model: ocam\nfile: /dev/zero\n")
    with pytest.raises(CalibError, match="/dev/zero: is a device"):
        _in_thread(lambda: load_camera(cam))


def test_a_file_over_the_size_limit_is_refused_by_its_size(tmp_path):
    big = tmp_path / "camera.yaml"
    with open(big, "wb") as f:
        f.truncate(2 << 30)  # sparse: 2 GiB that costs nothing to make
    with pytest.raises(CalibError, match="2.05e\\+03 MiB is too large for a camera file"):
        load_camera(big)


def test_a_file_growing_past_the_limit_while_read_is_refused(tmp_path):
    path = tmp_path / "f.yaml"
    path.write_bytes(b"x" * 100)
    assert read_input_bytes(path, "test file", 100) == b"x" * 100
    with pytest.raises(CalibError, match="101 bytes is too large"):
        path.write_bytes(b"x" * 101)
        read_input_bytes(path, "test file", 100)


# ---------------------------------------------------------------- YAML and JSON structure
def test_billion_laughs_is_refused_quickly():
    lines = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for prev, name in zip("abcdefgh", "bcdefghi"):
        lines.append(f"{name}: &{name} [{', '.join(['*' + prev] * 9)}]")
    # 9^9 = 387 million strings once expanded; 10 aliases-of-aliases levels in 9 lines of text.
    with pytest.raises(CalibError, match="holds more than 100,000 values"):
        _in_thread(lambda: parse_yaml_text("\n".join(lines), "lol.yaml"), timeout=5)


def test_aliases_within_the_limits_still_load():
    assert parse_yaml_text("a: &x [1, 2]\nb: *x\n", "ok.yaml") == {"a": [1, 2], "b": [1, 2]}


@pytest.mark.parametrize(
    "text",
    ["[" * 100_000 + "]" * 100_000, "{a: " * 5_000 + "1" + "}" * 5_000,
     "".join(" " * i + "- \n" for i in range(5_000)) + " " * 5_000 + "x\n"],
    ids=["flow_list_100k", "flow_map_5k", "block_list_5k"],
)
def test_deep_yaml_is_refused_not_a_recursion_error(text):
    # One promise whichever layer notices first (our event walk, or PyYAML's own cap from 6.0.4 on):
    # one line that names the file and says how deep is allowed.
    with pytest.raises(CalibError, match=f"^deep.yaml: YAML nested deeper than {MAX_DEPTH} levels") as info:
        _in_thread(lambda: parse_yaml_text(text, "deep.yaml"), timeout=10)
    assert "\n" not in str(info.value)


def test_nesting_at_the_limit_loads():
    text = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    value = parse_yaml_text(text, "ok.yaml")
    depth = 0
    while isinstance(value, list):
        depth += 1
        value = value[0] if value else None
    assert depth == MAX_DEPTH


def test_aliases_cannot_stack_nesting_past_the_limit():
    lines = ["a0: &a0 " + "[" * 40 + "]" * 40]
    for i in range(1, 5):
        lines.append(f"a{i}: &a{i} " + "[" * 30 + f"*a{i - 1}" + "]" * 30)
    with pytest.raises(CalibError, match="nested deeper"):
        parse_yaml_text("\n".join(lines), "stacked.yaml")


@pytest.mark.parametrize(
    "text, fragment",
    [("a: " + "9" * 100_000, "malformed YAML"), ("a: 2001-13-45", "malformed YAML"),
     ("a: !!python/object/apply:os.system ['true']", "malformed YAML")],
)
def test_constructor_errors_are_one_line(text, fragment):
    with pytest.raises(CalibError, match=fragment) as err:
        parse_yaml_text(text, "x.yaml")
    assert "\n" not in str(err.value)


def test_deep_json_is_refused_and_strings_do_not_count():
    with pytest.raises(CalibError, match=f"JSON nested deeper than {MAX_DEPTH} levels"):
        parse_json_text("[" * 100_000 + "]" * 100_000, "deep.json")
    assert parse_json_text(json.dumps({"s": "[[[[" * 1000 + '\\"'}), "ok.json") == {"s": "[[[[" * 1000 + '\\"'}


# ---------------------------------------------------------------- pairs
def _pairs_file(tmp_path: Path, entries: list) -> Path:
    path = tmp_path / "pairs.yaml"
    path.write_text(yaml.safe_dump({"pairs": entries}))
    return path


@pytest.mark.parametrize(
    "rc, fragment",
    [([True, False], "expected 2 numbers"), ([1e20, 5], "whole numbers from 0 to"), ([1.5, 2], "whole numbers"),
     ([-1, 2], "whole numbers from 0"), ([2**63, 0], "whole numbers from 0 to")],
)
def test_laser_rc_must_be_two_sane_whole_numbers(tmp_path, rc, fragment):
    with pytest.raises(CalibError, match=fragment):
        load_pairs_yaml(_pairs_file(tmp_path, [{"laser_rc": rc, "pixel": [1.0, 2.0]}]))


@pytest.mark.parametrize("key, value", [("laser_xyz", [1e300, 0.0, 0.0]), ("pixel", [1e300, 1.0]), ("pixel", [True, 2.0])])
def test_absurd_or_boolean_numbers_in_pairs_are_refused(tmp_path, key, value):
    entry = {"laser_xyz": [1.0, 2.0, 3.0], "pixel": [1.0, 2.0]}
    entry[key] = value
    with pytest.raises(CalibError, match=key):
        load_pairs_yaml(_pairs_file(tmp_path, [entry]))


def test_the_pair_cap_names_the_option(tmp_path):
    entry = "- laser_xyz: [1.0, 2.0, 3.0]\n  pixel: [1.0, 2.0]\n"
    path = tmp_path / "pairs.yaml"
    path.write_text("pairs:\n" + entry * (MAX_PAIRS + 1))
    with pytest.raises(CalibError, match=f"{MAX_PAIRS + 1:,} pairs; the cap is {MAX_PAIRS:,} pairs \\(raise it with --max-pairs\\)"):
        load_pairs_yaml(path)
    assert len(load_pairs_yaml(path, max_pairs=MAX_PAIRS + 1)) == MAX_PAIRS + 1


def test_a_huge_pairs_file_stops_early_and_names_the_option(tmp_path):
    path = tmp_path / "pairs.yaml"
    path.write_text("pairs:\n" + "- {laser_xyz: [1, 2, 3], pixel: [1, 2]}\n" * 100_000)
    with pytest.raises(CalibError, match="--max-pairs"):
        _in_thread(lambda: load_pairs_yaml(path), timeout=10)


# ---------------------------------------------------------------- cameras and extrinsics
def _camera(tmp_path: Path, **changes) -> Path:
    data = {"model": "pinhole", "width": 640, "height": 480, "K": [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]], "dist": []}
    data.update(changes)
    path = tmp_path / "cam.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    "changes, fragment",
    [({"K": [[1e300, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]}, "at most 1e\\+08"),
     ({"width": 10**9}, "width must be at most 65536"), ({"width": True}, "positive integer"),
     ({"dist": [1e300, 0, 0, 0]}, "at most 1e\\+08")],
)
def test_absurd_camera_numbers_are_refused(tmp_path, changes, fragment):
    with pytest.raises(CalibError, match=fragment):
        load_camera(_camera(tmp_path, **changes))


def test_image_size_override_is_bounded(tmp_path):
    with pytest.raises(CalibError, match="at most 65536"):
        load_camera(_camera(tmp_path), image_size=(10**9, 10**9))


@pytest.mark.parametrize("block", [{"translation_m": [1e300, 0, 0], "quaternion_xyzw": [0, 0, 0, 1]},
                                   {"translation_m": [0, 0, 0], "rpy_deg": [1e300, 0, 0]}])
def test_absurd_extrinsics_are_refused(tmp_path, block):
    path = tmp_path / "e.yaml"
    path.write_text(yaml.safe_dump({"T_camera_lidar": block}))
    with pytest.raises(CalibError, match="at most"):
        load_extrinsics_yaml(path)


def test_an_ocam_model_in_a_pjlab_json_with_a_shrinking_polynomial_is_refused(tmp_path):
    # PJLab's OCam layout (cam_K = [[c, d, u0], [e, 1, v0], [0, 0, 1]], cam_dist = world2cam), but the
    # polynomial's radius shrinks away from the axis: no camera projects like that.
    doc = {"front_camera-intrinsic": {"param": {
        "img_dist_w": 1280, "img_dist_h": 960,
        "cam_K": {"rows": 3, "cols": 3, "data": [[1.0, 0.0, 640.0], [0.0, 1.0, 480.0], [0.0, 0.0, 1.0]]},
        "cam_dist": {"rows": 1, "cols": 3, "data": [[100.0, -300.0, 0.0]]},
    }}}
    path = tmp_path / "Front.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibError) as err:
        load_camera(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and "world2cam polynomial does not grow" in msg and "\n" not in msg


# ---------------------------------------------------------------- sessions
def _session(**changes) -> dict:
    data = {"format": "ba-calib-session", "version": SESSION_VERSION, "next_id": 3,
            "pairs": [{"id": 1, "laser_rc": [2, 3], "pixel": [4.0, 5.0]}, {"id": 2, "laser_xyz": [1.0, 2.0, 3.0]}],
            "view": {"point_size": 2}}
    data.update(changes)
    return data


def test_a_valid_session_is_read_back():
    s = parse_session(_session(), "s.yaml")
    assert [p.id for p in s.picks] == [1, 2]
    assert s.picks[0].laser_rc == (2, 3) and s.picks[0].pixel == (4.0, 5.0) and s.picks[1].pixel is None
    assert s.next_id == 3 and s.view == {"point_size": 2}
    assert parse_session(_session(next_id=None), "s.yaml").next_id == 3  # above every id


@pytest.mark.parametrize(
    "changes, fragment",
    [({"version": 999}, "session version 999 is newer"), ({"version": "1"}, "'version' must be a whole number"),
     ({"version": True}, "'version' must be"), ({"next_id": "abc"}, "next_id: expected a whole number"),
     ({"next_id": -5}, "next_id: expected a whole number"), ({"next_id": 2**70}, "next_id"),
     ({"pairs": {"a": 1}}, "'pairs' must be a list"), ({"pairs": [{"id": "x"}]}, "id: expected a whole number"),
     ({"pairs": [{"id": 1}, {"id": 1}]}, "duplicate id 1"), ({"pairs": [{"id": 1, "laser_rc": [1e20, 5]}]}, "laser_rc"),
     ({"pairs": [{"id": 1, "laser_rc": [True, False]}]}, "laser_rc"), ({"view": [1]}, "'view' must be a mapping"),
     ({"format": "other"}, "not a ba-calib session")],
)
def test_bad_sessions_are_one_line_errors(changes, fragment):
    with pytest.raises(CalibError, match=fragment) as err:
        parse_session(_session(**changes), "s.yaml")
    assert str(err.value).startswith("s.yaml") and "\n" not in str(err.value)


def test_serve_refuses_a_session_it_cannot_restore_before_loading_the_scene(tmp_path):
    import subprocess
    import sys

    session = tmp_path / "s.yaml"
    session.write_text(yaml.safe_dump(_session(version=999)))
    proc = subprocess.run(
        [sys.executable, "-m", "app.cli", "serve", "--scan", str(tmp_path / "no-scan.npz"), "--image", str(tmp_path / "no.png"),
         "--camera", str(tmp_path / "no.yaml"), "--session", str(session), "--port", "0"],
        capture_output=True, text=True, timeout=120, cwd=REPO,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines() == [f"error: {session}: session version 999 is newer than this ba-calib reads ({SESSION_VERSION}); update ba-calib"]


def test_check_session_file_reads_sessions_and_plain_pairs_files(tmp_path):
    from calib_core.io.session_file import check_session_file

    check_session_file(tmp_path / "new.yaml")  # a new session: nothing to check
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(_session()))
    check_session_file(good)
    pairs = tmp_path / "pairs.yaml"
    pairs.write_text(yaml.safe_dump({"pairs": [{"laser_rc": [True, False], "pixel": [1.0, 2.0]}]}))
    with pytest.raises(CalibError, match="laser_rc"):
        check_session_file(pairs)
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(_session(next_id="abc")))
    with pytest.raises(CalibError, match="next_id"):
        check_session_file(bad)
