"""Device profiles: the TOML files in ``configs/profiles/`` as validated, frozen dataclasses.

Every fact about an instrument that is not fixed by a public document (PROTOCOLS.md)
lives in a profile, so a lab can correct it from its own manual without touching Python.
Both the drivers (``drivers.modbus_stepper``, ``drivers.stil``, ``drivers.glossmeter``)
and the simulated lab (``sim.wire``) read the same profile, so they speak the same bytes.

Loading
-------
``load_profile(name_or_path)`` returns one of :class:`StepperProfile`,
:class:`StilProfile`, :class:`ZgmProfile`, :class:`LineGlossProfile` (dispatching on the
top-level ``kind`` key); the typed loaders ``load_stepper_profile``, ``load_stil_profile``,
``load_zgm_profile`` and ``load_line_gloss_profile`` also check the kind. A bare name such
as ``"oriental-az"`` means ``configs/profiles/oriental-az.toml``; anything ending in
``.toml`` or containing a path separator is a path. Every problem raises
:class:`drivers.base.ProfileError` whose message names the file, the key and the reason.
Unknown keys are errors too (a typo must not silently fall back to a default).

Schema common to every profile
------------------------------
``kind``           one of ``"modbus-stepper"``, ``"stil-spectro"``, ``"zgm1120"``, ``"line-gloss"``
``name``           short identifier (normally the file stem)
``description``    free text
``unconfirmed``    list of dotted keys (``"registers.command_position"``) whose values are
                   not confirmed by a public source. Every listed key must exist.
``[serial]``       ``baudrate`` (int), ``bytesize`` (5..8, default 8), ``parity``
                   (``"N"``, ``"E"``, ``"O"``, default ``"N"``), ``stopbits`` (1 or 2, default 1).

kind = "modbus-stepper"
-----------------------
All 32-bit values are two registers, high word first (pymodbus ``word_order="big"``), signed.
``register_base``  0 when the file gives protocol addresses (Oriental Motor), 40001 when it
                   gives Modicon holding-register numbers (Applied Motion); the loader
                   subtracts it, so every address in :class:`StepperRegisters` is a 0-based
                   protocol address.
``move_style``     ``"direct-data"`` (Oriental AZ) or ``"command-opcode"`` (Applied Motion).

``[registers]`` (addresses of the FIRST register of each field)
    ``output_status``      32-bit status word; bits named in ``[status_bits]`` count from the
                           least significant bit of the 32-bit value.
    ``alarm_code``         32-bit present alarm code (0 = no alarm).
    ``feedback_position``  32-bit signed encoder position in steps.
    ``command_position``   optional, 32-bit signed commanded position in steps.
    direct-data only:
    ``input_command``      32-bit driver input command (latched); bits in ``[input_bits]``.
    ``direct_data``        first register of the 18-register direct-data block, field order
                           fixed by the AZ manual: data number, operation type, position
                           [steps], speed [counts], acceleration [counts], deceleration
                           [counts], operating current [0.1 %], trigger, destination; each a
                           32-bit pair.
    command-opcode only:
    ``command``            16-bit command register that receives an opcode.
    ``accel``, ``decel``, ``velocity``   16-bit registers (counts, see ``[units]``).
    ``target_position``    32-bit signed target position in steps.

``[status_bits]``  bit numbers: ``in_position``, ``moving``, ``alarm`` required; ``ready``,
                   ``busy``, ``home_end``, ``fault``, ``homing``, ``stopping`` optional.
``[input_bits]``   (direct-data) ``start``, ``zhome``, ``stop``, ``free``, ``alarm_reset``,
                   ``fw_pos``, ``rv_pos``. The driver pulses a bit: it writes the 32-bit
                   word with only that bit set, then writes 0; the device acts on the
                   rising edge.
``[direct_data]``  (direct-data) ``data_number``, ``operation_type`` (1 = absolute),
                   ``current`` (0.1 %), ``trigger`` (1 = start), ``destination`` (0 = now).
``[opcodes]``      (command-opcode) ``absolute_move``, ``relative_move``, ``enable``,
                   ``disable``, ``stop``, ``home``, ``alarm_reset``.
``[units]``        register counts per physical unit, either directly
                   ``speed_counts_per_step_s`` and ``accel_counts_per_step_s2`` or, for drives
                   that count motor revolutions, ``steps_per_rev`` with
                   ``speed_counts_per_rev_s`` and ``accel_counts_per_rev_s2`` (the loader
                   divides by ``steps_per_rev``). Register value = round(physical * counts).

Move sequences (what goes on the wire; the simulator must accept exactly these):
    direct-data:    one function-16 write of the 18 registers at ``direct_data`` with
                    trigger = ``direct_data.trigger``; the move starts on that write.
    command-opcode: function 16 writes of ``accel``, ``decel``, ``velocity`` (1 register each),
                    ``target_position`` (2 registers), then a function-16 write of
                    ``opcodes.absolute_move`` to ``command``.
    stop / home / alarm reset: direct-data pulses ``input_bits.stop`` / ``zhome`` /
                    ``alarm_reset``; command-opcode writes ``opcodes.stop`` / ``home`` /
                    ``alarm_reset`` (then ``enable``) to ``command``.
    connect:        command-opcode writes ``opcodes.enable`` to ``command``; direct-data
                    writes nothing.

kind = "stil-spectro"
---------------------
The STIL Ruby raw command set is NOT public; the whole command table is a design of ours.
``command_terminator`` / ``reply_terminator``  strings appended to commands / ending replies.
``encoding``       text encoding (``"ascii"``).
``timeout_s``      reply timeout; a measurement waits ``timeout_s + exposure``.
``[exposure]``     ``min_us``, ``max_us``, ``default_us``.
``[commands]``     ``identify``, ``set_exposure`` (may use ``{exposure_us}``), ``measure``.
``[replies]``      reply line templates in :meth:`str.format` syntax (the driver tries
                   ``error`` first, then the expected reply). ``identify``,
                   ``set_exposure`` (one line each) and ``measure`` (a list of lines, in order)
                   use the fields ``ident`` (text), ``exposure_us`` (int),
                   ``luminance_pct`` (float), ``start_nm``, ``step_nm``, ``count`` (int) and
                   ``values`` (``count`` comma-separated floats, % of the reference). ``error``
                   is the line the device sends instead of any reply, fields ``code`` (int)
                   and ``message`` (text). :func:`template_regex` turns a template into the
                   regex the driver matches; the simulator calls ``template.format(...)``.

kind = "zgm1120"
----------------
The protocol is fixed in ``drivers.glossmeter``; the profile holds ``reply_terminator``,
``timeout_s`` and ``[serial]``.

kind = "line-gloss"
-------------------
``pattern``        regex with named groups ``g20``, ``g60``, ``g85`` (at least one) and
                   optionally ``temperature``; a group that did not take part is "not measured".
``overflow_tokens`` strings that mean "over range" in a value group.
``trigger``        command sent to request a reading (``""``: the meter only pushes lines).
``line_terminator``, ``encoding``, ``timeout_s``, ``[serial]``.
"""

from __future__ import annotations

import re
import string
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from drivers.base import ProfileError

__all__ = [
    "PROFILES_DIR",
    "DirectDataDefaults",
    "InputBits",
    "LineGlossProfile",
    "Opcodes",
    "Profile",
    "SerialSettings",
    "StatusBits",
    "StepperProfile",
    "StepperRegisters",
    "StilProfile",
    "ZgmProfile",
    "load_line_gloss_profile",
    "load_profile",
    "load_stepper_profile",
    "load_stil_profile",
    "load_zgm_profile",
    "profile_path",
    "template_regex",
]


def _find_profiles_dir() -> Path:
    here = Path(__file__).resolve().parent
    for candidate in (
        here.parent / "configs" / "profiles",  # source checkout / editable install
        here.parent / "goniolab" / "_configs" / "profiles",  # wheel (force-include)
    ):
        if candidate.is_dir():
            return candidate
    return here.parent / "configs" / "profiles"


#: Directory holding the built-in profiles.
PROFILES_DIR: Path = _find_profiles_dir()


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True, slots=True)
class SerialSettings:
    """Serial line settings (also used for Modbus RTU)."""

    baudrate: int
    bytesize: int = 8
    parity: str = "N"
    stopbits: int = 1


@dataclass(frozen=True, slots=True)
class StepperRegisters:
    """0-based protocol addresses of a stepper controller's registers (see module doc)."""

    output_status: int
    alarm_code: int
    feedback_position: int
    command_position: int | None = None
    input_command: int | None = None
    direct_data: int | None = None
    command: int | None = None
    accel: int | None = None
    decel: int | None = None
    velocity: int | None = None
    target_position: int | None = None


@dataclass(frozen=True, slots=True)
class StatusBits:
    """Bit numbers (from the LSB of the 32-bit status word); ``None`` = not available."""

    in_position: int
    moving: int
    alarm: int
    ready: int | None = None
    busy: int | None = None
    home_end: int | None = None
    fault: int | None = None
    homing: int | None = None
    stopping: int | None = None


@dataclass(frozen=True, slots=True)
class InputBits:
    """Bit numbers of the 32-bit driver input command word (direct-data style)."""

    start: int
    zhome: int
    stop: int
    free: int
    alarm_reset: int
    fw_pos: int
    rv_pos: int


@dataclass(frozen=True, slots=True)
class DirectDataDefaults:
    """Constant fields of the direct-data block."""

    data_number: int = 0
    operation_type: int = 1
    current: int = 1000
    trigger: int = 1
    destination: int = 0


@dataclass(frozen=True, slots=True)
class Opcodes:
    """Command-register opcodes (command-opcode style)."""

    absolute_move: int
    relative_move: int
    enable: int
    disable: int
    stop: int
    home: int
    alarm_reset: int


@dataclass(frozen=True, slots=True)
class StepperProfile:
    """A Modbus stepper controller register map (``kind = "modbus-stepper"``)."""

    name: str
    path: Path
    description: str
    move_style: Literal["direct-data", "command-opcode"]
    serial: SerialSettings
    registers: StepperRegisters
    status_bits: StatusBits
    speed_counts_per_step_s: float
    accel_counts_per_step_s2: float
    input_bits: InputBits | None = None
    direct_data: DirectDataDefaults | None = None
    opcodes: Opcodes | None = None
    unconfirmed: tuple[str, ...] = ()
    kind: str = "modbus-stepper"


@dataclass(frozen=True, slots=True)
class StilProfile:
    """The STIL spectro-colorimeter line protocol (``kind = "stil-spectro"``)."""

    name: str
    path: Path
    description: str
    serial: SerialSettings
    command_terminator: str
    reply_terminator: str
    encoding: str
    timeout_s: float
    exposure_min_us: int
    exposure_max_us: int
    exposure_default_us: int
    cmd_identify: str
    cmd_set_exposure: str
    cmd_measure: str
    reply_identify: str
    reply_set_exposure: str
    reply_measure: tuple[str, ...]
    reply_error: str
    unconfirmed: tuple[str, ...] = ()
    kind: str = "stil-spectro"


@dataclass(frozen=True, slots=True)
class ZgmProfile:
    """Serial settings of a Zehntner ZGM1120 (``kind = "zgm1120"``)."""

    name: str
    path: Path
    description: str
    serial: SerialSettings
    reply_terminator: str
    timeout_s: float
    unconfirmed: tuple[str, ...] = ()
    kind: str = "zgm1120"


@dataclass(frozen=True, slots=True)
class LineGlossProfile:
    """A glossmeter that prints one line per reading (``kind = "line-gloss"``)."""

    name: str
    path: Path
    description: str
    serial: SerialSettings
    pattern: re.Pattern[str]
    overflow_tokens: tuple[str, ...]
    trigger: str
    line_terminator: str
    encoding: str
    timeout_s: float
    unconfirmed: tuple[str, ...] = ()
    kind: str = "line-gloss"


Profile = StepperProfile | StilProfile | ZgmProfile | LineGlossProfile


# --------------------------------------------------------------------------- templates
#: Regex for each template field of the STIL protocol.
TEMPLATE_FIELDS: dict[str, str] = {
    "ident": r".+?",
    "message": r".*?",
    "code": r"-?\d+",
    "exposure_us": r"\d+",
    "start_nm": r"\d+(?:\.\d+)?",
    "step_nm": r"\d+(?:\.\d+)?",
    "count": r"\d+",
    "luminance_pct": r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?",
    "values": r"[-+0-9.eE]+(?:,[-+0-9.eE]+)*",
}


def template_regex(template: str) -> re.Pattern[str]:
    """Compile a reply template (``"Y={luminance_pct:.4f}"``) into an anchored regex.

    Literal text is matched exactly; each ``{field}`` becomes a named group using the
    pattern in :data:`TEMPLATE_FIELDS` (format specs are ignored when parsing).

    Raises
    ------
    ValueError
        If the template uses an unknown field, a positional field or is malformed.
    """
    parts: list[str] = []
    seen: set[str] = set()
    for literal, field_name, _spec, _conv in string.Formatter().parse(template):
        parts.append(re.escape(literal))
        if field_name is None:
            continue
        if field_name not in TEMPLATE_FIELDS:
            raise ValueError(
                f"unknown field {{{field_name}}}; known: {', '.join(sorted(TEMPLATE_FIELDS))}"
            )
        if field_name in seen:
            parts.append(f"(?P={field_name})")
        else:
            parts.append(f"(?P<{field_name}>{TEMPLATE_FIELDS[field_name]})")
            seen.add(field_name)
    return re.compile("^" + "".join(parts) + "$")


# --------------------------------------------------------------------------- reader
class _Table:
    """Typed access to one TOML table with errors naming file and dotted key."""

    def __init__(self, path: Path, data: Mapping[str, Any], prefix: str = "") -> None:
        self.path = path
        self.data = data
        self.prefix = prefix
        self.used: set[str] = set()

    def key(self, key: str) -> str:
        return f"{self.prefix}{key}"

    def error(self, key: str, reason: str) -> ProfileError:
        return ProfileError(f"{self.path}: key '{self.key(key)}': {reason}")

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any, required: bool) -> Any:
        self.used.add(key)
        if key not in self.data:
            if required:
                raise self.error(key, "missing")
            return default
        return self.data[key]

    def get_int(
        self,
        key: str,
        default: int | None = None,
        *,
        required: bool = True,
        lo: int | None = None,
        hi: int | None = None,
    ) -> int:
        value = self._get(key, default, required and default is None)
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.error(key, f"expected an integer, got {value!r}")
        if lo is not None and value < lo:
            raise self.error(key, f"{value} is below the minimum {lo}")
        if hi is not None and value > hi:
            raise self.error(key, f"{value} is above the maximum {hi}")
        return value

    def opt_int(self, key: str, *, lo: int | None = None, hi: int | None = None) -> int | None:
        if key not in self.data:
            self.used.add(key)
            return None
        return self.get_int(key, lo=lo, hi=hi)

    def get_float(self, key: str, default: float | None = None, *, positive: bool = False) -> float:
        value = self._get(key, default, default is None)
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise self.error(key, f"expected a number, got {value!r}")
        if positive and not value > 0:
            raise self.error(key, f"must be > 0, got {value!r}")
        return float(value)

    def get_str(self, key: str, default: str | None = None, *, nonempty: bool = False) -> str:
        value = self._get(key, default, default is None)
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {value!r}")
        if nonempty and not value:
            raise self.error(key, "must not be empty")
        return value

    def str_list(self, key: str, default: list[str] | None = None) -> tuple[str, ...]:
        value = self._get(key, default, default is None)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(key, f"expected a list of strings, got {value!r}")
        return tuple(value)

    def get_table(self, key: str, *, required: bool = True) -> _Table:
        value = self._get(key, {}, required)
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {value!r}")
        return _Table(self.path, value, f"{self.prefix}{key}.")

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.error(unknown[0], "unknown key (typo?)")


def _serial(top: _Table, default_parity: str = "N") -> SerialSettings:
    t = top.get_table("serial")
    parity = t.get_str("parity", default_parity)
    if parity not in ("N", "E", "O"):
        raise t.error("parity", f"expected 'N', 'E' or 'O', got {parity!r}")
    stopbits = t.get_int("stopbits", 1)
    if stopbits not in (1, 2):
        raise t.error("stopbits", f"expected 1 or 2, got {stopbits}")
    settings = SerialSettings(
        baudrate=t.get_int("baudrate", lo=300, hi=4_000_000),
        bytesize=t.get_int("bytesize", 8, lo=5, hi=8),
        parity=parity,
        stopbits=stopbits,
    )
    t.finish()
    return settings


def _check_unconfirmed(top: _Table, data: Mapping[str, Any]) -> tuple[str, ...]:
    keys = top.str_list("unconfirmed", [])
    for dotted in keys:
        node: Any = data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                raise top.error("unconfirmed", f"lists {dotted!r}, which is not a key of the file")
            node = node[part]
    return keys


def _bit(t: _Table, key: str, *, required: bool = True) -> int | None:
    if not required and not t.has(key):
        t.used.add(key)
        return None
    return t.get_int(key, lo=0, hi=31)


# --------------------------------------------------------------------------- per kind
def _stepper(path: Path, top: _Table, data: Mapping[str, Any]) -> StepperProfile:
    style = top.get_str("move_style")
    if style not in ("direct-data", "command-opcode"):
        raise top.error("move_style", f"expected 'direct-data' or 'command-opcode', got {style!r}")
    base = top.get_int("register_base", 0)
    if base not in (0, 40001):
        raise top.error("register_base", f"expected 0 or 40001, got {base}")

    reg = top.get_table("registers")

    def addr(key: str, *, required: bool = True) -> int | None:
        if not required and not reg.has(key):
            reg.used.add(key)
            return None
        value = reg.get_int(key, lo=base, hi=base + 0xFFFF)
        return value - base

    needed_dd = style == "direct-data"
    registers = StepperRegisters(
        output_status=addr("output_status") or 0,
        alarm_code=addr("alarm_code") or 0,
        feedback_position=addr("feedback_position") or 0,
        command_position=addr("command_position", required=False),
        input_command=addr("input_command", required=needed_dd),
        direct_data=addr("direct_data", required=needed_dd),
        command=addr("command", required=not needed_dd),
        accel=addr("accel", required=not needed_dd),
        decel=addr("decel", required=not needed_dd),
        velocity=addr("velocity", required=not needed_dd),
        target_position=addr("target_position", required=not needed_dd),
    )
    reg.finish()

    sb = top.get_table("status_bits")
    status_bits = StatusBits(
        in_position=_bit(sb, "in_position") or 0,
        moving=_bit(sb, "moving") or 0,
        alarm=_bit(sb, "alarm") or 0,
        ready=_bit(sb, "ready", required=False),
        busy=_bit(sb, "busy", required=False),
        home_end=_bit(sb, "home_end", required=False),
        fault=_bit(sb, "fault", required=False),
        homing=_bit(sb, "homing", required=False),
        stopping=_bit(sb, "stopping", required=False),
    )
    sb.finish()

    input_bits = direct = None
    opcodes = None
    if needed_dd:
        ib = top.get_table("input_bits")
        input_bits = InputBits(
            **{k: ib.get_int(k, lo=0, hi=31) for k in InputBits.__dataclass_fields__}
        )
        ib.finish()
        dd = top.get_table("direct_data")
        direct = DirectDataDefaults(
            data_number=dd.get_int("data_number", 0, lo=0),
            operation_type=dd.get_int("operation_type", 1, lo=0),
            current=dd.get_int("current", 1000, lo=0, hi=1000),
            trigger=dd.get_int("trigger", 1),
            destination=dd.get_int("destination", 0, lo=0, hi=1),
        )
        dd.finish()
    else:
        op = top.get_table("opcodes")
        opcodes = Opcodes(
            **{k: op.get_int(k, lo=0, hi=0xFFFF) for k in Opcodes.__dataclass_fields__}
        )
        op.finish()

    un = top.get_table("units")
    if un.has("speed_counts_per_step_s"):
        speed = un.get_float("speed_counts_per_step_s", positive=True)
        accel = un.get_float("accel_counts_per_step_s2", positive=True)
    else:
        steps_per_rev = un.get_float("steps_per_rev", positive=True)
        speed = un.get_float("speed_counts_per_rev_s", positive=True) / steps_per_rev
        accel = un.get_float("accel_counts_per_rev_s2", positive=True) / steps_per_rev
    un.finish()

    return StepperProfile(
        name=top.get_str("name", nonempty=True),
        path=path,
        description=top.get_str("description", ""),
        move_style="direct-data" if needed_dd else "command-opcode",
        serial=_serial(top, "E"),
        registers=registers,
        status_bits=status_bits,
        speed_counts_per_step_s=speed,
        accel_counts_per_step_s2=accel,
        input_bits=input_bits,
        direct_data=direct,
        opcodes=opcodes,
        unconfirmed=_check_unconfirmed(top, data),
    )


def _template(t: _Table, key: str, value: str) -> str:
    try:
        template_regex(value)
    except ValueError as exc:
        raise t.error(key, f"bad reply template {value!r}: {exc}") from None
    return value


def _stil(path: Path, top: _Table, data: Mapping[str, Any]) -> StilProfile:
    ex = top.get_table("exposure")
    lo = ex.get_int("min_us", lo=1)
    hi = ex.get_int("max_us", lo=lo)
    default = ex.get_int("default_us", lo=lo, hi=hi)
    ex.finish()
    cmd = top.get_table("commands")
    identify = cmd.get_str("identify", nonempty=True)
    set_exposure = cmd.get_str("set_exposure", nonempty=True)
    try:
        set_exposure.format(exposure_us=1)
    except (KeyError, IndexError, ValueError) as exc:
        raise cmd.error("set_exposure", f"bad template {set_exposure!r}: {exc}") from None
    measure = cmd.get_str("measure", nonempty=True)
    cmd.finish()
    rep = top.get_table("replies")
    r_identify = _template(rep, "identify", rep.get_str("identify", nonempty=True))
    r_exposure = _template(rep, "set_exposure", rep.get_str("set_exposure", nonempty=True))
    r_measure = rep.str_list("measure")
    if not r_measure:
        raise rep.error("measure", "must list at least one reply line")
    for line in r_measure:
        _template(rep, "measure", line)
    fields = {f for line in r_measure for _, f, _, _ in string.Formatter().parse(line) if f}
    missing = {"luminance_pct", "values"} - fields
    if missing:
        raise rep.error("measure", f"templates lack the field(s) {sorted(missing)}")
    r_error = _template(rep, "error", rep.get_str("error", nonempty=True))
    rep.finish()
    encoding = top.get_str("encoding", "ascii")
    try:
        "".encode(encoding)
    except LookupError:
        raise top.error("encoding", f"unknown encoding {encoding!r}") from None
    return StilProfile(
        name=top.get_str("name", nonempty=True),
        path=path,
        description=top.get_str("description", ""),
        serial=_serial(top),
        command_terminator=top.get_str("command_terminator", nonempty=True),
        reply_terminator=top.get_str("reply_terminator", nonempty=True),
        encoding=encoding,
        timeout_s=top.get_float("timeout_s", positive=True),
        exposure_min_us=lo,
        exposure_max_us=hi,
        exposure_default_us=default,
        cmd_identify=identify,
        cmd_set_exposure=set_exposure,
        cmd_measure=measure,
        reply_identify=r_identify,
        reply_set_exposure=r_exposure,
        reply_measure=r_measure,
        reply_error=r_error,
        unconfirmed=_check_unconfirmed(top, data),
    )


def _zgm(path: Path, top: _Table, data: Mapping[str, Any]) -> ZgmProfile:
    return ZgmProfile(
        name=top.get_str("name", nonempty=True),
        path=path,
        description=top.get_str("description", ""),
        serial=_serial(top),
        reply_terminator=top.get_str("reply_terminator", nonempty=True),
        timeout_s=top.get_float("timeout_s", positive=True),
        unconfirmed=_check_unconfirmed(top, data),
    )


def _line_gloss(path: Path, top: _Table, data: Mapping[str, Any]) -> LineGlossProfile:
    raw = top.get_str("pattern", nonempty=True)
    try:
        pattern = re.compile(raw)
    except re.error as exc:
        raise top.error("pattern", f"invalid regex: {exc}") from None
    groups = set(pattern.groupindex)
    if not groups & {"g20", "g60", "g85"}:
        raise top.error("pattern", "needs at least one named group g20, g60 or g85")
    extra = groups - {"g20", "g60", "g85", "temperature"}
    if extra:
        raise top.error("pattern", f"unknown named group(s) {sorted(extra)}")
    encoding = top.get_str("encoding", "ascii")
    try:
        "".encode(encoding)
    except LookupError:
        raise top.error("encoding", f"unknown encoding {encoding!r}") from None
    return LineGlossProfile(
        name=top.get_str("name", nonempty=True),
        path=path,
        description=top.get_str("description", ""),
        serial=_serial(top),
        pattern=pattern,
        overflow_tokens=top.str_list("overflow_tokens", []),
        trigger=top.get_str("trigger", ""),
        line_terminator=top.get_str("line_terminator", nonempty=True),
        encoding=encoding,
        timeout_s=top.get_float("timeout_s", positive=True),
        unconfirmed=_check_unconfirmed(top, data),
    )


_KINDS: dict[str, Callable[[Path, _Table, Mapping[str, Any]], Profile]] = {
    "modbus-stepper": _stepper,
    "stil-spectro": _stil,
    "zgm1120": _zgm,
    "line-gloss": _line_gloss,
}


# --------------------------------------------------------------------------- public
def profile_path(name_or_path: str | Path) -> Path:
    """Resolve a profile name (``"oriental-az"``) or a path to a file path."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".toml") or "/" in text or "\\" in text:
        return Path(name_or_path)
    return PROFILES_DIR / f"{text}.toml"


def load_profile(name_or_path: str | Path) -> Profile:
    """Load and validate a profile by name or path.

    Raises
    ------
    ProfileError
        File missing or unreadable, TOML syntax error, missing/unknown key, wrong type or
        out-of-range value; the message names the file, the key and the reason.
    """
    path = profile_path(name_or_path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        known = sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))
        raise ProfileError(
            f"{path}: profile file not found (built-in profiles: {', '.join(known)})"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"{path}: cannot read profile: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{path}: TOML syntax error: {exc}") from None
    top = _Table(path, data)
    kind = top.get_str("kind")
    if kind not in _KINDS:
        raise top.error("kind", f"expected one of {sorted(_KINDS)}, got {kind!r}")
    profile = _KINDS[kind](path, top, data)
    top.finish()
    return profile


def _typed(name_or_path: str | Path, cls: type[Any]) -> Any:
    profile = load_profile(name_or_path)
    if not isinstance(profile, cls):
        raise ProfileError(
            f"{profile.path}: key 'kind': expected {cls.__dataclass_fields__['kind'].default!r}, "
            f"got {profile.kind!r}"
        )
    return profile


def load_stepper_profile(name_or_path: str | Path) -> StepperProfile:
    """Load a ``kind = "modbus-stepper"`` profile (see :func:`load_profile`)."""
    result: StepperProfile = _typed(name_or_path, StepperProfile)
    return result


def load_stil_profile(name_or_path: str | Path) -> StilProfile:
    """Load a ``kind = "stil-spectro"`` profile (see :func:`load_profile`)."""
    result: StilProfile = _typed(name_or_path, StilProfile)
    return result


def load_zgm_profile(name_or_path: str | Path) -> ZgmProfile:
    """Load a ``kind = "zgm1120"`` profile (see :func:`load_profile`)."""
    result: ZgmProfile = _typed(name_or_path, ZgmProfile)
    return result


def load_line_gloss_profile(name_or_path: str | Path) -> LineGlossProfile:
    """Load a ``kind = "line-gloss"`` profile (see :func:`load_profile`)."""
    result: LineGlossProfile = _typed(name_or_path, LineGlossProfile)
    return result
