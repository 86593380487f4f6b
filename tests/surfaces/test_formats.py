"""Tests for goniolab.surfaces (height-map files) and goniolab.optics.heightmap (the container, levelling)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from goniolab.optics.heightmap import (
    HeightMap,
    HeightMapError,
    fill_missing,
    level_plane,
)
from goniolab.surfaces import load_heightmap, save_heightmap


def _sample_map(ny: int = 5, nx: int = 7, *, with_nan: bool = True) -> HeightMap:
    rng = np.random.default_rng(7)
    z = rng.normal(0.0, 0.8, (ny, nx))
    if with_nan:
        z[1, 2] = np.nan
        z[ny - 1, 0] = np.nan
    return HeightMap(z_um=z, dx_um=0.5, dy_um=0.75, source="mem", meta={"note": "t"})


# ---------------------------------------------------------------- the dataclass


def test_heightmap_properties() -> None:
    hm = _sample_map()
    assert hm.shape == (5, 7)
    assert hm.n_valid == 33
    assert hm.valid_fraction == pytest.approx(33 / 35)
    assert hm.z_um.dtype == np.float64
    with pytest.raises(ValueError):
        hm.z_um[0, 0] = 1.0  # read-only


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "x"])
def test_heightmap_rejects_bad_steps(bad: object) -> None:
    with pytest.raises(HeightMapError, match=r"mysrc: dx_um"):
        HeightMap(z_um=np.zeros((2, 2)), dx_um=bad, dy_um=1.0, source="mysrc")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("z", "msg"),
    [
        (np.zeros(4), "2-D"),
        (np.zeros((0, 3)), "zero points"),
        (np.full((2, 2), np.inf), "inf"),
        (np.ones((2, 2), dtype=complex), "must be real"),
    ],
)
def test_heightmap_rejects_bad_heights(z: np.ndarray, msg: str) -> None:
    with pytest.raises(HeightMapError, match=rf"mysrc: .*{msg}"):
        HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="mysrc")


# ---------------------------------------------------------------- levelling


def test_level_plane_recovers_bumps_and_keeps_nan() -> None:
    ny, nx = 40, 50
    dx, dy = 0.5, 0.25
    ii, jj = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")

    def bump(i0: int, j0: int, amp: float) -> np.ndarray:
        return amp * np.exp(-((ii - i0) ** 2 + (jj - j0) ** 2) / 8.0)

    def mirror(i: int, j: int) -> tuple[int, int]:  # point reflection through the centre
        return ny - 1 - i, nx - 1 - j

    # Bumps and missing points in point-symmetric pairs: over the valid points the bumps
    # then have zero first moments in x and y, so their best plane is their mean alone and
    # levelling must return exactly bumps - mean(bumps).
    bumps = bump(10, 10, 2.0) + bump(*mirror(10, 10), 2.0)
    bumps += bump(20, 5, -1.5) + bump(*mirror(20, 5), -1.5)
    valid = np.ones((ny, nx), dtype=bool)
    valid[5, 7] = valid[mirror(5, 7)] = False
    tilted = bumps + 3.0 + 0.02 * jj * dx - 0.05 * ii * dy
    tilted[~valid] = np.nan
    out = level_plane(HeightMap(z_um=tilted, dx_um=dx, dy_um=dy, source="t"))
    assert np.array_equal(np.isnan(out.z_um), ~valid)
    expected = bumps - bumps[valid].mean()
    np.testing.assert_allclose(out.z_um[valid], expected[valid], rtol=0, atol=1e-12)


def test_level_plane_exact_plane_goes_to_zero() -> None:
    yy, xx = np.meshgrid(np.arange(6) * 2.0, np.arange(9) * 1.0, indexing="ij")
    hm = HeightMap(z_um=1.0 + 0.3 * xx + 0.1 * yy, dx_um=1.0, dy_um=2.0, source="p")
    np.testing.assert_allclose(level_plane(hm).z_um, 0.0, atol=1e-12)


def test_level_plane_no_valid_points() -> None:
    hm = HeightMap(z_um=np.full((3, 3), np.nan), dx_um=1.0, dy_um=1.0, source="allnan")
    with pytest.raises(HeightMapError, match=r"allnan: cannot level"):
        level_plane(hm)


def test_fill_missing_nearest_and_mean() -> None:
    z = np.array([[1.0, np.nan, np.nan, 4.0], [5.0, 6.0, 7.0, 8.0], [9.0, 9.0, 9.0, np.nan]])
    hm = HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="f")
    near = fill_missing(hm, "nearest").z_um
    # ties (two valid points at distance 1) may go either way
    assert near[0, 1] in (1.0, 6.0)
    assert near[0, 2] in (4.0, 7.0)
    assert near[2, 3] in (8.0, 9.0)
    assert not np.isnan(near).any()
    mean = fill_missing(hm, "mean").z_um
    valid = ~np.isnan(z)
    assert mean[0, 1] == mean[0, 2] == mean[2, 3] == pytest.approx(z[valid].sum() / 9.0)
    np.testing.assert_array_equal(mean[valid], z[valid])
    gap = HeightMap(z_um=np.array([[1.0, np.nan, np.nan, 4.0]]), dx_um=1.0, dy_um=1.0)
    np.testing.assert_array_equal(fill_missing(gap).z_um, [[1.0, 1.0, 4.0, 4.0]])


# ---------------------------------------------------------------- .npy


def test_npy_round_trip_with_sidecar(tmp_path: Path) -> None:
    hm = _sample_map()
    p = tmp_path / "scan.npy"
    save_heightmap(hm, p)
    assert (tmp_path / "scan.npy.json").exists()
    back = load_heightmap(p)
    np.testing.assert_array_equal(back.z_um, hm.z_um)
    assert (back.dx_um, back.dy_um) == (0.5, 0.75)
    assert back.meta["note"] == "t"
    assert back.source == "scan.npy"


def test_npy_is_read_without_a_copy(tmp_path: Path) -> None:
    """A float64 .npy is the map: no copy of it and no full-size temporary (the units check
    reads a sample of rows), and it is read-only through the array and its base (np.load
    returns a reshaped view of its read)."""
    import tracemalloc

    rng = np.random.default_rng(4)
    z = rng.normal(0.0, 0.2, (512, 512))
    path = tmp_path / "m.npy"
    np.save(path, z)
    (tmp_path / "m.npy.json").write_text('{"step_um": 0.5}')
    load_heightmap(path)  # imports, caches
    tracemalloc.start()
    try:
        hm = load_heightmap(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1.15 * z.nbytes  # was 3.25 x: a copy and five temporaries
    np.testing.assert_array_equal(hm.z_um, z)
    assert not hm.z_um.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        hm.z_um[0, 0] = 1.0
    base = hm.z_um.base
    assert base is None or not base.flags.writeable


def test_npy_without_sidecar_needs_step(tmp_path: Path) -> None:
    p = tmp_path / "bare.npy"
    np.save(p, np.arange(12, dtype=np.int32).reshape(3, 4))
    with pytest.raises(HeightMapError, match=r"bare.npy: no lateral step"):
        load_heightmap(p)
    hm = load_heightmap(p, step_um=(0.5, 2.0))
    assert (hm.dx_um, hm.dy_um) == (0.5, 2.0)
    np.testing.assert_array_equal(hm.z_um, np.arange(12.0).reshape(3, 4))


def test_npy_step_conflict_and_bad_arrays(tmp_path: Path) -> None:
    hm = _sample_map()
    p = tmp_path / "a.npy"
    save_heightmap(hm, p)
    with pytest.raises(HeightMapError, match=r"a.npy: step_um=1.0 contradicts"):
        load_heightmap(p, step_um=1.0)
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array([[{"a": 1}]], dtype=object), allow_pickle=True)
    with pytest.raises(HeightMapError, match=r"obj.npy"):
        load_heightmap(obj, step_um=1.0)
    one_d = tmp_path / "oned.npy"
    np.save(one_d, np.zeros(5))
    with pytest.raises(HeightMapError, match=r"oned.npy: .*2-D"):
        load_heightmap(one_d, step_um=1.0)
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((0, 4)))
    with pytest.raises(HeightMapError, match=r"empty.npy: .*zero points"):
        load_heightmap(empty, step_um=1.0)
    for bad_step in (float("nan"), float("inf"), 0.0):
        with pytest.raises(HeightMapError, match=r"oned.npy: step_um"):
            load_heightmap(one_d, step_um=bad_step)


def test_missing_file_directory_and_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(HeightMapError, match=r"nothere.npy: no such file"):
        load_heightmap(tmp_path / "nothere.npy")
    d = tmp_path / "adir.npy"
    d.mkdir()
    with pytest.raises(HeightMapError, match=r"adir.npy: is a directory"):
        load_heightmap(d)
    with pytest.raises(HeightMapError, match=r"x.bmp: unknown height-map extension"):
        load_heightmap(tmp_path / "x.bmp")


# ---------------------------------------------------------------- round trips


FLOAT_FORMATS = [
    ("npy", "npy"),
    ("csv", "csv"),
    ("txt", "txt"),
    ("sdf", "sdf"),
    ("sdf-ascii", "sdf"),
]
INT_FORMATS = [("sdf-int16", "sdf"), ("sdf-int32", "sdf"), ("sur", "sur"), ("sur-int16", "sur")]


@pytest.mark.parametrize(("fmt", "ext"), FLOAT_FORMATS)
def test_round_trip_float_formats_exact(tmp_path: Path, fmt: str, ext: str) -> None:
    hm = HeightMap(
        z_um=_sample_map().z_um * 1234.5678, dx_um=0.1, dy_um=0.3, source="m", meta={"k": "v"}
    )
    p = tmp_path / f"map.{ext}"
    save_heightmap(hm, p, fmt=fmt)
    back = load_heightmap(p)
    np.testing.assert_array_equal(back.z_um, hm.z_um)  # NaN positions and values, bit-exact
    assert (back.dx_um, back.dy_um) == (0.1, 0.3)


def test_round_trip_gwy_to_one_ulp(tmp_path: Path) -> None:
    hm = _sample_map()
    p = tmp_path / "map.gwy"
    save_heightmap(hm, p)
    back = load_heightmap(p)
    assert np.array_equal(np.isnan(back.z_um), np.isnan(hm.z_um))
    ok = ~np.isnan(hm.z_um)
    # metres on disk: z_um / 1e6 * 1e6 is within one ulp of z_um
    np.testing.assert_allclose(back.z_um[ok], hm.z_um[ok], rtol=2.3e-16, atol=0)
    assert (back.dx_um, back.dy_um) == (hm.dx_um, hm.dy_um)
    assert back.meta["note"] == "t"


@pytest.mark.parametrize(("fmt", "ext"), INT_FORMATS)
def test_round_trip_integer_formats_within_z_step(tmp_path: Path, fmt: str, ext: str) -> None:
    base = _sample_map(40, 30)
    hm = HeightMap(z_um=base.z_um + 500.0, dx_um=0.1, dy_um=0.7, source="m")
    p = tmp_path / f"map.{ext}"
    save_heightmap(hm, p, fmt=fmt)
    back = load_heightmap(p)
    step = float(back.meta["z_step_um"])
    ok = ~np.isnan(hm.z_um)
    span = float(np.nanmax(hm.z_um) - np.nanmin(hm.z_um))
    bits = 16 if fmt.endswith("int16") else 32
    if fmt.startswith("sdf"):
        # no z offset in SDF: the range is +-max|z| over the integer range
        assert step <= 1.0001 * float(np.nanmax(np.abs(hm.z_um))) / (2 ** (bits - 1) - 2)
    else:
        assert step <= 1.0001 * span / (2 ** (bits - 1) - 16)
    assert np.array_equal(np.isnan(back.z_um), ~ok)
    err = np.abs(back.z_um[ok] - hm.z_um[ok])
    assert err.max() <= step / 2 * (1 + 1e-9) + 1e-12 * 500.0
    assert (back.dx_um, back.dy_um) == (0.1, 0.7)


# ---------------------------------------------------------------- SUR from the spec


def _sur_header(**fields: object) -> bytearray:
    """A Digital Surf header built at the byte offsets of Gwyddion's surffile.c."""
    h = bytearray(512)
    layout = {
        "signature": ("12s", 0), "format": ("<h", 12), "n_objects": ("<H", 14),
        "version": ("<h", 16), "type": ("<h", 18), "object_name": ("30s", 20),
        "operator": ("30s", 50), "special_points": ("<h", 86), "absolute": ("<h", 88),
        "point_size": ("<h", 98), "zmin": ("<i", 100), "zmax": ("<i", 104),
        "xres": ("<i", 108), "yres": ("<i", 112), "n_points": ("<i", 116),
        "dx": ("<f", 120), "dy": ("<f", 124), "dz": ("<f", 128),
        "dx_unit": ("16s", 180), "dy_unit": ("16s", 196), "dz_unit": ("16s", 212),
        "inversion": ("<h", 290), "day": ("<h", 312), "month": ("<h", 314), "year": ("<h", 316),
        "compressed_size": ("<I", 324), "comment_size": ("<H", 334),
        "private_size": ("<H", 336), "z_offset": ("<f", 474),
    }  # fmt: skip
    defaults: dict[str, object] = {
        "signature": b"DIGITAL SURF", "format": 0, "n_objects": 1, "version": 1, "type": 2,
        "object_name": b"hand built", "absolute": 1,
    }  # fmt: skip
    for key, value in {**defaults, **fields}.items():
        code, offset = layout[key]
        struct.pack_into(code, h, offset, value)
    return h


def _sur_bytes(**over: object) -> bytes:
    comment, private = b"hello", b"xyz"
    ints = np.array([[0, 2, -102], [4, -6, 8]], dtype="<i2")
    fields: dict[str, object] = dict(
        point_size=16, zmin=-100, zmax=8, xres=3, yres=2, n_points=6, dx=2.0, dy=3.0,
        dz=0.5, dx_unit=b"\xb5m", dy_unit=b"\xb5m", dz_unit=b"nm", special_points=1,
        comment_size=len(comment), private_size=len(private), z_offset=10.0,
        day=21, month=11, year=2026,
    )  # fmt: skip
    fields.update(over)
    return bytes(_sur_header(**fields)) + comment + private + ints.tobytes()


SUR_EXPECTED_UM = np.array([[0.010, 0.011, np.nan], [0.012, 0.007, 0.014]])


def test_sur_hand_built_bytes(tmp_path: Path) -> None:
    p = tmp_path / "hand.sur"
    p.write_bytes(_sur_bytes())
    hm = load_heightmap(p)
    # z = point * dz + z_offset = (raw * 0.5 + 10) nm; -102 = zmin - 2 is non-measured
    np.testing.assert_allclose(hm.z_um, SUR_EXPECTED_UM, rtol=1e-12, atol=0)
    assert (hm.dx_um, hm.dy_um) == (2.0, 3.0)
    assert hm.meta["object_name"] == "hand built"
    assert hm.meta["comment"] == "hello"
    assert hm.meta["date"] == "2026-11-21"
    assert float(hm.meta["z_step_um"]) == pytest.approx(0.5e-3)


def test_sur_hand_built_int32_inversion_and_no_special_points(tmp_path: Path) -> None:
    ints = np.array([[1, -2], [300000, 4]], dtype="<i4")
    head = _sur_header(
        point_size=32, zmin=-2, zmax=300000, xres=2, yres=2, n_points=4, dx=1.5, dy=1.5,
        dz=1.0, dx_unit=b"mm", dy_unit=b"mm", dz_unit=b"nm", inversion=1,
    )  # fmt: skip
    p = tmp_path / "inv.sur"
    p.write_bytes(bytes(head) + ints.tobytes())
    hm = load_heightmap(p)
    # special_points = 0: -4 (= zmin - 2) is NOT a missing point here; inversion 1 negates z
    np.testing.assert_allclose(hm.z_um, -ints * 1e-3, rtol=1e-12)
    assert (hm.dx_um, hm.dy_um) == (1500.0, 1500.0)


def test_sur_hand_built_compressed(tmp_path: Path) -> None:
    ints = np.array([[0, 2, -102], [4, -6, 8]], dtype="<i2").tobytes()
    streams = [zlib.compress(ints[:6]), zlib.compress(ints[6:])]
    directory = struct.pack("<I", 2) + b"".join(
        struct.pack("<II", n, len(s)) for n, s in zip((6, 6), streams, strict=True)
    )
    head = bytes(_sur_bytes()[:520])  # header + comment + private zone
    head = b"DSCOMPRESSED" + head[12:]
    p = tmp_path / "zip.sur"
    p.write_bytes(head + directory + b"".join(streams))
    hm = load_heightmap(p)
    np.testing.assert_allclose(hm.z_um, SUR_EXPECTED_UM, rtol=1e-12, atol=0)


def test_sur_every_truncation_fails_naming_file(tmp_path: Path) -> None:
    full = _sur_bytes()
    p = tmp_path / "cut.sur"
    for n in range(len(full)):
        p.write_bytes(full[:n])
        with pytest.raises(HeightMapError, match=r"^cut\.sur: "):
            load_heightmap(p)
    p.write_bytes(full[:-3])
    with pytest.raises(HeightMapError, match=r"cut\.sur: truncated: header says 3x2 points"):
        load_heightmap(p)


@pytest.mark.parametrize(
    ("over", "msg"),
    [
        ({"signature": b"DIGITAL SURX"}, "not a Digital Surf file"),
        ({"dx": float("nan")}, "dx is not finite"),
        ({"dy": float("inf")}, "dy is not finite"),
        ({"dz": 0.0}, "zero spacing"),
        ({"xres": 0, "n_points": 0}, "zero points"),
        ({"n_points": 7}, "total points 7"),
        ({"point_size": 8}, "point size 8"),
        ({"type": 12}, "object type 12"),
        ({"dz_unit": b"furlong"}, "unknown z step unit"),
    ],
)
def test_sur_bad_headers(tmp_path: Path, over: dict[str, object], msg: str) -> None:
    p = tmp_path / "bad.sur"
    p.write_bytes(_sur_bytes(**over))
    with pytest.raises(HeightMapError, match=rf"^bad\.sur: .*{msg}"):
        load_heightmap(p)


# ---------------------------------------------------------------- SDF from the spec


def _sdf_binary_bytes(data_type: int = 5, zscale: float = 1e-9) -> bytes:
    """ISO 25178-71 binary SDF built field by field (81-byte header, little-endian)."""
    head = (
        b"bISO-1.0"
        + b"NISTtest".ljust(10, b"\0")
        + b"211120261200"
        + b"211120261201"
        + struct.pack("<H", 3)  # NumPoints (x)
        + struct.pack("<H", 2)  # NumProfiles (y)
        + struct.pack("<d", 2e-6)  # Xscale, m
        + struct.pack("<d", 0.5e-6)  # Yscale, m
        + struct.pack("<d", zscale)  # Zscale, m
        + struct.pack("<d", 1e-9)  # Zresolution, m
        + bytes([0, data_type, 0])  # Compression, DataType, CheckType
    )
    assert len(head) == 81
    ints = np.array([[1, -2, -32768], [3, 4, 5]], dtype="<i2")
    return head + ints.tobytes()


def test_sdf_binary_hand_built(tmp_path: Path) -> None:
    p = tmp_path / "hand.sdf"
    p.write_bytes(_sdf_binary_bytes())
    hm = load_heightmap(p)
    expected = np.array([[1e-3, -2e-3, np.nan], [3e-3, 4e-3, 5e-3]])  # raw * 1 nm, in um
    np.testing.assert_allclose(hm.z_um, expected, rtol=1e-12, atol=0)
    assert (hm.dx_um, hm.dy_um) == (2.0, 0.5)
    assert hm.meta["manufacturer"] == "NISTtest"


SDF_ASCII = """aISO-1.0
ManufacID   = NISTtest
CreateDate  = 211120261200
ModDate     = 211120261200
NumPoints   = 3
NumProfiles = 2
Xscale      = 1.0E-06
Yscale      = 2.0E-06
Zscale      = 1.0E-09
Zresolution = -1
Compression = 0
DataType    = 6
CheckType   = 0
*
10 20 BAD
-30 40 50
*
Operator = somebody
*
"""


def test_sdf_ascii_hand_written(tmp_path: Path) -> None:
    p = tmp_path / "hand.sdf"
    p.write_text(SDF_ASCII)
    hm = load_heightmap(p)
    expected = np.array([[0.01, 0.02, np.nan], [-0.03, 0.04, 0.05]])
    np.testing.assert_allclose(hm.z_um, expected, rtol=1e-12, atol=0)
    assert (hm.dx_um, hm.dy_um) == (1.0, 2.0)
    assert hm.meta["Operator"] == "somebody"


def test_sdf_every_truncation_fails_naming_file(tmp_path: Path) -> None:
    p = tmp_path / "cut.sdf"
    full = _sdf_binary_bytes()
    for n in range(len(full)):
        p.write_bytes(full[:n])
        with pytest.raises(HeightMapError, match=r"^cut\.sdf: "):
            load_heightmap(p)
    text = SDF_ASCII.encode()
    data_end = text.index(b"\n*\n", text.index(b"\n*\n") + 1) + 1  # the '*' after the data
    for n in range(data_end + 1):
        p.write_bytes(text[:n])
        with pytest.raises(HeightMapError, match=r"^cut\.sdf: "):
            load_heightmap(p)


@pytest.mark.parametrize(
    ("old", "new", "msg"),
    [
        ("aISO-1.0", "aXYZ-1.0", "not an SDF file"),
        ("Xscale      = 1.0E-06", "Xscale      = nan", "Xscale must be finite"),
        ("Yscale      = 2.0E-06", "Yscale      = inf", "Yscale must be finite"),
        ("NumPoints   = 3", "NumPoints   = 0", "zero points"),
        ("NumPoints   = 3", "NumPoints   = 4", "header says 4x2"),
        ("DataType    = 6", "DataType    = 9", "unknown SDF DataType 9"),
        ("Compression = 0", "Compression = 1", "compressed SDF not supported"),
        ("-30 40 50", "-30 4x0 50", "not a number"),
        ("NumProfiles = 2\n", "", "lacks NumProfiles"),
        ("Zscale      = 1.0E-09", "Zscale      = 1.0E+305", "overflow to infinity"),
    ],
)
def test_sdf_ascii_bad_headers(tmp_path: Path, old: str, new: str, msg: str) -> None:
    p = tmp_path / "bad.sdf"
    p.write_text(SDF_ASCII.replace(old, new))
    with pytest.raises(HeightMapError, match=rf"^bad\.sdf: .*{msg}"):
        load_heightmap(p)


# ---------------------------------------------------------------- gwy via gwyfile's API


def test_gwy_built_with_gwyfile(tmp_path: Path) -> None:
    from gwyfile.objects import GwyContainer, GwyDataField, GwySIUnit

    data_m = np.array([[1e-9, 2e-9, 3e-9], [4e-9, 5e-9, 6e-9]])
    mask = np.zeros((2, 3))
    mask[0, 1] = 1.0
    c = GwyContainer()
    c["/0/data"] = GwyDataField(
        data_m, xreal=3e-6, yreal=1e-6, si_unit_xy=GwySIUnit(unitstr="m"),
        si_unit_z=GwySIUnit(unitstr="m"),
    )  # fmt: skip
    c["/0/data/title"] = "Topo"
    c["/0/mask"] = GwyDataField(mask, xreal=3e-6, yreal=1e-6)
    p = tmp_path / "afm.gwy"
    c.tofile(str(p))
    hm = load_heightmap(p)
    expected = data_m * 1e6
    expected[0, 1] = np.nan
    np.testing.assert_allclose(hm.z_um, expected, rtol=1e-15, atol=0)
    assert (hm.dx_um, hm.dy_um) == (1.0, 0.5)
    assert hm.meta["title"] == "Topo"


def test_gwy_malformed_component_does_not_hang(tmp_path: Path) -> None:
    # An unterminated string component: gwyfile's parser loops forever on this.
    body = b"a\x00sxyz"
    p = tmp_path / "hang.gwy"
    p.write_bytes(b"GWYP" + b"GwyContainer\x00" + struct.pack("<I", len(body)) + body)
    with pytest.raises(HeightMapError, match=r"^hang\.gwy: corrupt or truncated"):
        load_heightmap(p)


def test_gwy_and_sdf_binary_non_finite_steps(tmp_path: Path) -> None:
    from gwyfile.objects import GwyContainer, GwyDataField

    c = GwyContainer()
    c["/0/data"] = GwyDataField(np.zeros((2, 2)), xreal=float("nan"), yreal=1e-6)
    p = tmp_path / "nan.gwy"
    c.tofile(str(p))
    with pytest.raises(HeightMapError, match=r"^nan\.gwy: xreal/yreal must be finite"):
        load_heightmap(p)
    raw = bytearray(_sdf_binary_bytes())
    struct.pack_into("<d", raw, 8 + 10 + 12 + 12 + 2 + 2, float("inf"))  # Xscale
    q = tmp_path / "inf.sdf"
    q.write_bytes(bytes(raw))
    with pytest.raises(HeightMapError, match=r"^inf\.sdf: Xscale must be finite"):
        load_heightmap(q)


def test_gwy_wrong_magic_and_no_field(tmp_path: Path) -> None:
    p = tmp_path / "x.gwy"
    p.write_bytes(b"GWYO" + b"\0" * 20)
    with pytest.raises(HeightMapError, match=r"^x\.gwy: not a Gwyddion"):
        load_heightmap(p)
    p.write_bytes(b"GWYP" + b"GwyContainer\x00" + struct.pack("<I", 0))
    with pytest.raises(HeightMapError, match=r"^x\.gwy: no GwyDataField"):
        load_heightmap(p)


# ---------------------------------------------------------------- text matrices


def test_gwyddion_ascii_export(tmp_path: Path) -> None:
    text = (
        "# Channel: Height\n# Width: 5.000 µm\n# Height: 2.500 µm\n# Value units: m\n"
        "1e-09\t2e-09\t3e-09\t4e-09\t5e-09\n6e-09\t7e-09\tnan\t9e-09\t1e-08\n"
    )
    p = tmp_path / "gwy_export.txt"
    p.write_text(text, encoding="utf-8")
    hm = load_heightmap(p)
    expected = np.array([[1, 2, 3, 4, 5], [6, 7, np.nan, 9, 10]]) * 1e-3
    np.testing.assert_allclose(hm.z_um, expected, rtol=1e-14, atol=0)
    assert (hm.dx_um, hm.dy_um) == (1.0, 1.25)  # extents / points
    assert hm.meta["channel"] == "Height"


def test_csv_semicolon_decimal_comma_units_and_missing(tmp_path: Path) -> None:
    p = tmp_path / "eu.csv"
    p.write_text("# z_unit = nm\n# dx_um = 0,5\n1,5;2;-\n;nan;-9999\n")
    with pytest.raises(HeightMapError, match=r"eu\.csv: header dx_um"):
        load_heightmap(p)
    p.write_text("# z_unit = nm\n# dx_um = 0.5\n1,5;2;-\n;nan;-9999\n")
    hm = load_heightmap(p, missing_value=-9999)
    expected = np.array([[1.5e-3, 2e-3, np.nan], [np.nan, np.nan, np.nan]])
    np.testing.assert_allclose(hm.z_um, expected, rtol=1e-15)
    assert (hm.dx_um, hm.dy_um) == (0.5, 0.5)


def test_whitespace_matrix_needs_step(tmp_path: Path) -> None:
    p = tmp_path / "plain.asc"
    p.write_text("1 2 3\n4   5 6\n")
    with pytest.raises(HeightMapError, match=r"plain\.asc: no lateral step"):
        load_heightmap(p)
    hm = load_heightmap(p, step_um=(1.0, 2.0))
    np.testing.assert_array_equal(hm.z_um, [[1, 2, 3], [4, 5, 6]])
    p.write_text("# missing_value = 5\n1 2 3\n4 5 6\n")
    assert np.isnan(load_heightmap(p, step_um=1.0).z_um[1, 1])


@pytest.mark.parametrize(
    ("content", "msg"),
    [
        ("# dx_um = 1\n1,2,3\n4,x,6\n", r"line 3, column 2: non-numeric cell 'x'"),
        ("# dx_um = 1\n1,2,3\n4,5\n", r"ragged rows: line 3 has 2 values, expected 3"),
        ("# dx_um = 1\n", r"zero points"),
        ("", r"zero points"),
        ("# dx_um = nan\n1,2\n", r"must be finite and > 0"),
        ("# dx_um = inf\n1,2\n", r"must be finite and > 0"),
        ("# dx_um = 1\n# z_unit = parsec\n1,2\n", r"unknown z unit 'parsec'"),
    ],
)
def test_csv_bad_input(tmp_path: Path, content: str, msg: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(content)
    with pytest.raises(HeightMapError, match=rf"^bad\.csv: .*{msg}"):
        load_heightmap(p)


@pytest.mark.parametrize("ext", ["npy", "csv", "txt", "sdf", "sur", "gwy"])
def test_every_reader_names_missing_file_and_directory(tmp_path: Path, ext: str) -> None:
    with pytest.raises(HeightMapError, match=rf"^gone\.{ext}: no such file"):
        load_heightmap(tmp_path / f"gone.{ext}", step_um=1.0)
    d = tmp_path / f"folder.{ext}"
    d.mkdir()
    with pytest.raises(HeightMapError, match=rf"^folder\.{ext}: is a directory"):
        load_heightmap(d, step_um=1.0)


@pytest.mark.parametrize(
    ("ext", "fmt"), [("sdf", None), ("sur", None), ("gwy", None), ("x", "npy")]
)
def test_wrong_magic(tmp_path: Path, ext: str, fmt: str | None) -> None:
    p = tmp_path / f"junk.{ext}"
    p.write_bytes(b"PK\x03\x04 this is a zip file, not a height map" * 20)
    with pytest.raises(HeightMapError, match=rf"^junk\.{ext}: "):
        load_heightmap(p, fmt=fmt, step_um=1.0 if fmt else None)


def test_writer_errors(tmp_path: Path) -> None:
    hm = _sample_map()
    with pytest.raises(HeightMapError, match=r"out\.png: unknown height-map extension"):
        save_heightmap(hm, tmp_path / "out.png")
    with pytest.raises(HeightMapError, match=r"out\.sdf: unknown height-map format 'tiff'"):
        save_heightmap(hm, tmp_path / "out.sdf", fmt="tiff")
    tiny = HeightMap(z_um=np.zeros((2, 2)), dx_um=1e-50, dy_um=1.0)
    with pytest.raises(HeightMapError, match=r"out\.sur: dx_um = 1e-50 does not fit"):
        save_heightmap(tiny, tmp_path / "out.sur")
    with pytest.raises(HeightMapError, match=r"out\.csv: cannot write"):
        save_heightmap(hm, tmp_path / "nodir" / "out.csv")
