"""Shared test set-up: the log file of every in-process ``goniolab`` call goes to a
per-test directory, never to the user's log dir; hypothesis draws the same examples on
every run (``derandomize``), so ``make test`` passes or fails the same way each time. To
search further: ``HYPOTHESIS_PROFILE=explore .venv/bin/python -m pytest tests/...``."""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("goniolab", derandomize=True, database=None)
settings.register_profile("explore", max_examples=1000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "goniolab"))


_log_dirs = itertools.count()


@pytest.fixture(scope="session")
def _log_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("logs")


@pytest.fixture(autouse=True)
def _log_dir(_log_root: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A new, empty log directory per test. (``tmp_path_factory.mktemp`` per test scanned
    the growing base directory for the next free number each time: 4 s of the suite's CPU.)"""
    path = _log_root / f"log{next(_log_dirs)}"
    path.mkdir()
    monkeypatch.setenv("GONIOLAB_LOG_DIR", str(path))
    return path


@pytest.fixture(scope="session")
def pg_shared() -> Iterator[Any]:
    """A throw-away PostgreSQL server (tests/pg_server.py) for the whole test process, for
    the modules that only create databases of their own in it (test_store_pg,
    test_store_list, test_notebook): an initdb and a start cost ~0.9 s of CPU each.
    test_store_faults freezes and restarts servers: it starts its own."""
    from tests.pg_server import find_pg_bin, pg_server

    bindir, why = find_pg_bin()
    if bindir is None:
        pytest.skip(why)
    with pg_server(bindir) as srv:
        yield srv


def pytest_configure(config: pytest.Config) -> None:
    """Under xdist, the controller fills the shared numba and twin caches once before the
    workers start (tests/_warm.py); a worker or a plain run does not."""
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", default=None):
        return
    from tests._warm import warm_caches

    warm_caches()


#: End-to-end tests measured at 10 s or more (``--durations`` per directory, one directory at
#: a time, 2-core machine; bench/README.md has the command and the table), and the longest
#: in-process ones of a full run (bench/README.md, "The whole suite"); updated from a
#: serial run's per-test wall and CPU time (``-p tests._cpu_report``, bench/README.md,
#: "The suite's CPU"): the ones under 1 s of wall and CPU there were taken out. They are
#: marked ``slow`` here, beside the ones marked in their files, so that ``-m "not slow"``
#: leaves them out and :func:`pytest_collection_modifyitems` starts them first. A test
#: renamed or removed just drops out of this list's effect.
MEASURED_SLOW = frozenset(
    {
        "tests/tui/test_lab.py::test_scan_on_the_sim_lab_measured_equals_predicted",
        "tests/tui/test_lab.py::test_pause_resume_abort_on_the_sim_lab",
        "tests/tui/test_lab.py::test_the_sim_lab_measures_the_sample_picked_in_the_form",
        "tests/tui/test_lab.py::test_run_identity_dialog_is_stored_with_the_next_runs",
        "tests/tui/test_lab.py::test_quit_during_a_scan_aborts_it_and_exits",
        "tests/tui/test_lab.py::test_geometry_out_of_reach_is_a_form_error",
        "tests/tui/test_app.py::test_gloss_log_and_runs_browser",
        "tests/tui/test_app.py::test_sample_picker_changes_the_prediction_and_a_new_scan_clears_old_metrics",
        "tests/tui/test_app.py::test_gloss_every_fills_the_log_while_idle",
        "tests/tui/test_app.py::test_command_palette_offers_abort",
        "tests/tui/test_terminal.py::test_goniolab_tui_runs_in_tmux",
        "tests/scan/test_align.py::test_align_on_the_twin_recovers_offsets_and_tilt_within_005_deg",
        "tests/scan/test_integration.py::test_ctrl_c_aborts_parks_and_says_how_to_resume",
        "tests/scan/test_integration.py::test_gloss_log_from_a_port_without_config",
        "tests/scan/test_integration.py::test_kill_9_then_resume_stores_every_reading_exactly_once",
        "tests/sim/test_wire.py::test_goniolab_sim_serve_subprocess",
        "tests/contract/test_interlock_random.py::test_random_concurrent_moves_keep_the_arms_apart",
        "tests/test_cli_alarm.py::test_an_alarm_before_a_scan_is_cleared_from_the_cli",
        "tests/test_cli_stop_signals.py::test_a_signal_parks_the_arms_of_the_wire_lab",
        "tests/test_cli_stop_signals.py::test_a_signal_ends_a_gloss_log_as_aborted",
        "tests/test_cli_stop_signals.py::test_a_signal_aborts_the_scan_and_parks",
        "tests/test_batch.py::test_dask_workers_get_absolute_paths",
        "tests/test_api.py::test_interrupting_a_scan_in_a_running_loop_aborts_it",
        "tests/test_api.py::test_the_readme_example_runs",
        "tests/test_notebook.py::test_run_scan_in_a_kernel_with_postgresql",
        "tests/test_notebook.py::test_run_scan_in_a_kernel_with_sqlite",
        "tests/test_notebook.py::test_interrupting_the_kernel_aborts_the_scan",
        "tests/test_store_pg.py::test_two_scans_write_at_once",
        "tests/test_store_pg.py::test_kill_9_mid_scan_then_resume",
        # measured at 2.5 s or more of wall or CPU in a serial run with tests/_cpu_report.py
        # (issue 26, "suite" section of bench/README.md), and not marked in their files
        "tests/drivers/test_modbus_stepper.py::test_line_noise_on_rtu_replies_is_only_protocol_error",
        "tests/tui/test_terminal.py::test_the_tui_ends_when_its_terminal_goes_away_just_after_the_first_frame",
        "tests/optics/test_kirchhoff.py::test_grazing_readings_are_continuous_where_the_source_is_split_and_clipped",
        "tests/test_store_faults.py::test_frozen_postgres_write_is_bounded",
        "tests/app/test_lab_scan.py::test_calibrate_and_align_store_their_runs",
        # in-process computations measured at 6-30 s in a full `pytest -n 2` run (load 4):
        # left unmarked, one could be the last test left on a worker's queue
        "tests/optics/test_kirchhoff.py::test_a_flat_map_at_89_deg_reads_the_beam_above_the_horizon",
        "tests/optics/test_facet.py::test_masked_cones_up_to_89_deg_match_brute_force",
        "tests/sim/test_twin_flakes.py::test_outside_the_lobe_stays_below_coverage_times_flake_reflectance",
    }
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the measured slow tests and, under xdist, start the slow tests first on every
    worker.

    xdist's ``worksteal`` scheduler (``make test``) hands each of the N workers a contiguous
    N-th of the collection, then lets an idle worker take half of the longest queue's tail.
    A slow test left at a queue's end would keep its worker busy after the others ran out,
    so the slow tests are dealt round-robin to the fronts of the N shares; the other tests
    keep their order (a module's tests stay together). Every worker sorts the same
    collection the same way (xdist requires identical collections).
    """
    for item in items:
        if item.nodeid.split("[")[0] in MEASURED_SLOW and item.get_closest_marker("slow") is None:
            item.add_marker(pytest.mark.slow)
    workers = _workers(config)
    if workers < 2 or len(items) < 2 * workers:
        return
    slow = [it for it in items if it.get_closest_marker("slow") is not None]
    fast = [it for it in items if it.get_closest_marker("slow") is None]
    shares: list[list[pytest.Item]] = [[] for _ in range(workers)]
    for k, it in enumerate(slow):
        shares[k % workers].append(it)
    # the share sizes the scheduler cuts: pending // nodes_remaining, node by node
    left = len(items)
    sizes = []
    for i in range(workers):
        sizes.append(left // (workers - i))
        left -= sizes[-1]
    pos = 0
    for share, size in zip(shares, sizes, strict=True):
        take = max(0, size - len(share))
        share.extend(fast[pos : pos + take])
        pos += take
    shares[-1].extend(fast[pos:])
    items[:] = [it for share in shares for it in share]


def _workers(config: pytest.Config) -> int:
    """The number of xdist workers of this run (on the controller and on each worker)."""
    inp = getattr(config, "workerinput", None)
    if inp is not None:
        return int(inp.get("workercount", 1))
    n = config.getoption("numprocesses", default=None)
    return int(n) if isinstance(n, int) else 0
