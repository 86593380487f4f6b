"""Start-up cost: building the CLI parser (``goniolab --help``) and ``goniolab samples``
must not import what they do not use (issue 13). Each check runs in a fresh interpreter and
looks at ``sys.modules``; no timing is asserted (bench/bench_startup.py measures it)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Loaded only by the commands that use them. numpy, pydantic, asyncio and sqlite3 are not
#: "heavy" libraries, but each costs tens to hundreds of milliseconds at start-up.
HEAVY = (
    "numba",
    "scipy",
    "colour",
    "colour_cxf",
    "xsdata",
    "textual",
    "textual_plot",
    "xarray",
    "matplotlib",
    "dask",
    "distributed",
    "rich",
    "numpy",
    "pydantic",
    "asyncio",
    "sqlite3",
)


def loaded(code: str) -> set[str]:
    probe = code + "\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))\n"
    out = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def heavy_in(modules: set[str]) -> list[str]:
    return sorted(m for m in modules if m.split(".")[0] in HEAVY)


def test_building_the_parser_imports_nothing_heavy() -> None:
    mods = loaded(
        "from goniolab.cli import build_parser\n"
        "p = build_parser()\n"
        # every sub-command registered its parser (the probe really built them)
        "assert {'predict', 'scan', 'samples', 'tui', 'runs'} <= set(p._subparsers._group_actions[0].choices)\n"
    )
    assert "goniolab.commands.predict" in mods and "goniolab.commands.scan" in mods
    assert heavy_in(mods) == []


def test_help_and_version_import_nothing_heavy() -> None:
    mods = loaded(
        "import contextlib, io\n"
        "from goniolab.cli import main\n"
        "for argv in (['--help'], ['predict', 'brdf', '--help'], ['--version']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()):\n"
        "        try:\n"
        "            main(argv)\n"
        "        except SystemExit:\n"
        "            pass\n"
    )
    assert heavy_in(mods) == []


@pytest.mark.parametrize("thread_env", [None, "OMP_NUM_THREADS", "GONIOLAB_THREADS"])
def test_samples_lists_the_library_without_numpy(
    thread_env: str | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a batch job's OMP_NUM_THREADS (or GONIOLAB_THREADS) made the thread check import
    # goniolab.optics, and numpy with it, for commands that never compute
    for name in ("OMP_NUM_THREADS", "GONIOLAB_THREADS"):
        monkeypatch.delenv(name, raising=False)
    if thread_env is not None:
        monkeypatch.setenv(thread_env, "4")
    mods = loaded(
        "import contextlib, io\n"
        "from goniolab.cli import main\n"
        "buf = io.StringIO()\n"
        "with contextlib.redirect_stdout(buf):\n"
        "    assert main(['samples', '--json']) == 0\n"
        "assert 'wittmann-3' in buf.getvalue()\n"
    )
    assert heavy_in(mods) == []


def test_optics_package_loads_its_names_on_first_use() -> None:
    mods = loaded("from goniolab.optics.apertures import Cone\nimport goniolab.optics")
    assert "numpy" in mods  # apertures is numpy code
    assert [m for m in heavy_in(mods) if m.split(".")[0] != "numpy"] == []
    # every public name still resolves, from the module the lazy table names
    code = (
        "import goniolab.optics as o, goniolab.surfaces as s\n"
        "for pkg in (o, s):\n"
        "    assert set(pkg._LAZY) | set(vars(pkg)) >= set(pkg.__all__), pkg.__name__\n"
        "    for name in pkg.__all__:\n"
        "        mod = pkg._LAZY.get(name, pkg.__name__ + '.' + name)  # eager: fresnel\n"
        "        assert getattr(pkg, name) is getattr(__import__(mod, fromlist=['x']), name), name\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True, timeout=120)


def test_facet_predictions_run_without_numba_or_scipy(tmp_path: Path) -> None:
    """``predict brdf|gloss --model facet`` (one command, one process) use the facet model's
    numba-free "lean" backend: numba's import and set-up cost ~1 s, more than the work."""
    import numpy as np

    z = np.random.default_rng(1).normal(0.0, 0.02, (128, 128))
    np.save(tmp_path / "m.npy", z)
    (tmp_path / "m.npy.json").write_text('{"step_um": 1.0}')
    mp = str(tmp_path / "m.npy")
    mods = loaded(
        "import contextlib, io, json\n"
        "from goniolab.cli import main\n"
        "for cmd in (['brdf', '--theta-i', '45', '--theta-r', '0:70:1'], ['gloss']):\n"
        "    buf = io.StringIO()\n"
        "    with contextlib.redirect_stdout(buf):\n"
        f"        assert main(['predict', cmd[0], {mp!r}, *cmd[1:], '--model', 'facet', '--json']) == 0\n"
        "    out = json.loads(buf.getvalue())\n"
        "    assert out['model'] in ('facet', {'G20': 'facet', 'G60': 'facet', 'G85': 'facet'}), out\n"
    )
    assert "goniolab.optics.facet" in mods  # the probe really predicted
    assert [m for m in heavy_in(mods) if m.split(".")[0] in ("numba", "scipy")] == []


@pytest.mark.parametrize(
    ("argv", "command"),
    [
        (["predict", "brdf", "m.npy"], "predict"),
        (["--debug", "scan", "--config", "x.toml"], "scan"),
        (["--log-level", "DEBUG", "samples"], "samples"),
        (["--log-level=DEBUG", "samples"], "samples"),
        (["--help"], None),
        (["--", "predict"], None),
        ([], None),
    ],
)
def test_the_command_is_found_past_the_top_level_options(
    argv: list[str], command: str | None
) -> None:
    from goniolab.cli import _command_in

    assert _command_in(argv) == command


def test_a_command_run_registers_only_its_own_parser_and_a_typo_lists_them_all(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from goniolab.cli import build_parser, main

    def choices(p: Any) -> set[str]:
        return set(p._subparsers._group_actions[0].choices)

    assert choices(build_parser("predict")) == {"predict"}
    assert {"predict", "scan", "samples", "tui", "runs"} <= choices(build_parser("nosuch"))
    assert main(["predict", "stats", "sample:wittmann-3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["map"] == "sample:wittmann-3"
    assert main(["predcit", "stats"]) == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'predcit'" in err and "'predict'" in err and "'scan'" in err


def test_the_cli_caps_blas_at_one_thread_unless_the_user_chose() -> None:
    """OpenBLAS's spinning workers doubled a predict's CPU time for no speed-up: the CLI sets
    OPENBLAS_NUM_THREADS=1 before numpy loads, and leaves a user's own setting alone."""
    probe = (
        "import os, sys\n"
        "from goniolab.cli import _one_blas_thread\n"
        "_one_blas_thread()\n"
        "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['MKL_NUM_THREADS'])\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    run = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    assert run.stdout.split() == ["1", "1"]
    env["OPENBLAS_NUM_THREADS"] = "2"
    run = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    assert run.stdout.split() == ["2", "1"]
