"""The glossmeter profiles: ``kind = "zgm1120"`` (:class:`ZgmProfile`, the Zehntner ZGM1120's
serial settings) and ``kind = "line-gloss"`` (:class:`LineGlossProfile`, a meter that prints
one line per reading), read by :mod:`drivers.glossmeter` and :mod:`sim.wire.serial`.

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

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from pydantic import AfterValidator, Field, Strict, model_validator

from drivers.profiles.schema_common import (
    Encoding,
    NonEmpty,
    Positive,
    ProfileFile,
    SerialSettings,
    Text,
    written_in,
)

__all__ = ["LineGlossFile", "LineGlossProfile", "ZgmFile", "ZgmProfile"]


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


class ZgmFile(ProfileFile):
    """``kind = "zgm1120"``."""

    kind: Literal["zgm1120"]
    reply_terminator: NonEmpty
    timeout_s: Positive
    led_argument: Annotated[int, Strict(), Field(ge=0, le=99)] = 1

    def profile(self, path: Path) -> ZgmProfile:
        return ZgmProfile(
            **self.common_fields(path),
            reply_terminator=self.reply_terminator,
            timeout_s=self.timeout_s,
            led_argument=self.led_argument,
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


class LineGlossFile(ProfileFile):
    """``kind = "line-gloss"``."""

    kind: Literal["line-gloss"]
    pattern: Annotated[str, Strict(), Field(min_length=1), AfterValidator(_line_pattern)]
    overflow_tokens: list[Text] = Field(default_factory=list)
    trigger: Text = ""
    line_terminator: NonEmpty
    encoding: Encoding = "ascii"
    timeout_s: Positive

    @model_validator(mode="after")
    def _speaks_its_encoding(self) -> LineGlossFile:
        written_in(self.encoding, {k: getattr(self, k) for k in ("trigger", "line_terminator")})
        return self

    def profile(self, path: Path) -> LineGlossProfile:
        return LineGlossProfile(
            **self.common_fields(path),
            pattern=re.compile(self.pattern),
            overflow_tokens=tuple(self.overflow_tokens),
            trigger=self.trigger,
            line_terminator=self.line_terminator,
            encoding=self.encoding,
            timeout_s=self.timeout_s,
        )
