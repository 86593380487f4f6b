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
    from contextlib import AsyncExitStack

    from goniolab.config import LabConfig
    from goniolab.scan.gloss_logger import GlossLogger, GlossResult
    from goniolab.scan.plans import GlossPlan
    from goniolab.store import RunMeta, RunStore

__all__ = [
    "GLOSS_CALIBRATION_KIND",
    "MeterPort",
    "gloss_calibrate",
    "gloss_calibration_cite",
    "gloss_log",
    "gloss_plan",
    "meter_pushes",
    "record_gloss_calibration",
    "stored_gloss_prediction",
]

#: The run kind of a stored glossmeter calibration (its record: the model's
#: ``gloss_calibration``).
GLOSS_CALIBRATION_KIND = "glosscal"
#: The largest deviation from the factory calibration a calibration may find: beyond it
#: the standard is dirty or damaged (ZGM 1120 Technical Manual rev 3.0, p. 22: more than
#: 10 % -> clean the standard and repeat).
MAX_DEVIATION_PCT = 10.0
#: How old the calibration a gloss run rests on may be before the run warns: the lab's
#: rule (ISO 2813:2014 asks for a calibration before use; the hours are ours).
DEFAULT_MAX_AGE_H = 24.0


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


async def _meter_on_port(stack: AsyncExitStack, port: MeterPort) -> Any:
    """Open and connect the glossmeter on ``port`` (closed when ``stack`` closes)."""
    from drivers.glossmeter import open_glossmeter

    meter = open_glossmeter(
        port.port, protocol=port.protocol, profile=port.profile,
        serial_number=port.serial_number, baudrate=port.baudrate,
        timeout_s=port.timeout_s,
    )  # fmt: skip
    await meter.connect()
    stack.push_async_callback(meter.close)
    return meter


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
    max_age_h: float | None = None,
) -> GlossResult:
    """Log glossmeter readings of ``plan`` into a new ``gloss`` run of ``store``: from the
    glossmeter of ``config`` or the meter on ``port`` (one of them). ``mode``: ``measure``
    (ask for each reading) or ``push`` (take what the meter sends; the default for a
    pushing protocol on a port). ``watch`` consumes the run's events; ``on_start`` gets the
    logger once the run is stored (stop it there). The run records the calibration it
    rests on (:func:`gloss_calibration_cite`; older than ``max_age_h``: a warning;
    default: the config's ``[glossmeter] calibration_max_age_h``, else
    :data:`DEFAULT_MAX_AGE_H`).

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
    if max_age_h is None:
        max_age_h = (
            config.glossmeter.calibration_max_age_h if config is not None else DEFAULT_MAX_AGE_H
        )
    with lab_errors("gloss log"):
        async with AsyncExitStack() as stack:
            if config is not None:
                session = await stack.enter_async_context(
                    GlossSession.open(config, store, sample=plan.sample, time_scale=time_scale)
                )
            else:
                assert port is not None
                from drivers.timing import RealClock

                meter = await _meter_on_port(stack, port)
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
            cite = record_gloss_calibration(
                store, logger.run_id, session.meter, plan.angles_deg, max_age_h=max_age_h
            )
            notify(f"glossmeter calibration: {describe_gloss_calibration(cite)}")
            for w in cite["warnings"]:
                notify(f"warning: glossmeter calibration: {w}")
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


def meter_identity(meter: object) -> str:
    """What names a glossmeter in its calibration records: its serial number when the
    driver knows it (ZGM1120), else its driver class and device name."""
    serial = getattr(meter, "serial_number", None)
    if serial:
        return f"serial {serial}"
    return f"{type(meter).__name__} {getattr(meter, 'name', '?')}"


def _iso(ts: float) -> str:
    import datetime as dt

    return dt.datetime.fromtimestamp(ts, tz=dt.UTC).isoformat(timespec="seconds")


def gloss_standard_gu(
    standard: str | None, angles_deg: Sequence[int], *, config: LabConfig | None
) -> dict[str, Any]:
    """The standard a calibration is made on, with its certified GU per geometry.

    ``None``: the meter's own working standard (Cal2Standard 0: its certified values are
    held in the meter, ``gu`` empty). Otherwise a ``fresnel`` standard of the config's
    ``standards.toml``: a polished dielectric of index n is, by ISO 2813:2014's definition
    of the gloss unit, ``100 R(n, theta) / R(1.567, theta)`` GU (R: unpolarised Fresnel
    reflectance, Born & Wolf sec. 1.5.2), 100 GU for the primary black glass.

    Raises
    ------
    UserError
        No config to read the standards from, no such standard, not a ``fresnel`` one.
    """
    if standard is None:
        return {
            "name": "working standard",
            "description": "the meter's own working standard (its certified values are held "
            "in the meter: Cal2Standard 0)",
            "gu": {},
        }
    if config is None:
        raise UserError("gloss calibrate: --standard needs --config (its standards.toml)")
    import math

    from goniolab.optics.apertures import ISO2813_BLACK_GLASS_N  # 100 GU, ISO 2813 sec. 6
    from goniolab.optics.fresnel import fresnel
    from goniolab.scan.standards import load_standards, standards_path

    std = load_standards(standards_path(config.source)).get(standard)
    if std.model != "fresnel":
        raise UserError(
            f"gloss calibrate: standard {standard} is a {std.model} standard; a gloss "
            'standard needs its refractive index (model = "fresnel")'
        )
    gu = {}
    for a in angles_deg:
        cos_i = math.cos(math.radians(a))
        gu[str(a)] = round(
            100.0 * float(fresnel(cos_i, std.n)) / float(fresnel(cos_i, ISO2813_BLACK_GLASS_N)), 1
        )
    return {**std.cite(), "name": std.name, "description": std.description, "gu": gu}


async def gloss_calibrate(
    store: RunStore,
    *,
    config: LabConfig | None = None,
    port: MeterPort | None = None,
    angles_deg: Sequence[int] = (20, 60, 85),
    standard: str | None = None,
    time_scale: float | None = None,
    notify: Notify = quiet,
) -> tuple[int, dict[str, Any]]:
    """Calibrate the glossmeter of ``config`` (or on ``port``) at each of ``angles_deg``
    on ``standard`` (:func:`gloss_standard_gu`), one Calibrate (ZGM1120 opcode 72) per
    geometry, and store the record as a run of kind :data:`GLOSS_CALIBRATION_KIND`:
    time, instrument, standard, the deviation from the factory calibration the meter
    returns (ppm) per geometry. Returns ``(run id, record)``.

    Raises
    ------
    UserError
        The meter cannot calibrate remotely, is not on its standard, refuses, or finds a
        deviation above :data:`MAX_DEVIATION_PCT` (the run is stored as failed, exit 1).
    """
    import time
    from contextlib import AsyncExitStack

    from goniolab import __version__
    from goniolab.session import GlossSession

    if (config is None) == (port is None):
        raise UserError("gloss calibrate: give a lab config or a port (one of them)")
    angles = tuple(dict.fromkeys(int(a) for a in angles_deg))
    for a in angles:
        if a not in (20, 60, 85):
            raise UserError(f"gloss calibrate: geometry {a} deg is not one of 20, 60, 85")
    std = gloss_standard_gu(standard, angles, config=config)
    with lab_errors("gloss calibrate"):
        async with AsyncExitStack() as stack:
            if config is not None:
                session = await stack.enter_async_context(
                    GlossSession.open(config, store, time_scale=time_scale)
                )
                meter: Any = session.meter
                protocol = config.glossmeter.protocol if config.lab.mode != "sim" else "sim"
            else:
                assert port is not None
                meter = await _meter_on_port(stack, port)
                protocol = port.protocol
            calibrate = getattr(meter, "calibrate", None)
            if calibrate is None:
                raise UserError(
                    f"gloss calibrate: the {protocol} meter has no remote calibration command: "
                    "calibrate it on its own keys"
                )
            identity = meter_identity(meter)
            on_standard: bool | None = None
            if standard is None and hasattr(meter, "is_on_standard"):
                on_standard = bool(await meter.is_on_standard())  # opcode 28
            t0 = time.time()
            record: dict[str, Any] = {
                "time": t0,
                "time_iso": _iso(t0),
                "instrument": {"identity": identity, "name": getattr(meter, "name", ""),
                               "protocol": protocol,
                               "serial_number": getattr(meter, "serial_number", None)},
                "standard": std,
                "on_standard": on_standard,
                "max_deviation_pct": MAX_DEVIATION_PCT,
                "angles": {},
                "ok": False,
            }  # fmt: skip
            run_id = store.create_run(
                kind=GLOSS_CALIBRATION_KIND,
                plan={"kind": GLOSS_CALIBRATION_KIND, "angles_deg": list(angles),
                      "standard": std["name"]},
                config={"glossmeter": identity, "protocol": protocol},
                sample="", model={"gloss_calibration": record}, version=__version__,
            )  # fmt: skip
            problem = ""
            if on_standard is False:
                problem = "the meter is not on its working standard (GetIsOnStandard = 0)"
            from drivers.base import DeviceError

            for a in angles if not problem else ():
                dgu = None
                if std["gu"]:
                    dgu = round(10.0 * std["gu"][str(a)])  # Cal2StandValue in 0.1 GU
                try:
                    ppm = int(await calibrate(a, second_standard_dgu=dgu))
                except DeviceError as exc:
                    problem = f"G{a}: the meter refused: {exc}"
                    break
                ok = abs(ppm) <= MAX_DEVIATION_PCT * 1e4
                record["angles"][str(a)] = {
                    "deviation_ppm": ppm,
                    "deviation_pct": ppm / 1e4,
                    "ok": ok,
                }
                notify(f"G{a}: deviation {ppm} ppm ({ppm / 1e4:+.4f} %)")
                if not ok:
                    problem = (
                        f"G{a}: deviation {ppm / 1e4:+.2f} % from the factory calibration is "
                        f"more than {MAX_DEVIATION_PCT:g} %: clean the standard and repeat"
                    )
                    break
            record["ok"] = not problem
            record["problem"] = problem
            store.update_model(run_id, {"gloss_calibration": record})
            store.set_status(run_id, "failed" if problem else "done", problem)
            if problem:
                raise UserError(
                    f"gloss calibrate: calibration run {run_id} failed: {problem}", exit_code=1
                )
    return run_id, record


def gloss_calibration_cite(
    store: RunStore,
    identity: str,
    *,
    at: float,
    angles_deg: Sequence[int],
    max_age_h: float = DEFAULT_MAX_AGE_H,
) -> dict[str, Any]:
    """What a gloss run started at ``at`` rests on: the newest successful calibration
    record of the glossmeter ``identity`` made before ``at`` (``run`` None: none recorded
    in this store), its age, standard and deviations, and its ``warnings`` (none, older
    than ``max_age_h``, a geometry of the run it did not calibrate)."""
    import math

    found = None
    for rec in store.list_runs(kind=GLOSS_CALIBRATION_KIND):  # newest first
        if rec.status != "done":
            continue
        record = rec.model.get("gloss_calibration") or {}
        inst = record.get("instrument") or {}
        t = float(record.get("time", rec.created_at))
        if inst.get("identity") == identity and t <= at:
            found = (rec.id, record, t)
            break
    cite: dict[str, Any] = {"instrument": identity, "max_age_h": max_age_h}
    if found is None:
        return {
            **cite,
            "run": None,
            "warnings": [
                f"none recorded in this store for {identity}: the readings rest on the "
                "meter's own last calibration (run goniolab gloss calibrate)"
            ],
        }
    run_id, record, t = found
    age_h = (at - t) / 3600.0
    angles = record.get("angles") or {}
    std = record.get("standard") or {}
    cite.update(
        run=run_id,
        time_iso=record.get("time_iso", _iso(t)),
        age_h=age_h,
        standard=std.get("name", ""),
        standard_gu=std.get("gu", {}),
        deviation_ppm={k: v.get("deviation_ppm") for k, v in angles.items()},
    )
    warnings: list[str] = []
    if math.isfinite(max_age_h) and age_h > max_age_h:
        warnings.append(
            f"the calibration (run {run_id}) is {age_h:.1f} h old at the run's start, older "
            f"than {max_age_h:g} h (the lab's rule): run goniolab gloss calibrate"
        )
    missing = [a for a in angles_deg if str(a) not in angles]
    if missing:
        warnings.append(
            "calibration run {} did not calibrate {}".format(
                run_id, ", ".join(f"G{a}" for a in missing)
            )
        )
    cite["warnings"] = warnings
    return cite


def record_gloss_calibration(
    store: RunStore,
    run_id: int,
    meter: object,
    angles_deg: Sequence[int],
    *,
    max_age_h: float = DEFAULT_MAX_AGE_H,
) -> dict[str, Any]:
    """Store in gloss run ``run_id`` the calibration of ``meter`` it rests on
    (:func:`gloss_calibration_cite` at the run's creation) as its model's
    ``glossmeter_calibration``; return it (its ``warnings`` for the face to show)."""
    cite = gloss_calibration_cite(
        store,
        meter_identity(meter),
        at=store.get_run(run_id).created_at,
        angles_deg=angles_deg,
        max_age_h=max_age_h,
    )
    store.update_model(run_id, {"glossmeter_calibration": cite})
    return cite


def describe_gloss_calibration(cite: dict[str, Any]) -> str:
    """One line of a run's glossmeter calibration (``runs show``, ``gloss log``)."""
    if cite.get("run") is None:
        return f"none recorded in this store (for {cite.get('instrument', '?')})"
    dev = ", ".join(
        f"G{a} {int(p) / 1e4:+.4f} %"
        for a, p in sorted((cite.get("deviation_ppm") or {}).items(), key=lambda kv: int(kv[0]))
        if p is not None
    )
    return (
        f"run {cite['run']} ({cite.get('time_iso', '')}, {float(cite['age_h']):.1f} h before "
        f"the run) on {cite.get('standard', '?')}, deviation {dev}"
    )


def describe_calibration_record(record: dict[str, Any]) -> list[str]:
    """The lines of a stored glossmeter calibration (``runs show`` of a ``glosscal`` run)."""
    inst = record.get("instrument") or {}
    std = record.get("standard") or {}
    gu = ", ".join(f"G{a} {float(v):.1f} GU" for a, v in (std.get("gu") or {}).items())
    lines = [
        f"glossmeter {inst.get('identity', '?')} ({inst.get('protocol', '?')}) at "
        f"{record.get('time_iso', '?')}",
        f"standard: {std.get('name', '?')}"
        + (f" ({gu})" if gu else "")
        + (f", certificate {std['certificate']}" if std.get("certificate") else ""),
    ]
    for a, r in (record.get("angles") or {}).items():
        lines.append(
            f"G{a}: deviation from the factory calibration {r.get('deviation_ppm')} ppm"
            + ("" if r.get("ok", True) else f" (more than {MAX_DEVIATION_PCT:g} %)")
        )
    if record.get("problem"):
        lines.append(f"refused: {record['problem']}")
    return lines
