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

The schema of each kind lives with its kind: the keys common to every profile in
:mod:`drivers.profiles.schema_common`, ``kind = "modbus-stepper"`` in
:mod:`drivers.profiles.stepper_schema`, ``kind = "stil-spectro"`` in
:mod:`drivers.profiles.stil_schema`, ``kind = "zgm1120"`` and ``kind = "line-gloss"`` in
:mod:`drivers.profiles.gloss_schema` (each module doc lists its keys). Every public name
is re-exported here, so ``from drivers.profiles import StepperProfile`` keeps working.
:data:`PROFILE_KINDS` maps each ``kind`` to its file schema; :func:`load_profile_of_kind`
loads a profile of one kind (the protocol registry, :mod:`drivers.protocols`, uses it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

from pydantic import ValidationError

from drivers.base import ProfileError
from drivers.profiles.gloss_schema import LineGlossFile, LineGlossProfile, ZgmFile, ZgmProfile
from drivers.profiles.schema_common import (
    PROFILES_DIR,
    ProfileFile,
    SerialSettings,
    profile_error,
    profile_path,
)
from drivers.profiles.stepper_schema import (
    DirectDataDefaults,
    InputBits,
    Opcodes,
    StatusBits,
    StepperFile,
    StepperProfile,
    StepperRegisters,
)
from drivers.profiles.stil_schema import StilFile, StilProfile, template_regex
from drivers.toml_schema import first_issue, plain_reason, short_repr
from labtoml import TomlFileError, read_toml

__all__ = [
    "PROFILES_DIR",
    "PROFILE_KINDS",
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
    "load_profile_of_kind",
    "load_stepper_profile",
    "load_stil_profile",
    "load_zgm_profile",
    "profile_path",
    "template_regex",
]

Profile = StepperProfile | StilProfile | ZgmProfile | LineGlossProfile


#: ``kind`` -> the pydantic schema of that kind of file; its ``profile(path)`` builds the
#: frozen profile object. A protocol that brings a new kind of profile adds its schema here
#: through its registry entry (:class:`drivers.protocols.ProtocolEntry`, ``profile_schema``).
PROFILE_KINDS: dict[str, type[ProfileFile]] = {
    "modbus-stepper": StepperFile,
    "stil-spectro": StilFile,
    "zgm1120": ZgmFile,
    "line-gloss": LineGlossFile,
}


# --------------------------------------------------------------------------- public
def _read(path: Path) -> dict[str, Any]:
    try:
        return read_toml(path, what="profile file")
    except TomlFileError as exc:
        hint = ""
        if exc.not_found:
            known = sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))
            hint = f" (built-in profiles: {', '.join(known)})"
        raise ProfileError(f"{exc}{hint}") from None


def _validate(path: Path, data: dict[str, Any], schema: type[ProfileFile]) -> Any:
    try:
        checked = schema.model_validate(data)
    except ValidationError as exc:
        raise profile_error(path, *first_issue(exc, plain_reason)) from None
    return checked.profile(path)


def load_profile(name_or_path: str | Path) -> Profile:
    """Load and validate a profile by name or path.

    Raises
    ------
    ProfileError
        File missing or unreadable, TOML syntax error, missing/unknown key, wrong type or
        out-of-range value; the message names the file, the key and the reason.
    """
    path = profile_path(name_or_path)
    data = _read(path)
    kind = data.get("kind")
    if kind is None:
        raise profile_error(path, "kind", "missing")
    if not isinstance(kind, str) or kind not in PROFILE_KINDS:
        raise profile_error(
            path, "kind", f"expected one of {sorted(PROFILE_KINDS)}, got {short_repr(kind)}"
        )
    profile: Profile = _validate(path, data, PROFILE_KINDS[kind])
    return profile


def load_profile_of_kind(
    name_or_path: str | Path, kind: str, schema: type[ProfileFile] | None = None
) -> Any:
    """Load a profile that must be of ``kind``.

    A kind :data:`PROFILE_KINDS` knows is validated by its own schema (the file is first
    validated as what it says it is, then its kind is compared); a new kind brings its
    ``schema`` (a protocol's ``profile_schema``, :mod:`drivers.protocols`).

    Raises
    ------
    ProfileError
        As :func:`load_profile`, and when the file's ``kind`` is another one.
    ValueError
        ``kind`` is unknown and no ``schema`` is given.
    """
    path = profile_path(name_or_path)
    if kind in PROFILE_KINDS:
        profile: Any = load_profile(path)
    elif schema is None:
        raise ValueError(f"no schema for profile kind {kind!r} (known: {sorted(PROFILE_KINDS)})")
    else:
        data = _read(path)
        found = data.get("kind")
        if found is None:
            raise profile_error(path, "kind", "missing")
        if found != kind:
            raise profile_error(path, "kind", f"expected {kind!r}, got {short_repr(found)}")
        return _validate(path, data, schema)
    if profile.kind != kind:
        raise profile_error(profile.path, "kind", f"expected {kind!r}, got {profile.kind!r}")
    return profile


#: The ``kind`` of each built-in profile class.
_KIND_OF: dict[type, str] = {
    StepperProfile: "modbus-stepper",
    StilProfile: "stil-spectro",
    ZgmProfile: "zgm1120",
    LineGlossProfile: "line-gloss",
}

_P = TypeVar("_P", StepperProfile, StilProfile, ZgmProfile, LineGlossProfile)


def _typed(name_or_path: str | Path, cls: type[_P]) -> _P:
    profile: _P = load_profile_of_kind(name_or_path, _KIND_OF[cls])
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
