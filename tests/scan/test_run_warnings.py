"""A scan's warnings (its non-fatal instrument events: a stale or missed calibration, a
prediction note, a retried reading, a skipped approach) stay with the run: the same lines
on stderr as they happen, in ``goniolab scan --json`` (``warnings``) and in the stored run
(``run_warnings`` of its model), not on stderr only."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.scan.events import EventBus, InstrumentError, Progress, RecordingBus, WarningLog
from goniolab.store import RunStore
from tests.scan.test_calibrate import _config


def _warning(run_id: int, message: str, *, fatal: bool = False) -> InstrumentError:
    return InstrumentError(run_id=run_id, device="spectro", message=message, fatal=fatal)


def test_the_log_keeps_a_runs_warnings_in_order_repeats_counted() -> None:
    log = WarningLog(3)
    bus = EventBus()
    q = bus.subscribe()
    recording = RecordingBus(bus, log)
    for ev in (
        _warning(3, "reading retried"),
        _warning(3, "the link came back"),
        _warning(3, "reading retried"),
        _warning(3, "it broke", fatal=True),  # a fault ends the run with its reason
        _warning(4, "another run's"),
        Progress(run_id=3, done=1, total=2, eta_s=1.0),
    ):
        recording.publish(ev)
    assert log.lines() == ["spectro: reading retried (2 times)", "spectro: the link came back"]
    assert q.qsize() == 6  # every event still reaches the subscribers of the bus
    many = WarningLog(1)
    for i in range(WarningLog.MAX_LINES + 3):
        many.add(_warning(1, f"w{i}"))
    assert len(many.lines()) == WarningLog.MAX_LINES + 1
    assert many.lines()[-1] == "... and 3 more warnings (see the run's log)"


def test_a_scans_warnings_reach_stderr_json_and_the_stored_run(tmp_path: Path) -> None:
    # a certificate of n = 1.52 for the 1.567 glass: the calibration's check misses, and
    # every later scan warns about it (tests/scan/test_calibrate.py)
    text = (configs_dir() / "standards.toml").read_text().replace("n = 1.567", "n = 1.52")
    cfg = _config(tmp_path, standards=text)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["calibrate", "--config", str(cfg), "--time-scale", "0"]) == 0
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["scan", "--config", str(cfg), "--theta-r", "40,45", "--repeats", "1",
                     "--time-scale", "0", "--json"])  # fmt: skip
    assert code == 0, err.getvalue()
    doc = json.loads(out.getvalue())
    said = [
        line.removeprefix("goniolab: warning: ")
        for line in err.getvalue().splitlines()
        if line.startswith("goniolab: warning: ")
    ]
    missed = [w for w in said if "missed its certificate" in w]
    assert missed and missed[0].startswith(
        "calibration: the calibration's check standard (black_glass, certificate SIM-BG-0001)"
    )
    assert doc["warnings"] == said
    with RunStore(str(tmp_path / "runs.sqlite")) as store:
        assert store.get_run(int(doc["run_id"])).model["run_warnings"] == said


def test_a_prediction_notice_is_the_models_warning_not_the_calibrations() -> None:
    from goniolab.scan.runner import notice_event

    ev = notice_event(5, "prediction: 85 deg is computed by kirchhoff")
    assert (ev.device, ev.message, ev.fatal, ev.run_id) == (
        "model", "85 deg is computed by kirchhoff", False, 5,
    )  # fmt: skip
    old = "the calibration (run 2) is 25.0 h old, older than 24 h: run goniolab calibrate"
    ev = notice_event(5, old)
    assert (ev.device, ev.message) == ("calibration", old)
