"""Fuzzing the height-map readers: only HeightMapError may escape, whatever the bytes.

Random byte strings and mutated valid files (byte flips, truncations, insertions) are fed
to every reader; a reader may return a HeightMap (the mutation kept the file valid) or
raise HeightMapError naming the file, nothing else, and never hang.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces import load_heightmap, save_heightmap

FUZZ = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    database=None,
)

# (reader format, file extension, writer format or None for a hand-made seed)
FORMATS = [
    ("npy", "npy", "npy"),
    ("csv", "csv", "csv"),
    ("txt", "txt", "txt"),
    ("sdf", "sdf", "sdf"),
    ("sdf", "sdf", "sdf-ascii"),
    ("sdf", "sdf", "sdf-int16"),
    ("sur", "sur", "sur"),
    ("sur", "sur", None),  # DSCOMPRESSED seed
    ("gwy", "gwy", "gwy"),
]
IDS = [w or "sur-compressed" for _, _, w in FORMATS]


def _seed_map() -> HeightMap:
    rng = np.random.default_rng(3)
    z = rng.normal(0.0, 1.0, (4, 5))
    z[1, 1] = np.nan
    return HeightMap(z_um=z, dx_um=0.5, dy_um=0.25, source="seed", meta={"k": "v"})


def _compressed_sur(plain: bytes) -> bytes:
    comment_size, private_size = struct.unpack_from("<HH", plain, 334)
    start = 512 + comment_size + private_size
    data = plain[start:]
    directory = struct.pack("<III", 1, len(data), len(zlib.compress(data)))
    return b"DSCOMPRESSED" + plain[12:start] + directory + zlib.compress(data)


def _seed_bytes(tmp: Path, ext: str, writer: str | None) -> bytes:
    p = tmp / f"seed.{ext}"
    save_heightmap(_seed_map(), p, fmt=writer or "sur")
    raw = p.read_bytes()
    return _compressed_sur(raw) if writer is None else raw


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    tmp = tmp_path_factory.mktemp("seeds")
    out = {}
    for (fmt, ext, writer), ident in zip(FORMATS, IDS, strict=True):
        raw = _seed_bytes(tmp, ext, writer)
        p = tmp / f"check.{ext}"
        p.write_bytes(raw)
        # the seed itself must read back, or the mutations test nothing
        hm = load_heightmap(p, fmt=fmt, step_um=None if fmt != "npy" else 0.5)
        assert hm.shape == (4, 5)
        out[ident] = raw
    return out


def _feed(tmp: Path, ext: str, fmt: str, data: bytes) -> None:
    p = tmp / f"fuzz.{ext}"
    p.write_bytes(data)
    for step in (None, 0.5):
        try:
            hm = load_heightmap(p, fmt=fmt, step_um=step)
        except HeightMapError as exc:
            assert str(exc).startswith(f"fuzz.{ext}: "), str(exc)
        else:
            assert hm.z_um.ndim == 2 and hm.z_um.size > 0
            assert np.isfinite(hm.dx_um) and hm.dx_um > 0


@st.composite
def _mutations(draw: st.DrawFn, seed: bytes) -> bytes:
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["flip", "set", "truncate", "insert", "delete"]))
        pos = draw(st.integers(0, max(len(data) - 1, 0)))
        if kind == "flip" and data:
            data[pos] ^= 1 << draw(st.integers(0, 7))
        elif kind == "set" and data:
            data[pos] = draw(st.sampled_from([0, 0xFF, 0x7F, 0x80, ord("*"), ord("\n")]))
        elif kind == "truncate":
            del data[pos:]
        elif kind == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        elif kind == "delete":
            del data[pos : pos + draw(st.integers(1, 16))]
    return bytes(data)


@pytest.mark.parametrize(("fmt", "ext", "writer"), FORMATS, ids=IDS)
def test_random_bytes(tmp_path: Path, fmt: str, ext: str, writer: str | None) -> None:
    @FUZZ
    @given(st.binary(max_size=1024))
    def run(data: bytes) -> None:
        _feed(tmp_path, ext, fmt, data)

    run()


@pytest.mark.parametrize(("fmt", "ext", "writer"), FORMATS, ids=IDS)
def test_mutated_valid_files(
    tmp_path: Path, seeds: dict[str, bytes], fmt: str, ext: str, writer: str | None
) -> None:
    seed = seeds[writer or "sur-compressed"]

    @FUZZ
    @given(st.data())
    def run(data: st.DataObject) -> None:
        _feed(tmp_path, ext, fmt, data.draw(_mutations(seed)))

    run()
