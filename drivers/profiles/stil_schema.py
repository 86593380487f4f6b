"""The ``kind = "stil-spectro"`` profile: the STIL spectro-colorimeter's line protocol
(:class:`StilProfile`, read by :mod:`drivers.stil` and :mod:`sim.wire.serial`), and
:func:`template_regex`, which turns a reply template into the regex the driver matches.

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
"""

from __future__ import annotations

import re
import string
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field, Strict, field_validator, model_validator

from drivers.profiles.schema_common import (
    Encoding,
    Int,
    NonEmpty,
    Positive,
    ProfileFile,
    Section,
    SerialSettings,
    Text,
    written_in,
)
from drivers.toml_schema import KeyedValueError, short_repr

__all__ = ["TEMPLATE_FIELDS", "ReplyTemplate", "StilFile", "StilProfile", "template_regex"]


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


class _Exposure(Section):
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


class _Commands(Section):
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


class _Replies(Section):
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


class StilFile(ProfileFile):
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
    def _speaks_its_encoding(self) -> StilFile:
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
        written_in(self.encoding, {**texts, **replies})
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
            **self.common_fields(path),
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
        )
