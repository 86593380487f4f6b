"""The ``kind = "modbus-stepper"`` profile: a Modbus stepper controller's register map
(:class:`StepperProfile`, read by :mod:`drivers.modbus_stepper` and :mod:`sim.wire.modbus`).

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
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, Strict, field_validator, model_validator

from drivers.profiles.schema_common import (
    TABLE_CONFIG,
    Address,
    Bit,
    Positive,
    ProfileFile,
    Section,
    SerialSettings,
    Word,
    one_of,
    table,
)
from drivers.toml_schema import KeyedValueError

__all__ = [
    "DirectDataDefaults",
    "InputBits",
    "Opcodes",
    "StatusBits",
    "StepperFile",
    "StepperProfile",
    "StepperRegisters",
]

#: Each field of the direct-data block is a signed 32-bit register pair.
_INT32_MAX = 2**31 - 1


@table(frozen=True, slots=True, config=TABLE_CONFIG)
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


@table(frozen=True, slots=True, config=TABLE_CONFIG)
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


@table(frozen=True, slots=True, config=TABLE_CONFIG)
class InputBits:
    """Bit numbers of the 32-bit driver input command word (direct-data style)."""

    start: Bit
    zhome: Bit
    stop: Bit
    free: Bit
    alarm_reset: Bit
    fw_pos: Bit
    rv_pos: Bit


@table(frozen=True, slots=True, config=TABLE_CONFIG)
class DirectDataDefaults:
    """Constant fields of the direct-data block."""

    data_number: Annotated[int, Strict(), Field(ge=0, le=_INT32_MAX)] = 0
    operation_type: Annotated[int, Strict(), Field(ge=0, le=_INT32_MAX)] = 1
    current: Annotated[int, Strict(), Field(ge=0, le=1000)] = 1000
    trigger: Annotated[int, Strict(), Field(ge=-_INT32_MAX - 1, le=_INT32_MAX)] = 1
    destination: Annotated[int, Strict(), Field(ge=0, le=1)] = 0


@table(frozen=True, slots=True, config=TABLE_CONFIG)
class Opcodes:
    """Command-register opcodes (command-opcode style)."""

    absolute_move: Word
    relative_move: Word
    enable: Word
    disable: Word
    stop: Word
    home: Word
    alarm_reset: Word


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


class _Units(Section):
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


class StepperFile(ProfileFile):
    """``kind = "modbus-stepper"``."""

    kind: Literal["modbus-stepper"]
    move_style: Literal["direct-data", "command-opcode"]
    register_base: Annotated[int, Strict(), one_of(0, 40001)] = 0
    registers: StepperRegisters
    status_bits: StatusBits
    input_bits: InputBits | None = None
    direct_data: DirectDataDefaults | None = None
    opcodes: Opcodes | None = None
    units: _Units
    single_register_fields: list[Literal["output_status", "alarm_code"]] = Field(
        default_factory=list
    )

    @field_validator("serial", mode="before")
    @classmethod
    def _rtu_parity_even(cls, value: Any) -> Any:
        # a stepper's serial line is Modbus RTU, whose default frame is 8 data bits, even parity
        return {"parity": "E", **value} if isinstance(value, dict) else value

    @model_validator(mode="after")
    def _style_and_base(self) -> StepperFile:
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
            **self.common_fields(path),
            move_style=self.move_style,
            registers=dataclasses.replace(self.registers, **addresses),
            status_bits=self.status_bits,
            speed_counts_per_step_s=speed,
            accel_counts_per_step_s2=accel,
            input_bits=self.input_bits,
            direct_data=self.direct_data,
            opcodes=self.opcodes,
            single_register_fields=tuple(self.single_register_fields),
        )


def _fields(obj: StepperRegisters) -> dict[str, int | None]:
    return {k: getattr(obj, k) for k in obj.__dataclass_fields__}
