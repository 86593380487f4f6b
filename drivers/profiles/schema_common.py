"""What every device profile shares: where the built-in profiles live, the strict value
types, the ``[serial]`` table and the keys common to every file (:class:`ProfileFile`).

The kinds of profile build on it: :mod:`drivers.profiles.stepper_schema`,
:mod:`drivers.profiles.stil_schema`, :mod:`drivers.profiles.gloss_schema`; the loader is
:mod:`drivers.profiles` (its module doc has the whole picture).

Schema common to every profile
------------------------------
``kind``           one of ``"modbus-stepper"``, ``"stil-spectro"``, ``"zgm1120"``, ``"line-gloss"``
``name``           short identifier (normally the file stem)
``description``    free text
``unconfirmed``    list of dotted keys (``"registers.command_position"``) whose values are
                   not confirmed by a public source. Every listed key must exist.
``[serial]``       ``baudrate`` (int), ``bytesize`` (5..8, default 8), ``parity``
                   (``"N"``, ``"E"``, ``"O"``, default ``"N"``), ``stopbits`` (1 or 2, default 1).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal, Self

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ModelWrapValidatorHandler,
    Strict,
    model_validator,
)
from pydantic.dataclasses import dataclass as table

from drivers.base import ProfileError
from drivers.toml_schema import KeyedValueError, short_repr

__all__ = [
    "PROFILES_DIR",
    "TABLE_CONFIG",
    "Address",
    "Bit",
    "Encoding",
    "Int",
    "NonEmpty",
    "Positive",
    "ProfileFile",
    "Section",
    "SerialSettings",
    "Text",
    "Word",
    "known_encoding",
    "one_of",
    "profile_error",
    "profile_path",
    "table",
    "written_in",
]


def _find_profiles_dir() -> Path:
    root = Path(__file__).resolve().parents[2]  # drivers/profiles/ -> the source tree
    for candidate in (
        root / "configs" / "profiles",  # source checkout / editable install
        root / "goniolab" / "_configs" / "profiles",  # wheel (force-include)
    ):
        if candidate.is_dir():
            return candidate
    return root / "configs" / "profiles"


#: Directory holding the built-in profiles.
PROFILES_DIR: Path = _find_profiles_dir()


def profile_path(name_or_path: str | Path) -> Path:
    """Resolve a profile name (``"oriental-az"``) or a path to a file path."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".toml") or "/" in text or "\\" in text:
        return Path(name_or_path)
    return PROFILES_DIR / f"{text}.toml"


def written_in(encoding: str, texts: dict[str, str]) -> None:
    """Check that every text (by its dotted key) can be written in ``encoding``.

    Raises
    ------
    KeyedValueError
        The first text that cannot, naming its key.
    """
    for key, text in texts.items():
        try:
            text.encode(encoding)
        except UnicodeError:
            raise KeyedValueError(
                key, f"{short_repr(text)} cannot be written in {encoding}"
            ) from None


def profile_error(path: Path, key: str, reason: str) -> ProfileError:
    """The one-line error naming the profile file, the key and the reason."""
    return ProfileError(f"{path}: key '{key}': {reason}")


# --------------------------------------------------------------------------- value types
def one_of(*allowed: int) -> AfterValidator:
    def check(value: int) -> int:
        if value not in allowed:
            raise ValueError(f"expected {' or '.join(map(str, allowed))}, got {value}")
        return value

    return AfterValidator(check)


def known_encoding(value: str) -> str:
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
Encoding = Annotated[str, Strict(), AfterValidator(known_encoding)]

TABLE_CONFIG = ConfigDict(extra="forbid")


# --------------------------------------------------------------------------- tables
@table(frozen=True, slots=True, config=TABLE_CONFIG)
class SerialSettings:
    """Serial line settings (also used for Modbus RTU)."""

    baudrate: Annotated[int, Strict(), Field(ge=300, le=4_000_000)]
    bytesize: Annotated[int, Strict(), Field(ge=5, le=8)] = 8
    parity: Literal["N", "E", "O"] = "N"
    stopbits: Annotated[int, Strict(), one_of(1, 2)] = 1


# --------------------------------------------------------------------------- file schema
class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _is_key(data: Any, dotted: str) -> bool:
    node = data
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return False
        node = node[part]
    return True


class ProfileFile(Section):
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

    def common_fields(self, path: Path) -> dict[str, Any]:
        """The fields every profile object has, for its constructor."""
        return {
            "name": self.name,
            "path": path,
            "description": self.description,
            "serial": self.serial,
            "unconfirmed": tuple(self.unconfirmed),
        }

    def profile(self, path: Path) -> Any:
        """The frozen profile object this file describes (each kind of file defines it)."""
        raise NotImplementedError(f"{type(self).__name__} does not build a profile")
