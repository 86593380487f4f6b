"""The notebook face in a real Jupyter kernel (nbclient + ipykernel), issue 22.2.

A kernel runs an asyncio loop in its main thread, so ``run_scan`` there cannot just call
``asyncio.run``; the first version ran the scan in a worker thread with the store opened
in the kernel's thread (``sqlite3.ProgrammingError: SQLite objects created in a thread can
only be used in that same thread``, nothing stored). These tests execute notebook cells in
an ipykernel, as a user's Jupyter would, and read the outputs the notebook file would keep.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from goniolab.store import RunStore, StoreError

# a kernel starts in seconds, more on a loaded machine; each test runs whole scans in it
pytestmark = pytest.mark.timeout(600)

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "lab-sim.toml"


def _kernel_env() -> dict[str, str]:
    """This interpreter's environment with the repository on PYTHONPATH and the planted
    PostgreSQL password (a user exports it before starting Jupyter; the kernel inherits it)."""
    from tests.pg_server import PLANTED_PASSWORD

    return {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        "PGPASSWORD": PLANTED_PASSWORD,
    }


@pytest.fixture(scope="module")
def notebook(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """One python3 kernel (this interpreter, this PYTHONPATH) driven by nbclient, for the
    module's notebook tests: a kernel's start and its first ``import goniolab.api`` cost
    more CPU than the scans the tests run in it. Each test runs its own cells (its own
    store, its run ids 1 and 2)."""
    cwd = tmp_path_factory.mktemp("kernel")
    client = nbclient.NotebookClient(
        nbformat.v4.new_notebook(), timeout=300, kernel_name="python3",
        resources={"metadata": {"path": str(cwd)}},
    )  # fmt: skip
    client.km = client.create_kernel_manager()
    client.start_new_kernel(env=_kernel_env())  # type: ignore[no-untyped-call]
    client.start_new_kernel_client()
    try:
        yield client
    finally:
        client._cleanup_kernel()


def _execute(cells: list[str], client: Any) -> list[Any]:
    """Run ``cells`` in the kernel of ``client``, as a notebook of their own."""
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(src) for src in cells]
    client.nb = nb
    for index, cell in enumerate(nb.cells):
        client.execute_cell(cell, index)
    return list(nb.cells)


def _text(cell: Any) -> str:
    """The cell's execute_result as text."""
    for out in cell.outputs:
        if out.output_type == "execute_result":
            return str(out.data["text/plain"])
    raise AssertionError(f"no result in {cell.outputs}")


def _streams(cell: Any, name: str) -> str:
    return "".join(o.text for o in cell.outputs if o.output_type == "stream" and o.name == name)


def _scan_cells(store: str) -> list[str]:
    args = (
        f"{str(CONFIG)!r}, sample='sample:wittmann-3', theta_r_deg='30:40:5', repeats=2, "
        f"time_scale=0, store={store!r}"
    )
    return [
        "import goniolab.api as gl",
        f"run = gl.run_scan({args})\n(run.id, run.status)",
        f"run2 = await gl.run_scan_async({args})\n(run2.id, run2.status)",
        "run.plot()",
    ]


def _check_scan_cells(cells: list[Any]) -> None:
    assert _text(cells[1]) == "(1, 'done')"
    assert _text(cells[2]) == "(2, 'done')"
    for cell in cells[1:3]:
        # progress is a notebook widget (rich's bar in an ipywidgets Output), nothing on stdout
        kinds = [set(o.get("data", {})) for o in cell.outputs if o.output_type == "display_data"]
        assert any("application/vnd.jupyter.widget-view+json" in k for k in kinds), cell.outputs
        assert _streams(cell, "stdout") == ""
    # the figure shows inline without %matplotlib inline
    pngs = [o for o in cells[3].outputs if "image/png" in o.get("data", {})]
    assert len(pngs) == 1, cells[3].outputs
    assert pngs[0]["data"]["image/png"]  # base64 PNG


def test_run_scan_in_a_kernel_with_sqlite(tmp_path: Path, notebook: Any) -> None:
    store = tmp_path / "runs.sqlite"
    _check_scan_cells(_execute(_scan_cells(str(store)), notebook))
    with RunStore(store, readonly=True) as s:
        for rid in (1, 2):
            assert s.get_run(rid).status == "done"
            assert s.count_points(rid) == 3 * 2  # 30, 35, 40 deg x 2 repeats


def test_run_scan_in_a_kernel_with_postgresql(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, notebook: Any, request: pytest.FixtureRequest
) -> None:
    from tests.pg_server import PLANTED_PASSWORD

    srv = request.getfixturevalue("pg_shared")  # skips without PostgreSQL
    url = srv.create_db(f"notebook{os.getpid()}")
    monkeypatch.setenv("PGPASSWORD", PLANTED_PASSWORD)  # the kernel has it (_kernel_env)
    _check_scan_cells(_execute(_scan_cells(url), notebook))
    with RunStore(url, readonly=True) as s:
        assert [s.get_run(r).status for r in (1, 2)] == ["done", "done"]
        assert s.count_points(2) == 6


@pytest.fixture(scope="module")
def kernel() -> Iterator[tuple[Any, Any]]:
    """One python3 kernel and its blocking client for the interruption tests (its start
    and imports cost more CPU than the scans; an interrupted cell leaves it usable, as
    Jupyter's "interrupt kernel" does)."""
    from jupyter_client.manager import start_new_kernel

    km, kc = start_new_kernel(kernel_name="python3", env=_kernel_env())
    try:
        yield km, kc
    finally:
        km.shutdown_kernel(now=True)


@pytest.mark.parametrize("call", ["gl.run_scan", "await gl.run_scan_async"])
def test_interrupting_the_kernel_aborts_the_scan(
    tmp_path: Path, call: str, kernel: tuple[Any, Any]
) -> None:
    """Jupyter's "interrupt kernel" (SIGINT) during a scan stops it: the run is stored
    ``aborted`` (arms stopped and parked) and no reading is added afterwards, whether the
    scan ran in its worker thread (run_scan) or on the kernel's loop (run_scan_async)."""
    import time

    store = tmp_path / "runs.sqlite"
    km, kc = kernel
    kc.execute_interactive("import goniolab.api as gl", timeout=120)
    msg_id = kc.execute(
        f"run = {call}({str(CONFIG)!r}, sample='sample:flat', theta_r_deg='20:60:1', "
        f"time_scale=4.0, store={str(store)!r}, progress=False)"
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # interrupt once readings are being stored
        time.sleep(0.2)
        if store.exists():
            try:
                with RunStore(store, readonly=True) as s:
                    runs = s.list_runs()
                    if runs and s.count_points(runs[0].id) >= 2:
                        break
            except StoreError:  # the file exists, its tables not yet
                continue
    km.interrupt_kernel()
    while True:  # the cell ends (its result or the interruption)
        msg = kc.get_iopub_msg(timeout=120)
        if (
            msg["parent_header"].get("msg_id") == msg_id
            and msg["msg_type"] == "status"
            and msg["content"]["execution_state"] == "idle"
        ):
            break
    with RunStore(store, readonly=True) as s:
        rec = s.list_runs()[0]
        n = s.count_points(rec.id)
        assert rec.status == "aborted" and 2 <= n < 41
    time.sleep(1.0)  # nothing keeps measuring in the background
    with RunStore(store, readonly=True) as s:
        assert s.count_points(rec.id) == n
