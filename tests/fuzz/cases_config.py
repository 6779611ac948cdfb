"""Fuzz cases for every non-scan file the CLI takes, and for its arguments.

Files: camera files (our YAML, ROS ``camera_info``, OCamCalib ``calib_results.txt``, the
``file:`` an OCam YAML names, PJLab JSON, our format as JSON), pairs files, extrinsics files,
session files, and output paths.  Three groups:

* ``config/<kind>/generic/...``: the same hostile file types for each input (FIFO, devices,
  link loops, a sparse 2 GiB file, binary junk, "billion laughs", nesting 100,000 deep ...);
* ``config/<kind>/...``: malformed content specific to the file's format;
* ``config/mutation/...``: seeded random byte mutations of valid files.

The valid files are consistent: the pairs of each camera are exact projections of points
placed with the sample's ground-truth pose, so the unmutated cases solve cleanly.
"""

from __future__ import annotations

import json
import os
import random
import stat
from pathlib import Path

import numpy as np
import yaml

from .case import FuzzCase

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_data"
OTHER_TOOLS = REPO.parent / "shared" / "data" / "other_tools_files"
SEED = 20071029  # IROS 2007

PINHOLE = {"model": "pinhole", "width": 640, "height": 480,
           "K": [[500.0, 0.0, 319.5], [0.0, 505.0, 239.5], [0.0, 0.0, 1.0]], "dist": [-0.1, 0.02, 0.001, -0.001, 0.0]}
FISHEYE = {"model": "fisheye", "width": 800, "height": 600,
           "K": [[300.0, 0.0, 399.5], [0.0, 300.0, 299.5], [0.0, 0.0, 1.0]], "D": [0.05, -0.01, 0.002, -0.0005]}
ROS = {"image_width": 640, "image_height": 480, "camera_name": "fuzz",
       "camera_matrix": {"rows": 3, "cols": 3, "data": [520.0, 0, 320.0, 0, 520.0, 240.0, 0, 0, 1]},
       "distortion_model": "plumb_bob",
       "distortion_coefficients": {"rows": 1, "cols": 5, "data": [-0.2, 0.05, 0.0, 0.0, 0.0]}}
PJLAB = {"center_camera-intrinsic": {"sensor_name": "center_camera", "param_type": "intrinsic", "param": {
    "img_dist_w": 640, "img_dist_h": 480,
    "cam_K": {"rows": 3, "cols": 3, "type": 6, "continuous": True, "data": [[510.0, 0, 320.0], [0, 512.0, 240.0], [0, 0, 1]]},
    "cam_dist": {"rows": 1, "cols": 5, "type": 6, "continuous": True, "data": [[-0.15, 0.03, 0.0, 0.0, 0.0]]}}}}


def _dump(data) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)


def _pairs_for(camera_path: Path, rng: np.random.Generator, n: int = 10) -> list[dict]:
    """``n`` exact pairs for a camera: pixels spread over the image, points 3-9 m out, in the lidar frame."""
    from calib_core.cameras import load_camera
    from calib_core.io.extrinsics import load_extrinsics_yaml

    camera = load_camera(camera_path)
    T = load_extrinsics_yaml(SAMPLE / "ground_truth.yaml")["T_camera_lidar"]
    w, h = camera.width, camera.height
    pixels = np.column_stack([rng.uniform(0.2 * w, 0.8 * w, n), rng.uniform(0.2 * h, 0.8 * h, n)])
    rays = camera.bearing(pixels)
    ok = np.isfinite(rays).all(axis=1)
    pixels, rays = pixels[ok], rays[ok]
    X_cam = rays * rng.uniform(3.0, 9.0, len(rays))[:, None]
    Tinv = np.linalg.inv(T)
    X_lidar = X_cam @ Tinv[:3, :3].T + Tinv[:3, 3]
    return [{"laser_xyz": [float(v) for v in x], "pixel": [float(u) for u in p], "id": i}
            for i, (x, p) in enumerate(zip(X_lidar, pixels))]


# ------------------------------------------------------------------------ generic hostile files
def _generic_files(folder: Path, suffix: str, yaml_like: bool) -> list[tuple[str, Path]]:
    """The hostile files every input gets, as (label, path)."""
    folder.mkdir(parents=True, exist_ok=True)
    out: list[tuple[str, Path]] = []

    def text(label: str, content: str | bytes) -> None:
        p = folder / f"{label}{suffix}"
        p.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
        out.append((label, p))

    out.append(("missing", folder / f"missing{suffix}"))
    d = folder / f"folder{suffix}"
    d.mkdir(exist_ok=True)
    out.append(("folder", d))
    fifo = folder / f"fifo{suffix}"
    if not fifo.exists():
        os.mkfifo(fifo)
    out.append(("fifo", fifo))
    for dev in ("/dev/zero", "/dev/null", "/dev/urandom", "/dev/full"):
        out.append((f"dev_{Path(dev).name}", Path(dev)))
    loop_a, loop_b = folder / f"loop_a{suffix}", folder / f"loop_b{suffix}"
    for a, b in ((loop_a, loop_b), (loop_b, loop_a)):
        if not a.is_symlink():
            a.symlink_to(b.name)
    out.append(("symlink_loop", loop_a))
    dangling = folder / f"dangling{suffix}"
    if not dangling.is_symlink():
        dangling.symlink_to("nowhere" + suffix)
    out.append(("dangling_link", dangling))
    to_zero = folder / f"link_to_zero{suffix}"
    if not to_zero.is_symlink():
        to_zero.symlink_to("/dev/zero")
    out.append(("link_to_dev_zero", to_zero))
    sparse = folder / f"sparse_2gib{suffix}"
    with open(sparse, "wb") as f:
        f.truncate(2 << 30)
    out.append(("sparse_2gib", sparse))
    rnd = random.Random(SEED)
    text("empty", b"")
    text("binary_junk", bytes(rnd.getrandbits(8) for _ in range(4096)))
    text("nul_bytes", b"\0" * 4096)
    text("invalid_utf8", b"model: pinhole\nwidth: \xff\xfe\xfd\n")
    text("utf16", "model: pinhole\nwidth: 640\n".encode("utf-16"))
    text("long_line_2mb", "a" * (2 << 20))
    text("whitespace_3mb", " \n" * (3 << 19))
    text("control_chars", "".join(chr(c) for c in range(1, 32)) * 10)
    text("deep_flow_100k", "[" * 100_000 + "]" * 100_000)
    text("deep_map_flow_20k", "{a: " * 20_000 + "1" + "}" * 20_000)
    if yaml_like:
        lol = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
        for i, name in enumerate("bcdefghi"):
            prev = "a" if i == 0 else "bcdefghi"[i - 1]
            lol.append(f"{name}: &{name} [{','.join(['*' + prev] * 9)}]")
        text("billion_laughs", "\n".join(lol) + "\n")
        text("many_aliases", "a: &x 1\nb: [" + ", ".join(["*x"] * 5000) + "]\n")
        text("deep_block_5000", "".join(" " * i + "- \n" for i in range(0, 5000)) + " " * 5000 + "x\n")
        text("deep_block_map_3000", "".join(" " * i + "k:\n" for i in range(3000)))
        text("huge_int_100k_digits", "model: pinhole\nwidth: " + "9" * 100_000 + "\n")
        text("bad_timestamp", "model: pinhole\nwhen: 2001-13-45\nwidth: 640\n")
        text("python_tag", "model: !!python/object/apply:os.system ['true']\n")
        text("multi_document", "model: pinhole\n---\nmodel: fisheye\n")
        text("top_level_list", "- 1\n- 2\n")
        text("top_level_scalar", "hello\n")
        text("top_level_null", "~\n")
        text("duplicate_keys", "pairs: []\npairs: []\nmodel: pinhole\nmodel: ocam\n")
        text("tabs", "model:\tpinhole\n\twidth: 640\n")
        text("unclosed_quote", 'model: "pinhole\n')
        text("anchor_undefined", "model: *nothing\n")
        text("wide_mapping_200k", "".join(f"k{i}: {i}\n" for i in range(200_000)))
        text("binary_tag", "model: !!binary " + "QUFB" * 100_000 + "\n")
    else:
        text("json_deep_100k", "[" * 100_000 + "]" * 100_000)
        text("json_deep_object", '{"a":' * 50_000 + "1" + "}" * 50_000)
        text("json_nan", '{"model": "pinhole", "width": NaN, "height": Infinity}')
        text("json_truncated", '{"model": "pinhole", "width": 6')
        text("json_list", "[1, 2, 3]")
        text("json_huge_number", '{"model": "pinhole", "width": 1' + "0" * 5000 + "}")
        text("json_bad_escape", '{"model": "\\uZZZZ"}')
        text("json_lone_surrogate", '{"model": "\\ud800"}')
    return out


# ------------------------------------------------------------------------ format-specific content
def _camera_yaml_texts(folder: Path) -> dict[str, str]:
    p = dict(PINHOLE)

    def own(**changes) -> str:
        d = dict(p)
        for k, v in changes.items():
            if v is None:
                d.pop(k, None)
            else:
                d[k] = v
        return _dump(d)

    fifo = folder / "ocam_fifo.txt"
    if not fifo.exists():
        os.mkfifo(fifo)
    (folder / "ocam_sparse.txt").open("wb").truncate(1 << 30)
    return {
        "model_unknown": own(model="kannala_brandt_9"),
        "model_missing": own(model=None),
        "model_list": own(model=["pinhole"]),
        "model_number": own(model=3),
        "K_missing": own(K=None),
        "K_2x2": own(K=[[1, 0], [0, 1]]),
        "K_ragged": own(K=[[500, 0, 320], [0, 500], [0, 0, 1]]),
        "K_strings": own(K=[["a", 0, 320], [0, 500, 240], [0, 0, 1]]),
        "K_bools": own(K=[[True, False, True], [False, True, True], [False, False, True]]),
        "K_nan": "model: pinhole\nwidth: 640\nheight: 480\nK: [[.nan, 0, 320], [0, 500, 240], [0, 0, 1]]\n",
        "K_inf": "model: pinhole\nwidth: 640\nheight: 480\nK: [[.inf, 0, 320], [0, 500, 240], [0, 0, 1]]\n",
        "K_1e300": own(K=[[1e300, 0, 320], [0, 1e300, 240], [0, 0, 1]]),
        "K_1e400": "model: pinhole\nwidth: 640\nheight: 480\nK: [[1e400, 0, 320], [0, 500, 240], [0, 0, 1]]\n",
        "K_negative_f": own(K=[[-500, 0, 320], [0, 500, 240], [0, 0, 1]]),
        "K_zero_f": own(K=[[0, 0, 320], [0, 0, 240], [0, 0, 1]]),
        "K_skew": own(K=[[500, 3, 320], [0, 500, 240], [0, 0, 1]]),
        "K_tiny_f": own(K=[[1e-300, 0, 320], [0, 1e-300, 240], [0, 0, 1]]),
        "K_nested_deep": own(K=[[[[[[500]]]]]]),
        "dist_7_terms": own(dist=[0.1] * 7),
        "dist_huge": own(dist=[1e300, 0, 0, 0, 0]),
        "dist_strings": own(dist="k1 k2"),
        "dist_mapping": own(dist={"k1": 0.1}),
        "dist_wild": own(dist=[50.0, -80.0, 0.0, 0.0, 100.0]),
        "width_zero": own(width=0),
        "width_negative": own(width=-640),
        "width_fraction": own(width=640.5),
        "width_bool": own(width=True),
        "width_1e9": own(width=1_000_000_000, height=1_000_000_000),
        "width_1e300": own(width=1e300),
        "width_string": own(width="640"),
        "width_huge_int": own(width=2**70),
        "fisheye_D_3": _dump({**FISHEYE, "D": [0.1, 0.0, 0.0]}),
        "fisheye_D_missing": _dump({k: v for k, v in FISHEYE.items() if k != "D"}),
        "fisheye_D_wild": _dump({**FISHEYE, "D": [5.0, -20.0, 40.0, -30.0]}),
        "ocam_file_dev_zero": "model: ocam\nfile: /dev/zero\n",
        "ocam_file_dev_urandom": "model: ocam\nfile: /dev/urandom\n",
        "ocam_file_fifo": "model: ocam\nfile: ocam_fifo.txt\n",
        "ocam_file_sparse_1gib": "model: ocam\nfile: ocam_sparse.txt\n",
        "ocam_file_folder": "model: ocam\nfile: .\n",
        "ocam_file_self": "model: ocam\nfile: ocam_file_self.yaml\n",
        "ocam_file_missing": "model: ocam\nfile: nowhere.txt\n",
        "ocam_file_empty_string": "model: ocam\nfile: ''\n",
        "ocam_file_number": "model: ocam\nfile: 12\n",
        "ocam_file_traversal": "model: ocam\nfile: ../../../../../../../../etc/shadow\n",
        "ocam_inline_missing_pol": "model: ocam\nxc: 240\nyc: 320\nc: 1\nd: 0\ne: 0\nwidth: 640\nheight: 480\n",
        "ocam_inline_pol_empty": "model: ocam\npol: []\nxc: 240\nyc: 320\nc: 1\nd: 0\ne: 0\nwidth: 640\nheight: 480\n",
        "ocam_inline_singular_affine": "model: ocam\npol: [-100, 0, 0.004]\nxc: 240\nyc: 320\nc: 0\nd: 0\ne: 0\nwidth: 640\nheight: 480\n",
        "ocam_inline_pol_1e300": "model: ocam\npol: [-1e300, 0, 1e300]\nxc: 240\nyc: 320\nc: 1\nd: 0\ne: 0\nwidth: 640\nheight: 480\n",
        "ocam_inline_pol_zero": "model: ocam\npol: [0, 0, 0]\nxc: 240\nyc: 320\nc: 1\nd: 0\ne: 0\nwidth: 640\nheight: 480\n",
        "ocam_size_mismatch": "model: ocam\nfile: " + str(SAMPLE / "calib_results.txt") + "\nwidth: 640\n",
        "ros_data_missing": _dump({**ROS, "camera_matrix": {"rows": 3, "cols": 3}}),
        "ros_rows_cols_mismatch": _dump({**ROS, "camera_matrix": {"rows": 2, "cols": 2, "data": ROS["camera_matrix"]["data"]}}),
        "ros_rows_1e300": _dump({**ROS, "camera_matrix": {"rows": 1e300, "cols": 1, "data": ROS["camera_matrix"]["data"]}}),
        "ros_rows_huge_int": _dump({**ROS, "camera_matrix": {"rows": 2**80, "cols": 2**80, "data": [1]}}),
        "ros_unknown_distortion": _dump({**ROS, "distortion_model": "division"}),
        "ros_distortion_null": _dump({**ROS, "distortion_coefficients": None}),
        "ros_data_null": _dump({**ROS, "camera_matrix": {"rows": 3, "cols": 3, "data": None}}),
        "ros_matrix_is_list": _dump({**ROS, "camera_matrix": [1, 2, 3]}),
        "ros_size_string": _dump({**ROS, "image_width": "wide"}),
        "ros_equidistant_5": _dump({**ROS, "distortion_model": "equidistant"}),
    }


def _ocam_txt_texts() -> dict[str, str]:
    good = (SAMPLE / "calib_results.txt").read_text()
    nums = "5 -111.29 0.0 0.0041857 -1.54014e-05 7.42759e-08\n\n4 172.5 108.2 -1.7 8.8\n\n242.3 318.6\n\n1.0008 0.0011 -0.0009\n\n480 640\n"
    return {
        "only_comments": "# nothing\n# here\n",
        "ends_early": "5 -111.29 0.0 0.0041857\n",
        "count_zero": "0\n0\n242.3 318.6\n1 0 0\n480 640\n",
        "count_1e9": "1000000000 1 2 3\n",
        "count_fraction": "2.5 -111 0 1 1 240 320 1 0 0 480 640\n",
        "count_negative": "-3 1 2 3\n",
        "count_nan": "nan 1 2\n",
        "extra_numbers": nums + "1 2 3 4\n",
        "words": "five -111.29 zero\n",
        "nan_values": nums.replace("-111.29", "nan"),
        "inf_values": nums.replace("242.3", "inf"),
        "value_1e300": nums.replace("-111.29", "-1e300"),
        "value_1e400": nums.replace("-111.29", "-1e400"),
        "size_zero": nums.replace("480 640", "0 0"),
        "size_huge": nums.replace("480 640", "1e9 1e9"),
        "size_fraction": nums.replace("480 640", "480.5 640"),
        "affine_singular": nums.replace("1.0008 0.0011 -0.0009", "0 0 0"),
        "pol_all_zero": nums.replace("-111.29 0.0 0.0041857 -1.54014e-05 7.42759e-08", "0 0 0 0 0"),
        "hex_numbers": nums.replace("480 640", "0x1e0 0x280"),
        "underscored_numbers": nums.replace("480 640", "4_80 6_40"),
        "very_long_number": nums.replace("242.3", "2" * 100_000),
        "crlf": good.replace("\n", "\r\n"),
        "no_newline_at_end": good.rstrip("\n"),
    }


def _pjlab_json_texts() -> dict[str, str]:
    def with_param(**changes) -> str:
        d = json.loads(json.dumps(PJLAB))
        param = d["center_camera-intrinsic"]["param"]
        for k, v in changes.items():
            if v is None:
                param.pop(k, None)
            else:
                param[k] = v
        return json.dumps(d)

    out = {
        "no_param": json.dumps({"a": {"b": 1}}),
        "two_blocks": json.dumps({"a": PJLAB["center_camera-intrinsic"], "b": PJLAB["center_camera-intrinsic"]}),
        "param_list": json.dumps({"param": [1, 2]}),
        "cam_K_missing": with_param(cam_K=None),
        "cam_K_2x2": with_param(cam_K={"data": [[1, 0], [0, 1]]}),
        "cam_K_strings": with_param(cam_K={"data": [["a", 0, 1], [0, 1, 1], [0, 0, 1]]}),
        "cam_K_no_data": with_param(cam_K={"rows": 3}),
        "cam_K_1e300": with_param(cam_K={"data": [[1e300, 0, 1], [0, 1e300, 1], [0, 0, 1]]}),
        "cam_dist_20": with_param(cam_dist={"data": [[0.01] * 20]}),
        "cam_dist_null": with_param(cam_dist={"data": None}),
        "size_negative": with_param(img_dist_w=-1),
        "size_1e9": with_param(img_dist_w=10**9, img_dist_h=10**9),
        "size_string": with_param(img_dist_w="640"),
        "own_format_bad": json.dumps({"model": "pinhole", "K": "nope"}),
        "own_format_ocam_dev_zero": json.dumps({"model": "ocam", "file": "/dev/zero"}),
    }
    real = OTHER_TOOLS / "cam" / "pjlab_surround_ocam_Front.json"
    if real.is_file():
        out["pjlab_ocam_front_real_file"] = real.read_text()
    return out


def _pairs_texts(good: list[dict], many_good: list[dict]) -> dict[str, str]:
    xyz, px = good[0]["laser_xyz"], good[0]["pixel"]

    def with_first(**changes) -> str:
        first = dict(good[0])
        for k, v in changes.items():
            if v is None:
                first.pop(k, None)
            else:
                first[k] = v
        return _dump({"pairs": [first] + good[1:]})

    # Big files written as text: yaml.safe_dump of 100,000 entries takes seconds.
    many = "pairs:\n" + "".join(f"- laser_xyz: [{1.0 + i * 1e-3}, 2.0, 3.0]\n  pixel: [100.0, 100.0]\n" for i in range(100_000))
    same = "pairs:\n" + f"- laser_xyz: {xyz}\n  pixel: {px}\n" * 1_000
    over_cap = same + f"- laser_xyz: {xyz}\n  pixel: {px}\n"
    # 200 distinct pairs spread over the image with no pose behind them: all wrong, none repeated.
    random_200 = "pairs:\n" + "".join(
        f"- laser_xyz: [{5 + (i % 7)}.0, {(i % 20) * 0.5 - 5:.1f}, {(i // 20) * 0.5 - 2.5:.1f}]\n  pixel: [{20 + (i * 37) % 600}.5, {20 + (i * 53) % 440}.25]\n"
        for i in range(200))
    # The cap: 1,000 exact pairs (as many as automatic proposals could make).
    at_cap = "pairs:\n" + "".join(f"- laser_xyz: {p['laser_xyz']}\n  pixel: {p['pixel']}\n" for p in many_good)
    return {
        "laser_rc_bools": with_first(laser_xyz=None, laser_rc=[True, False]),
        "laser_rc_1e20": with_first(laser_xyz=None, laser_rc=[1e20, 5]),
        "laser_rc_fraction": with_first(laser_xyz=None, laser_rc=[1.5, 2]),
        "laser_rc_negative": with_first(laser_xyz=None, laser_rc=[-1, 2]),
        "laser_rc_2p63": with_first(laser_xyz=None, laser_rc=[2**63, 0]),
        "laser_rc_strings": with_first(laser_xyz=None, laser_rc=["1", "2"]),
        "laser_rc_three": with_first(laser_xyz=None, laser_rc=[1, 2, 3]),
        "laser_rc_and_xyz": with_first(laser_rc=[1, 2]),
        "neither_laser": with_first(laser_xyz=None),
        "pixel_missing": with_first(pixel=None),
        "pixel_nan": with_first(pixel=[float("nan"), 1.0]),
        "pixel_outside": with_first(pixel=[-1000.0, 5.0]),
        "pixel_1e300": with_first(pixel=[1e300, 1e300]),
        "pixel_bools": with_first(pixel=[True, True]),
        "pixel_nested": with_first(pixel=[[1, 2], [3, 4]]),
        "xyz_1e300": with_first(laser_xyz=[1e300, 0.0, 0.0]),
        "xyz_1e200_all": _dump({"pairs": [dict(p, laser_xyz=[v * 1e200 for v in p["laser_xyz"]]) for p in good]}),
        "xyz_at_origin": with_first(laser_xyz=[0.0, 0.0, 0.0]),
        "xyz_inf": with_first(laser_xyz=[float("inf"), 0.0, 0.0]),
        "id_bool": with_first(id=True),
        "id_negative": with_first(id=-5),
        "id_huge": with_first(id=2**40),
        "id_string": with_first(id="seven"),
        "source_unknown": with_first(source="psychic"),
        "precision_zero": with_first(precision_px=0),
        "precision_negative": with_first(precision_px=-1.0),
        "precision_1e300": with_first(precision_px=1e300),
        "check_string": with_first(check="yes"),
        "unknown_key": with_first(colour="red"),
        "pairs_null": "pairs: ~\n",
        "pairs_mapping": "pairs: {a: 1}\n",
        "pairs_string": "pairs: many\n",
        "pairs_empty": "pairs: []\n",
        "three_pairs": _dump({"pairs": good[:3]}),
        "all_identical": _dump({"pairs": [good[0]] * 10}),
        "all_checks": _dump({"pairs": [dict(p, check=True) for p in good]}),
        "collinear_points": _dump({"pairs": [dict(p, laser_xyz=[1.0 + i, 2.0 + i, 3.0 + i]) for i, p in enumerate(good)]}),
        "coplanar_4": _dump({"pairs": [dict(p, laser_xyz=[x, y, 0.0]) for p, (x, y) in zip(good, [(5, 1), (5, -1), (6, 1), (6, -1)])]}),
        "swapped_pixels": _dump({"pairs": [dict(p, pixel=q["pixel"]) for p, q in zip(good, good[::-1])]}),
        "pairs_1000_at_cap": at_cap,
        "pairs_200_random": random_200,
        "pairs_1000_identical": same,
        "pairs_1001_over_cap": over_cap,
        "pairs_100k": many,
        "pairs_100k_flow": "pairs: [" + ", ".join("{laser_xyz: [1, 2, 3], pixel: [1, 2]}" for _ in range(100_000)) + "]\n",
        "pairs_alias_bomb": "p: &p {laser_xyz: [1, 2, 3], pixel: [100, 100]}\nq: &q [" + ", ".join(["*p"] * 900) + "]\npairs: " + "[" + ", ".join(["*p"] * 900) + "]\n",
        "pairs_in_list_of_lists": _dump({"pairs": [[p] for p in good]}),
    }


def _extrinsics_texts() -> dict[str, str]:
    gt = yaml.safe_load((SAMPLE / "ground_truth.yaml").read_text())
    T = gt["T_camera_lidar"]

    def with_T(block) -> str:
        return _dump({**gt, "T_camera_lidar": block})

    m = T["matrix"]
    return {
        "T_missing": _dump({k: v for k, v in gt.items() if k != "T_camera_lidar"}),
        "T_list": with_T([1, 2, 3]),
        "T_empty": with_T({}),
        "matrix_3x4": with_T({"matrix": m[:3]}),
        "matrix_strings": with_T({"matrix": [["a"] * 4] * 4}),
        "matrix_bools": with_T({"matrix": [[True, False, False, False]] * 4}),
        "matrix_last_row": with_T({"matrix": m[:3] + [[1.0, 0.0, 0.0, 1.0]]}),
        "matrix_not_rotation": with_T({"matrix": [[2.0, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, 2.0, 0], [0, 0, 0, 1]]}),
        "matrix_reflection": with_T({"matrix": [[-1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]]}),
        "matrix_nan": with_T({"matrix": [[float("nan")] * 4] * 4}),
        "translation_1e300": with_T({"matrix": [r[:3] + [1e300] for r in m[:3]] + [m[3]]}),
        "translation_1e300_quat": with_T({"translation_m": [1e300, 0, 0], "quaternion_xyzw": [0, 0, 0, 1]}),
        "quaternion_zero": with_T({"translation_m": [0, 0, 0], "quaternion_xyzw": [0, 0, 0, 0]}),
        "quaternion_3": with_T({"translation_m": [0, 0, 0], "quaternion_xyzw": [0, 0, 1]}),
        "rpy_1e300": with_T({"translation_m": [0, 0, 0], "rpy_deg": [1e300, 0, 0]}),
        "forms_disagree": with_T({**T, "rpy_deg": [0.0, 0.0, 0.0]}),
        "translation_only": with_T({"translation_m": [0, 0, 0]}),
        "matrix_deep": with_T({"matrix": [[[[[[1]]]]]]}),
    }


def _session_texts(good: list[dict]) -> dict[str, str]:
    base = {"format": "ba-calib-session", "version": 1, "next_id": 3,
            "pairs": [{"id": 1, "laser_rc": [82, 397], "pixel": [359.9, 223.6]}, {"id": 2, "laser_rc": [91, 137]}]}

    def sess(**changes) -> str:
        return _dump({**base, **changes})

    return {
        "version_999": sess(version=999),
        "version_string": sess(version="one"),
        "next_id_abc": sess(next_id="abc"),
        "next_id_negative": sess(next_id=-5),
        "next_id_huge": sess(next_id=2**70),
        "pairs_mapping": sess(pairs={"a": 1}),
        "id_string": sess(pairs=[{"id": "x", "laser_rc": [1, 2]}]),
        "id_duplicate": sess(pairs=[{"id": 1, "laser_rc": [1, 2]}, {"id": 1, "laser_rc": [2, 3]}]),
        "laser_rc_1e20": sess(pairs=[{"id": 1, "laser_rc": [1e20, 5]}]),
        "laser_rc_bools": sess(pairs=[{"id": 1, "laser_rc": [True, False]}]),
        "laser_rc_outside_scene": sess(pairs=[{"id": 1, "laser_rc": [100_000, 5]}]),
        "pixel_outside_image": sess(pairs=[{"id": 1, "pixel": [-50.0, 10.0]}]),
        "view_list": sess(view=[1, 2]),
    }


# ------------------------------------------------------------------------ mutations
def _mutate(data: bytes, rnd: random.Random) -> bytes:
    """1-8 random edits: flip, overwrite, insert, delete, duplicate or truncate."""
    b = bytearray(data)
    for _ in range(rnd.randint(1, 8)):
        if not b:
            b.extend(rnd.randbytes(8))
        op = rnd.choice(["flip", "byte", "insert", "delete", "dup", "truncate", "digit", "special"])
        i = rnd.randrange(len(b))
        if op == "flip":
            b[i] ^= 1 << rnd.randrange(8)
        elif op == "byte":
            b[i] = rnd.randrange(256)
        elif op == "insert":
            b[i:i] = rnd.randbytes(rnd.randint(1, 16))
        elif op == "delete":
            del b[i : i + rnd.randint(1, 32)]
        elif op == "dup":
            j = min(len(b), i + rnd.randint(1, 64))
            b[i:i] = b[i:j] * rnd.randint(1, 50)
        elif op == "truncate":
            del b[i:]
        elif op == "digit":
            digits = [k for k, c in enumerate(b) if 48 <= c <= 57]
            if digits:
                b[rnd.choice(digits)] = rnd.choice(b"0123456789-.e")
        else:
            b[i:i] = rnd.choice([b"*x", b"&x", b"[", b"{", b"]", b"}", b"!!", b"\t", b"---\n", b"1e999", b"-", b":", b'"'])
    return bytes(b)


# ------------------------------------------------------------------------ the cases
def make_cases(folder: Path) -> list[FuzzCase]:
    """Write the config corpus into ``folder``; return its cases (outputs are relative: one folder per case)."""
    folder = Path(folder).resolve()
    valid = folder / "valid"
    valid.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(SEED)
    scan, image = str(SAMPLE / "scan.npz"), str(SAMPLE / "image.png")
    gt = str(SAMPLE / "ground_truth.yaml")

    # Valid camera files of every format, each with exact pairs.
    (valid / "calib_results.txt").write_bytes((SAMPLE / "calib_results.txt").read_bytes())
    cams = {
        "ocam_yaml": ("camera_ocam.yaml", "model: ocam\nfile: calib_results.txt\n"),
        "ocam_txt": ("calib_results.txt", None),
        "pinhole_yaml": ("camera_pinhole.yaml", _dump(PINHOLE)),
        "fisheye_yaml": ("camera_fisheye.yaml", _dump(FISHEYE)),
        "ros_yaml": ("camera_ros.yaml", _dump(ROS)),
        "pjlab_json": ("camera_pjlab.json", json.dumps(PJLAB, indent=2)),
        "own_json": ("camera_own.json", json.dumps(PINHOLE)),
    }
    cam_path: dict[str, Path] = {}
    pairs_path: dict[str, Path] = {}
    for key, (name, content) in cams.items():
        p = valid / name
        if content is not None:
            p.write_text(content)
        cam_path[key] = p
        pp = valid / f"pairs_{key}.yaml"
        pp.write_text(_dump({"pairs": _pairs_for(p, rng)}))
        pairs_path[key] = pp
    good_pairs = yaml.safe_load(pairs_path["ocam_yaml"].read_text())["pairs"]

    def solve(camera: Path | str, pairs: Path | str, *extra: str, out: str = "out.yaml") -> list[str]:
        return ["solve", "--camera", str(camera), "--pairs", str(pairs), "-o", out, *extra]

    def colorize(extrinsics: Path | str, out: str = "out.ply", camera: Path | str = SAMPLE / "camera.yaml") -> list[str]:
        return ["colorize", "--scan", scan, "--image", image, "--camera", str(camera), "--extrinsics", str(extrinsics), "-o", out]

    def serve(session: Path | str) -> list[str]:
        # A session that is accepted would serve until killed: the address cannot be bound, so every
        # case ends (and one that is wrongly accepted hangs until the time limit: a failure).
        return ["serve", "--scan", scan, "--image", image, "--camera", str(SAMPLE / "camera.yaml"),
                "--session", str(session), "--host", "192.0.2.1", "--port", "0"]

    cases: list[FuzzCase] = []
    add = lambda name, argv, stdin=None: cases.append(FuzzCase(f"config/{name}", argv, stdin))  # noqa: E731

    # Clean results first: every valid camera format solves.
    for key in cams:
        add(f"valid/{key}", solve(cam_path[key], pairs_path[key]))
    add("valid/colorize", colorize(gt))

    # Generic hostile files for every input.
    for label, path in _generic_files(folder / "g_cam_yaml", ".yaml", True):
        add(f"camera_yaml/generic/{label}", solve(path, pairs_path["pinhole_yaml"]))
    for label, path in _generic_files(folder / "g_cam_json", ".json", False):
        add(f"camera_json/generic/{label}", solve(path, pairs_path["pjlab_json"]))
    for label, path in _generic_files(folder / "g_cam_txt", ".txt", False):
        add(f"camera_txt/generic/{label}", solve(path, pairs_path["ocam_txt"]))
    for label, path in _generic_files(folder / "g_pairs", ".yaml", True):
        add(f"pairs/generic/{label}", solve(cam_path["pinhole_yaml"], path))
    for label, path in _generic_files(folder / "g_extr", ".yaml", True):
        add(f"extrinsics/generic/{label}", colorize(path))
    ocam_dir = folder / "g_ocam_file"
    for label, path in _generic_files(ocam_dir, ".txt", False):
        y = ocam_dir / f"cam_{label}.yaml"
        y.write_text(_dump({"model": "ocam", "file": str(path)}))
        add(f"ocam_file/generic/{label}", solve(y, pairs_path["ocam_yaml"]))
    for label, path in _generic_files(folder / "g_session", ".yaml", True):
        if label in ("missing", "empty", "dangling_link", "symlink_loop", "folder", "top_level_null", "duplicate_keys"):
            continue  # a missing, empty or pairs-only session is a valid start: the server would run (see serve())
        add(f"session/generic/{label}", serve(path))

    # Format-specific content.
    cam_dir = folder / "camera_yaml"
    cam_dir.mkdir(exist_ok=True)
    for label, text in _camera_yaml_texts(cam_dir).items():
        p = cam_dir / f"{label}.yaml"
        p.write_text(text)
        pairs = pairs_path["fisheye_yaml"] if label.startswith("fisheye") else pairs_path["pinhole_yaml"]
        add(f"camera_yaml/{label}", solve(p, pairs))
    txt_dir = folder / "camera_txt"
    txt_dir.mkdir(exist_ok=True)
    for label, text in _ocam_txt_texts().items():
        p = txt_dir / f"{label}.txt"
        p.write_text(text)
        add(f"camera_txt/{label}", solve(p, pairs_path["ocam_txt"]))
    json_dir = folder / "camera_json"
    json_dir.mkdir(exist_ok=True)
    for label, text in _pjlab_json_texts().items():
        p = json_dir / f"{label}.json"
        p.write_text(text)
        add(f"camera_json/{label}", solve(p, pairs_path["pjlab_json"]))
    pairs_dir = folder / "pairs"
    pairs_dir.mkdir(exist_ok=True)
    many_good = _pairs_for(cam_path["ocam_yaml"], rng, 1_000)
    for label, text in _pairs_texts(good_pairs, many_good).items():
        p = pairs_dir / f"{label}.yaml"
        p.write_text(text)
        add(f"pairs/{label}", solve(cam_path["ocam_yaml"], p))
    cell_pairs = pairs_dir / "cells.yaml"
    cell_pairs.write_text("pairs:\n- laser_rc: [100000, 5]\n  pixel: [10, 10]\n- laser_rc: [1, 1]\n  pixel: [10, 10]\n")
    add("pairs/cell_outside_scan", solve(SAMPLE / "camera.yaml", cell_pairs, "--scan", scan))
    add("pairs/cells_without_scan", solve(SAMPLE / "camera.yaml", SAMPLE / "pairs.yaml"))
    extr_dir = folder / "extrinsics"
    extr_dir.mkdir(exist_ok=True)
    for label, text in _extrinsics_texts().items():
        p = extr_dir / f"{label}.yaml"
        p.write_text(text)
        add(f"extrinsics/{label}", colorize(p))
    sess_dir = folder / "session"
    sess_dir.mkdir(exist_ok=True)
    for label, text in _session_texts(good_pairs).items():
        p = sess_dir / f"{label}.yaml"
        p.write_text(text)
        add(f"session/{label}", serve(p))

    # Output paths.
    out_dir = folder / "outputs"
    out_dir.mkdir(exist_ok=True)
    a_file = out_dir / "a_file"
    a_file.write_text("keep me\n")
    fifo = out_dir / "fifo.yaml"
    if not fifo.exists():
        os.mkfifo(fifo)
    # Private device nodes (same numbers as /dev/full and /dev/null): code that wrongly replaces
    # its output must not replace the machine's own devices.  mknod needs root; else no device cases.
    devices = {}
    for name, (major, minor) in (("full", (1, 7)), ("null", (1, 3))):
        node = out_dir / f"dev_{name}"
        try:
            if not node.exists():
                os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(major, minor))
            devices[name] = str(node)
        except OSError:
            pass
    for name, target in (("link_to_dev_full.yaml", devices.get("full", "/nonexistent")), ("link_to_folder.yaml", str(out_dir)),
                         ("link_loop_a.yaml", "link_loop_b.yaml"), ("link_loop_b.yaml", "link_loop_a.yaml")):
        if not (out_dir / name).is_symlink():
            (out_dir / name).symlink_to(target)
    ok_solve = (cam_path["ocam_yaml"], pairs_path["ocam_yaml"])
    outputs = {f"dev_{name}": node for name, node in devices.items()}
    if "full" in devices:
        outputs["link_to_dev_full"] = str(out_dir / "link_to_dev_full.yaml")
    for label, out in {
        **outputs, "folder": str(out_dir), "fifo": str(fifo), "link_to_folder": str(out_dir / "link_to_folder.yaml"),
        "link_loop": str(out_dir / "link_loop_a.yaml"), "parent_is_file": str(a_file / "x.yaml"),
        "name_too_long": "x" * 300 + ".yaml", "empty_path": "", "new_nested_folders": "a/b/c/out.yaml",
        "undecodable_name": "out-\udcff\udcfe.yaml", "proc_file": "/proc/self/status", "root_folder": "/",
    }.items():
        add(f"output/solve/{label}", solve(*ok_solve, out=out))
    add("output/ba_images/existing_file", ["ba-images", "--scan", scan, "-o", str(a_file)])
    if devices:
        add("output/ba_images/dev_null", ["ba-images", "--scan", scan, "-o", devices.get("null", devices.get("full"))])
        add("output/colorize/dev_full", colorize(gt, out=devices.get("full", devices.get("null"))))
    add("output/colorize/folder", colorize(gt, out=str(out_dir)))
    add("output/sample/existing_file", ["sample", "-o", str(a_file)])

    # Arguments.
    pin = (cam_path["pinhole_yaml"], pairs_path["pinhole_yaml"])
    for label, extra in {
        "image_size_1e9": ["--image-size", "1e9", "1e9"],
        "image_size_big_ints": ["--image-size", "1000000000", "1000000000"],
        "image_size_zero": ["--image-size", "0", "0"],
        "image_size_negative": ["--image-size", "-640", "480"],
        "image_size_one_value": ["--image-size", "640"],
        "image_size_huge_int": ["--image-size", "9" * 40, "480"],
        "image_size_smaller": ["--image-size", "64", "48"],
        "max_pairs_zero": ["--max-pairs", "0"],
        "max_pairs_negative": ["--max-pairs", "-1"],
        "max_pairs_3": ["--max-pairs", "3"],
        "cost_unknown": ["--cost", "telepathy"],
        "organize_unknown": ["--organize", "magic"],
        "beams_zero": ["--scan", scan, "--beams", "0"],
        "beams_negative": ["--scan", scan, "--beams", "-64"],
        "beams_huge": ["--scan", scan, "--beams", "10000000000"],
        "h_res_nan": ["--scan", scan, "--h-res-deg", "nan"],
        "h_res_inf": ["--scan", scan, "--h-res-deg", "inf"],
        "h_res_zero": ["--scan", scan, "--h-res-deg", "0"],
        "v_res_negative": ["--scan", scan, "--v-res-deg", "-1"],
        "unknown_option": ["--frobnicate"],
        "scan_is_camera": ["--scan", str(SAMPLE / "camera.yaml")],
    }.items():
        add(f"args/solve/{label}", solve(*pin, *extra))
    add("args/no_command_args", ["solve"])
    add("args/unknown_command", ["calibrate-everything"])
    add("args/version", ["--version"])
    add("args/help", ["solve", "--help"])
    add("args/serve_port_99999", ["serve", "--port", "99999"])
    add("args/serve_port_negative", ["serve", "--port", "-1"])
    add("args/serve_missing_inputs", ["serve", "--scan", scan])
    add("args/stdin_junk", solve(*pin), stdin=bytes(range(256)) * 64)

    # Seeded random byte mutations of every valid text file.
    rnd = random.Random(SEED)
    mut_dir = folder / "mutations"
    mut_dir.mkdir(exist_ok=True)
    sources = [(f"camera_{k}", cam_path[k], k) for k in cams] + [(f"pairs_{k}", pairs_path[k], k) for k in ("ocam_yaml", "pinhole_yaml")]
    sources.append(("extrinsics", SAMPLE / "ground_truth.yaml", None))
    for label, src, key in sources:
        data = src.read_bytes()
        for i in range(8):
            p = mut_dir / f"{label}_{i}{src.suffix}"
            p.write_bytes(_mutate(data, rnd))
            if label.startswith("camera_"):
                if key == "ocam_yaml":  # the YAML names calib_results.txt next to it
                    (mut_dir / "calib_results.txt").write_bytes(cam_path["ocam_txt"].read_bytes())
                add(f"mutation/{label}_{i}", solve(p, pairs_path[key]))
            elif label.startswith("pairs_"):
                add(f"mutation/{label}_{i}", solve(cam_path[key], p))
            else:
                add(f"mutation/{label}_{i}", colorize(p))
    return cases
