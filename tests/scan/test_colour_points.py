"""Every reading's colour stored beside its spectrum; bad spectra keep the reading."""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from drivers.base import SpectroReading
from goniolab.colour.spectra import ColourSettings
from goniolab.export import export_rows
from goniolab.scan.colour import PointColour
from goniolab.scan.events import InstrumentError, PointMeasured
from goniolab.scan.plans import BrdfPlan
from goniolab.store import RunStore

from .conftest import FakeLab
from .test_runner import drive, make_runner


def _l_star(y: float) -> float:
    # CIE 15:2004 eq. 8.1, with its linear segment below Y/Yn = (24/116)^3
    return 116.0 * y ** (1.0 / 3.0) - 16.0 if y > (24 / 116) ** 3 else 24389 / 27 * y


async def test_each_point_stores_its_colour(fake_lab: FakeLab, store: RunStore) -> None:
    plan = BrdfPlan(45.0, (30.0, 44.0))
    pc = PointColour(ColourSettings(), "mirror", 6.0)
    runner, bus = make_runner(fake_lab, store, plan, point_colour=pc)
    events = await drive(runner, bus, lambda ev: None)
    pts = store.points(runner.run_id)
    assert len(pts) == 2 and all(p.colour is not None for p in pts)
    for p in pts:
        assert p.colour is not None
        # a flat spectrum of reflectance r = lum/100 is neutral with L* from eq. 8.1
        r = p.luminance_pct / 100.0
        assert p.colour["Y"] == pytest.approx(100.0 * r, rel=1e-6)
        assert p.colour["L"] == pytest.approx(_l_star(r), abs=1e-6)
        assert abs(p.colour["a"]) < 0.01 and abs(p.colour["b"]) < 0.01
    measured = [e for e in events if isinstance(e, PointMeasured)]
    assert all(e.lab is not None for e in measured)
    rows = export_rows(store, runner.run_id)
    assert pts[1].colour is not None and pts[1].colour["L"] > 20
    assert rows[1]["L_star"] == pytest.approx(pts[1].colour["L"])


async def test_diffuser_scale_divides_by_the_detector_cone(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, (20.0,))
    runner, bus = make_runner(
        fake_lab, store, plan, point_colour=PointColour(detector_cone_deg=6.0)
    )
    await drive(runner, bus, lambda ev: None)
    (p,) = store.points(runner.run_id)
    factor = 1.0 / (math.sin(math.radians(3.0)) ** 2 * math.cos(math.radians(20.0)))
    assert p.colour is not None
    assert p.colour["Y"] == pytest.approx(p.luminance_pct * factor, rel=1e-6)


async def test_a_bad_spectrum_keeps_the_reading_and_says_why(
    fake_lab: FakeLab, store: RunStore
) -> None:
    real = fake_lab.spectro.measure

    async def nan_spectrum() -> SpectroReading:
        r = await real()
        values = list(r.values)
        values[3] = float("nan")
        return SpectroReading(r.wavelengths_nm, tuple(values), r.luminance_pct, r.exposure_us)

    fake_lab.spectro.measure = nan_spectrum  # type: ignore[method-assign]
    plan = BrdfPlan(45.0, (20.0, 30.0))
    runner, bus = make_runner(fake_lab, store, plan)
    events = await drive(runner, bus, lambda ev: None)
    pts = store.points(runner.run_id)
    assert len(pts) == 2 and all(p.colour is None for p in pts)
    assert "value at 410 nm is nan" in pts[0].colour_error
    errs = [e for e in events if isinstance(e, InstrumentError)]
    assert errs and not errs[0].fatal and "410 nm" in errs[0].message
    assert store.get_run(runner.run_id).status == "done"


def test_an_old_store_gains_the_colour_columns_and_keeps_its_rows(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan={}, config={}, sample="x", model={}, version="0")
        s.add_point(rid, index=0, repeat=0, theta_i_deg=45, theta_r_deg=40,
                    measured_theta_i_deg=45, measured_theta_r_deg=40, luminance_pct=3.0,
                    raw={}, timestamp=1.0)  # fmt: skip
    db = sqlite3.connect(path)
    for col in ("colour_X", "colour_Y", "colour_Z", "colour_L", "colour_a", "colour_b",
                "colour_C", "colour_h_deg", "colour_error"):  # fmt: skip
        db.execute(f"ALTER TABLE points DROP COLUMN {col}")
    db.commit()
    db.close()
    with RunStore(path, readonly=True) as ro:  # read-only: no migration, still readable
        (p,) = ro.points(rid)
        assert p.colour is None and p.luminance_pct == 3.0
    with RunStore(path) as s:
        (p,) = s.points(rid)
        assert p.luminance_pct == 3.0 and p.colour is None
        s.add_point(rid, index=1, repeat=0, theta_i_deg=45, theta_r_deg=50,
                    measured_theta_i_deg=45, measured_theta_r_deg=50, luminance_pct=2.0,
                    raw={}, timestamp=2.0, colour=dict.fromkeys("XYZLabC", 1.0) | {"h_deg": 9.0})  # fmt: skip
        assert s.points(rid)[1].colour == dict.fromkeys("XYZLabC", 1.0) | {"h_deg": 9.0}


def _spoil(r: SpectroReading, how: str) -> SpectroReading:
    wl, v = list(r.wavelengths_nm), list(r.values)
    if how == "length":
        v = v[:-1]
    elif how == "negative":
        v[5] = -0.25
    elif how == "nan":
        v[3] = float("nan")
    elif how == "short":
        wl, v = wl[5:-4], v[5:-4]
    return SpectroReading(tuple(wl), tuple(v), r.luminance_pct, r.exposure_us)


@pytest.mark.parametrize(
    ("how", "needle"),
    [
        ("length", "40 values for 41 wavelengths"),
        ("negative", "value at 430 nm is negative (-0.25, below the noise floor -0.05)"),
        ("nan", "value at 410 nm is nan"),
        ("short", "wavelengths 430-740 nm do not cover 400-700 nm"),
    ],
)
async def test_a_bad_spectrum_is_named_and_nothing_is_lost(
    fake_lab: FakeLab, store: RunStore, how: str, needle: str
) -> None:
    real = fake_lab.spectro.measure
    calls = 0

    async def measure() -> SpectroReading:  # the second geometry's readings are spoilt
        nonlocal calls
        calls += 1
        r = await real()
        return _spoil(r, how) if calls == 2 else r

    fake_lab.spectro.measure = measure  # type: ignore[method-assign]
    runner, bus = make_runner(fake_lab, store, BrdfPlan(45.0, (20.0, 30.0, 40.0)))
    events = await drive(runner, bus, lambda ev: None)
    pts = store.points(runner.run_id)
    assert [p.theta_r_deg for p in pts] == [20.0, 30.0, 40.0]  # every reading stored
    good, bad, after = pts
    assert good.colour is not None and after.colour is not None and bad.colour is None
    assert bad.colour_error.startswith("spectrum: ") and needle in bad.colour_error
    assert bad.luminance_pct > 0 and bad.raw  # the reading and its spectrum are kept
    errs = [e for e in events if isinstance(e, InstrumentError)]
    assert len(errs) == 1 and not errs[0].fatal and needle in errs[0].message
    assert store.get_run(runner.run_id).status == "done"


async def test_noise_around_zero_is_not_a_negative_spectrum(
    fake_lab: FakeLab, store: RunStore
) -> None:
    # a dark sample's dark-subtracted spectrum dips a little below 0 in the blue: that is
    # noise (read as 0), not a broken spectrum
    real = fake_lab.spectro.measure

    async def noisy() -> SpectroReading:
        r = await real()
        v = list(r.values)
        v[0], v[1], v[2] = -0.02, -0.049, 0.01
        return SpectroReading(r.wavelengths_nm, tuple(v), r.luminance_pct, r.exposure_us)

    fake_lab.spectro.measure = noisy  # type: ignore[method-assign]
    pc = PointColour(ColourSettings(), "mirror", 6.0)
    runner, bus = make_runner(fake_lab, store, BrdfPlan(45.0, (30.0,)), point_colour=pc)
    events = await drive(runner, bus, lambda ev: None)
    (p,) = store.points(runner.run_id)
    assert p.colour is not None and p.colour_error == ""
    assert not [e for e in events if isinstance(e, InstrumentError)]
    v = np.array(p.raw["values"])
    clipped = pc.measured(p.raw["wavelengths_nm"], np.maximum(v, 0.0), 30.0)
    assert p.colour["L"] == pytest.approx(clipped.L) and p.colour["b"] == pytest.approx(clipped.b)
