"""Fuzzing the height-map readers: only HeightMapError may escape, whatever the bytes.

Random byte strings and mutated valid files (byte flips, truncations, insertions) are fed
to every reader, and any JSON to the ``.npy`` sidecar; a reader may return a HeightMap
(the mutation kept the file valid) or raise one HeightMapError line naming the file,
nothing else, within hypothesis's deadline per case (a hang or a bomb fails the test).
"""

from __future__ import annotations

import json
import struct
import zlib
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces import load_heightmap, save_heightmap

FUZZ = settings(
    max_examples=120,
    deadline=timedelta(seconds=3),
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
    ("sdf", "sdf", "sdf-int32"),
    ("sur", "sur", "sur"),
    ("sur", "sur", "sur-int16"),
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
            assert str(exc).startswith(f"fuzz.{ext}: ") and "\n" not in str(exc), str(exc)
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


_json_values = st.recursive(
    st.one_of(
        st.none(), st.booleans(), st.integers(-(2**70), 2**70),
        st.floats(allow_nan=False, allow_infinity=False),
        st.sampled_from([0, -1, 1e-320, 1e308, 0.5, "nm", "um", "m", "A", "pm", "furlong", "",
                         "\u00b5m", "0.5"]),
        st.text(max_size=8),
    ),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.dictionaries(st.text(max_size=4), inner, max_size=3)),
    max_leaves=6,
)  # fmt: skip
_sidecar_keys = st.sampled_from(["dx_um", "dy_um", "step_um", "z_unit", "z_scale", "meta", "dz"])


def test_npy_sidecar(tmp_path: Path, seeds: dict[str, bytes]) -> None:
    """Any JSON in the ``.npy.json`` sidecar (values, NaN/Infinity tokens, other documents):
    a map with positive finite steps, or one HeightMapError line naming the sidecar."""
    (tmp_path / "fuzz.npy").write_bytes(seeds["npy"])

    @FUZZ
    @given(
        body=st.one_of(
            st.dictionaries(_sidecar_keys, _json_values, max_size=4).map(json.dumps),
            _json_values.map(json.dumps),
            st.sampled_from(['{"dx_um": NaN}', '{"step_um": Infinity}', '{"dx_um": -Infinity}',
                             '{"step_um": 1e999}', "[" * 100_000, "{", "", "\ufeff{}"]),
            st.binary(max_size=64).map(lambda b: b.decode("latin-1")),
        ),
        step=st.sampled_from([None, 0.5]),
    )  # fmt: skip
    def run(body: str, step: float | None) -> None:
        (tmp_path / "fuzz.npy.json").write_text(body, encoding="utf-8")
        try:
            hm = load_heightmap(tmp_path / "fuzz.npy", step_um=step)
        except HeightMapError as exc:
            message = str(exc)
            assert message.startswith(("fuzz.npy: ", "fuzz.npy.json: ")), message
            assert "\n" not in message and len(message) < 600, message
        else:
            assert hm.z_um.shape == (4, 5)
            assert np.isfinite(hm.dx_um) and hm.dx_um > 0 and np.isfinite(hm.dy_um) and hm.dy_um > 0

    run()
