"""A link that drops and comes back, end to end on the wire: the simulated lab served on
Modbus TCP and ptys (configs/lab-sim-wire.toml), the real drivers, the CLI commands. The
dropped serial device takes its pty away and publishes a new one once it is back
(``[sim.faults] recover_after_s`` of lab clock later); the commands reconnect and lose
no reading."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from goniolab.store import RunStore
from tests.scan.test_integration import NOISELESS, lab_config, run_cli

pytestmark = pytest.mark.wire


def test_scan_reconnects_the_spectro_and_stores_every_reading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # seeded: with seed 5 the spectro drops during the scan (not while the lab connects);
    # which points it hits depends on how many requests a reading takes (the STIL fence)
    faults = {"devices": '["spectro"]', "disconnect_rate": "0.15", "recover_after_s": "0.5"}
    sim = {**NOISELESS, "seed": "5"}
    cfg = lab_config(tmp_path, base="lab-sim-wire.toml", sim=sim, faults=faults)
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-r", "40:50:1", "--time-scale", "0", "--json",
         "--store", str(store)],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    s = json.loads(out)
    assert s["state"] == "done" and s["readings"] == 11
    # the drop was reported and the port reopened while the scan went on (which point it
    # hits depends on the wire's timing since the STIL fence added an operation per reading)
    assert re.search(r"\(point \d+, repeat 0: retry 1 of 2, reconnecting\)", err), err
    with RunStore(store) as st:
        points = st.points(s["run_id"])
        assert [p.index for p in points] == list(range(11))
    # noiseless ideal twin: the readings after a reconnect are the model's, as before it
    assert s["rmse_pct"] < 1e-2 * s["predicted_peak"]["amplitude_pct"]


def test_gloss_log_reconnects_the_glossmeter_and_logs_every_reading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    faults = {"devices": '["glossmeter"]', "disconnect_rate": "0.2", "recover_after_s": "0.5"}
    sim = {**NOISELESS, "seed": "2"}  # seeded: three drops in six readings
    cfg = lab_config(tmp_path, base="lab-sim-wire.toml", sim=sim, faults=faults)
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["gloss", "log", "--config", str(cfg), "--count", "6", "--time-scale", "0", "--json",
         "--store", str(store)],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    *lines, stats = [json.loads(x) for x in out.splitlines()]
    assert [x["seq"] for x in lines] == list(range(6)) and stats["readings"] == 6
    assert err.count("warning: glossmeter: read from") == 3
    with RunStore(store) as st:
        rows = st.gloss_readings(lines[0]["run_id"])
        assert len(rows) == 6 and all(r.values_gu[60] is not None for r in rows)


@pytest.mark.parametrize("base", ["lab-sim.toml"])
def test_scan_waits_for_a_spectro_restart_of_20_s(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], base: str
) -> None:
    # issue 21: a controller restart takes 7-20 s and the retry window was ~1.5 s (the scan
    # failed and needed `scan resume`); the scan now waits up to 30 s of lab clock, says so,
    # and continues without losing or repeating a point (seeded: the spectro drops at point
    # 5 and is back 20 s later). In-process: the wire's fault injection is timing-dependent
    faults = {"devices": '["spectro"]', "disconnect_rate": "0.05", "recover_after_s": "20"}
    cfg = lab_config(tmp_path, base=base, sim={**NOISELESS, "seed": "3"}, faults=faults)
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-r", "40:50:1", "--time-scale", "0", "--json",
         "--store", str(store)],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    assert "reconnect after 20 s (point 5, repeat 0: retry 1 of 2, reconnecting)" in err
    assert "waiting up to 30 s" in err
    s = json.loads(out)
    with RunStore(store) as st:
        assert [p.index for p in st.points(s["run_id"])] == list(range(11))
    assert s["rmse_pct"] < 1e-2 * s["predicted_peak"]["amplitude_pct"]
