"""``scan resume`` (issues 22.6, 23.9): the hint names the store, the run resumes with its
stored config (a changed file is refused, naming the keys, unless --use-current-config),
and a relative ``--sample`` is stored absolute."""

from __future__ import annotations

import re
import shlex
import sqlite3
from pathlib import Path

import pytest

from goniolab.app.lab_setup import resume_command
from goniolab.cli import main
from goniolab.store import RunStore, default_store_path
from tests.test_session import CLI_PLAN, sim_config


def _interrupt(store: Path, run_id: int, keep: int) -> None:
    """Leave run ``run_id`` as an aborted scan with its first ``keep`` geometries."""
    db = sqlite3.connect(store)
    db.execute("DELETE FROM points WHERE run_id = ? AND idx >= ?", (run_id, keep))
    db.execute("UPDATE runs SET status = 'aborted', finished_at = NULL WHERE id = ?", (run_id,))
    db.commit()
    db.close()


def test_resume_hint_names_the_store(tmp_path: Path) -> None:
    store = tmp_path / "my store.sqlite"
    with RunStore(store) as s:
        rid = s.create_run(kind="brdf", plan={}, config={}, sample="", model={}, version="t")
        hint = resume_command(rid, s)
    assert shlex.split(hint) == ["goniolab", "scan", "resume", str(rid), "--store", str(store)]
    default = default_store_path()
    if default.exists():  # the default store is named by nothing at all
        with RunStore(default, readonly=True) as d:
            assert resume_command(7, d) == "goniolab scan resume 7"


@pytest.mark.slow  # runs the sim lab (instant clock)
def test_resume_uses_the_stored_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    cfg = sim_config(tmp_path)
    store = tmp_path / "runs" / "s.sqlite"
    store.parent.mkdir()
    argv = ["scan", "--config", str(cfg), *CLI_PLAN, "--store", str(store), "--json"]
    assert main(argv) == 0
    capsys.readouterr()
    _interrupt(store, 1, keep=2)
    assert main(["runs", "show", "1", "--store", str(store)]) == 0
    hint = re.search(r"continue it with: (.*)", capsys.readouterr().out)
    assert hint is not None
    resume_argv = shlex.split(hint.group(1))[1:]
    assert resume_argv == ["scan", "resume", "1", "--store", str(store.resolve())]

    # the live file changed something that matters: refused, naming the key
    text = cfg.read_text()
    changed = re.sub(r"(?m)^n = .*$", "n = 1.9", text)
    assert changed != text
    cfg.write_text(changed)
    monkeypatch.chdir(tmp_path / "runs")  # from another directory: the hint is complete
    assert main(resume_argv) == 2
    err = capsys.readouterr().err
    assert "sample.n: 1.55 -> 1.9" in err and "--use-current-config" in err
    with RunStore(store) as s:
        assert s.count_points(1) == 4  # nothing measured

    # the file gone: the run's own snapshot resumes it
    cfg.unlink()
    assert main([*resume_argv, "--json", "--time-scale", "0"]) == 0
    capsys.readouterr()
    with RunStore(store) as s:
        assert s.get_run(1).status == "done" and s.count_points(1) == 10

    # --use-current-config goes on with the new file and says what changed
    cfg.write_text(changed)
    _interrupt(store, 1, keep=4)
    code = main(
        [*resume_argv, "--config", str(cfg), "--use-current-config", "--json", "--time-scale", "0"]
    )
    assert code == 0
    assert "resuming with the current config: sample.n: 1.55 -> 1.9" in capsys.readouterr().err


@pytest.mark.slow
def test_relative_sample_is_stored_absolute(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import numpy as np

    cfg = sim_config(tmp_path)
    (tmp_path / "maps").mkdir()
    x = np.linspace(0.0, 6.28, 64)
    np.save(tmp_path / "maps" / "w.npy", 0.05 * np.sin(x)[None, :] * np.cos(x)[:, None])
    (tmp_path / "maps" / "w.npy.json").write_text('{"step_um": 1.0}')
    monkeypatch.chdir(tmp_path / "maps")
    store = tmp_path / "s.sqlite"
    argv = ["scan", "--config", str(cfg), "--sample", "w.npy", "--theta-i", "30",
            "--theta-r", "20:30:10", "--repeats", "1", "--store", str(store), "--json",
            "--operator", "ada", "--sample-id", "P-3", "--tag", "t1", "--note", "n"]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    with RunStore(store) as s:
        rec = s.get_run(1)
    assert rec.sample == str(tmp_path / "maps" / "w.npy")
    assert rec.plan["sample"] == rec.sample
    assert (rec.operator, rec.sample_id, rec.tags, rec.notes) == ("ada", "P-3", ("t1",), "n")
