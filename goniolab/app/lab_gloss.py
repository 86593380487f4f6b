"""The gloss log on a lab (issue 24): glossmeter readings into the run store.

:func:`gloss_log` opens the glossmeter of a lab config (real or simulated), or a meter on a
port with no config (:class:`MeterPort`), predicts the sample's ISO 2813 gloss when it has
a height map, records a ``gloss`` run and logs each reading into it
(:class:`goniolab.session.GlossSession`). The face watches the run's events (``watch``)
and stops the logger it is handed (``on_start``); the result is typed
(:class:`goniolab.scan.gloss_logger.GlossResult`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from goniolab.app.lab_setup import Notify, lab_errors, quiet
from goniolab.errors import UserError

if TYPE_CHECKING:
    import asyncio

    from goniolab.config import LabConfig
    from goniolab.scan.gloss_logger import GlossLogger, GlossResult
    from goniolab.scan.plans import GlossPlan
    from goniolab.store import RunMeta, RunStore

__all__ = ["MeterPort", "gloss_log", "gloss_plan", "meter_pushes", "stored_gloss_prediction"]


@dataclass(frozen=True)
class MeterPort:
    """A glossmeter on a port with no lab config (``gloss log --port``)."""

    port: str
    protocol: str = "zgm1120"
    profile: str | None = None
    serial_number: str = "401120999"
    baudrate: int | None = None
    timeout_s: float = 2.0
    n: float = 1.55  # refractive index of the sample the prediction is made for


def meter_pushes(protocol: str) -> bool:
    """Whether a ``protocol``'s meter prints its readings on its own (drivers.protocols)."""
    from drivers.protocols import GLOSSMETERS

    return GLOSSMETERS[protocol].pushes_readings


def gloss_plan(count: int, angles_deg: Sequence[int], sample: str) -> GlossPlan:
    """The gloss log's plan: ``count`` readings (0: until stopped) at ``angles_deg``."""
    from goniolab.scan.plans import GlossPlan, PlanError

    try:
        return GlossPlan(count=count, angles_deg=tuple(angles_deg), sample=sample)
    except PlanError as exc:
        raise UserError(f"gloss log: {exc}") from exc


async def gloss_log(
    store: RunStore,
    plan: GlossPlan,
    *,
    config: LabConfig | None = None,
    port: MeterPort | None = None,
    time_scale: float | None = None,
    mode: str | None = None,
    interval_s: float = 0.0,
    meta: RunMeta | None = None,
    watch: Callable[[asyncio.Queue[Any]], Coroutine[Any, Any, None]] | None = None,
    on_start: Callable[[GlossLogger], None] | None = None,
    notify: Notify = quiet,
) -> GlossResult:
    """Log glossmeter readings of ``plan`` into a new ``gloss`` run of ``store``: from the
    glossmeter of ``config`` or the meter on ``port`` (one of them). ``mode``: ``measure``
    (ask for each reading) or ``push`` (take what the meter sends; the default for a
    pushing protocol on a port). ``watch`` consumes the run's events; ``on_start`` gets the
    logger once the run is stored (stop it there).

    Raises
    ------
    UserError
        The meter cannot be reached, the store refuses the run.
    """
    import asyncio
    from contextlib import AsyncExitStack

    from goniolab.session import GlossSession, SampleModels

    if (config is None) == (port is None):
        raise UserError("gloss log: give a lab config or a port (one of them)")
    with lab_errors("gloss log"):
        async with AsyncExitStack() as stack:
            if config is not None:
                session = await stack.enter_async_context(
                    GlossSession.open(config, store, sample=plan.sample, time_scale=time_scale)
                )
            else:
                assert port is not None
                from drivers.glossmeter import open_glossmeter
                from drivers.timing import RealClock

                meter = open_glossmeter(
                    port.port, protocol=port.protocol, profile=port.profile,
                    serial_number=port.serial_number, baudrate=port.baudrate,
                    timeout_s=port.timeout_s,
                )  # fmt: skip
                await meter.connect()
                stack.push_async_callback(meter.close)
                session = GlossSession(
                    meter, RealClock(), store,
                    config={"port": port.port, "protocol": port.protocol,
                            "baudrate": port.baudrate},
                    models=SampleModels(port.n),
                )  # fmt: skip
            if mode is None:
                mode = "push" if port is not None and meter_pushes(port.protocol) else "measure"
            logger = await session.start(plan, mode=mode, interval_s=interval_s, meta=meta)
            notify(f"run {logger.run_id} in store {store.location}")
            # what the stored run says about its predicted gloss (a model out of its
            # validity, a clamp), before the first reading is printed beside it
            for w in stored_gloss_prediction(store, logger.run_id)["warnings"]:
                notify(f"warning: model: {w}")
            logging.getLogger("goniolab").info("run %d in store %s", logger.run_id, store.location)
            watcher: asyncio.Task[None] | None = None
            if watch is not None:
                watcher = asyncio.create_task(watch(session.bus.subscribe()))
            if on_start is not None:
                on_start(logger)
            try:
                return await logger.run()
            finally:
                session.bus.close()
                if watcher is not None:
                    await watcher


def stored_gloss_prediction(store: RunStore, run_id: int) -> dict[str, Any]:
    """The predicted gloss of gloss run ``run_id`` as its record holds it: ``computed_by``
    (geometry -> the model that computed it, :func:`goniolab.optics.provenance.
    gloss_provenance_of`) and the ``warnings`` of those numbers (empty without a
    prediction)."""
    model = store.get_run(run_id).model
    model = model if isinstance(model, dict) else {}
    computed_by = model.get("computed_by")
    warnings = model.get("warnings")
    return {
        "computed_by": dict(computed_by) if isinstance(computed_by, dict) else {},
        "warnings": [str(w) for w in warnings] if isinstance(warnings, list) else [],
    }
