"""Fuzzing what every height-map reader trusts: the header fields that size the data
(hypothesis, with a time bound per case). Sizes, counts, steps and types take hostile
values -- 0, negative, huge, NaN, the type maximum -- in otherwise valid files; a reader
returns a map no larger than the limit or raises HeightMapError naming the file, within
the deadline (the decompression bomb of issue 10 took 37 s and 5.3 GB)."""

from __future__ import annotations

import os
import re
import struct
import zlib
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces import load_heightmap, save_heightmap
from goniolab.surfaces._common import MAX_MAP_POINTS_ENV

LIMIT = 1_000_000  # points allowed while fuzzing (a fuzzed header may not cost more)

BOUNDED = settings(
    max_examples=40,
    deadline=timedelta(seconds=3),
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    database=None,
)

i32 = st.one_of(
    st.sampled_from([0, 1, -1, 2, 5, 1000, 65535, 2**31 - 1, -(2**31)]),
    st.integers(-(2**31), 2**31 - 1),
)
u16 = st.one_of(st.sampled_from([0, 1, 4, 5, 1000, 65535]), st.integers(0, 65535))
u32 = st.one_of(
    st.sampled_from([0, 1, 20, 80, 1032 * 80, 2**31, 2**32 - 1]), st.integers(0, 2**32 - 1)
)
f64 = st.one_of(
    st.sampled_from([0.0, -1.0, 1e-300, 1e-6, 1.0, 1e300, float("inf"), float("nan")]),
    st.floats(allow_nan=True, allow_infinity=True),
)


@pytest.fixture(autouse=True)
def _limit() -> Iterator[None]:
    old = os.environ.get(MAX_MAP_POINTS_ENV)
    os.environ[MAX_MAP_POINTS_ENV] = str(LIMIT)
    yield
    if old is None:
        os.environ.pop(MAX_MAP_POINTS_ENV, None)
    else:
        os.environ[MAX_MAP_POINTS_ENV] = old


def _f32(x: float) -> float:
    """``x`` as the float32 a header holds (beyond its range: infinity)."""
    with np.errstate(over="ignore"):
        return float(np.float32(x))


def _seed(tmp: Path, fmt: str, suffix: str) -> bytes:
    z = np.random.default_rng(2).normal(0.0, 1.0, (4, 5))
    p = tmp / f"seed.{suffix}"
    save_heightmap(HeightMap(z_um=z, dx_um=0.5, dy_um=0.5, source="s", meta={}), p, fmt=fmt)
    return p.read_bytes()


def _feed(tmp: Path, suffix: str, data: bytes) -> None:
    p = tmp / f"fuzz.{suffix}"
    p.write_bytes(data)
    try:
        hm = load_heightmap(p, step_um=0.5 if suffix == "npy" else None)
    except HeightMapError as exc:
        assert str(exc).startswith(f"fuzz.{suffix}: "), str(exc)
        return
    assert hm.z_um.ndim == 2 and 0 < hm.z_um.size <= LIMIT
    assert np.isfinite(hm.dx_um) and hm.dx_um > 0 and np.isfinite(hm.dy_um) and hm.dy_um > 0


def test_sur_header_fields(tmp_path: Path) -> None:
    seed = _seed(tmp_path, "sur", "sur")

    @BOUNDED
    @given(
        xres=i32,
        yres=i32,
        n_points=i32,
        point_size=st.sampled_from([0, 8, 16, 32, 64, -16]),
        comment=u16,
        private=u16,
        dz=f64,
        z_offset=f64,
        special=st.sampled_from([0, 1, 2]),
    )
    def run(xres: int, yres: int, n_points: int, point_size: int, comment: int, private: int,
            dz: float, z_offset: float, special: int) -> None:  # fmt: skip
        raw = bytearray(seed)
        struct.pack_into("<iii", raw, 108, xres, yres, n_points)
        struct.pack_into("<h", raw, 98, point_size)
        struct.pack_into("<HH", raw, 334, comment, private)
        struct.pack_into("<f", raw, 128, _f32(dz))
        struct.pack_into("<f", raw, 474, _f32(z_offset))
        struct.pack_into("<h", raw, 86, special)
        _feed(tmp_path, "sur", bytes(raw))

    run()


def test_compressed_sur_stream_directory(tmp_path: Path) -> None:
    plain = _seed(tmp_path, "sur", "sur")
    comment_size, private_size = struct.unpack_from("<HH", plain, 334)
    start = 512 + comment_size + private_size
    data = plain[start:]

    @BOUNDED
    @given(
        xres=st.one_of(st.just(5), i32),
        yres=st.one_of(st.just(4), i32),
        count=st.one_of(st.just(1), u32),
        raw_len=st.one_of(st.just(len(data)), u32),
        zip_len=st.one_of(st.none(), u32),
        body=st.sampled_from(["real", "zeros", "junk"]),
    )
    def run(xres: int, yres: int, count: int, raw_len: int, zip_len: int | None,
            body: str) -> None:  # fmt: skip
        if body == "real":
            stream = zlib.compress(data)
        elif body == "zeros":  # a genuine stream of the declared size (a small bomb)
            stream = zlib.compress(bytes(min(raw_len, 4 * LIMIT + 4)), 9)
        else:
            stream = b"\x78\x9c" + bytes(range(256)) * 4
        head = bytearray(plain[:start])
        struct.pack_into("<iii", head, 108, xres, yres, xres * yres & 0x7FFFFFFF)
        directory = struct.pack("<III", count, raw_len, len(stream) if zip_len is None else zip_len)
        _feed(tmp_path, "sur", b"DSCOMPRESSED" + bytes(head[12:]) + directory + stream)

    run()


def test_binary_sdf_header_fields(tmp_path: Path) -> None:
    seed = _seed(tmp_path, "sdf", "sdf")

    @BOUNDED
    @given(nx=u16, ny=u16, xs=f64, ys=f64, zs=f64, dtype=st.integers(0, 255),
           compression=st.sampled_from([0, 1, 255]), cut=st.integers(0, 200))  # fmt: skip
    def run(nx: int, ny: int, xs: float, ys: float, zs: float, dtype: int, compression: int,
            cut: int) -> None:  # fmt: skip
        raw = bytearray(seed)
        struct.pack_into("<HHddd", raw, 42, nx, ny, xs, ys, zs)
        struct.pack_into("<BB", raw, 78, compression, dtype)
        _feed(tmp_path, "sdf", bytes(raw[: max(0, len(raw) - cut)]))

    run()


def test_ascii_sdf_header_values(tmp_path: Path) -> None:
    seed = _seed(tmp_path, "sdf-ascii", "sdf").decode()
    keys = ["NumPoints", "NumProfiles", "Xscale", "Yscale", "Zscale", "DataType", "Compression"]
    values = st.one_of(st.sampled_from(["0", "-1", "65535", "1e9", "999999999999", "nan", "inf",
                                        "1e-320", "", "x", "5", "4"]),
                       st.integers().map(str), st.floats().map(repr))  # fmt: skip

    @BOUNDED
    @given(st.dictionaries(st.sampled_from(keys), values, min_size=1, max_size=3))
    def run(change: dict[str, str]) -> None:
        text = seed
        for key, value in change.items():
            text = re.sub(rf"^{key}\s*=.*$", f"{key} = {value}", text, count=1, flags=re.M)
        _feed(tmp_path, "sdf", text.encode())

    run()


def test_npy_array_header(tmp_path: Path) -> None:
    seed = _seed(tmp_path, "npy", "npy")
    (tmp_path / "fuzz.npy.json").unlink(missing_ok=True)

    @BOUNDED
    @given(shape=st.lists(st.one_of(st.integers(-1, 10), st.sampled_from([2**31, 2**62, 10**6])),
                          min_size=0, max_size=3),
           descr=st.sampled_from(["<f8", "<i4", "|u1", ">f4", "<c16", "|O", "<U3", "<f2"]))  # fmt: skip
    def run(shape: list[int], descr: str) -> None:
        header = repr({"descr": descr, "fortran_order": False, "shape": tuple(shape)})
        header = header.encode("latin-1")
        pad = 64 - (10 + len(header) + 1) % 64
        head = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header) + pad + 1) + header
        body = seed[seed.index(b"\n", 10) + 1 :]
        _feed(tmp_path, "npy", head + b" " * pad + b"\n" + body)

    run()


def test_gwy_field_sizes(tmp_path: Path) -> None:
    seed = _seed(tmp_path, "gwy", "gwy")
    xres_at = seed.index(b"xres\x00i") + 6
    yres_at = seed.index(b"yres\x00i") + 6
    data_at = seed.index(b"data\x00D") + 6

    @BOUNDED
    @given(xres=i32, yres=i32, count=u32)
    def run(xres: int, yres: int, count: int) -> None:
        raw = bytearray(seed)
        struct.pack_into("<i", raw, xres_at, xres)
        struct.pack_into("<i", raw, yres_at, yres)
        struct.pack_into("<I", raw, data_at, count)
        _feed(tmp_path, "gwy", bytes(raw))

    run()


def test_text_headers_and_rows(tmp_path: Path) -> None:
    header_values = st.sampled_from(["0", "-1", "1e-320", "1e300", "nan", "inf", "x", "5 um",
                                     "1e9 m", "", "µm", "1"])  # fmt: skip
    keys = st.sampled_from(["dx_um", "dy_um", "step_um", "z_unit", "missing_value", "Width",
                            "Height", "Value units"])  # fmt: skip
    cells = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                      st.sampled_from(["", "nan", "-", "BAD", "1e308", "x"]))  # fmt: skip

    @BOUNDED
    @given(head=st.dictionaries(keys, header_values, max_size=4),
           rows=st.lists(st.lists(cells, min_size=1, max_size=6), min_size=0, max_size=6),
           sep=st.sampled_from([",", ";", "\t", " "]))  # fmt: skip
    def run(head: dict[str, str], rows: list[list[str]], sep: str) -> None:
        lines = [f"# {k} = {v}" for k, v in head.items()]
        lines += [sep.join(r) for r in rows]
        _feed(tmp_path, "csv", ("\n".join(lines) + "\n").encode())

    run()
