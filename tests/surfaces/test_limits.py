"""Height-map files that declare more than they are: every reader bounds what a header may
declare (against the file size and a configurable limit, ``GONIOLAB_MAX_MAP_POINTS``) before
allocating, and inflates compressed data in bounded steps (issue 10, defect 2: a 1.5 MB
``.sur`` declaring a huge map allocated 5.3 GB and ended in a numpy traceback after 37 s)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces import load_heightmap, save_heightmap
from goniolab.surfaces._common import (
    DEFAULT_MAX_MAP_POINTS,
    MAX_MAP_POINTS_ENV,
    ZLIB_MAX_RATIO,
    max_map_points,
)

SMALL_LIMIT = 10_000  # points: the maps below are 1000 x 1000


@pytest.fixture
def small_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(MAX_MAP_POINTS_ENV, str(SMALL_LIMIT))


def _map(nx: int, ny: int) -> HeightMap:
    z = np.zeros((ny, nx))
    z[0, 0] = 1.0
    return HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="t", meta={})


def _sur_header(tmp: Path, nx: int, ny: int) -> bytes:
    """The 512-byte header (plus comment zone) goniolab writes for an nx x ny int32 map."""
    p = tmp / "h.sur"
    save_heightmap(_map(2, 1), p, fmt="sur")
    raw = bytearray(p.read_bytes())
    comment_size, private_size = struct.unpack_from("<HH", raw, 334)
    start = 512 + comment_size + private_size
    struct.pack_into("<iii", raw, 108, nx, ny, nx * ny)
    return bytes(raw[:start])


def _dscompressed(header: bytes, streams: list[tuple[int, bytes]]) -> bytes:
    directory = struct.pack("<I", len(streams))
    directory += b"".join(struct.pack("<II", raw_len, len(z)) for raw_len, z in streams)
    return b"DSCOMPRESSED" + header[12:] + directory + b"".join(z for _, z in streams)


def test_the_limit_defaults_and_reads_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(MAX_MAP_POINTS_ENV, raising=False)
    assert max_map_points() == DEFAULT_MAX_MAP_POINTS == 8192 * 8192
    monkeypatch.setenv(MAX_MAP_POINTS_ENV, "1_000_000")
    assert max_map_points() == 1_000_000
    monkeypatch.setenv(MAX_MAP_POINTS_ENV, "lots")
    with pytest.raises(HeightMapError, match=MAX_MAP_POINTS_ENV):
        max_map_points()


def test_a_compressed_sur_over_the_limit_fails_before_inflating(
    tmp_path: Path, small_limit: None
) -> None:
    """1000 x 1000 int32 = 4 MB of zeros deflate to a few kB: a real (small) bomb."""
    data = bytes(4 * 1000 * 1000)
    p = tmp_path / "bomb.sur"
    p.write_bytes(
        _dscompressed(_sur_header(tmp_path, 1000, 1000), [(len(data), zlib.compress(data, 9))])
    )
    assert p.stat().st_size < 20_000
    with pytest.raises(
        HeightMapError, match=rf"1000x1000 = 1000000 points, more than the limit of {SMALL_LIMIT}"
    ) as info:
        load_heightmap(p)
    assert str(info.value).startswith("bomb.sur: ") and MAX_MAP_POINTS_ENV in str(info.value)


def test_a_huge_declared_sur_is_refused_at_the_default_limit(tmp_path: Path) -> None:
    """30000 x 30000 int32 (3.6 GB) from a 1 kB file: refused from the header, before the
    (garbage) stream is touched."""
    p = tmp_path / "huge.sur"
    p.write_bytes(
        _dscompressed(_sur_header(tmp_path, 30000, 30000), [(3_600_000_000, b"\x78" * 1000)])
    )
    with pytest.raises(HeightMapError, match="more than the limit"):
        load_heightmap(p)


def test_a_stream_claiming_more_than_zlib_can_expand_is_refused(tmp_path: Path) -> None:
    """Within the limit, but 100 x 100 int32 = 40000 bytes claimed from a 10-byte stream."""
    p = tmp_path / "ratio.sur"
    p.write_bytes(
        _dscompressed(_sur_header(tmp_path, 100, 100), [(40_000, b"\x78\x9c" + bytes(8))])
    )
    with pytest.raises(HeightMapError, match=f"{ZLIB_MAX_RATIO}:1"):
        load_heightmap(p)


def test_a_stream_that_inflates_beyond_its_claim_stops_there(tmp_path: Path) -> None:
    """The directory claims 400 bytes for a stream of 40000: inflating stops at the claim."""
    big = zlib.compress(bytes(40_000))
    p = tmp_path / "over.sur"
    p.write_bytes(_dscompressed(_sur_header(tmp_path, 10, 10), [(400, big)]))
    with pytest.raises(HeightMapError, match="more than the 400 bytes it claims"):
        load_heightmap(p)


def test_compressed_streams_must_add_up_to_the_map(tmp_path: Path) -> None:
    data = bytes(4 * 10 * 10)
    p = tmp_path / "sum.sur"
    p.write_bytes(_dscompressed(_sur_header(tmp_path, 10, 10), [(200, zlib.compress(data[:200]))]))
    with pytest.raises(HeightMapError, match="200 bytes, header implies 400"):
        load_heightmap(p)


def test_a_valid_sur_in_two_compressed_streams_reads_as_the_plain_file(tmp_path: Path) -> None:
    z = np.random.default_rng(1).normal(0.0, 1.0, (30, 40))
    plain = tmp_path / "plain.sur"
    save_heightmap(HeightMap(z_um=z, dx_um=0.5, dy_um=0.5, source="t", meta={}), plain, fmt="sur")
    raw = plain.read_bytes()
    comment_size, private_size = struct.unpack_from("<HH", raw, 334)
    start = 512 + comment_size + private_size
    data = raw[start:]
    half = len(data) // 2
    p = tmp_path / "two.sur"
    p.write_bytes(_dscompressed(raw[:start], [(half, zlib.compress(data[:half])),
                                              (len(data) - half, zlib.compress(data[half:]))]))  # fmt: skip
    np.testing.assert_array_equal(load_heightmap(p).z_um, load_heightmap(plain).z_um)


@pytest.mark.parametrize(
    ("fmt", "suffix"),
    [("sur", "sur"), ("sdf", "sdf"), ("sdf-int16", "sdf"), ("sdf-ascii", "sdf"),
     ("npy", "npy"), ("csv", "csv"), ("txt", "txt"), ("gwy", "gwy")],
)  # fmt: skip
def test_every_reader_refuses_a_map_over_the_limit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fmt: str, suffix: str
) -> None:
    """A genuine 120 x 100 map (12000 points) is refused when the limit is 10000 points and
    read when the limit allows it."""
    p = tmp_path / f"m.{suffix}"
    save_heightmap(_map(120, 100), p, fmt=fmt)
    monkeypatch.setenv(MAX_MAP_POINTS_ENV, str(SMALL_LIMIT))
    with pytest.raises(HeightMapError, match="more than the limit") as info:
        load_heightmap(p)
    assert str(info.value).startswith(f"m.{suffix}: ")
    monkeypatch.setenv(MAX_MAP_POINTS_ENV, "12000")
    assert load_heightmap(p).shape == (100, 120)


def test_a_binary_sdf_header_over_the_limit_is_refused_before_the_data_is_read(
    tmp_path: Path,
) -> None:
    """65535 x 65535 float64 declared by an 81-byte header with no data: the limit speaks
    first (the file could never hold it either)."""
    p = tmp_path / "h.sdf"
    save_heightmap(_map(2, 2), p, fmt="sdf")
    raw = bytearray(p.read_bytes()[:81])
    struct.pack_into("<HH", raw, 42, 65535, 65535)
    p.write_bytes(bytes(raw))
    with pytest.raises(
        HeightMapError, match="65535x65535 = 4294836225 points, more than the limit"
    ):
        load_heightmap(p)
