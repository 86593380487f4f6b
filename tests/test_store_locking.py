"""Portable run claims (issue 22.8): the store imports and claims without ``fcntl``."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from goniolab.store import RunStore

REPO = Path(__file__).resolve().parents[1]


def test_store_and_api_import_and_claim_without_fcntl(tmp_path: Path) -> None:
    # a Windows instrument PC has no fcntl: importing it must fail there, and everything
    # that opens a store must still work (issue 22.8: `import goniolab.api` failed)
    code = textwrap.dedent(
        f"""
        import sys
        sys.modules["fcntl"] = None  # `import fcntl` now raises ImportError
        try:
            import fcntl  # noqa: F401
        except ImportError:
            pass
        else:
            raise SystemExit("fcntl still importable")
        import goniolab.api  # noqa: F401
        from goniolab.store import RunBusy, RunStore
        with RunStore({str(tmp_path / "s.sqlite")!r}) as s:
            rid = s.create_run(kind="brdf", plan={{}}, config={{}}, sample="", model={{}},
                               version="0")
            with s.claim_run(rid):
                assert s.is_claimed(rid) is True
                try:
                    with s.claim_run(rid):
                        pass
                except RunBusy as exc:
                    print("busy:", exc)
            assert s.is_claimed(rid) is False
        print("fcntl" in sys.modules and sys.modules["fcntl"] is not None)
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        timeout=120,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("busy: store ") and "already being measured" in lines[0]
    assert lines[1] == "False"  # nothing brought fcntl back


def test_claim_lives_beside_the_store_not_in_it(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan={}, config={}, sample="", model={}, version="0")
        with s.claim_run(rid):
            locks = sorted(p.name for p in (tmp_path / "s.sqlite-locks").iterdir())
            assert locks == [f"run-{rid}.lock"]


def test_one_store_serves_several_threads(tmp_path: Path) -> None:
    # issue 22.2: a store opened in Jupyter's thread and written by the scan's worker thread
    # failed ("SQLite objects created in a thread can only be used in that same thread")
    import threading

    with RunStore(tmp_path / "s.sqlite") as s:
        runs = [
            s.create_run(kind="brdf", plan={}, config={}, sample="", model={}, version="0")
            for _ in range(4)
        ]
        errors: list[BaseException] = []

        def write(rid: int) -> None:
            try:
                for i in range(50):
                    s.add_point(rid, index=i, repeat=0, theta_i_deg=45.0, theta_r_deg=float(i),
                                measured_theta_i_deg=45.0, measured_theta_r_deg=float(i),
                                luminance_pct=float(rid), raw={}, timestamp=0.0)  # fmt: skip
                    s.set_status(rid, "running")
            except BaseException as exc:
                errors.append(exc)

        threads = [threading.Thread(target=write, args=(rid,)) for rid in runs]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert errors == []
        for rid in runs:
            assert sorted(s.done_keys(rid)) == [(i, 0) for i in range(50)]
            assert {p.luminance_pct for p in s.points(rid)} == {float(rid)}
