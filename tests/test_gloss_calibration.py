"""Glossmeter calibration: ``goniolab gloss calibrate`` and the calibration a gloss run cites.

Independent truths: the ZGM 1120 command strings of docs/PROTOCOLS.md (``72| <serial>|<tid>|
<AngleBinary>|<Cal2Standard>|<Cal2StandValue>:``, AngleBinary bit 0/1/2 = 20/60/85 deg, so 1,
2, 4), the manual's 10 % limit on the deviation (p. 22), ISO 2813's 100 GU for black glass of
n = 1.567 and the Fresnel equations (Born & Wolf sec. 1.5.2) for another index, the twin's
drift formula (:class:`sim.twin_gloss.GlossDrift`), and stored timestamps (no sleeping).
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import re
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.timing import SimClock
from goniolab.app.lab_gloss import (
    MeterPort,
    gloss_calibrate,
    gloss_calibration_cite,
    gloss_standard_gu,
)
from goniolab.cli import main
from goniolab.config import load_lab_config
from goniolab.errors import UserError
from goniolab.store import RunStore
from sim.twin_gloss import GlossDrift, SimGlossmeter
from tests.drivers.conftest import PtyPair
from tests.scan.test_integration import NOISELESS, lab_config

SERIAL = "401120999"


@pytest.fixture
def pty() -> Iterator[PtyPair]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    try:
        yield PtyPair(master, os.ttyname(slave))
    finally:
        os.close(master)
        os.close(slave)


async def fake_meter(pty: PtyPair, replies: list[bytes]) -> list[bytes]:
    """Answer each ':'-terminated command with the next reply; the commands received."""
    commands = []
    for reply in replies:
        commands.append(await pty.read_until(b":"))
        os.write(pty.fd, reply + b"\r\n")
    return commands


async def test_calibrate_sends_one_calibrate_per_geometry_and_stores_the_record(
    pty: PtyPair, tmp_path: Path
) -> None:
    replies = [b"28| 401120999|aa|1", b"72| 401120999|ab|5361",
               b"72| 401120999|ac|-120", b"72| 401120999|ad|88"]  # fmt: skip
    with RunStore(tmp_path / "s.sqlite") as store:
        fake = asyncio.create_task(fake_meter(pty, replies))
        run_id, record = await gloss_calibrate(store, port=MeterPort(pty.path))
        assert await fake == [
            b"28| 401120999|aa:",  # GetIsOnStandard first (working standard)
            b"72| 401120999|ab|1|0|0:",  # 20 deg: bit 0, the working standard
            b"72| 401120999|ac|2|0|0:",  # 60 deg: bit 1
            b"72| 401120999|ad|4|0|0:",  # 85 deg: bit 2
        ]
        assert {a: r["deviation_ppm"] for a, r in record["angles"].items()} == {
            "20": 5361, "60": -120, "85": 88,
        }  # fmt: skip
        assert record["angles"]["20"]["deviation_pct"] == 0.5361  # 5361 ppm (manual p. 22)
        assert record["instrument"]["identity"] == f"serial {SERIAL}"
        assert record["on_standard"] is True and record["ok"] is True
        rec = store.get_run(run_id)
    # the stored record round trip, in a store opened again
    with RunStore(tmp_path / "s.sqlite", readonly=True) as again:
        stored = again.get_run(run_id)
        assert (stored.kind, stored.status) == ("glosscal", "done")
        assert stored.model["gloss_calibration"] == json.loads(json.dumps(record))
        assert stored.model == rec.model
        cite = gloss_calibration_cite(
            again, f"serial {SERIAL}", at=record["time"] + 3600.0, angles_deg=(20, 60, 85)
        )
    assert cite["run"] == run_id and cite["age_h"] == pytest.approx(1.0)
    assert cite["deviation_ppm"] == {"20": 5361, "60": -120, "85": 88}
    assert cite["warnings"] == []


async def test_a_deviation_above_ten_percent_is_refused_and_not_cited(
    pty: PtyPair, tmp_path: Path
) -> None:
    replies = [b"28| 401120999|aa|1", b"72| 401120999|ab|5361",
               b"72| 401120999|ac|100001"]  # 10.0001 % at 60 deg  # fmt: skip
    with RunStore(tmp_path / "s.sqlite") as store:
        fake = asyncio.create_task(fake_meter(pty, replies))
        with pytest.raises(UserError, match="clean the standard and repeat") as info:
            await gloss_calibrate(store, port=MeterPort(pty.path))
        assert info.value.exit_code == 1
        # 85 deg is not calibrated after the refused 60 deg
        assert (await fake)[1:] == [b"72| 401120999|ab|1|0|0:", b"72| 401120999|ac|2|0|0:"]
        (rec,) = store.list_runs()
        assert rec.status == "failed" and "more than 10 %" in rec.reason
        assert rec.model["gloss_calibration"]["angles"]["60"]["ok"] is False
        cite = gloss_calibration_cite(
            store, f"serial {SERIAL}", at=rec.created_at + 1.0, angles_deg=(60,)
        )
    assert cite["run"] is None
    assert cite["warnings"][0].startswith(f"none recorded in this store for serial {SERIAL}")


async def test_a_meter_off_its_standard_is_not_calibrated(pty: PtyPair, tmp_path: Path) -> None:
    with RunStore(tmp_path / "s.sqlite") as store:
        fake = asyncio.create_task(fake_meter(pty, [b"28| 401120999|aa|0"]))
        with pytest.raises(UserError, match="not on its working standard"):
            await gloss_calibrate(store, port=MeterPort(pty.path, timeout_s=0.2))
        assert await fake == [b"28| 401120999|aa:"]  # no Calibrate sent
        assert store.list_runs()[0].status == "failed"


async def test_a_meter_without_remote_calibration_is_refused(pty: PtyPair, tmp_path: Path) -> None:
    with RunStore(tmp_path / "s.sqlite") as store:
        with pytest.raises(UserError, match="has no remote calibration command"):
            await gloss_calibrate(store, port=MeterPort(pty.path, protocol="line"))
        assert store.list_runs() == []  # nothing stored: nothing was calibrated


def test_a_standard_of_standards_toml_is_worth_its_fresnel_gloss(tmp_path: Path) -> None:
    cfg = load_lab_config(lab_config(tmp_path, sim=NOISELESS))
    # ISO 2813:2014: black glass n = 1.567 is 100 GU at every geometry
    assert gloss_standard_gu("black_glass", (20, 60, 85), config=cfg)["gu"] == {
        "20": 100.0, "60": 100.0, "85": 100.0,
    }  # fmt: skip

    def r(n: float, theta_deg: float) -> float:  # Born & Wolf sec. 1.5.2, unpolarised
        ci = math.cos(math.radians(theta_deg))
        ct = math.sqrt(1.0 - (math.sin(math.radians(theta_deg)) / n) ** 2)
        rs = ((ci - n * ct) / (ci + n * ct)) ** 2
        rp = ((n * ci - ct) / (n * ci + ct)) ** 2
        return (rs + rp) / 2.0

    # a black glass certified at another index (a worn or other glass)
    from goniolab.scan.standards import standards_path

    text = standards_path(cfg.source).read_text()  # the lab's (the repo's) standards
    std = tmp_path / "standards.toml"  # beside the config: read first (standards_path)
    assert "n = 1.567" in text
    std.write_text(text.replace("n = 1.567", "n = 1.50"))
    got = gloss_standard_gu("black_glass", (60,), config=cfg)["gu"]["60"]
    assert got == pytest.approx(round(100.0 * r(1.50, 60.0) / r(1.567, 60.0), 1))
    assert 85.0 < got < 95.0
    with pytest.raises(UserError, match="fresnel"):
        gloss_standard_gu("white_tile", (60,), config=cfg)


async def test_the_twin_returns_to_the_certified_value_after_calibration() -> None:
    """A 100 GU standard under the drifting twin: 10 h later it reads high; calibrating
    60 deg brings G60 back to 100 GU within the noise, and leaves G20 drifted."""
    clock = SimClock(0.0)
    drift = GlossDrift(noise_gu=0.1)

    class Standard:
        def gloss(self, angles: tuple[int, ...]) -> dict[int, float]:
            return {a: 100.0 for a in angles}

    gm = SimGlossmeter(Standard(), clock, drift=drift)  # type: ignore[arg-type]
    await gm.connect()
    await clock.sleep(10 * 3600.0)
    t = clock.now() + gm.measure_time_s  # the calibration's time
    gain = drift.gain(t, 0.0)  # 5 % drift + the warm-up's temperature term
    assert gain > 1.05
    ppm = await gm.calibrate(60)
    assert ppm == round((gain - 1.0) * 1e6)  # Calibrate's reply: the deviation in ppm
    after = await gm.measure()
    assert after.values_gu[60] == pytest.approx(100.0, abs=5 * 0.1 + 0.05)
    assert after.values_gu[20] is not None and after.values_gu[20] > 104.0
    await gm.calibrate(20)
    assert (await gm.measure()).values_gu[20] == pytest.approx(100.0, abs=5 * 0.1 + 0.05)


async def test_the_wire_twin_calibrates_the_geometry_the_frame_names() -> None:
    """sim/wire/zgm.py: ``72| SN|xy|2|0|0`` (AngleBinary 2 = 60 deg) resets 60 deg only."""
    from sim.wire.zgm import ZgmProtocol

    clock = SimClock(0.0)
    drift = GlossDrift(noise_gu=0.0)

    class Standard:
        def gloss(self, angles: tuple[int, ...]) -> dict[int, float]:
            return {a: 100.0 for a in angles}

    gm = SimGlossmeter(Standard(), clock, drift=drift)  # type: ignore[arg-type]
    await gm.connect()
    wire = ZgmProtocol(gm, SERIAL)
    await clock.sleep(3600.0)
    ppm = round((drift.gain(3600.0, 0.0) - 1.0) * 1e6)
    assert await wire.handle(f"72| {SERIAL}|xy|2|0|0") == f"72| {SERIAL}|xy|{ppm}"
    # 85 deg was not calibrated: its deviation is the same hour's; 60 deg's is 0 now
    assert await wire.handle(f"72| {SERIAL}|xz|4|0|0") == f"72| {SERIAL}|xz|{ppm}"
    assert await wire.handle(f"72| {SERIAL}|ya|2|0|0") == f"72| {SERIAL}|ya|0"


def _gloss_log(cfg: Path, store: str, *extra: str) -> None:
    argv = ["gloss", "log", "--config", str(cfg), "--count", "1", "--time-scale", "0",
            "--store", store, "--angles", "60", "--json", *extra]  # fmt: skip
    assert main(argv) == 0


def test_gloss_log_and_runs_show_name_the_calibration_and_warn_when_old(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store = str(tmp_path / "s.sqlite")
    assert main(["gloss", "calibrate", "--config", str(cfg), "--time-scale", "0",
                 "--store", store, "--angles", "60", "--json"]) == 0  # fmt: skip
    cal = json.loads(capsys.readouterr().out)
    assert cal["run_id"] == 1 and list(cal["angles"]) == ["60"]
    identity = cal["instrument"]["identity"]
    from goniolab.datasets import run_dataset  # runs export (netCDF, Parquet) of the record

    with RunStore(store, readonly=True) as s:
        ds = run_dataset(s, 1)
    assert ds.attrs["kind"] == "glosscal" and ds.attrs["stored_readings"] == 0
    stored = json.loads(ds.attrs["model_json"])["gloss_calibration"]
    assert stored["angles"]["60"]["deviation_ppm"] == cal["angles"]["60"]["deviation_ppm"]

    _gloss_log(cfg, store)
    captured = capsys.readouterr()
    last = json.loads(captured.out.splitlines()[-1])
    assert last["calibration"]["run"] == 1 and last["calibration"]["warnings"] == []
    assert last["calibration"]["deviation_ppm"] == {"60": cal["angles"]["60"]["deviation_ppm"]}
    assert f"goniolab: glossmeter calibration: run 1 ({cal['time_iso']}, " in captured.err
    assert main(["runs", "show", "2", "--store", store]) == 0
    out = capsys.readouterr().out
    assert f"  glossmeter calibration: run 1 ({cal['time_iso']}, 0.0 h before the run) on " \
           "working standard, deviation G60 " in out  # fmt: skip
    assert "calibration warning" not in out
    assert main(["runs", "show", "2", "--store", store, "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)["run"]["model"]["glossmeter_calibration"]
    assert shown["run"] == 1 and shown["instrument"] == identity

    # the calibration's stored time, 30 h before now: the next run warns (no sleeping)
    with RunStore(store) as s:
        record = dict(s.get_run(1).model["gloss_calibration"])
        record["time"] -= 30 * 3600.0
        s.update_model(1, {"gloss_calibration": record})
    _gloss_log(cfg, store)
    err = capsys.readouterr().err
    assert re.search(
        r"goniolab: warning: glossmeter calibration: the calibration \(run 1\) is 30\.0 h old "
        r"at the run's start, older than 24 h \(the lab's rule\)", err
    ), err  # fmt: skip
    assert main(["runs", "show", "3", "--store", store]) == 0
    assert "  calibration warning: the calibration (run 1) is 30.0 h old" in capsys.readouterr().out
    # a longer rule: no warning
    _gloss_log(cfg, store, "--calibration-max-age-h", "48")
    assert "warning: glossmeter calibration" not in capsys.readouterr().err
    # the lab's rule in its config ([glossmeter] calibration_max_age_h); the option wins
    text = cfg.read_text()
    cfg48 = tmp_path / "lab48.toml"
    cfg48.write_text(
        text.replace("[glossmeter]\n", "[glossmeter]\ncalibration_max_age_h = 48\n", 1)
    )
    _gloss_log(cfg48, store)
    assert "warning: glossmeter calibration" not in capsys.readouterr().err
    _gloss_log(cfg48, store, "--calibration-max-age-h", "24")
    assert "older than 24 h (the lab's rule)" in capsys.readouterr().err
    cfg12 = tmp_path / "lab12.toml"
    cfg12.write_text(
        text.replace("[glossmeter]\n", "[glossmeter]\ncalibration_max_age_h = 12\n", 1)
    )
    _gloss_log(cfg12, store)
    assert "older than 12 h (the lab's rule)" in capsys.readouterr().err
    # inf is the lab's "never", in the config as on the command line
    cfg_inf = tmp_path / "lab_inf.toml"
    cfg_inf.write_text(
        text.replace("[glossmeter]\n", "[glossmeter]\ncalibration_max_age_h = inf\n", 1)
    )
    _gloss_log(cfg_inf, store)
    assert "warning: glossmeter calibration" not in capsys.readouterr().err
    _gloss_log(cfg, store, "--calibration-max-age-h", "inf")
    assert "warning: glossmeter calibration" not in capsys.readouterr().err
    # a rule that is no age (0, a string, a boolean): the file, the key and the reason
    for value in ("0", '"48"', "true"):
        bad = tmp_path / "bad.toml"
        bad.write_text(
            text.replace("[glossmeter]\n", f"[glossmeter]\ncalibration_max_age_h = {value}\n", 1)
        )
        assert main(["gloss", "log", "--config", str(bad), "--count", "1", "--store", store]) != 0
        err = capsys.readouterr().err
        assert str(bad) in err and "glossmeter.calibration_max_age_h" in err, (value, err)


def test_docs_calibration_states_the_codes_limits() -> None:
    """docs/CALIBRATION.md's 10 % and 24 h are the code's (docs that cannot go stale)."""
    from goniolab.app.lab_gloss import DEFAULT_MAX_AGE_H, MAX_DEVIATION_PCT
    from goniolab.commands.gloss import register

    doc = " ".join((Path(__file__).resolve().parents[1] / "docs" / "CALIBRATION.md")
                   .read_text(encoding="utf-8").split())  # fmt: skip
    m = re.search(r"a deviation above (?P<x>[0-9.]+) % \(the manual, p\. 22\)", doc)
    assert m and float(m["x"]) == MAX_DEVIATION_PCT
    m = re.search(r"`--calibration-max-age-h` \((?P<x>[0-9.]+) h: the lab's rule", doc)
    assert m and float(m["x"]) == DEFAULT_MAX_AGE_H
    import argparse

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["gloss", "log", "--port", "x"])
    assert args.calibration_max_age_h is None  # the config's rule, else DEFAULT_MAX_AGE_H
    from goniolab.config.sections import GlossmeterConfig

    assert GlossmeterConfig.model_fields["calibration_max_age_h"].default == DEFAULT_MAX_AGE_H
    m = re.search(r"`\[glossmeter\] calibration_max_age_h` \((?P<x>[0-9.]+) h\)", doc)
    assert m and float(m["x"]) == DEFAULT_MAX_AGE_H
