"""Gloss of many height maps at once: every core, or a dask.distributed cluster.

``goniolab predict gloss A.sur B.sur ...`` predicts each map in its own worker process
(:class:`concurrent.futures.ProcessPoolExecutor`, ``--jobs`` workers, default one per
core); ``--scheduler ADDRESS`` sends the same work to an existing dask.distributed cluster
(the optional extra ``goniolab[dask]``; its workers must see the same files: relative
paths are made absolute before they are sent). Results
stream back as maps finish (completion order, each row names its map), so a long batch
shows progress and a failure on one map does not stop the others.

Every worker runs the facet kernels on one thread (:func:`goniolab.optics.facet.limit_threads`):
the parallelism is across maps, and a map's numbers do not depend on how the batch was
split: the local pool and a dask cluster return identical rows.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from goniolab.errors import UserError

__all__ = ["GlossOptions", "absolute_specs", "gloss_row", "run_dask", "run_local"]

#: What to install for ``--scheduler``.
DASK_EXTRA = "goniolab[dask]"


@dataclass(frozen=True)
class GlossOptions:
    """The ``predict gloss`` options shared by every map of a batch (picklable)."""

    n: complex = complex(1.55)
    step_um: float | None = None
    slope_method: str = "forward"
    weighting: str = "radiometric"
    masking: bool = True  # as the CLI's --masking (default on)
    model: str = "auto"
    wavelength_nm: float | None = None


def _index_json(n: complex) -> float | list[float]:
    return n.real if n.imag == 0 else [n.real, n.imag]


def gloss_row(spec: str, options: GlossOptions) -> dict[str, Any]:
    """The ``predict gloss --json`` object of one map, or ``{"map", "error"}`` when the map
    cannot be predicted (the message names the file and the reason). Runs in a worker."""
    from goniolab.model_cache import model_for
    from goniolab.optics.facet import limit_threads
    from goniolab.optics.gloss_standards import gloss_report

    try:
        with limit_threads(1):
            model = model_for(
                spec,
                n=options.n,
                step_um=options.step_um,
                slope_method=options.slope_method,  # type: ignore[arg-type]
                weighting=options.weighting,  # type: ignore[arg-type]
                masking=options.masking,
                model=options.model,
                wavelength_nm=options.wavelength_nm,
            )
            rep = gloss_report(model)
    except UserError as exc:
        return {"map": spec, "error": str(exc)}
    except ValueError as exc:  # a geometry the model cannot answer for this map
        return {"map": spec, "error": f"{spec}: {exc}"}
    except MemoryError:
        return {"map": spec, "error": f"{spec}: out of memory predicting this map"}
    except Exception as exc:  # one map's failure must not end the batch
        return {"map": spec, "error": f"{spec}: {type(exc).__name__}: {exc}"}
    return {
        "map": spec,
        "n": _index_json(options.n),
        "G20": rep.G20,
        "G60": rep.G60,
        "G85": rep.G85,
        "haze_index": rep.haze_index,
        "e430": asdict(rep.e430),
        "d523_angle": rep.d523_recommended_angle,
        # the model that computed each number and the notes (issue 20), as predict gloss
        "model": {k: v for k, v in rep.models.items() if not k.startswith("e430.")},
        "e430_model": {k[5:]: v for k, v in rep.models.items() if k.startswith("e430.")},
        "warnings": list(rep.warnings),
    }


def _init_worker() -> None:
    """Pool worker start: quiet numba's threads; the kernels load from the disk cache."""
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")


def run_local(
    specs: Sequence[str], options: GlossOptions, *, jobs: int | None = None
) -> Iterator[dict[str, Any]]:
    """Rows of :func:`gloss_row` as the maps finish, over ``jobs`` worker processes."""
    from concurrent.futures import ProcessPoolExecutor, as_completed

    workers = max(1, min(jobs or os.cpu_count() or 1, len(specs)))
    if workers == 1:
        for spec in specs:
            yield gloss_row(spec, options)
        return
    with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker) as pool:
        futures = {pool.submit(gloss_row, spec, options): spec for spec in specs}
        try:
            for fut in as_completed(futures):
                yield _result_row(fut, futures[fut])
        finally:
            for fut in futures:
                fut.cancel()


def _result_row(fut: Any, spec: str) -> dict[str, Any]:
    """The row of a finished future, or an error row naming the map when its worker died
    (killed by the kernel's OOM killer, a crash in a native library): the batch goes on
    with the other maps (issue 23.5)."""
    try:
        row: dict[str, Any] = fut.result()
    except Exception as exc:  # BrokenProcessPool, a dask worker lost ...
        reason = str(exc).splitlines()[0] if str(exc) else ""
        return {"map": spec, "error": f"{spec}: worker failed: {type(exc).__name__}: {reason}"}
    return row


def absolute_specs(specs: Sequence[str]) -> list[str]:
    """``specs`` with every file path made absolute against this process's directory
    (``sample:NAME`` as it is): a dask worker runs in its own directory, where a relative
    ``w1.npy`` is not found (issue 22.10)."""
    from pathlib import Path

    from goniolab.surfaces.resolve import SAMPLE_PREFIX

    return [s if s.startswith(SAMPLE_PREFIX) or not s else str(Path(s).absolute()) for s in specs]


def _client(address: str) -> Any:
    try:
        from distributed import Client
    except ImportError:
        raise UserError(
            f"--scheduler needs dask.distributed, an optional extra: pip install '{DASK_EXTRA}'"
        ) from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise UserError(f"--scheduler {address}: cannot reach the scheduler: {exc}") from None


def run_dask(
    specs: Sequence[str], options: GlossOptions, *, address: str
) -> Iterator[dict[str, Any]]:
    """Rows of :func:`gloss_row` as the maps finish on the dask cluster at ``address``."""
    client = _client(address)
    try:
        from distributed import as_completed

        paths = absolute_specs(specs)
        futures = client.map(gloss_row, paths, options=options, pure=False)
        typed = {fut.key: spec for fut, spec in zip(futures, specs, strict=True)}
        try:
            for fut in as_completed(futures):
                row = _result_row(fut, typed[fut.key])
                row["map"] = typed[fut.key]  # as the user typed it, as the local rows
                yield row
        finally:
            client.cancel(futures)
    finally:
        client.close()
