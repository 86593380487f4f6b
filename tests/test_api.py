"""The notebook face: xarray / pandas objects with units, and the README's example runs."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import goniolab.api as gl
from goniolab.errors import UserError
from tests._runs import lum, make_store

ROOT = Path(__file__).resolve().parents[1]


def test_load_surface_is_a_dataarray_with_units(tmp_path: Path) -> None:
    z = np.arange(12, dtype=np.float64).reshape(3, 4) * 0.01
    np.save(tmp_path / "m.npy", z)
    (tmp_path / "m.npy.json").write_text('{"dx_um": 2.0, "dy_um": 3.0}')
    da = gl.load_surface(tmp_path / "m.npy")
    assert da.dims == ("y_um", "x_um")
    np.testing.assert_array_equal(da.values, z)
    np.testing.assert_array_equal(da["x_um"].values, [0.0, 2.0, 4.0, 6.0])
    np.testing.assert_array_equal(da["y_um"].values, [0.0, 3.0, 6.0])
    assert da.attrs["units"] == "um" and da["x_um"].attrs["units"] == "um"


def test_predict_brdf_matches_the_cli_numbers(capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from goniolab.cli import main

    ds = gl.predict_brdf("sample:wittmann-3", theta_i_deg=45, theta_r_deg=[40.0, 45.0, 50.0])
    # the notebook face and the CLI share their defaults (auto, masking on)
    argv = ["predict", "brdf", "sample:wittmann-3", "--theta-r", "40,45,50", "--json"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(ds["luminance_pct"].values, doc["luminance_pct"], rtol=1e-12)
    np.testing.assert_allclose(ds["brdf_sr"].values, doc["brdf_sr"], rtol=1e-12)
    assert ds["luminance_pct"].dims == ("theta_r_deg",)
    assert ds["brdf_sr"].attrs["units"] == "sr-1"
    assert ds["theta_r_deg"].attrs["units"] == "degree"
    np.testing.assert_array_equal(
        ds["aspecular_deg"].values, [5.0, 0.0, -5.0]
    )  # E2194: theta_i - theta_r


def test_predict_gloss_of_a_flat_black_glass_is_100_gu() -> None:
    # ISO 2813: the polished black glass of n = 1.567 is 100 GU at every geometry
    ds = gl.predict_gloss("sample:flat", n=1.567)
    np.testing.assert_allclose(ds["gloss_gu"].values, [100.0, 100.0, 100.0], rtol=1e-3)
    assert list(ds["geometry_deg"].values) == [20, 60, 85]
    assert ds["gloss_gu"].attrs["units"] == "1"  # UDUNITS has no GU: the scale is said
    assert "gloss units" in ds["gloss_gu"].attrs["long_name"]


def test_open_runs_and_run_to_xarray(tmp_path: Path) -> None:
    store = make_store(tmp_path / "s.sqlite")
    df = gl.open_runs(store)
    assert list(df.index) == [2, 1]
    assert list(df["kind"]) == ["gloss", "brdf"] and list(df["readings"]) == [2, 5]
    assert str(df["created_at"].dtype).startswith("datetime64")
    run = gl.open_run(1, store)
    ds = run.to_xarray()
    assert ds["luminance_pct"].sel(theta_r_deg=45.0, repeat=1).item() == lum(1, 1)
    assert run.to_dataframe()["luminance_pct"].tolist()[:2] == [lum(0, 0), lum(0, 1)]
    with pytest.raises(UserError, match="no run 9"):
        gl.open_run(9, store)


def test_a_bad_angle_list_is_a_user_error() -> None:
    with pytest.raises(UserError, match="theta_r_deg"):
        gl.predict_brdf("sample:flat", theta_r_deg="10:0:1")


def test_the_readme_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## In a notebook") :]
    code = re.search(r"```python\n(.*?)```", section, re.S)
    assert code is not None
    (tmp_path / "configs").symlink_to(ROOT / "configs")
    monkeypatch.chdir(tmp_path)
    exec(compile(code.group(1), "README.md", "exec"), {"__name__": "readme"})
    assert (tmp_path / "run.png").read_bytes()[:4] == b"\x89PNG"
    ds = gl.open_run(1, tmp_path / "runs.sqlite").to_xarray()
    assert ds.attrs["status"] == "done" and ds.attrs["stored_readings"] == 12
    # the simulated lab is the realistic twin: it measures its own truth, so the residuals
    # are its model error against the prediction (docs/TWIN.md: wittmann-3's peak is about
    # 19 % lower than predicted), not noise around zero
    worst = float(np.nanmax(np.abs(ds["residual_pct"].values)))
    peak = float(np.nanmax(ds["predicted_pct"].values))
    assert 0.02 * peak < worst < 0.3 * peak


def _rough(n: int = 96) -> np.ndarray:
    rng = np.random.default_rng(7)
    z = np.cumsum(np.cumsum(rng.normal(size=(n, n)), axis=0), axis=1)
    return z / np.std(np.diff(z, axis=1)) * 0.05


def test_a_subsampled_map_takes_its_step_from_the_coordinates(tmp_path: Path) -> None:
    """Issue 22.10: after ``isel(x_um=slice(None, None, 2))`` xarray keeps ``dx_um = 1`` while
    the coordinates step by 2. The truth: the same heights as a HeightMap of dx 2 um."""
    from goniolab.optics.heightmap import HeightMap

    z = _rough()
    np.save(tmp_path / "m.npy", z)
    (tmp_path / "m.npy.json").write_text('{"dx_um": 1.0, "dy_um": 1.0}')
    da = gl.load_surface(tmp_path / "m.npy")
    half = da.isel(x_um=slice(None, None, 2))
    with pytest.raises(UserError, match=r"x_um: coordinates step by 2 um but attrs\['dx_um'\] = 1"):
        gl.predict_gloss(half, model="facet")
    truth = gl.predict_gloss(HeightMap(z[:, ::2], 2.0, 1.0), model="facet")["gloss_gu"].values
    del half.attrs["dx_um"]  # the coordinates alone decide
    np.testing.assert_allclose(gl.predict_gloss(half, model="facet")["gloss_gu"].values, truth)
    half.attrs["dx_um"] = 2.0  # or the attribute set right
    np.testing.assert_allclose(gl.predict_gloss(half, model="facet")["gloss_gu"].values, truth)
    # a transposed DataArray is the same map, not a map with x and y swapped
    np.testing.assert_allclose(
        gl.predict_gloss(half.T, model="facet")["gloss_gu"].values, truth, rtol=1e-12
    )
    # an uneven grid is refused
    uneven = da.isel(x_um=[0, 1, 3, 4, 5, 6])
    with pytest.raises(UserError, match="not evenly spaced"):
        gl.predict_gloss(uneven, model="facet")


def test_interrupting_a_scan_in_a_running_loop_aborts_it(tmp_path: Path) -> None:
    """A notebook's kernel interrupt arrives as KeyboardInterrupt in the thread waiting for
    the scan (which runs on its own loop in a worker thread): the scan is aborted like
    Ctrl-C in ``goniolab scan`` (arms stopped and parked, run stored ``aborted``), not left
    moving in the background."""
    import asyncio
    import os
    import signal
    import threading

    async def cell() -> gl.Run:  # what a notebook cell runs: inside a running loop
        return gl.run_scan(ROOT / "configs" / "lab-sim.toml", sample="sample:flat",
                           theta_r_deg="20:60:1", time_scale=4.0,
                           store=store, progress=False)  # fmt: skip

    store = tmp_path / "runs.sqlite"
    stop = threading.Event()

    def interrupt_after_two_readings() -> None:
        """The kernel's interrupt: SIGINT to the process (KeyboardInterrupt in the main
        thread), sent once the scan has stored readings, whatever the machine's speed."""
        from goniolab.store import RunStore, StoreError

        while not stop.wait(0.05):
            try:
                with RunStore(store, readonly=True) as s:
                    if any(s.count_points(r.id) >= 2 for r in s.list_runs()):
                        os.kill(os.getpid(), signal.SIGINT)
                        return
            except StoreError:  # not created yet
                continue

    watcher = threading.Thread(target=interrupt_after_two_readings, daemon=True)
    loop = asyncio.new_event_loop()  # no asyncio.Runner SIGINT handler: as in ipykernel
    watcher.start()
    try:
        run = loop.run_until_complete(cell())
    finally:
        stop.set()
        watcher.join()
        loop.close()
    rec = run.record
    assert rec.status == "aborted" and "aborted by the operator" in (rec.reason or "")
    assert 0 < run.to_xarray().attrs["stored_readings"] < 41


def test_run_scan_stores_the_run_identity(tmp_path: Path) -> None:
    # issue 22 item 4: operator, physical sample id, notes and tags from the notebook face
    store = tmp_path / "runs.sqlite"
    run = gl.run_scan(ROOT / "configs" / "lab-sim.toml", sample="sample:flat",
                      theta_r_deg="40:50:5", time_scale=0, store=store, progress=False,
                      operator="ada", sample_id="LIMS-9", notes="from a notebook",
                      tags=["nb", "q4", "nb"])  # fmt: skip
    record = run.record
    assert (record.operator, record.sample_id, record.notes, record.tags) == (
        "ada",
        "LIMS-9",
        "from a notebook",
        ("nb", "q4"),
    )
    assert len(record.uuid) == 36
