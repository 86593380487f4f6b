"""Device profiles: the TOML files in ``configs/profiles/`` as validated, frozen dataclasses.

Every fact about an instrument that is not fixed by a public document lives in a profile,
so a lab can correct it from its own manual without touching Python. Each address, opcode
and scaling in the built-in profiles is listed, with its source and a confidence mark
(confirmed / inferred / unconfirmed), in ``docs/PROTOCOLS.md`` (a test checks it).
Both the drivers (``drivers.modbus_stepper``, ``drivers.stil``, ``drivers.glossmeter``)
and the simulated lab (``sim.wire``) read the same profile, so they speak the same bytes.

Each kind of file is a pydantic model (``_StepperFile``, ``_StilFile``, ``_ZgmFile``,
``_LineGlossFile``: the schema below, as code); the small tables (``[serial]``,
``[status_bits]``, ``[input_bits]``, ``[direct_data]``, ``[opcodes]``) are pydantic
dataclasses that the profile objects carry as they are. Types are strict: ``true`` is not
a number, ``"0x7E"`` is not an integer, ``1.0`` is not an integer.

Loading
-------
``load_profile(name_or_path)`` returns one of :class:`StepperProfile`,
:class:`StilProfile`, :class:`ZgmProfile`, :class:`LineGlossProfile` (dispatching on the
top-level ``kind`` key); the typed loaders ``load_stepper_profile``, ``load_stil_profile``,
``load_zgm_profile`` and ``load_line_gloss_profile`` also check the kind. A bare name such
as ``"oriental-az"`` means ``configs/profiles/oriental-az.toml``; anything ending in
``.toml`` or containing a path separator is a path. Every problem raises
:class:`drivers.base.ProfileError` whose message names the file, the key and the reason
(``oriental-az.toml: key 'status_bits.moving': 40 is above the maximum 31``; the first
problem found). Unknown keys are errors too (a typo must not silently fall back to a default).

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

``single_register_fields``  (optional) names among ``output_status`` and ``alarm_code``
                   that are ONE 16-bit register on this drive (Applied Motion ST-Q: alarm
                   code 40001 and status code 40002 are SHORT, 920-0072 p. 7); the driver
                   and the simulator then read / serve one register instead of a pair.
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
The protocol is fixed in ``drivers.glossmeter`` (Zehntner ZGM 1120 technical manual
rev 3.0, docs/PROTOCOLS.md); the profile holds ``reply_terminator``, ``timeout_s``,
``[serial]`` and ``led_argument`` (the ``LED`` argument of ControlLEDOn/Off, opcodes 48/52,
whose encoding the manual's retrieved pages do not give: unconfirmed, default 1).

kind = "line-gloss"
-------------------
``pattern``        regex with named groups ``g20``, ``g60``, ``g85`` (at least one) and
                   optionally ``temperature``; a group that did not take part is "not measured".
``overflow_tokens`` strings that mean "over range" in a value group.
``trigger``        command sent to request a reading (``""``: the meter only pushes lines).
``line_terminator``, ``encoding``, ``timeout_s``, ``[serial]``.
"""

from __future__ import annotations

import dataclasses
import re
import string
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Self, TypeVar

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ModelWrapValidatorHandler,
    Strict,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic.dataclasses import dataclass as table

from drivers.base import ProfileError
from drivers.toml_schema import (
    KeyedValueError,
    TomlFileError,
    first_issue,
    plain_reason,
    read_toml,
    short_repr,
)

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


# --------------------------------------------------------------------------- value types
def _one_of(*allowed: int) -> AfterValidator:
    def check(value: int) -> int:
        if value not in allowed:
            raise ValueError(f"expected {' or '.join(map(str, allowed))}, got {value}")
        return value

    return AfterValidator(check)


def _known_encoding(value: str) -> str:
    try:
        "".encode(value)
    except LookupError:
        raise ValueError(f"unknown encoding {short_repr(value)}") from None
    return value


#: Each field of the direct-data block is a signed 32-bit register pair.
_INT32_MAX = 2**31 - 1

#: Strict scalars: TOML ``true`` is not a number, ``"0x7E"`` and ``1.0`` are not integers.
Int = Annotated[int, Strict()]
Bit = Annotated[int, Strict(), Field(ge=0, le=31)]
Word = Annotated[int, Strict(), Field(ge=0, le=0xFFFF)]
Address = Annotated[int, Strict(), Field(ge=0)]
Positive = Annotated[float, Strict(), Field(gt=0, allow_inf_nan=False)]
Text = Annotated[str, Strict()]
NonEmpty = Annotated[str, Strict(), Field(min_length=1)]
Encoding = Annotated[str, Strict(), AfterValidator(_known_encoding)]

_TABLE = ConfigDict(extra="forbid")


# --------------------------------------------------------------------------- tables
@table(frozen=True, slots=True, config=_TABLE)
class SerialSettings:
    """Serial line settings (also used for Modbus RTU)."""

    baudrate: Annotated[int, Strict(), Field(ge=300, le=4_000_000)]
    bytesize: Annotated[int, Strict(), Field(ge=5, le=8)] = 8
    parity: Literal["N", "E", "O"] = "N"
    stopbits: Annotated[int, Strict(), _one_of(1, 2)] = 1


@table(frozen=True, slots=True, config=_TABLE)
class StepperRegisters:
    """0-based protocol addresses of a stepper controller's registers (see module doc).

    While a file is validated the fields hold the numbers as written; the loader then
    subtracts ``register_base``.
    """

    output_status: Address
    alarm_code: Address
    feedback_position: Address
    command_position: Address | None = None
    input_command: Address | None = None
    direct_data: Address | None = None
    command: Address | None = None
    accel: Address | None = None
    decel: Address | None = None
    velocity: Address | None = None
    target_position: Address | None = None


@table(frozen=True, slots=True, config=_TABLE)
class StatusBits:
    """Bit numbers (from the LSB of the 32-bit status word); ``None`` = not available."""

    in_position: Bit
    moving: Bit
    alarm: Bit
    ready: Bit | None = None
    busy: Bit | None = None
    home_end: Bit | None = None
    fault: Bit | None = None
    homing: Bit | None = None
    stopping: Bit | None = None


@table(frozen=True, slots=True, config=_TABLE)
class InputBits:
    """Bit numbers of the 32-bit driver input command word (direct-data style)."""

    start: Bit
    zhome: Bit
    stop: Bit
    free: Bit
    alarm_reset: Bit
    fw_pos: Bit
    rv_pos: Bit


@table(frozen=True, slots=True, config=_TABLE)
class DirectDataDefaults:
    """Constant fields of the direct-data block."""

    data_number: Annotated[int, Strict(), Field(ge=0, le=_INT32_MAX)] = 0
    operation_type: Annotated[int, Strict(), Field(ge=0, le=_INT32_MAX)] = 1
    current: Annotated[int, Strict(), Field(ge=0, le=1000)] = 1000
    trigger: Annotated[int, Strict(), Field(ge=-_INT32_MAX - 1, le=_INT32_MAX)] = 1
    destination: Annotated[int, Strict(), Field(ge=0, le=1)] = 0


@table(frozen=True, slots=True, config=_TABLE)
class Opcodes:
    """Command-register opcodes (command-opcode style)."""

    absolute_move: Word
    relative_move: Word
    enable: Word
    disable: Word
    stop: Word
    home: Word
    alarm_reset: Word


# --------------------------------------------------------------------------- profiles
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
    single_register_fields: tuple[str, ...] = ()
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
    led_argument: int = 1
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
    # counts of the strongest channel over full scale (1 = saturated); -1: not reported
    "peak_fraction": r"-1|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?",
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


def _reply_template(value: str) -> str:
    try:
        template_regex(value)
    except ValueError as exc:
        raise ValueError(f"bad reply template {short_repr(value)}: {exc}") from None
    return value


ReplyTemplate = Annotated[str, Strict(), Field(min_length=1), AfterValidator(_reply_template)]


# --------------------------------------------------------------------------- file schema
class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _is_key(data: Any, dotted: str) -> bool:
    node = data
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return False
        node = node[part]
    return True


class _File(_Section):
    """The keys every profile has (module doc, "Schema common to every profile")."""

    name: NonEmpty
    description: Text = ""
    unconfirmed: list[Text] = []
    serial: SerialSettings

    @model_validator(mode="wrap")
    @classmethod
    def _unconfirmed_keys_exist(cls, data: Any, handler: ModelWrapValidatorHandler[Self]) -> Self:
        checked = handler(data)  # every other key first: a typo is reported as such
        for dotted in checked.unconfirmed:
            if not _is_key(data, dotted):
                raise KeyedValueError(
                    "unconfirmed", f"lists {dotted!r}, which is not a key of the file"
                )
        return checked


class _Units(_Section):
    """``[units]``: register counts per step, given per step or per motor revolution."""

    speed_counts_per_step_s: Positive | None = None
    accel_counts_per_step_s2: Positive | None = None
    steps_per_rev: Positive | None = None
    speed_counts_per_rev_s: Positive | None = None
    accel_counts_per_rev_s2: Positive | None = None

    @model_validator(mode="after")
    def _one_convention(self) -> _Units:
        per_step = ("speed_counts_per_step_s", "accel_counts_per_step_s2")
        per_rev = ("steps_per_rev", "speed_counts_per_rev_s", "accel_counts_per_rev_s2")
        given, other = (
            (per_step, per_rev) if self.speed_counts_per_step_s is not None else (per_rev, per_step)
        )
        for key in given:
            if getattr(self, key) is None:
                raise KeyedValueError(key, "missing")
        for key in other:
            if getattr(self, key) is not None:
                raise KeyedValueError(key, f"give either {' and '.join(given)} or {key}, not both")
        return self

    def counts_per_step(self) -> tuple[float, float]:
        """(speed counts per step/s, acceleration counts per step/s^2)."""
        if self.speed_counts_per_step_s is not None and self.accel_counts_per_step_s2 is not None:
            return self.speed_counts_per_step_s, self.accel_counts_per_step_s2
        assert self.steps_per_rev and self.speed_counts_per_rev_s and self.accel_counts_per_rev_s2
        return (
            self.speed_counts_per_rev_s / self.steps_per_rev,
            self.accel_counts_per_rev_s2 / self.steps_per_rev,
        )


_STYLE_REGISTERS: dict[str, tuple[str, ...]] = {
    "direct-data": ("input_command", "direct_data"),
    "command-opcode": ("command", "accel", "decel", "velocity", "target_position"),
}
_STYLE_TABLES: dict[str, tuple[str, ...]] = {
    "direct-data": ("input_bits", "direct_data"),
    "command-opcode": ("opcodes",),
}


class _StepperFile(_File):
    """``kind = "modbus-stepper"``."""

    kind: Literal["modbus-stepper"]
    move_style: Literal["direct-data", "command-opcode"]
    register_base: Annotated[int, Strict(), _one_of(0, 40001)] = 0
    registers: StepperRegisters
    status_bits: StatusBits
    input_bits: InputBits | None = None
    direct_data: DirectDataDefaults | None = None
    opcodes: Opcodes | None = None
    units: _Units
    single_register_fields: list[Literal["output_status", "alarm_code"]] = []

    @field_validator("serial", mode="before")
    @classmethod
    def _rtu_parity_even(cls, value: Any) -> Any:
        # a stepper's serial line is Modbus RTU, whose default frame is 8 data bits, even parity
        return {"parity": "E", **value} if isinstance(value, dict) else value

    @model_validator(mode="after")
    def _style_and_base(self) -> _StepperFile:
        style = self.move_style
        for key, addr in _fields(self.registers).items():
            if addr is None:
                if key in _STYLE_REGISTERS[style]:
                    raise KeyedValueError(f"registers.{key}", "missing")
            elif addr < self.register_base:
                raise KeyedValueError(
                    f"registers.{key}", f"{addr} is below the minimum {self.register_base}"
                )
            elif addr > self.register_base + 0xFFFF:
                raise KeyedValueError(
                    f"registers.{key}",
                    f"{addr} is above the maximum {self.register_base + 0xFFFF}",
                )
        for styled, tables in _STYLE_TABLES.items():
            for key in tables:
                present = getattr(self, key) is not None
                if styled == style and not present:
                    raise KeyedValueError(key, "missing")
                if styled != style and present:
                    raise KeyedValueError(key, f"not used with move_style {style!r}")
        return self

    def profile(self, path: Path) -> StepperProfile:
        base = self.register_base
        numbers = _fields(self.registers).items()
        addresses = {k: v - base for k, v in numbers if v is not None}
        speed, accel = self.units.counts_per_step()
        return StepperProfile(
            name=self.name,
            path=path,
            description=self.description,
            move_style=self.move_style,
            serial=self.serial,
            registers=dataclasses.replace(self.registers, **addresses),
            status_bits=self.status_bits,
            speed_counts_per_step_s=speed,
            accel_counts_per_step_s2=accel,
            input_bits=self.input_bits,
            direct_data=self.direct_data,
            opcodes=self.opcodes,
            unconfirmed=tuple(self.unconfirmed),
            single_register_fields=tuple(self.single_register_fields),
        )


class _Exposure(_Section):
    min_us: Annotated[int, Strict(), Field(ge=1)]
    max_us: Int
    default_us: Int

    @model_validator(mode="after")
    def _ordered(self) -> _Exposure:
        if self.max_us < self.min_us:
            raise KeyedValueError("max_us", f"{self.max_us} is below the minimum {self.min_us}")
        if not self.min_us <= self.default_us <= self.max_us:
            raise KeyedValueError(
                "default_us",
                f"{self.default_us} is outside [min_us, max_us] = [{self.min_us}, {self.max_us}]",
            )
        return self


#: What ``str.format`` raises for a template that does not fit its fields.
_FORMAT_ERRORS = (KeyError, IndexError, ValueError, AttributeError, TypeError)

#: Values of the kind the simulator (``sim.wire.serial``) and a device put into each STIL
#: reply: identify, set_exposure, error, and the measure lines.
_IDENT: dict[str, Any] = {"ident": "STIL RUBY SN 000000"}
_ERROR: dict[str, Any] = {"code": 2, "message": "exposure out of range"}
_MEASURE: dict[str, Any] = {
    **_IDENT,
    "luminance_pct": 12.3456,
    "start_nm": 380,
    "step_nm": 5,
    "count": 12,
    "values": ",".join(f"{v:.4f}" for v in range(1, 13)),
    "peak_fraction": 0.4210,
}


def _reads_back(template: str, fields: dict[str, Any]) -> str | None:
    """Why a line written from ``template`` would not be read by it (``None``: it is).

    The simulator writes replies with ``template.format(...)`` and the driver reads them
    with :func:`template_regex`; a format spec such as ``{luminance_pct:d}`` or
    ``{count:x}`` passes the parse but breaks one of the two at run time.
    """
    try:
        line = template.format(**fields)
    except _FORMAT_ERRORS as exc:
        return f"cannot be written: {exc}"
    if template_regex(template).match(line) is None:
        return f"writes {line[:60]!r}, which it does not read back"
    return None


class _Commands(_Section):
    identify: NonEmpty
    set_exposure: NonEmpty
    measure: NonEmpty

    @field_validator("set_exposure")
    @classmethod
    def _formats(cls, value: str) -> str:
        try:
            value.format(exposure_us=1)
        except _FORMAT_ERRORS as exc:  # "{exposure_us.x}" is an AttributeError, "[0]" a TypeError
            raise ValueError(f"bad template {short_repr(value)}: {exc}") from None
        return value


class _Replies(_Section):
    identify: ReplyTemplate
    set_exposure: ReplyTemplate
    measure: list[Text]
    error: ReplyTemplate

    @field_validator("measure")
    @classmethod
    def _measure_lines(cls, lines: list[str]) -> list[str]:
        if not lines:
            raise ValueError("must list at least one reply line")
        for line in lines:
            _reply_template(line)
        fields = {f for line in lines for _, f, _, _ in string.Formatter().parse(line) if f}
        missing = {"luminance_pct", "values"} - fields
        if missing:
            raise ValueError(f"templates lack the field(s) {sorted(missing)}")
        return lines


class _StilFile(_File):
    """``kind = "stil-spectro"``."""

    kind: Literal["stil-spectro"]
    command_terminator: NonEmpty
    reply_terminator: NonEmpty
    encoding: Encoding = "ascii"
    timeout_s: Positive
    exposure: _Exposure
    commands: _Commands
    replies: _Replies

    @model_validator(mode="after")
    def _speaks_its_encoding(self) -> _StilFile:
        """Every line the driver or the simulator writes encodes in ``encoding`` and every
        reply reads back through its template (else the first reading fails, not the load)."""
        exposure = {"exposure_us": self.exposure.default_us}
        c, r = self.commands, self.replies
        texts = {
            "command_terminator": self.command_terminator,
            "reply_terminator": self.reply_terminator,
            "commands.identify": c.identify,
            "commands.set_exposure": c.set_exposure.format(**exposure),
            "commands.measure": c.measure,
        }
        replies = {
            "replies.identify": r.identify,
            "replies.set_exposure": r.set_exposure,
            "replies.error": r.error,
            **{f"replies.measure[{i}]": line for i, line in enumerate(r.measure)},
        }
        for key, text in {**texts, **replies}.items():
            try:
                text.encode(self.encoding)
            except UnicodeError:
                raise KeyedValueError(
                    key, f"{short_repr(text)} cannot be written in {self.encoding}"
                ) from None
        fields: dict[str, dict[str, Any]] = {
            "commands.set_exposure": exposure,
            "replies.identify": _IDENT,
            "replies.set_exposure": exposure,
            "replies.error": _ERROR,
        }
        for key, template in {"commands.set_exposure": c.set_exposure, **replies}.items():
            why = _reads_back(template, fields.get(key, {**_MEASURE, **exposure}))
            if why is not None:
                raise KeyedValueError(key, f"template {short_repr(template)} {why}")
        return self

    def profile(self, path: Path) -> StilProfile:
        return StilProfile(
            name=self.name,
            path=path,
            description=self.description,
            serial=self.serial,
            command_terminator=self.command_terminator,
            reply_terminator=self.reply_terminator,
            encoding=self.encoding,
            timeout_s=self.timeout_s,
            exposure_min_us=self.exposure.min_us,
            exposure_max_us=self.exposure.max_us,
            exposure_default_us=self.exposure.default_us,
            cmd_identify=self.commands.identify,
            cmd_set_exposure=self.commands.set_exposure,
            cmd_measure=self.commands.measure,
            reply_identify=self.replies.identify,
            reply_set_exposure=self.replies.set_exposure,
            reply_measure=tuple(self.replies.measure),
            reply_error=self.replies.error,
            unconfirmed=tuple(self.unconfirmed),
        )


class _ZgmFile(_File):
    """``kind = "zgm1120"``."""

    kind: Literal["zgm1120"]
    reply_terminator: NonEmpty
    timeout_s: Positive
    led_argument: Annotated[int, Strict(), Field(ge=0, le=99)] = 1

    def profile(self, path: Path) -> ZgmProfile:
        return ZgmProfile(
            name=self.name,
            path=path,
            description=self.description,
            serial=self.serial,
            reply_terminator=self.reply_terminator,
            timeout_s=self.timeout_s,
            led_argument=self.led_argument,
            unconfirmed=tuple(self.unconfirmed),
        )


def _line_pattern(value: str) -> str:
    try:
        pattern = re.compile(value)
    except (re.error, OverflowError, RecursionError) as exc:  # "a{4294967296}": OverflowError
        raise ValueError(f"invalid regex: {exc}") from None
    groups = set(pattern.groupindex)
    if not groups & {"g20", "g60", "g85"}:
        raise ValueError("needs at least one named group g20, g60 or g85")
    extra = groups - {"g20", "g60", "g85", "temperature"}
    if extra:
        raise ValueError(f"unknown named group(s) {sorted(extra)}")
    return value


class _LineGlossFile(_File):
    """``kind = "line-gloss"``."""

    kind: Literal["line-gloss"]
    pattern: Annotated[str, Strict(), Field(min_length=1), AfterValidator(_line_pattern)]
    overflow_tokens: list[Text] = []
    trigger: Text = ""
    line_terminator: NonEmpty
    encoding: Encoding = "ascii"
    timeout_s: Positive

    @model_validator(mode="after")
    def _speaks_its_encoding(self) -> _LineGlossFile:
        for key in ("trigger", "line_terminator"):
            text = getattr(self, key)
            try:
                text.encode(self.encoding)
            except UnicodeError:
                raise KeyedValueError(
                    key, f"{short_repr(text)} cannot be written in {self.encoding}"
                ) from None
        return self

    def profile(self, path: Path) -> LineGlossProfile:
        return LineGlossProfile(
            name=self.name,
            path=path,
            description=self.description,
            serial=self.serial,
            pattern=re.compile(self.pattern),
            overflow_tokens=tuple(self.overflow_tokens),
            trigger=self.trigger,
            line_terminator=self.line_terminator,
            encoding=self.encoding,
            timeout_s=self.timeout_s,
            unconfirmed=tuple(self.unconfirmed),
        )


def _fields(obj: StepperRegisters) -> dict[str, int | None]:
    return {k: getattr(obj, k) for k in obj.__dataclass_fields__}


_KINDS: dict[str, type[_StepperFile | _StilFile | _ZgmFile | _LineGlossFile]] = {
    "modbus-stepper": _StepperFile,
    "stil-spectro": _StilFile,
    "zgm1120": _ZgmFile,
    "line-gloss": _LineGlossFile,
}


# --------------------------------------------------------------------------- public
def _error(path: Path, key: str, reason: str) -> ProfileError:
    return ProfileError(f"{path}: key '{key}': {reason}")


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
        data = read_toml(path, what="profile file")
    except TomlFileError as exc:
        hint = ""
        if exc.not_found:
            known = sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))
            hint = f" (built-in profiles: {', '.join(known)})"
        raise ProfileError(f"{exc}{hint}") from None
    kind = data.get("kind")
    if kind is None:
        raise _error(path, "kind", "missing")
    if not isinstance(kind, str) or kind not in _KINDS:
        raise _error(path, "kind", f"expected one of {sorted(_KINDS)}, got {short_repr(kind)}")
    try:
        schema = _KINDS[kind].model_validate(data)
    except ValidationError as exc:
        raise _error(path, *first_issue(exc, plain_reason)) from None
    return schema.profile(path)


_P = TypeVar("_P", StepperProfile, StilProfile, ZgmProfile, LineGlossProfile)


def _typed(name_or_path: str | Path, cls: type[_P]) -> _P:
    profile = load_profile(name_or_path)
    if not isinstance(profile, cls):
        expected = cls.__dataclass_fields__["kind"].default
        raise _error(profile.path, "kind", f"expected {expected!r}, got {profile.kind!r}")
    return profile


def load_stepper_profile(name_or_path: str | Path) -> StepperProfile:
    """Load a ``kind = "modbus-stepper"`` profile (see :func:`load_profile`)."""
    return _typed(name_or_path, StepperProfile)


def load_stil_profile(name_or_path: str | Path) -> StilProfile:
    """Load a ``kind = "stil-spectro"`` profile (see :func:`load_profile`)."""
    return _typed(name_or_path, StilProfile)


def load_zgm_profile(name_or_path: str | Path) -> ZgmProfile:
    """Load a ``kind = "zgm1120"`` profile (see :func:`load_profile`)."""
    return _typed(name_or_path, ZgmProfile)


def load_line_gloss_profile(name_or_path: str | Path) -> LineGlossProfile:
    """Load a ``kind = "line-gloss"`` profile (see :func:`load_profile`)."""
    return _typed(name_or_path, LineGlossProfile)
