"""The instrument protocols goniolab speaks: one table per kind of device.

Each table (:data:`STEPPERS`, :data:`SPECTROS`, :data:`GLOSSMETERS`) maps a protocol name
(what a lab config's ``protocol`` key and ``goniolab gloss log --protocol`` say) to a
:class:`ProtocolEntry`: a one-line description, the ``kind`` of profile it reads and its
built-in default profile, the driver class that speaks it and, where the digital twin can
serve it on the wire, the simulator that does. Everything that names a protocol reads this
table: the config validation (:mod:`goniolab.config`), the CLI choices
(``goniolab gloss log --protocol``), the lab's driver construction (:mod:`goniolab.lab_wiring`,
:func:`drivers.glossmeter.open_glossmeter`) and docs/ARCHITECTURE.md.

This module imports only the standard library: the CLI reads the names while it builds its
parser (``goniolab --help`` loads no pydantic, no pyserial). The driver class and a profile
schema are therefore named as ``"module:attribute"`` strings, imported on first use.

Drivers never import the simulator (tests/test_layers.py), so the twin registers its
simulators here itself (:mod:`sim.assembly`, with :meth:`ProtocolTable.register_simulator`).

Adding a protocol: one module with its driver class (and its profile schema, when it needs
a new kind of profile) plus one :meth:`ProtocolTable.register` call; see
docs/ARCHITECTURE.md, "Adding an instrument protocol", for a worked example.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

__all__ = [
    "GLOSSMETERS",
    "SPECTROS",
    "STEPPERS",
    "TABLES",
    "DeviceKind",
    "ProtocolEntry",
    "ProtocolTable",
    "Simulator",
    "import_ref",
]

#: The kinds of device the lab has a protocol table for.
DeviceKind = Literal["stepper", "spectro", "glossmeter"]

#: What the twin registers for a protocol it serves on the wire: called with the simulated
#: instrument (``sim.instruments``), the loaded profile and the lab config's section of that
#: device; returns the wire device (a Modbus unit or a pty device of ``sim.wire``).
Simulator = Callable[[Any, Any, Any], Any]


def import_ref(ref: str) -> Any:
    """The object a ``"package.module:attribute"`` reference names (imported now).

    Raises
    ------
    ValueError
        ``ref`` is not of the form ``module:attribute``, or names nothing.
    """
    module, sep, attr = ref.partition(":")
    if not sep or not module or not attr:
        raise ValueError(f"expected 'module:attribute', got {ref!r}")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{ref!r} names nothing importable: {exc}") from None


@dataclass(frozen=True, slots=True)
class ProtocolEntry:
    """One protocol of one kind of device.

    Parameters
    ----------
    device
        ``"stepper"``, ``"spectro"`` or ``"glossmeter"``.
    name
        The protocol name a config or the CLI gives (``"zgm1120"``).
    description
        One line for ``--help`` and the docs.
    profile_kind
        The ``kind`` of the profile files the protocol reads (``drivers.profiles``).
    default_profile
        The built-in profile used when none is given (a name in ``configs/profiles``).
    driver
        ``"module:Class"`` of the driver. Its constructor takes the device name, then the
        keywords of its kind of device (``port``, ``profile``, ``baudrate``, ``timeout_s``
        for the serial devices, see :func:`drivers.glossmeter.open_glossmeter`) and the
        ``options`` below.
    options
        Further settings of the config section this driver takes as keywords
        (``("serial_number",)`` for the ZGM1120).
    pushes_readings
        Glossmeters: the meter prints readings on its own, so ``gloss log`` without a
        config takes what it pushes (``--mode push``) unless told otherwise.
    profile_schema
        ``"module:Class"`` of the pydantic schema (a
        :class:`drivers.profiles.schema_common.ProfileFile`) of a ``profile_kind`` that
        :data:`drivers.profiles.PROFILE_KINDS` does not know; ``""`` for the built-in kinds.
    """

    device: DeviceKind
    name: str
    description: str
    profile_kind: str
    default_profile: str
    driver: str
    options: tuple[str, ...] = ()
    pushes_readings: bool = False
    profile_schema: str = ""

    def driver_class(self) -> Any:
        """The driver class (imported now)."""
        return import_ref(self.driver)

    def load_profile(self, name_or_path: str | Path) -> Any:
        """Load and validate a profile of this protocol's kind.

        Raises
        ------
        drivers.base.ProfileError
            The file is missing, invalid or of another kind (names file, key and reason).
        """
        from drivers.profiles import load_profile_of_kind

        schema = import_ref(self.profile_schema) if self.profile_schema else None
        return load_profile_of_kind(name_or_path, self.profile_kind, schema)


class ProtocolTable:
    """The protocols of one kind of device, in registration order."""

    def __init__(self, device: DeviceKind) -> None:
        self.device: DeviceKind = device
        self._entries: dict[str, ProtocolEntry] = {}
        self._simulators: dict[str, Simulator] = {}

    def register(self, entry: ProtocolEntry) -> ProtocolEntry:
        """Add a protocol; returns it.

        Raises
        ------
        ValueError
            The entry is for another kind of device, or the name is taken.
        """
        if entry.device != self.device:
            raise ValueError(f"a {entry.device} protocol cannot go in the {self.device} table")
        if entry.name in self._entries:
            raise ValueError(f"{self.device} protocol {entry.name!r} is already registered")
        self._entries[entry.name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove a protocol and its simulator (a test's toy protocol)."""
        self._entries.pop(name, None)
        self._simulators.pop(name, None)

    def register_simulator(self, name: str, simulator: Simulator) -> None:
        """The twin serves protocol ``name`` with ``simulator`` (see :data:`Simulator`).

        Raises
        ------
        ValueError
            No such protocol.
        """
        self[name]  # raises for an unknown protocol
        self._simulators[name] = simulator

    def simulator(self, name: str) -> Simulator | None:
        """The twin's simulator of protocol ``name``, ``None`` if the twin does not serve it."""
        return self._simulators.get(name)

    def simulated(self) -> tuple[str, ...]:
        """The protocols the twin serves on the wire."""
        return tuple(n for n in self._entries if n in self._simulators)

    def names(self) -> tuple[str, ...]:
        """Every protocol name, in registration order."""
        return tuple(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __getitem__(self, name: str) -> ProtocolEntry:
        """The entry of ``name``.

        Raises
        ------
        ValueError
            Unknown protocol (the message lists the known ones).
        """
        try:
            return self._entries[name]
        except KeyError:
            known = ", ".join(repr(n) for n in self._entries)
            raise ValueError(f"unknown {self.device} protocol {name!r} (known: {known})") from None

    def entries(self) -> tuple[ProtocolEntry, ...]:
        """Every entry, in registration order."""
        return tuple(self._entries.values())

    def help_text(self) -> str:
        """``name: description`` of every protocol, for ``--help``."""
        return "; ".join(f"{e.name}: {e.description}" for e in self._entries.values())


STEPPERS = ProtocolTable("stepper")
SPECTROS = ProtocolTable("spectro")
GLOSSMETERS = ProtocolTable("glossmeter")

#: Every table by kind of device.
TABLES: dict[DeviceKind, ProtocolTable] = {
    "stepper": STEPPERS,
    "spectro": SPECTROS,
    "glossmeter": GLOSSMETERS,
}

# --------------------------------------------------------------------------- built-ins
STEPPERS.register(
    ProtocolEntry(
        device="stepper",
        name="modbus",
        description="Modbus RTU/TCP stepper controller, register map from a "
        "'modbus-stepper' profile (Oriental Motor AZ, Applied Motion ST-Q)",
        profile_kind="modbus-stepper",
        default_profile="oriental-az",
        driver="drivers.modbus_stepper:ModbusStepperAxis",
    )
)
SPECTROS.register(
    ProtocolEntry(
        device="spectro",
        name="stil",
        description="STIL spectro-colorimeter line protocol, commands and replies from a "
        "'stil-spectro' profile",
        profile_kind="stil-spectro",
        default_profile="stil-ruby",
        driver="drivers.stil:StilSpectro",
    )
)
GLOSSMETERS.register(
    ProtocolEntry(
        device="glossmeter",
        name="zgm1120",
        description="Zehntner ZGM 1120 command protocol (Technical Manual rev 3.0, section 6)",
        profile_kind="zgm1120",
        default_profile="zgm1120",
        driver="drivers.glossmeter:Zgm1120",
        options=("serial_number",),
    )
)
GLOSSMETERS.register(
    ProtocolEntry(
        device="glossmeter",
        name="line",
        description="a meter that prints one line per reading, parsed by the regex of a "
        "'line-gloss' profile (BYK, Rhopoint, Elcometer)",
        profile_kind="line-gloss",
        default_profile="line-gloss-example",
        driver="drivers.glossmeter:LineGlossmeter",
        pushes_readings=True,
    )
)
