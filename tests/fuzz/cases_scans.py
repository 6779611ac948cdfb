"""Hostile scan and image files for the fuzz corpus.

:func:`make_cases` writes, into a folder, files in every scan format the CLI
reads (PCD ascii / binary / binary_compressed, PLY ascii / binary, LAS, LAZ,
``.bin``, ``.npy``, ``.npz`` and native ``.npz``) and the PNG / JPEG / BMP /
TIFF images ``colorize --image`` reads: broken headers, declared sizes that
the data does not hold, size bombs, truncations, non-finite and absurd
values, too few points, special files, plus seeded random byte mutations of
valid files.  Each case is a ``ba-calib`` invocation that reads one of them.
"""

from __future__ import annotations

import io
import os
import random
import shutil
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .case import FuzzCase

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"

# --------------------------------------------------------------------------
# A valid small scan: 16 rings x 180 columns around the sensor, with fields
# --------------------------------------------------------------------------

RECORD = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f8")])


def base_records(n_rings: int = 16, n_cols: int = 180, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    ring, col = np.meshgrid(np.arange(n_rings), np.arange(n_cols), indexing="ij")
    ring, col = ring.ravel(), col.ravel()
    elevation = np.radians(-15.0 + 2.0 * ring)
    azimuth = np.radians(180.0 - 2.0 * (col + 0.5))
    distance = 6.0 + 4.0 * np.abs(np.sin(azimuth * 2)) + rng.normal(0, 0.01, ring.size)
    rec = np.zeros(ring.size, RECORD)
    rec["x"] = distance * np.cos(elevation) * np.cos(azimuth)
    rec["y"] = distance * np.cos(elevation) * np.sin(azimuth)
    rec["z"] = distance * np.sin(elevation)
    rec["intensity"] = rng.uniform(0, 100, ring.size).round()
    rec["ring"] = ring
    rec["time"] = col * 1e-4
    return rec


# --------------------------------------------------------------------------
# Writers (per the format documents; independent of the readers)
# --------------------------------------------------------------------------

PCD_FIELDS = {
    "FIELDS": "x y z intensity ring time",
    "SIZE": "4 4 4 4 2 8",
    "TYPE": "F F F F U F",
    "COUNT": "1 1 1 1 1 1",
}


def pcd_header(n: int, encoding: str, *, width: int | None = None, height: int = 1, points: int | None = None,
               version: str = "0.7", **override: str | None) -> bytes:
    keys = {
        "VERSION": version,
        **PCD_FIELDS,
        "WIDTH": str(n if width is None else width),
        "HEIGHT": str(height),
        "VIEWPOINT": "0 0 0 1 0 0 0",
        "POINTS": str(n if points is None else points),
        "DATA": encoding,
    }
    keys.update(override)
    lines = ["# .PCD v0.7 - Point Cloud Data file format"] + [f"{k} {v}" for k, v in keys.items() if v is not None]
    return ("\n".join(lines) + "\n").encode()


def pcd_ascii_body(rec: np.ndarray) -> bytes:
    return "".join(
        f"{x!r} {y!r} {z!r} {i!r} {r} {t!r}\n" for x, y, z, i, r, t in rec.tolist()
    ).encode()


def lzf_literal(data: bytes) -> bytes:
    """LZF made of literal runs only (control byte = run length - 1)."""
    out = bytearray()
    for start in range(0, len(data), 32):
        chunk = data[start : start + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def pcd_compressed_body(rec: np.ndarray) -> bytes:
    raw = b"".join(np.ascontiguousarray(rec[name]).tobytes() for name in rec.dtype.names)
    packed = lzf_literal(raw)
    return struct.pack("<II", len(packed), len(raw)) + packed


def pcd_file(rec: np.ndarray, encoding: str, **header) -> bytes:
    body = {"ascii": pcd_ascii_body, "binary": lambda r: r.tobytes(), "binary_compressed": pcd_compressed_body}[encoding](rec)
    return pcd_header(len(rec), encoding, **header) + body


def ply_file(xyz: np.ndarray, fmt: str, extra_header: str = "", count: int | None = None, dtype: str = "float") -> bytes:
    n = len(xyz) if count is None else count
    head = f"ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty {dtype} x\nproperty {dtype} y\nproperty {dtype} z\n{extra_header}end_header\n"
    if fmt == "ascii":
        body = "".join(f"{a!r} {b!r} {c!r}\n" for a, b, c in xyz.tolist()).encode()
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        body = xyz.astype(f"{order}f{4 if dtype == 'float' else 8}").tobytes()
    return head.encode() + body


def las_bytes(xyz: np.ndarray, laz: bool = False, version: str = "1.2") -> bytes:
    import laspy

    header = laspy.LasHeader(point_format=1, version=version)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.intensity = np.arange(len(xyz), dtype=np.uint16)
    buffer = io.BytesIO()
    las.write(buffer, do_compress=laz)
    return buffer.getvalue()


def npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def npy_header(shape, descr: str = "<f8", fortran: bool = False, version=(1, 0)) -> bytes:
    buffer = io.BytesIO()
    header = {"descr": descr, "fortran_order": fortran, "shape": tuple(shape)}
    if version == (1, 0):
        np.lib.format.write_array_header_1_0(buffer, header)
    else:
        np.lib.format.write_array_header_2_0(buffer, header)
    return buffer.getvalue()


def npz_bytes(members: dict[str, bytes], compression: int = zipfile.ZIP_DEFLATED) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=compression, compresslevel=1 if compression == zipfile.ZIP_DEFLATED else None) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return buffer.getvalue()


def zip_bomb(member: str, header: bytes, zero_bytes: int, extra: dict[str, bytes] | None = None) -> bytes:
    """An archive whose ``member`` is ``header`` plus ``zero_bytes`` zeros, deflated."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for name, data in (extra or {}).items():
            archive.writestr(name, data)
        with archive.open(member, "w", force_zip64=True) as handle:
            handle.write(header)
            chunk = bytes(1 << 22)
            for start in range(0, zero_bytes, len(chunk)):
                handle.write(chunk[: min(len(chunk), zero_bytes - start)])
    return buffer.getvalue()


def png_bytes(width: int, height: int, rows: int | None = None, color_type: int = 2, bit_depth: int = 8,
              crc_ok: bool = True, extra_chunks: list[tuple[bytes, bytes]] = ()) -> bytes:
    """A PNG declaring ``width`` x ``height``, holding ``rows`` rows (default: all)."""
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[color_type]
    row_bytes = 1 + (width * channels * bit_depth + 7) // 8
    rows = height if rows is None else rows
    compressor = zlib.compressobj(1)
    pixels = b"".join(compressor.compress(b"\0" * row_bytes) for _ in range(rows)) + compressor.flush()

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc if crc_ok else crc ^ 1)

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)
    body = chunk(b"IHDR", ihdr)
    if color_type == 3:
        body += chunk(b"PLTE", bytes(3 * 4))
    for kind, data in extra_chunks:
        body += chunk(kind, data)
    return b"\x89PNG\r\n\x1a\n" + body + chunk(b"IDAT", pixels) + chunk(b"IEND", b"")


def encoded(image: np.ndarray, suffix: str, params=()) -> bytes:
    import cv2

    ok, buffer = cv2.imencode(suffix, image, list(params))
    assert ok
    return buffer.tobytes()


def jpeg_with_size(jpeg: bytes, width: int, height: int) -> bytes:
    """A JPEG whose SOF0 frame header declares another size."""
    at = jpeg.index(b"\xff\xc0")
    return jpeg[: at + 5] + struct.pack(">HH", height, width) + jpeg[at + 9 :]


# --------------------------------------------------------------------------
# The hostile files
# --------------------------------------------------------------------------


def _pcd_files(rec: np.ndarray) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    n = len(rec)
    for enc in ("ascii", "binary", "binary_compressed"):
        good = pcd_file(rec, enc)
        head_len = len(pcd_header(n, enc))
        files[f"pcd_{enc}_valid.pcd"] = good
        files[f"pcd_{enc}_cut_in_header.pcd"] = good[: head_len // 2]
        files[f"pcd_{enc}_header_only.pcd"] = good[:head_len]
        files[f"pcd_{enc}_cut_one_byte.pcd"] = good[:-1]
        files[f"pcd_{enc}_cut_half.pcd"] = good[: head_len + (len(good) - head_len) // 2]
        files[f"pcd_{enc}_trailing_junk.pcd"] = good + b"\x00junk" * 100
        files[f"pcd_{enc}_points_1e12.pcd"] = pcd_file(rec[:1], enc, width=10**12, points=10**12)
        files[f"pcd_{enc}_points_2e31.pcd"] = pcd_file(rec, enc, width=2**31, points=2**31)
        files[f"pcd_{enc}_points_mismatch.pcd"] = pcd_file(rec, enc, points=n + 1)
        files[f"pcd_{enc}_width_negative.pcd"] = pcd_file(rec, enc, width=-n, points=-n)
        files[f"pcd_{enc}_count3_on_x.pcd"] = pcd_file(rec, enc, COUNT="3 1 1 1 1 1")
        files[f"pcd_{enc}_count0.pcd"] = pcd_file(rec, enc, COUNT="0 1 1 1 1 1")
        files[f"pcd_{enc}_count_garbage.pcd"] = pcd_file(rec, enc, COUNT="a b c d e f")
        files[f"pcd_{enc}_size3.pcd"] = pcd_file(rec, enc, SIZE="3 4 4 4 2 8")
        files[f"pcd_{enc}_type_q.pcd"] = pcd_file(rec, enc, TYPE="Q F F F U F")
        files[f"pcd_{enc}_f2.pcd"] = pcd_file(rec, enc, SIZE="2 4 4 4 2 8")
        files[f"pcd_{enc}_few_sizes.pcd"] = pcd_file(rec, enc, SIZE="4 4")
        files[f"pcd_{enc}_no_fields.pcd"] = pcd_file(rec, enc, FIELDS=None)
        files[f"pcd_{enc}_no_data_line.pcd"] = pcd_file(rec, enc, DATA=None)
        files[f"pcd_{enc}_no_xyz.pcd"] = pcd_file(rec, enc, FIELDS="a b c intensity ring time")
        files[f"pcd_{enc}_upper_xyz.pcd"] = pcd_file(rec, enc, FIELDS="X Y Z intensity ring time")
        files[f"pcd_{enc}_dup_fields.pcd"] = pcd_file(rec, enc, FIELDS="x x z intensity ring time")
        files[f"pcd_{enc}_version_5.pcd"] = pcd_file(rec, enc, version=".5")
        files[f"pcd_{enc}_version_junk.pcd"] = pcd_file(rec, enc, version="\u00e9\u00e9")
        files[f"pcd_{enc}_viewpoint_nan.pcd"] = pcd_file(rec, enc, VIEWPOINT="nan 0 0 1 0 0 0")
        files[f"pcd_{enc}_viewpoint_short.pcd"] = pcd_file(rec, enc, VIEWPOINT="0 0")
        files[f"pcd_{enc}_tall_flat.pcd"] = pcd_file(rec, enc, width=1, height=n)
        files[f"pcd_{enc}_organized.pcd"] = pcd_file(rec, enc, width=180, height=n // 180)
        two = rec[:2]
        files[f"pcd_{enc}_two_points.pcd"] = pcd_file(two, enc)
        nan = rec.copy()
        nan["x"] = np.nan
        files[f"pcd_{enc}_all_nan.pcd"] = pcd_file(nan, enc)
        files[f"pcd_{enc}_all_nan_organized.pcd"] = pcd_file(nan, enc, width=180, height=n // 180)
        inf = rec.copy()
        inf["z"][::7] = np.inf
        files[f"pcd_{enc}_inf.pcd"] = pcd_file(inf, enc)
        huge = rec.copy()
        huge["x"][5] = 3e38
        files[f"pcd_{enc}_3e38.pcd"] = pcd_file(huge, enc)
        bad_ring = rec.copy()
        bad_ring["ring"] = np.arange(n) * 997 % 65535
        files[f"pcd_{enc}_ring_wild.pcd"] = pcd_file(bad_ring, enc)
        same = rec.copy()
        same["ring"] = 0
        files[f"pcd_{enc}_one_ring.pcd"] = pcd_file(same, enc)
        zero = rec.copy()
        for axis in "xyz":
            zero[axis] = 0
        files[f"pcd_{enc}_all_at_origin.pcd"] = pcd_file(zero, enc)
    # Encoding-specific.
    good_ascii = pcd_file(rec, "ascii")
    files["pcd_ascii_cut_mid_number.pcd"] = good_ascii[:-3]
    files["pcd_ascii_e300.pcd"] = good_ascii.replace(pcd_ascii_body(rec[-1:]), b"1e300 0 0 1 0 0\n")
    files["pcd_ascii_words.pcd"] = good_ascii.replace(pcd_ascii_body(rec[-1:]), b"one two three four five six\n")
    files["pcd_ascii_extra_value.pcd"] = good_ascii.replace(pcd_ascii_body(rec[-1:]), b"1 2 3 4 5 6 7\n")
    files["pcd_ascii_missing_value.pcd"] = good_ascii.replace(pcd_ascii_body(rec[-1:]), b"1 2 3 4 5\n")
    files["pcd_ascii_blank_lines.pcd"] = good_ascii.replace(b"\n", b"\n\n")
    files["pcd_ascii_crlf.pcd"] = good_ascii.replace(b"\n", b"\r\n")
    files["pcd_ascii_tabs_commas.pcd"] = pcd_header(len(rec), "ascii") + pcd_ascii_body(rec).replace(b" ", b",\t")
    files["pcd_ascii_ring_negative.pcd"] = good_ascii.replace(pcd_ascii_body(rec[-1:]), b"1 2 3 4 -5 6\n")
    files["pcd_ascii_ring_float.pcd"] = good_ascii.replace(pcd_ascii_body(rec[-1:]), b"1 2 3 4 5.5 6\n")
    files["pcd_ascii_binary_junk.pcd"] = pcd_header(len(rec), "ascii") + bytes(range(256)) * 20
    files["pcd_ascii_long_line.pcd"] = pcd_header(3, "ascii") + b"1 " * 300_000 + b"\n"
    files["pcd_ascii_nan_tokens.pcd"] = pcd_header(4, "ascii") + b"nan nan nan 0 0 0\n" * 4
    head = pcd_header(len(rec), "binary_compressed")
    body = pcd_compressed_body(rec)
    compressed, raw = struct.unpack("<II", body[:8])
    files["pcd_compressed_size_lie_big.pcd"] = head + struct.pack("<II", compressed * 100, raw) + body[8:]
    files["pcd_compressed_uncompressed_lie.pcd"] = head + struct.pack("<II", compressed, 2**32 - 1) + body[8:]
    files["pcd_compressed_lzf_garbage.pcd"] = head + struct.pack("<II", compressed, raw) + bytes([0xE0, 0xFF]) * (compressed // 2)
    files["pcd_compressed_no_sizes.pcd"] = head + b"\x01\x02"
    files["pcd_header_comment_flood.pcd"] = b"# comment\n" * 100_000 + good_ascii
    files["pcd_header_binary_bytes.pcd"] = b"VERSION \xff\xfe\n" + good_ascii
    files["pcd_header_huge_line.pcd"] = b"FIELDS " + b"x " * 500_000 + b"\n" + good_ascii
    files["pcd_empty.pcd"] = b""
    files["pcd_png_bytes.pcd"] = png_bytes(4, 4)
    files["pcd_zero_points.pcd"] = pcd_header(0, "binary")
    # Issue 23: an image stored as an organised cloud (PCL's lena.pcd: x, y the pixel, z = 0): no 3-D extent.
    grid = "".join(f"{c} {r} 0 {(r * 7 + c) % 256}\n" for r in range(32) for c in range(32))
    files["pcd_image_as_cloud_z0.pcd"] = (
        "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 32\nHEIGHT 32\n"
        "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1024\nDATA ascii\n" + grid
    ).encode()
    return files


def _ply_files(xyz: np.ndarray) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
        short = {"ascii": "ascii", "binary_little_endian": "le", "binary_big_endian": "be"}[fmt]
        good = ply_file(xyz, fmt)
        files[f"ply_{short}_valid.ply"] = good
        files[f"ply_{short}_count_1e12.ply"] = ply_file(xyz[:1], fmt, count=10**12)
        files[f"ply_{short}_count_more.ply"] = ply_file(xyz, fmt, count=len(xyz) + 5)
        files[f"ply_{short}_count_less.ply"] = ply_file(xyz, fmt, count=len(xyz) - 5)
        files[f"ply_{short}_count_negative.ply"] = ply_file(xyz, fmt, count=-3)
        files[f"ply_{short}_cut.ply"] = good[:-7]
        files[f"ply_{short}_two.ply"] = ply_file(xyz[:2], fmt)
        files[f"ply_{short}_faces_1e9.ply"] = ply_file(xyz, fmt, extra_header="element face 1000000000\nproperty list uchar int vertex_indices\n")
        files[f"ply_{short}_double_1e300.ply"] = ply_file(np.vstack([xyz, [[1e300, 0, 0]]]), fmt, dtype="double")
        nan = xyz.copy()
        nan[:] = np.nan
        files[f"ply_{short}_all_nan.ply"] = ply_file(nan, fmt)
    files["ply_no_end_header.ply"] = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
    files["ply_bad_format.ply"] = ply_file(xyz, "ascii").replace(b"format ascii", b"format zip")
    files["ply_unknown_type.ply"] = ply_file(xyz, "ascii").replace(b"property float x", b"property quad x")
    files["ply_no_x.ply"] = ply_file(xyz, "ascii").replace(b"property float x", b"property float q")
    files["ply_count_words.ply"] = ply_file(xyz, "ascii").replace(b"element vertex", b"element vertex many")
    files["ply_list_huge.ply"] = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        b"element face 1\nproperty list uint int vertex_indices\nend_header\n"
        + xyz[:3].astype("<f4").tobytes() + struct.pack("<I", 2**31) + b"\0" * 16
    )
    files["ply_faces_out_of_range.ply"] = ply_file(xyz[:3], "ascii", extra_header="element face 1\nproperty list uchar int vertex_indices\n") + b"3 0 1 99999\n"
    files["ply_texture_missing.ply"] = ply_file(xyz[:3], "ascii", extra_header="element face 1\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\n").replace(
        b"format ascii 1.0\n", b"format ascii 1.0\ncomment TextureFile nowhere.png\n") + b"3 0 1 2 6 0 0 1 0 0 1\n"
    files["ply_words_in_data.ply"] = ply_file(xyz[:3], "ascii").rsplit(b"end_header\n", 1)[0] + b"end_header\na b c\nd e f\ng h i\n"
    files["ply_empty.ply"] = b""
    files["ply_magic_only.ply"] = b"ply\n"
    return files


def _las_files(xyz: np.ndarray) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    good = las_bytes(xyz)
    files["las_valid.las"] = good
    for cut in (50, 200, 227, len(good) // 2, len(good) - 3):
        files[f"las_cut_{cut}.las"] = good[:cut]
    data = bytearray(good)
    struct.pack_into("<I", data, 107, 4_000_000_000)
    files["las_count_4e9.las"] = bytes(data)
    data = bytearray(good)
    struct.pack_into("<I", data, 107, len(xyz) + 10)
    files["las_count_more.las"] = bytes(data)
    data = bytearray(good)
    struct.pack_into("<I", data, 96, 2**31)
    files["las_offset_beyond.las"] = bytes(data)
    data = bytearray(good)
    struct.pack_into("<3d", data, 131, 1e300, 1e300, 1e300)
    files["las_scale_1e300.las"] = bytes(data)
    data = bytearray(good)
    struct.pack_into("<3d", data, 131, float("nan"), 0.001, 0.001)
    files["las_scale_nan.las"] = bytes(data)
    data = bytearray(good)
    struct.pack_into("<3d", data, 131, 0.0, 0.0, 0.0)
    files["las_scale_zero.las"] = bytes(data)
    data = bytearray(good)
    data[104] = 99
    files["las_point_format_99.las"] = bytes(data)
    data = bytearray(good)
    data[24:26] = bytes([9, 9])
    files["las_version_9_9.las"] = bytes(data)
    data = bytearray(good)
    struct.pack_into("<H", data, 105, 1)
    files["las_record_length_1.las"] = bytes(data)
    files["las_two_points.las"] = las_bytes(xyz[:2])
    files["las_magic_only.las"] = b"LASF"
    files["las_v14_valid.las"] = las_bytes(xyz, version="1.4")
    laz = las_bytes(xyz, laz=True)
    files["laz_valid.laz"] = laz
    for cut in (300, len(laz) // 2, len(laz) - 20):
        files[f"laz_cut_{cut}.laz"] = laz[:cut]
    data = bytearray(laz)
    struct.pack_into("<I", data, 107, 4_000_000_000)
    files["laz_count_4e9.laz"] = bytes(data)
    data = bytearray(laz)
    struct.pack_into("<I", data, 107, len(xyz) * 3)
    files["laz_count_more.laz"] = bytes(data)
    data = bytearray(laz)
    middle = len(data) // 2 + 100
    data[middle : middle + 64] = bytes(range(64))
    files["laz_corrupt_chunk.laz"] = bytes(data)
    files["laz_is_plain_las.laz"] = good
    files["las_is_laz.las"] = laz
    return files


def _bin_files(rec: np.ndarray) -> dict[str, bytes]:
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=1)
    four = np.column_stack([xyz, rec["intensity"] / 100]).astype("<f4")
    five = np.column_stack([xyz, rec["intensity"], rec["ring"]]).astype("<f4")
    rng = np.random.default_rng(5)
    files = {
        "bin_kitti_valid.bin": four.tobytes(),
        "bin_nuscenes_valid.pcd.bin": five.tobytes(),
        "bin_six_valid.bin": np.column_stack([xyz, rng.uniform(0, 1, (len(xyz), 3))]).astype("<f4").tobytes(),
        "bin_empty.bin": b"",
        "bin_one_byte.bin": b"\x01",
        "bin_odd_bytes.bin": four.tobytes()[:-2],
        "bin_one_float_short.bin": four.tobytes()[:-4],
        "bin_two_points.bin": four[:2].tobytes(),
        "bin_all_nan.bin": np.full(four.shape, np.nan, "<f4").tobytes(),
        "bin_all_zero.bin": np.zeros(four.shape, "<f4").tobytes(),
        "bin_inf.bin": np.where(np.arange(four.size).reshape(four.shape) % 9 == 0, np.inf, four).astype("<f4").tobytes(),
        "bin_3e38.bin": np.vstack([four, [[3e38, 0, 0, 0]]]).astype("<f4").tobytes(),
        "bin_noise.bin": rng.uniform(-50, 50, four.size).astype("<f4").tobytes(),
        "bin_random_bytes.bin": rng.integers(0, 256, four.size * 4, dtype=np.uint8).tobytes(),
        "bin_text.bin": b"1.0 2.0 3.0 4.0\n" * 64,
        "bin_float64.bin": four.astype("<f8").tobytes(),
        "bin_big_endian.bin": four.astype(">f4").tobytes(),
        "bin_denormals.bin": np.full(four.size, 1e-42, "<f4").tobytes(),
    }
    return files


def _npy_files(rec: np.ndarray) -> dict[str, bytes]:
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=1)
    files = {
        "npy_valid.npy": npy_bytes(xyz),
        "npy_valid_structured.npy": npy_bytes(rec),
        "npy_upper_structured.npy": npy_bytes(rec.astype([("X", "<f4"), ("Y", "<f4"), ("Z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f8")])),
        "npy_organized.npy": npy_bytes(xyz.reshape(16, 180, 3)),
        "npy_shape_1e12.npy": npy_header((10**12, 3)) + xyz[:1].tobytes(),
        "npy_shape_lie.npy": npy_header((len(xyz) + 10, 3)) + xyz.tobytes(),
        "npy_shape_overflow.npy": npy_header((2**62, 2**62, 3)) + xyz[:1].tobytes(),
        "npy_shape_negative.npy": npy_bytes(xyz).replace(f"({len(xyz)}, 3)".encode(), b"(-1, 3)  ".ljust(len(f"({len(xyz)}, 3)"), b" ")),
        "npy_pickle.npy": npy_bytes(np.array([{"a": 1}, None], dtype=object)),
        "npy_fortran.npy": npy_bytes(np.asfortranarray(xyz)),
        "npy_zero_d.npy": npy_bytes(np.array(5.0)),
        "npy_one_d.npy": npy_bytes(np.arange(30.0)),
        "npy_five_columns.npy": npy_bytes(np.zeros((10, 5))),
        "npy_complex.npy": npy_bytes(xyz.astype(np.complex64)),
        "npy_bool.npy": npy_bytes(xyz > 0),
        "npy_strings.npy": npy_bytes(np.array([["a", "b", "c"]] * 5)),
        "npy_float16.npy": npy_bytes(xyz.astype(np.float16)),
        "npy_int64_huge.npy": npy_bytes(np.full((5, 3), 2**62, np.int64)),
        "npy_two_points.npy": npy_bytes(xyz[:2]),
        "npy_empty.npy": npy_bytes(np.zeros((0, 3))),
        "npy_all_nan.npy": npy_bytes(np.full((10, 3), np.nan)),
        "npy_1e300.npy": npy_bytes(np.vstack([xyz, [[1e300, 1e300, 1e300]]])),
        "npy_structured_no_xyz.npy": npy_bytes(np.zeros(5, [("a", "f4"), ("b", "f4")])),
        "npy_structured_subarray_x.npy": npy_bytes(np.zeros(5, [("x", "f4", (3,)), ("y", "f4"), ("z", "f4")])),
        "npy_structured_string_x.npy": npy_bytes(np.zeros(5, [("x", "S4"), ("y", "f4"), ("z", "f4")])),
        "npy_v2_header.npy": npy_header(xyz.shape, version=(2, 0)) + xyz.astype("<f8").tobytes(),
        "npy_header_garbage.npy": b"\x93NUMPY\x01\x00\x20\x00{'descr': '<f8', 'fortran_order': oops}\n",
        "npy_header_len_huge.npy": b"\x93NUMPY\x02\x00\xff\xff\xff\x7f{",
        "npy_magic_only.npy": b"\x93NUMPY",
        "npy_is_npz.npy": npz_bytes({"x.npy": npy_bytes(xyz[:, 0])}),
    }
    return files


def _npz_files(rec: np.ndarray) -> dict[str, bytes]:
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64)
    x, y, z = (npy_bytes(xyz[:, i]) for i in range(3))
    n = len(xyz)
    from calib_core.lidar.spherical import spherical_depth

    sphere = spherical_depth(np.linalg.norm(xyz, axis=1).reshape(16, 180), np.radians(15 - 2.0 * np.arange(16)), np.radians(180 - 2.0 * (np.arange(180) + 0.5)))
    native = {
        "model.npy": npy_bytes(np.array("spherical")),
        "range_m.npy": npy_bytes(sphere.range_m),
        "elevation_rad.npy": npy_bytes(np.radians(15 - 2.0 * np.arange(16))),
        "azimuth_rad.npy": npy_bytes(np.radians(180 - 2.0 * (np.arange(180) + 0.5))),
    }
    big = 6_000_000
    files = {
        "npz_xyz_valid.npz": npz_bytes({"x.npy": x, "y.npy": y, "z.npy": z, "intensity.npy": npy_bytes(rec["intensity"])}),
        "npz_points_valid.npz": npz_bytes({"points.npy": npy_bytes(xyz)}),
        "npz_native_valid.npz": npz_bytes(native),
        "npz_native_blank.npz": npz_bytes({**native, "range_m.npy": npy_bytes(np.full((16, 180), np.nan))}),
        "npz_native_organized_blank.npz": npz_bytes({"model.npy": npy_bytes(np.array("organized")), "points.npy": npy_bytes(np.full((4, 5, 3), np.nan))}),
        "npz_native_inf.npz": npz_bytes({**native, "range_m.npy": npy_bytes(np.full((16, 180), np.inf))}),
        "npz_native_1e300.npz": npz_bytes({**native, "range_m.npy": npy_bytes(np.full((16, 180), 1e300))}),
        "npz_native_negative.npz": npz_bytes({**native, "range_m.npy": npy_bytes(-sphere.range_m)}),
        "npz_native_no_range.npz": npz_bytes({k: v for k, v in native.items() if k != "range_m.npy"}),
        "npz_native_bad_model.npz": npz_bytes({**native, "model.npy": npy_bytes(np.array("velodyne"))}),
        "npz_native_model_bytes.npz": npz_bytes({**native, "model.npy": npy_bytes(np.array(b"spherical"))}),
        "npz_native_model_pickle.npz": npz_bytes({**native, "model.npy": npy_bytes(np.array([None], dtype=object))}),
        "npz_native_wrong_shapes.npz": npz_bytes({**native, "elevation_rad.npy": npy_bytes(np.zeros(7))}),
        "npz_native_huge_broadcast.npz": npz_bytes({"model.npy": npy_bytes(np.array("rotating_2d")), "range_m.npy": npy_bytes(np.ones((2, 2))),
                                                     "theta_rad.npy": npy_bytes(np.zeros((3000, 1))), "phi_rad.npy": npy_bytes(np.zeros(3000)),
                                                     "dx_m.npy": npy_bytes(np.array(0.0)), "dz_m.npy": npy_bytes(np.array(0.0))}),
        "npz_native_header_lie.npz": npz_bytes({**native, "range_m.npy": npy_header((100000, 100000)) + b"\0" * 64}),
        "npz_native_bomb.npz": zip_bomb("range_m.npy", npy_header((3000, 2000)), 3000 * 2000 * 8,
                                        {"model.npy": npy_bytes(np.array("spherical")), "elevation_rad.npy": npy_bytes(np.zeros(3000)), "azimuth_rad.npy": npy_bytes(np.zeros(2000))}),
        "npz_points_bomb.npz": zip_bomb("points.npy", npy_header((big, 3)), big * 24),
        "npz_x_bomb.npz": zip_bomb("x.npy", npy_header((big,)), big * 8, {"y.npy": y, "z.npy": z}),
        "npz_big_bomb.npz": zip_bomb("points.npy", npy_header((20_000_000, 3)), 20_000_000 * 24),
        "npz_just_under_cap_zeros.npz": zip_bomb("points.npy", npy_header((4_900_000, 3)), 4_900_000 * 24),
        "npz_header_lie.npz": npz_bytes({"points.npy": npy_header((10**9, 3)) + xyz.tobytes()}),
        "npz_xyz_lengths_differ.npz": npz_bytes({"x.npy": x, "y.npy": y, "z.npy": npy_bytes(xyz[:5, 2])}),
        "npz_xyz_2d.npz": npz_bytes({"x.npy": npy_bytes(xyz), "y.npy": y, "z.npy": z}),
        "npz_pickle.npz": npz_bytes({"points.npy": npy_bytes(np.array([None, 1], dtype=object))}),
        "npz_no_arrays.npz": npz_bytes({"readme.txt": b"hello"}),
        "npz_many_members.npz": npz_bytes({f"a{i}.npy": npy_bytes(np.zeros(1)) for i in range(2000)}),
        "npz_two_unknown.npz": npz_bytes({"a.npy": x, "b.npy": y}),
        "npz_stored_bzip2.npz": npz_bytes({"points.npy": npy_bytes(xyz)}, zipfile.ZIP_BZIP2),
        "npz_stored_lzma.npz": npz_bytes({"points.npy": npy_bytes(xyz)}, zipfile.ZIP_LZMA),
        "npz_crc_broken.npz": _flip_crc(npz_bytes({"points.npy": npy_bytes(xyz)}, zipfile.ZIP_STORED)),
        "npz_truncated.npz": npz_bytes({"points.npy": npy_bytes(xyz)})[:-100],
        "npz_not_zip.npz": b"PK\x03\x04 this is not a zip",
        "npz_empty.npz": b"",
        "npz_two_points.npz": npz_bytes({"points.npy": npy_bytes(xyz[:2])}),
        "npz_1e300.npz": npz_bytes({"points.npy": npy_bytes(np.vstack([xyz, [[1e300, 0, 0]]]))}),
        "npz_is_npy.npz": npy_bytes(xyz),
        "npz_v3_header.npz": npz_bytes({"points.npy": b"\x93NUMPY\x03\x00" + npy_header(xyz.shape)[8:] + xyz.tobytes()}),
        "npz_encrypted_flag.npz": _set_encrypted(npz_bytes({"points.npy": npy_bytes(xyz)}, zipfile.ZIP_STORED)),
        # Issue 23: a deflate stream damaged so that zlib itself fails (not the CRC); scans too small for BA images.
        "npz_native_zlib_damaged.npz": _zlib_damaged(npz_bytes(native), "range_m.npy"),
        "npz_points_zlib_damaged.npz": _zlib_damaged(npz_bytes({"points.npy": npy_bytes(xyz)}), "points.npy"),
        "npz_rotating_1x1.npz": npz_bytes(_rotating_members(1, 1)),
        "npz_rotating_1x6.npz": npz_bytes(_rotating_members(1, 6)),
        "npz_rotating_2x1.npz": npz_bytes(_rotating_members(2, 1)),
    }
    _ = n
    return files


def _rotating_members(rows: int, cols: int) -> dict[str, bytes]:
    """A native rotating-scanner scan of ``rows`` x ``cols`` cells, ranges 2-3 m."""
    return {
        "model.npy": npy_bytes(np.array("rotating_2d")),
        "range_m.npy": npy_bytes(2.0 + np.arange(rows * cols, dtype=np.float64).reshape(rows, cols) / (rows * cols)),
        "theta_rad.npy": npy_bytes(np.linspace(-0.5, 0.5, rows)[:, None]),
        "phi_rad.npy": npy_bytes(np.linspace(0.0, 3.0, cols)[None, :]),
        "dx_m.npy": npy_bytes(np.array(0.0)),
        "dz_m.npy": npy_bytes(np.array(0.0)),
    }


def _zlib_damaged(data: bytes, member: str) -> bytes:
    """Flip the first bit past the middle of ``member``'s deflate stream that makes zlib fail on reading."""
    data = bytearray(data)
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as archive:
        info = archive.getinfo(member)
    at = info.header_offset
    start = at + 30 + int.from_bytes(data[at + 26 : at + 28], "little") + int.from_bytes(data[at + 28 : at + 30], "little")
    stream = bytes(data[start : start + info.compress_size])
    for offset in range(info.compress_size // 2, info.compress_size):
        for bit in range(8):
            damaged = bytearray(stream)
            damaged[offset] ^= 1 << bit
            try:
                zlib.decompressobj(-15).decompress(bytes(damaged), info.file_size)
            except zlib.error:
                data[start + offset] ^= 1 << bit
                return bytes(data)
    raise ValueError(f"no bit flip of {member} makes a zlib error")


def _flip_crc(data: bytes) -> bytes:
    """Corrupt one stored data byte: the CRC check fails on reading."""
    data = bytearray(data)
    at = data.index(b"\x93NUMPY") + 200
    data[at] ^= 0xFF
    return bytes(data)


def _set_encrypted(data: bytes) -> bytes:
    """Set the 'encrypted' flag of every entry (local and central headers)."""
    data = bytearray(data)
    for signature, flag_at in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        start = 0
        while (start := data.find(signature, start)) >= 0:
            data[start + flag_at] |= 1
            start += 4
    return bytes(data)


def _image_files() -> dict[str, bytes]:
    rng = np.random.default_rng(7)
    picture = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)  # the sample camera's size
    jpeg = encoded(picture, ".jpg")
    png = encoded(picture, ".png")
    files = {
        "img_valid.png": png,
        "img_valid.jpg": jpeg,
        "img_png_30000.png": png_bytes(30000, 30000, rows=1),
        "img_png_65535.png": png_bytes(65535, 65535, rows=1),
        "img_png_2e31_wide.png": png_bytes(2**31 - 1, 1, rows=0),
        "img_png_zero_size.png": png_bytes(0, 0, rows=0),
        "img_png_short_rows.png": png_bytes(200, 200, rows=20),
        "img_png_crc_bad.png": png_bytes(20, 20, crc_ok=False),
        "img_png_16bit.png": encoded(picture.astype(np.uint16) * 257, ".png"),
        "img_png_grey_alpha.png": png_bytes(30, 20, color_type=4),
        "img_png_palette.png": png_bytes(30, 20, color_type=3),
        "img_png_bad_iccp.png": png_bytes(30, 20, extra_chunks=[(b"iCCP", b"bad\x00\x00" + zlib.compress(b"not a profile"))]),
        "img_png_cut_header.png": png[:20],
        "img_png_cut_half.png": png[: len(png) // 2],
        "img_png_idat_garbage.png": png_bytes(30, 20)[:40] + bytes(range(200)),
        "img_jpeg_cut_half.jpg": jpeg[: len(jpeg) // 2],
        "img_jpeg_cut_header.jpg": jpeg[:30],
        "img_jpeg_65000.jpg": jpeg_with_size(jpeg, 65000, 65000),
        "img_jpeg_30000.jpg": jpeg_with_size(jpeg, 30000, 30000),
        "img_jpeg_zero.jpg": jpeg_with_size(jpeg, 0, 0),
        "img_jpeg_garbage_after_soi.jpg": b"\xff\xd8" + bytes(range(256)) * 10,
        "img_jpeg_grey.jpg": encoded(picture[:, :, 0], ".jpg"),
        "img_bmp_valid.bmp": encoded(picture, ".bmp"),
        "img_bmp_huge.bmp": _bmp_with_size(encoded(picture, ".bmp"), 40000, 40000),
        "img_tiff_valid.tif": encoded(picture, ".tif"),
        "img_tiff_float.tif": encoded(picture.astype(np.float32) / 255, ".tif"),
        "img_empty.png": b"",
        "img_text.png": b"not an image at all\n",
        "img_png_named_jpg.jpg": png,
        "img_webp.webp": encoded(picture, ".webp"),
    }
    return files


def _bmp_with_size(bmp: bytes, width: int, height: int) -> bytes:
    data = bytearray(bmp)
    struct.pack_into("<ii", data, 18, width, height)
    return bytes(data)


# --------------------------------------------------------------------------
# Seeded random byte mutations of valid files
# --------------------------------------------------------------------------


def mutate(data: bytes, rng: random.Random) -> bytes:
    """Flip, overwrite, insert, delete or truncate a few bytes."""
    data = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        if not data:
            break
        at = rng.randrange(len(data))
        kind = rng.choice(("flip", "byte", "insert", "delete", "truncate", "digits"))
        if kind == "flip":
            data[at] ^= 1 << rng.randrange(8)
        elif kind == "byte":
            data[at] = rng.randrange(256)
        elif kind == "insert":
            data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif kind == "delete":
            del data[at : at + rng.randint(1, 16)]
        elif kind == "truncate":
            del data[max(at, len(data) // 2) :]
        else:
            data[at : at + 1] = rng.choice((b"9" * 12, b"-", b"e308", b"nan", b"\n"))
    return bytes(data)


# --------------------------------------------------------------------------
# The corpus
# --------------------------------------------------------------------------


def make_cases(folder: Path) -> list[FuzzCase]:
    """Write the hostile scan and image files into ``folder``; return the invocations that read them."""
    folder = Path(folder)
    scans = folder / "scans"
    images = folder / "images"
    mutants = folder / "mutants"
    out = folder / "out"
    for sub in (scans, images, mutants, out):
        sub.mkdir(parents=True, exist_ok=True)

    rec = base_records()
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64)
    scan_files: dict[str, bytes] = {}
    for maker in (lambda: _pcd_files(rec), lambda: _ply_files(xyz), lambda: _las_files(xyz), lambda: _bin_files(rec), lambda: _npy_files(rec), lambda: _npz_files(rec)):
        scan_files.update(maker())

    cases: list[FuzzCase] = []

    def scan_case(name: str, path: Path, *options: str) -> None:
        cases.append(FuzzCase(name=name, argv=["ba-images", "--scan", str(path), *options, "-o", str(out / "ba")]))

    for name, data in scan_files.items():
        path = scans / name
        path.write_bytes(data)
        scan_case(f"scan/{name}", path)
    # Options against the files.
    scan_case("scan/bin_columns_wrong", scans / "bin_kitti_valid.bin", "--bin-columns", "7")
    scan_case("scan/bin_columns_2", scans / "bin_kitti_valid.bin", "--bin-columns", "2")
    scan_case("scan/bin_columns_5_on_kitti", scans / "bin_kitti_valid.bin", "--bin-columns", "5")
    scan_case("scan/bin_columns_noise", scans / "bin_noise.bin", "--bin-columns", "4")
    scan_case("scan/max_points_tiny", scans / "pcd_binary_valid.pcd", "--max-points", "10")
    scan_case("scan/max_points_zero", scans / "pcd_binary_valid.pcd", "--max-points", "0")
    scan_case("scan/max_points_negative", scans / "npz_native_valid.npz", "--max-points", "-5")

    # Special files.
    fifo = scans / "fifo.pcd"
    if not fifo.exists():
        os.mkfifo(fifo)
    scan_case("special/fifo_scan", fifo)
    (scans / "folder.pcd").mkdir(exist_ok=True)
    scan_case("special/folder_scan", scans / "folder.pcd")
    scan_case("special/dev_zero", Path("/dev/zero"))
    link = scans / "zero_link.bin"
    if not link.is_symlink():
        link.symlink_to("/dev/zero")
    scan_case("special/symlink_to_dev_zero", link)
    loop = scans / "loop.pcd"
    if not loop.is_symlink():
        loop.symlink_to(loop.name)
    scan_case("special/symlink_loop", loop)
    scan_case("special/missing", scans / "missing.pcd")
    sparse = scans / "sparse_2g.bin"
    with open(sparse, "wb") as handle:
        handle.truncate(2 * 1024**3)  # sparse: no disk used
    scan_case("special/sparse_2gb_bin", sparse)
    sparse_npy = scans / "sparse_header.npy"
    with open(sparse_npy, "wb") as handle:
        handle.write(npy_header((50_000_000, 3)))
        handle.truncate(len(npy_header((50_000_000, 3))) + 50_000_000 * 24)
    scan_case("special/sparse_npy_1200mb", sparse_npy)
    scan_case("scan/pcd_organize_ring", scans / "pcd_ascii_valid.pcd", "--organize", "ring")
    other = scans / "cloud.xyz"
    other.write_bytes(b"1 2 3\n")
    scan_case("special/xyz_suffix", other)

    # Images, through colorize (scan, camera and extrinsics from the bundled sample).
    base = folder / "base"
    base.mkdir(exist_ok=True)
    for name in ("scan.npz", "camera.yaml", "calib_results.txt", "ground_truth.yaml"):
        shutil.copyfile(SAMPLE / name, base / name)
    small_scan = scans / "npy_valid.npy"

    def image_case(name: str, path: Path) -> None:
        cases.append(
            FuzzCase(
                name=name,
                argv=["colorize", "--scan", str(small_scan), "--image", str(path), "--camera", str(base / "camera.yaml"),
                      "--extrinsics", str(base / "ground_truth.yaml"), "--no-occlusion", "-o", str(out / "colored.ply")],
            )
        )

    for name, data in _image_files().items():
        path = images / name
        path.write_bytes(data)
        image_case(f"image/{name}", path)
    fifo_image = images / "fifo.png"
    if not fifo_image.exists():
        os.mkfifo(fifo_image)
    image_case("special/fifo_image", fifo_image)
    image_case("special/dev_zero_image", Path("/dev/zero"))
    image_case("special/folder_image", images)

    # Seeded random mutations of valid files of every kind.
    rng = random.Random(20261123)
    seeds = {name: scan_files[name] for name in sorted(scan_files) if "valid" in name}
    seeds.update({name: data for name, data in _image_files().items() if "valid" in name})
    for round_ in range(4):
        for name, data in sorted(seeds.items()):
            mutant = mutants / f"m{round_}_{name}"
            mutant.write_bytes(mutate(data, rng))
            if name.startswith("img_"):
                image_case(f"mutant/{mutant.name}", mutant)
            else:
                scan_case(f"mutant/{mutant.name}", mutant)
    return cases
