"""What the use cases on a lab share (issue 24): the lab config read once, the run
store opened, the plans built, the stored config a run resumes with, the library's errors
a user can act on turned into :class:`goniolab.errors.UserError`.

The one plan builder (:func:`brdf_plan`) of the CLI, the notebook API, the TUI and the
bluesky face; the use cases themselves are in :mod:`goniolab.app.lab_scan`. Nothing heavy
is imported with this module (``goniolab --help`` stays light).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab.errors import UserError

if TYPE_CHECKING:  # loaded when a use case runs
    from goniolab.config import LabConfig
    from goniolab.scan.align import AlignPlan
    from goniolab.scan.plans import BrdfPlan
    from goniolab.scan.runner import PlanRefused
    from goniolab.store import RunMeta, RunRecord, RunStore

__all__ = [
    "Notify",
    "SpecimenHook",
    "absolute_sample",
    "align_plan",
    "brdf_plan",
    "check_map",
    "check_reach",
    "check_sample",
    "config_changes",
    "e2194_angles",
    "lab_errors",
    "load_config",
    "open_store",
    "plan_refused",
    "quiet",
    "resume_command",
    "resume_config",
    "run_meta",
    "scan_sample",
    "started_with",
    "stderr_notify",
    "store_location",
    "with_model",
]

#: A line for the operator (the CLI prints it on stderr).
Notify = Callable[[str], None]
#: Swaps the specimen ("mirror", "sample", "standard") and returns once it is in place.
SpecimenHook = Callable[[str], Awaitable[None]]


def quiet(text: str) -> None:
    return None


# --------------------------------------------------------------------------- config, store
def load_config(path: str | Path, store: str | Path | None = None) -> LabConfig:
    """The lab config of ``path``, validated (:func:`goniolab.config.load_lab_config`): the
    one place a use case reads it, once per use case. ``store`` (``--store``) replaces
    ``[lab] store``, so the alignment state is the one beside the store the run uses."""
    import goniolab.config

    return goniolab.config.load_lab_config(path, store=store)


def with_model(cfg: LabConfig, model: str | None) -> LabConfig:
    """``cfg`` with ``[sample] model`` set to ``model`` (``None``: as it is)."""
    if model is None:
        return cfg
    return cfg.model_copy(update={"sample": cfg.sample.model_copy(update={"model": model})})


def store_location(
    store: str | Path | None = None, *, config: LabConfig | str | Path | None = None
) -> str | Path:
    """The store a use case opens, chosen here for every face: ``store`` (``--store``)
    first, then the ``[lab] store`` of ``config`` (a loaded :class:`LabConfig`, or the path
    of a lab config file, read here), then the default file
    (:func:`goniolab.store.resolve_store_path`)."""
    from goniolab.store import resolve_store_path

    if isinstance(config, str | Path):
        config = load_config(config) if str(config) else None
    config_store = None if config is None else config.lab.store
    return resolve_store_path(None if store is None else str(store), config_store)


def open_store(
    store: str | Path | None = None,
    *,
    config: LabConfig | str | Path | None = None,
    create: bool = True,
    readonly: bool = False,
    exit_code: int = 2,
) -> RunStore:
    """The run store :func:`store_location` chooses, opened (``readonly``: nothing is
    created or written; ``create=False``: it must exist).

    Raises
    ------
    UserError
        It cannot be opened (its message names the store and the reason).
    """
    from goniolab.store import RunStore, StoreError

    try:
        return RunStore(store_location(store, config=config), create=create, readonly=readonly)
    except StoreError as exc:
        raise UserError(str(exc), exit_code=exit_code) from exc


def run_meta(
    operator: str | None = None,
    sample_id: str | None = None,
    notes: str | None = None,
    tags: Sequence[str] = (),
) -> RunMeta:
    """The run metadata a face was given (``None``: not given; :meth:`RunMeta.given`)."""
    from goniolab.store import RunMeta

    return RunMeta.given(operator, sample_id, notes, tags)


def plan_refused(exc: PlanRefused) -> UserError:
    """The dry run's refusal as the user reads it, from every face (``goniolab scan``,
    the TUI form, the notebook): ``plan refused (no arm moved): point N (theta_i=..,
    theta_r=..) is unsafe: <the driver's reason>``."""
    return UserError(f"plan refused (no arm moved): {exc}")


@contextlib.contextmanager
def lab_errors(what: str = "") -> Any:
    """Turn the library's errors a user can act on into :class:`UserError`: an instrument
    that cannot be reached (or fails outside a run, which records its own faults), a store
    that refuses a write, a plan the arms cannot run, a run another process holds."""
    from drivers.base import DeviceError
    from goniolab.scan.plans import PlanError
    from goniolab.scan.runner import PlanRefused
    from goniolab.store import RunBusy, StoreError

    try:
        yield
    except PlanRefused as exc:
        raise plan_refused(exc) from exc
    except RunBusy as exc:
        raise UserError(f"{exc} (no arm moved)") from exc
    except PlanError as exc:
        raise UserError(f"{what}: {exc}" if what else str(exc)) from exc
    except DeviceError as exc:
        raise UserError(f"instrument error: {exc}", exit_code=1) from exc
    except StoreError as exc:
        raise UserError(str(exc), exit_code=1) from exc


# --------------------------------------------------------------------------- plans
def check_map(cfg: LabConfig, sample: str, *, given: bool, step_um: float | None) -> LabConfig:
    """``cfg`` with ``step_um`` as ``[sample] step_um``, after the map was read once, so
    that a map without a lateral step (a ``.npy`` without sidecar) is one error naming the
    map and the option, not the config (issue 27, item 6). ``given``: the sample came from
    ``--sample`` (else from the config's ``[sample] map``)."""
    if step_um is not None:
        if not step_um > 0 or step_um != step_um:
            raise UserError(f"scan: --step-um must be > 0, got {step_um:g}")
        cfg = cfg.model_copy(update={"sample": cfg.sample.model_copy(update={"step_um": step_um})})
    if sample.startswith("sample:"):
        return cfg
    from goniolab.surfaces.resolve import resolve_map

    try:
        resolve_map(sample if given else cfg.sample_map(), step_um=cfg.sample.step_um)
    except UserError as exc:  # its text starts with the map's file name
        if given:
            raise UserError(f"--sample {exc}") from None
        raise UserError(f"{cfg.source}: sample.map: {exc} (or set [sample] step_um)") from None
    return cfg


def absolute_sample(spec: str) -> str:
    """A height-map path made absolute (``sample:NAME`` as it is), so that the stored run
    names the same file from any directory (``scan resume`` elsewhere, a dask worker)."""
    if not spec or spec.startswith("sample:"):
        return spec
    return str(Path(spec).expanduser().resolve())


def check_sample(spec: str, *, option: str = "--sample", given: str = "") -> str:
    """``spec`` (``sample:NAME`` or a height-map path) when it names a built-in sample or a
    file, as it is (:func:`goniolab.session.check_sample`: a :class:`UserError` naming
    ``option`` otherwise)."""
    from goniolab.session import check_sample as check

    check(spec, option=option, given=given)
    return spec


def scan_sample(cfg: LabConfig, sample: str | None, *, option: str = "--sample") -> str:
    """The sample a scan measures: ``sample`` checked and made absolute, else the config's
    ``[sample] map``."""
    if not sample:
        return cfg.sample.map
    from goniolab.session import check_sample

    check_sample(sample, option=option)
    return absolute_sample(sample)


def brdf_plan(
    cfg: LabConfig,
    *,
    sample: str,
    theta_i_deg: float = 45.0,
    theta_r_deg: str | Sequence[float] = "0:70:1",
    repeats: int | None = None,
    dwell_s: float = 0.0,
    exposure_us: int | None = None,
    mirror_reference: bool = False,
    auto_exposure: bool = True,
    what: str = "scan",
    angles_option: str = "--theta-r",
) -> BrdfPlan:
    """The in-plane plan: ``theta_r_deg`` (``"start:stop:step"``, ``"a,b,c"`` or numbers)
    at ``theta_i_deg``, ``exposure_us`` defaulting to the config's ``[spectro]``.

    Raises
    ------
    UserError
        ``what: reason`` for a plan that cannot be (an angle list, a repeat count).
    """
    from goniolab.scan.plans import DEFAULT_REPEATS, BrdfPlan, PlanError, parse_angles

    spec = theta_r_deg if isinstance(theta_r_deg, str) else [float(v) for v in theta_r_deg]
    try:
        return BrdfPlan(
            theta_i_deg=float(theta_i_deg),
            theta_r_deg=parse_angles(spec, name=angles_option),
            repeats=DEFAULT_REPEATS if repeats is None else int(repeats),
            dwell_s=float(dwell_s),
            exposure_us=cfg.spectro.exposure_us if exposure_us is None else int(exposure_us),
            mirror_reference=mirror_reference,
            sample=sample,
            auto_exposure=bool(auto_exposure),
        )
    except PlanError as exc:
        raise UserError(f"{what}: {exc}") from exc


def check_reach(
    cfg: LabConfig,
    plan: BrdfPlan,
    *,
    corrections_deg: tuple[float, float] | None = None,
) -> None:
    """Refuse ``plan`` when the arms cannot reach one of its geometries (or the park
    position), before any instrument is reached: the dry run's check
    (:func:`goniolab.scan.dryrun.check_reach`) against the config's ``[goniometer]``
    limits and interlock, through the driver's words (:func:`drivers.arm_limits.
    geometry_problem`) and :func:`lab_errors`' translation, so that the TUI form says
    what ``goniolab scan`` says for the same plan.

    ``corrections_deg``: the alignment corrections the arms add to every move (the open
    lab's; default the config's ``[alignment]``).

    Raises
    ------
    UserError
        ``plan refused (no arm moved): point N (theta_i=.., theta_r=..) is unsafe: ..``.
    """
    from goniolab.scan.dryrun import check_reach as refuse_unsafe
    from goniolab.scan.dryrun import config_reach

    g = cfg.goniometer
    corr = cfg.alignment.corrections_deg() if corrections_deg is None else corrections_deg
    check_geometry, reach = config_reach(g, corr)
    with lab_errors():
        refuse_unsafe(
            plan.points(),
            check_geometry,
            park_deg=(g.park.theta_i_deg, g.park.theta_r_deg),
            reach=reach,
        )


def e2194_angles(
    cfg: LabConfig, theta_i_deg: float, *, theta_r_given: bool
) -> tuple[str, list[str]]:
    """The ASTM E2194 / E2539 / DIN 6175-2 geometry: the detector angles (``"a,b,c"``,
    ascending) of the aspecular angles -15, 15, 25, 45, 75, 110 deg at 45 deg incidence,
    and a notice for each one the detector arm cannot reach (its limits, or beyond the
    lamp: it would pass through the lamp arm), with the reason."""
    from goniolab.colour.multiangle import (
        E2194_ASPECULAR_DEG,
        E2194_INCIDENCE_DEG,
        theta_r_for_aspecular,
    )

    if theta_i_deg != E2194_INCIDENCE_DEG:
        raise UserError(
            f"scan --plan e2194: the standard lights at 45 deg, not --theta-i {theta_i_deg:g}"
        )
    if theta_r_given:
        raise UserError("scan --plan e2194 sets the detector angles itself; drop --theta-r")
    pairs = sorted((theta_r_for_aspecular(a), a) for a in E2194_ASPECULAR_DEG)
    lo, hi = cfg.goniometer.detector.limits_deg
    where = f"{cfg.source or 'config'}: goniometer.detector.limits_deg"
    keep: list[float] = []
    notices: list[str] = []
    for t, a in pairs:
        if t < -E2194_INCIDENCE_DEG:
            notices.append(
                f"scan --plan e2194: aspecular {a:g} deg skipped: theta_r {t:g} lies beyond the "
                f"lamp (-{E2194_INCIDENCE_DEG:g} deg), the detector arm would pass through the "
                f"lamp arm (by reciprocity it is theta_i {-t:g}, theta_r -{E2194_INCIDENCE_DEG:g}; "
                "a plan holds one incidence)"
            )
        elif not lo <= t <= hi:
            notices.append(
                f"scan --plan e2194: aspecular {a:g} deg skipped: theta_r {t:g} outside the "
                f"detector arm's {lo:g}..{hi:g} deg ({where})"
            )
        else:
            keep.append(t)
    if not keep:
        raise UserError(f"scan --plan e2194: no standard angle is within reach ({where})")
    return ",".join(f"{t:g}" for t in keep), notices


def align_plan(
    cfg: LabConfig, *, sample: str, theta_i_deg: str | Sequence[float], exposure_us: int | None
) -> AlignPlan:
    """The alignment's plan (:class:`goniolab.scan.align.AlignPlan`) at ``theta_i_deg``."""
    from goniolab.scan.align import AlignPlan
    from goniolab.scan.plans import PlanError, parse_angles

    try:
        return AlignPlan(
            theta_i_deg=parse_angles(theta_i_deg, name="--align-theta-i"),
            exposure_us=exposure_us or cfg.spectro.exposure_us,
            sample=sample,
        )
    except PlanError as exc:
        raise UserError(f"scan --plan align: {exc}") from exc


#: Config keys that do not change what a run measures (where the instruments are plugged,
#: how long to wait for them, the store, the run's own metadata): a live config that
#: differs from the run's snapshot only there resumes without a word.
_RESUME_IGNORED_SECTIONS = ("lab", "run", "glossmeter")
_RESUME_IGNORED_KEYS = frozenset(
    {"transport", "host", "port", "unit_id", "serial_port", "baudrate", "parity", "timeout_s",
     "move_timeout_s", "serial_number", "protocol"}
)  # fmt: skip


def _flat(doc: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(doc, dict):
        out: dict[str, Any] = {}
        for k, v in doc.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: doc}


def config_changes(snapshot: dict[str, Any], live: dict[str, Any]) -> list[str]:
    """The keys (dotted) whose value differs between a run's stored config and the live
    one, among those that change what is measured; ``"key: stored -> live"`` each."""
    a, b = _flat(snapshot), _flat(live)
    out = []
    for key in sorted(set(a) | set(b)):
        parts = key.split(".")
        if key.startswith("_") or parts[0] in _RESUME_IGNORED_SECTIONS:
            continue
        if parts[-1] in _RESUME_IGNORED_KEYS:
            continue
        if a.get(key) != b.get(key):
            out.append(f"{key}: {a.get(key, '(unset)')!r} -> {b.get(key, '(unset)')!r}")
    return out


def started_with(rec: RunRecord) -> str | None:
    """The model a stored run started with (a ``scan --model`` override included)."""
    from goniolab.model_registry import model_names

    name = rec.model.get("model_name")
    return name if name in model_names() else None


def resume_config(
    rec: RunRecord,
    config_arg: str | None,
    use_current: bool,
    *,
    live: LabConfig | None = None,
    notify: Notify = quiet,
) -> LabConfig:
    """The config a stored run resumes with: its stored snapshot (issue 23.9), unless
    ``use_current``. The live file (``config_arg`` or the one the run started with;
    ``live`` when it is already loaded) is compared with the snapshot: a change that
    alters the measurement is refused, naming each key, unless ``use_current`` (then the
    live file is used, and each change is a notice).

    Raises
    ------
    UserError
        A change refused, or a snapshot that cannot be used and no live file.
    """
    from pydantic import ValidationError

    from goniolab.config import LabConfig
    from goniolab.session import with_sample

    snap = dict(rec.config)
    source = str(snap.pop("_source", "") or "")
    live_path = config_arg or (source if source and Path(source).exists() else "")
    if live is None and live_path:
        live = load_config(live_path)
    if live is not None:
        # what the run's own command line set (its sample, a --model) is no config change
        live = with_model(with_sample(live, rec.sample), started_with(rec))
    stored: LabConfig | None = None
    why = ""
    try:
        stored = LabConfig.model_validate(snap).model_copy(update={"source": source})
    except ValidationError as exc:
        why = " ".join(str(exc).split())
    if use_current:
        if live is None:
            raise UserError(f"run {rec.id}: --use-current-config needs --config FILE")
        if stored is not None:
            for line in config_changes(
                stored.model_dump(mode="json"), live.model_dump(mode="json")
            ):
                notify(f"resuming with the current config: {line}")
        return live
    if stored is None:
        if live is None:
            raise UserError(
                f"run {rec.id}: its stored config cannot be used ({why}); pass --config FILE"
            )
        notify(f"run {rec.id}: its stored config cannot be used ({why}); resuming with {live_path}")
        return live
    if live is not None:
        changes = config_changes(stored.model_dump(mode="json"), live.model_dump(mode="json"))
        if changes:
            raise UserError(
                f"run {rec.id}: {live_path} changed since the run started ("
                + "; ".join(changes)
                + "): the rest of the run would not measure what its first readings did. "
                "Resume with the run's stored config by restoring the file, or pass "
                "--use-current-config to go on with the new one"
            )
        # the live file may hold what the snapshot could not keep (a store password)
        stored = stored.model_copy(update={"lab": live.lab, "source": live.source})
    return stored


def resume_command(run_id: int, store: RunStore) -> str:
    """The command that resumes run ``run_id`` of ``store``: ``--store`` named unless it is
    the default store (a store chosen by ``--store`` or a config's ``[lab] store`` would
    otherwise be lost: ``scan resume`` reads the run's config from the store itself). A
    PostgreSQL URL is shown without its password (libpq reads it from PGPASSWORD or
    ~/.pgpass)."""
    import shlex

    from goniolab.store import default_store_path

    cmd = f"goniolab scan resume {run_id}"
    if store.is_postgres:
        return f"{cmd} --store {shlex.quote(store.location)}"
    try:
        default = store.path.resolve() == default_store_path().resolve()
    except OSError:
        default = False
    if not default:
        cmd += f" --store {shlex.quote(str(store.path.resolve()))}"
    return cmd


def stderr_notify(text: str) -> None:
    """The CLI's :data:`Notify`: ``goniolab: text`` on stderr."""
    print(f"goniolab: {text}", file=sys.stderr)
