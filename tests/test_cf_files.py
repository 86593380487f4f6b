"""goniolab's netCDF files follow the CF conventions (issue 22.11) and read back.

Other tools rejected the first exports: time in ``nanoseconds since`` (cftime refuses it),
``GU`` as a unit (not UDUNITS; pint reads giga-enzyme-units), ``_FillValue`` on coordinates,
no ``long_name``s or ``history``; the haze index's long name said G60 - G85 for G60 - G20.

The truths: the CF compliance checker (``cfchecks``, NCAS/CEDA) when it is installed; the
rules themselves read from the raw HDF5 attributes (h5py) and checked with cftime and
UDUNITS-2 (cfunits) otherwise; the ASTM D4039 definition haze index = G60 - G20.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import goniolab.api as gl
from goniolab.cli import main
from goniolab.datasets import TIME_UNITS, run_dataset, write_netcdf
from goniolab.errors import UserError
from goniolab.store import RunStore
from tests._runs import T0, make_store

h5py = pytest.importorskip("h5py")


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cf")
    store = make_store(d / "s.sqlite")
    out = {}
    for rid in (1, 2):
        out[f"run{rid}"] = d / f"run{rid}.nc"
        assert (
            main(["runs", "export", str(rid), "--store", str(store), "-o", str(out[f"run{rid}"])])
            == 0
        )
    out["gloss"] = write_netcdf(gl.predict_gloss("sample:flat"), d / "gloss.nc")
    out["brdf"] = write_netcdf(gl.predict_brdf("sample:flat", theta_r_deg="40:50:5"), d / "brdf.nc")
    out["map"] = write_netcdf(gl.load_surface("sample:flat").to_dataset(), d / "map.nc")
    # a multi-angle run with spectra and predicted reflectance factors, its run export and
    # its spectra export (a text variable: measured / predicted)
    from tests.colour._spectral_runs import make_spectral_store

    spectral = make_spectral_store(d / "spectral.sqlite")
    out["spectral_run"] = d / "spectral_run.nc"
    assert (
        main(["runs", "export", "1", "--store", str(spectral), "-o", str(out["spectral_run"])]) == 0
    )
    out["spectra"] = d / "spectra.nc"
    assert main(["runs", "spectra", "1", "--store", str(spectral), "-o", str(out["spectra"]),
                 "--which", "both"]) == 0  # fmt: skip
    out["store"] = store
    return out


NAMES = ["run1", "run2", "gloss", "brdf", "map", "spectral_run", "spectra"]

# The checker needs the CF standard-name, area-type and region tables (it downloads them
# otherwise). goniolab uses one standard name, "time" (canonical units s, as in the CF
# table); the other two tables are not consulted by goniolab's files.
_TABLES = {
    "sn.xml": '<?xml version="1.0"?><standard_name_table><version_number>84</version_number>'
    '<last_modified>2024-01-19T15:55:10Z</last_modified><entry id="time"><canonical_units>s'
    "</canonical_units><description>Time.</description></entry></standard_name_table>",
    "at.xml": '<?xml version="1.0"?><area_type_table><version_number>12</version_number>'
    '<date>2024</date><entry id="land"><description>land</description></entry></area_type_table>',
    "rn.xml": '<?xml version="1.0"?><standard_region_table><version_number>4</version_number>'
    '<date>2024</date><entry id="global"><description>g</description></entry>'
    "</standard_region_table>",
}


def _cfchecks() -> str | None:
    exe = Path(sys.executable).with_name("cfchecks")
    if exe.exists():
        try:
            import cfchecker.cfchecks  # noqa: F401 - needs the UDUNITS-2 C library
        except Exception:  # FileNotFoundError without libudunits2
            return None
        return str(exe)
    return shutil.which("cfchecks")


@pytest.mark.parametrize("name", NAMES)
def test_the_cf_checker_finds_no_error_and_no_warning(
    files: dict[str, Path], name: str, tmp_path: Path
) -> None:
    exe = _cfchecks()
    if exe is None:
        pytest.skip("cfchecker (pip install cfchecker, needs libudunits2) is not installed")
    for fname, text in _TABLES.items():
        (tmp_path / fname).write_text(text)
    t = tmp_path
    proc = subprocess.run(
        [exe, "-v", "1.8", "-s", str(t / "sn.xml"), "-a", str(t / "at.xml"), "-r",
         str(t / "rn.xml"), str(files[name])],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert "ERRORS detected: 0" in proc.stdout, proc.stdout
    assert "WARNINGS given: 0" in proc.stdout, proc.stdout


def _raw(path: Path) -> tuple[dict[str, object], dict[str, dict[str, object]], set[str]]:
    """Global attributes, every variable's attributes and the coordinate (dimension) names."""

    def text(v: object) -> object:
        return v.decode() if isinstance(v, bytes) else v

    with h5py.File(path, "r") as f:
        glob = {k: text(v) for k, v in f.attrs.items()}
        variables, dims = {}, set()
        for name, obj in f.items():
            attrs = {k: text(v) for k, v in obj.attrs.items()}
            if attrs.get("CLASS") == "DIMENSION_SCALE":
                dims.add(name)
            if attrs.get("NAME", "").startswith("This is a netCDF dimension but not"):
                continue  # a bare dimension without a coordinate variable
            variables[name] = attrs
        return glob, variables, dims


@pytest.mark.parametrize("name", NAMES)
def test_the_cf_rules_hold_in_the_raw_file(files: dict[str, Path], name: str) -> None:
    cfunits = pytest.importorskip("cfunits")
    glob, variables, dims = _raw(files[name])
    assert glob["Conventions"] == "CF-1.8"
    assert "goniolab" in str(glob["history"])
    coordinate_names = set(dims)
    for var in variables.values():
        coordinate_names.update(str(var.get("coordinates", "")).split())
    for vname, attrs in variables.items():
        assert attrs.get("long_name"), f"{name}:{vname} has no long_name"
        if vname in coordinate_names:
            assert "_FillValue" not in attrs, f"{name}:{vname}: a coordinate with _FillValue"
        if "units" in attrs:
            units = str(attrs["units"])
            assert cfunits.Units(units).isvalid, f"{name}:{vname}: {units!r} is not UDUNITS"
            assert units != "GU"
        if vname.endswith("_gu") or vname.startswith("e430_") or vname == "haze_index":
            assert attrs["units"] == "1" and "gloss units" in str(attrs["long_name"])
            assert "GU" in str(attrs["units_metadata"])


def test_time_is_in_seconds_since_the_epoch_and_cftime_reads_it(files: dict[str, Path]) -> None:
    cftime = pytest.importorskip("cftime")
    with h5py.File(files["run1"], "r") as f:
        t = f["time"]
        assert str(t.attrs["units"]) == TIME_UNITS and str(t.attrs["calendar"]) == "standard"
        assert str(t.attrs["standard_name"]) == "time"
        first = float(t[0, 0])
    assert first == pytest.approx(T0, abs=1e-6)  # 2026-01-01T00:00:00.125 UTC
    when = cftime.num2date(first, TIME_UNITS, "standard")
    assert (when.year, when.month, when.day, when.microsecond) == (2026, 1, 1, 125000)


def test_haze_index_is_g60_minus_g20_and_says_so(files: dict[str, Path]) -> None:
    ds = gl.open_dataset(files["gloss"])
    g = ds["gloss_gu"]
    assert ds["haze_index"].item() == pytest.approx(
        float(g.sel(geometry_deg=60) - g.sel(geometry_deg=20)), abs=1e-12
    )
    assert "G60 - G20" in ds["haze_index"].attrs["long_name"]


@pytest.mark.parametrize("rid", [1, 2])
def test_an_export_reads_back_equal_to_the_run(files: dict[str, Path], rid: int) -> None:
    back = gl.open_dataset(files[f"run{rid}"])
    with RunStore(files["store"], readonly=True) as s:
        ds = run_dataset(s, rid)
    assert set(back.data_vars) == set(ds.data_vars)
    for name in ds.variables:
        a, b = ds[name].values, back[name].values
        if np.issubdtype(a.dtype, np.datetime64):
            # microsecond-exact through float64 seconds
            diff = (b - a)[~np.isnat(a)].astype("timedelta64[ns]").astype(np.int64)
            assert np.all(np.abs(diff) <= 1000), name
            assert np.array_equal(np.isnat(a), np.isnat(b)), name
        else:
            np.testing.assert_array_equal(b, a, err_msg=str(name))
        assert back[name].attrs.get("units") == ds[name].attrs.get("units"), name
    for key in ("run_id", "kind", "status", "plan_json", "config_json"):
        assert back.attrs[key] == ds.attrs[key]


def test_open_dataset_of_a_non_netcdf_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "x.nc"
    bad.write_text("not netcdf")
    with pytest.raises(UserError, match=r"x\.nc: not a netCDF file"):
        gl.open_dataset(bad)
