"""What a store row means: the records of runs and readings, decoded from their columns.

:class:`RunRecord` (one row of ``runs``), :class:`RunMeta` (what the operator says about a
run), :class:`PointRow`, :class:`PredictedColour` and :class:`GlossRow` (one reading each),
the run's identity (:func:`legacy_uuid` for runs stored before runs had a UUID) and the JSON
encoding of every JSON column (:func:`json_text`, :func:`json_column`).
"""

from __future__ import annotations

import json
import uuid as uuidlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from goniolab.store.exceptions import StoreDamaged

__all__ = [
    "COLOUR_KEYS",
    "GlossRow",
    "PointRow",
    "PredictedColour",
    "RunMeta",
    "RunRecord",
    "json_column",
    "json_text",
    "legacy_uuid",
    "run_select",
    "search_text",
]

#: Measured colour of a reading (issue 11): CIE XYZ, L*a*b* and L*C*h, in this order (the
#: ``points.colour_*`` columns, :attr:`PointRow.colour`).
COLOUR_KEYS: tuple[str, ...] = ("X", "Y", "Z", "L", "a", "b", "C", "h_deg")

#: The columns of a :class:`RunRecord`, in the order :meth:`RunRecord.from_row` reads them
#: (``{identity}``: the identity columns, or NULLs in an old read-only store).
_RUN_SELECT = (
    "SELECT id, kind, plan_json, config_json, sample, model_json, version, status,"
    " reason, created_at, updated_at, finished_at, {identity} FROM runs"
)
_IDENTITY_SELECT = "uuid, operator, notes, tags_json, sample_id"
_NO_IDENTITY_SELECT = "NULL, NULL, NULL, NULL, NULL"
#: The namespace of the UUIDs given to runs stored before runs had one.
_LEGACY_NAMESPACE = uuidlib.UUID("6f1c2a7e-3b1d-5c4e-9a8b-0d2e4f6a8c10")


def run_select(*, has_identity: bool) -> str:
    """The ``SELECT ... FROM runs`` whose rows :meth:`RunRecord.from_row` reads; a store
    without the identity columns (an old one opened read-only) selects NULLs for them."""
    return _RUN_SELECT.format(identity=_IDENTITY_SELECT if has_identity else _NO_IDENTITY_SELECT)


def legacy_uuid(location: str, run_id: int, created_at: float) -> str:
    """The UUID of a run stored before runs had one: a UUID 5 of the store's location, the
    run id and its creation time (the same whether the store is upgraded or read as it is,
    distinct for two PCs' stores at the same path: their creation times differ)."""
    return str(uuidlib.uuid5(_LEGACY_NAMESPACE, f"{location}\n{run_id}\n{created_at!r}"))


def search_text(rec: RunRecord) -> str:
    """What ``runs list --search`` looks in, lower-case."""
    return "\n".join([rec.sample, rec.sample_id, rec.operator, rec.notes, *rec.tags]).lower()


def json_text(obj: Any) -> str:
    """The text of a JSON column (keys sorted; what JSON cannot hold as its ``str``)."""
    return json.dumps(obj, sort_keys=True, default=str)


def json_column(run_id: int, column: str, text: Any) -> Any:
    """Decode one JSON column; :class:`StoreDamaged` naming the run and column if it is not."""
    try:
        return json.loads(text)
    except (TypeError, ValueError) as exc:
        raise StoreDamaged(f"run {run_id}: {column} is not valid JSON ({exc})") from None


@dataclass(frozen=True, slots=True)
class RunRecord:
    """One row of ``runs`` with its JSON columns decoded.

    ``damage`` is empty for a sound row; for a row whose JSON cannot be decoded it says
    which column and why (``plan``/``config``/``model`` are then empty): :meth:`RunStore.
    list_runs` lists such a run, :meth:`RunStore.get_run` refuses it in one line.

    ``brief``: a listing's record (:meth:`RunStore.list_briefs`), whose ``config`` snapshot
    and ``model`` were not read (they are empty here; :meth:`RunStore.get_run` reads them).
    """

    id: int
    kind: str
    plan: dict[str, Any]
    config: dict[str, Any]
    sample: str
    model: dict[str, Any]
    version: str
    status: str
    reason: str
    created_at: float
    updated_at: float
    finished_at: float | None
    uuid: str = ""
    operator: str = ""
    notes: str = ""
    tags: tuple[str, ...] = ()
    sample_id: str = ""
    damage: str = ""
    brief: bool = False

    @classmethod
    def from_row(cls, row: Sequence[Any], location: str = "", *, brief: bool = False) -> RunRecord:
        """From the columns of :func:`run_select`, in that order (a row without the identity
        columns gets :func:`legacy_uuid` and empty metadata); ``brief``: the config and
        model columns are not decoded (a listing's record)."""
        run_id = int(row[0])
        damage: list[str] = []
        decoded: list[Any] = []
        for k, column in ((2, "plan_json"), (3, "config_json"), (5, "model_json")):
            if brief and k != 2:
                decoded.append({})
                continue
            try:
                value = json_column(run_id, column, row[k])
                if not isinstance(value, dict):
                    raise StoreDamaged(f"run {run_id}: {column} is not a JSON object")
            except StoreDamaged as exc:
                damage.append(str(exc).split(": ", 1)[1])
                value = {}
            decoded.append(value)
        ident = list(row[12:17]) if len(row) > 12 else [None] * 5
        tags: tuple[str, ...] = ()
        if ident[3]:
            try:
                tags = tuple(str(t) for t in json.loads(ident[3]))
            except (TypeError, ValueError):
                damage.append("tags_json is not valid JSON")
        created = float(row[9])
        return cls(
            id=run_id,
            kind=str(row[1]),
            plan=decoded[0],
            config=decoded[1],
            sample=str(row[4]),
            model=decoded[2],
            version=str(row[6]),
            status=str(row[7]),
            reason=str(row[8]),
            created_at=created,
            updated_at=float(row[10]),
            finished_at=None if row[11] is None else float(row[11]),
            uuid=str(ident[0]) if ident[0] else legacy_uuid(location, run_id, created),
            operator=str(ident[1] or ""),
            notes=str(ident[2] or ""),
            tags=tags,
            sample_id=str(ident[4] or ""),
            damage="; ".join(damage),
            brief=brief,
        )

    def as_dict(self) -> dict[str, Any]:
        """Return the record as a JSON-serialisable dict."""
        doc = {
            "id": self.id,
            "uuid": self.uuid,
            "kind": self.kind,
            "plan": self.plan,
            "config": self.config,
            "sample": self.sample,
            "sample_id": self.sample_id,
            "operator": self.operator,
            "notes": self.notes,
            "tags": list(self.tags),
            "model": self.model,
            "version": self.version,
            "status": self.status,
            "reason": self.reason,
            "created_at": self.created_at,
            "updated_at": self.updated_at,
            "finished_at": self.finished_at,
        }
        if self.damage:
            doc["damage"] = self.damage
        return doc


@dataclass(frozen=True, slots=True)
class RunMeta:
    """What the operator says about a run: who, which physical sample, notes, tags.

    Set from ``goniolab scan --operator/--sample-id/--note/--tag``, the config's ``[run]``
    table, the TUI and the API; changed later with ``goniolab runs annotate``.
    """

    operator: str = ""
    sample_id: str = ""
    notes: str = ""
    tags: tuple[str, ...] = field(default_factory=tuple)

    @classmethod
    def given(
        cls,
        operator: str | None = None,
        sample_id: str | None = None,
        notes: str | None = None,
        tags: Iterable[str] = (),
    ) -> RunMeta:
        """From what a face was given (``None``: not given; tags: empty ones dropped, each
        kept once, in order)."""
        return cls(
            operator=operator or "",
            sample_id=sample_id or "",
            notes=notes or "",
            tags=tuple(dict.fromkeys(str(t) for t in tags if t)),
        )

    def merged(self, other: RunMeta) -> RunMeta:
        """``other``'s non-empty fields over this one's (tags: both, in order, once each)."""
        return RunMeta(
            operator=other.operator or self.operator,
            sample_id=other.sample_id or self.sample_id,
            notes=other.notes or self.notes,
            tags=tuple(dict.fromkeys((*self.tags, *other.tags))),
        )


@dataclass(frozen=True, slots=True)
class PointRow:
    """One stored reading (one row of ``points``)."""

    index: int
    repeat: int
    theta_i_deg: float
    theta_r_deg: float
    measured_theta_i_deg: float
    measured_theta_r_deg: float
    luminance_pct: float
    raw: dict[str, Any]
    timestamp: float
    #: Measured colour (keys of :data:`COLOUR_KEYS`), ``None`` when the spectrum could not
    #: be converted (then ``colour_error`` says why) or the store predates colour.
    colour: dict[str, float] | None = None
    colour_error: str = ""

    @classmethod
    def from_row(cls, r: Sequence[Any]) -> PointRow:
        """From the columns idx, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,
        measured_theta_r_deg, luminance_pct, raw_json, timestamp and, when the store has
        them, the colour columns (:data:`COLOUR_KEYS` order, then colour_error)."""
        colour = None
        error = ""
        if len(r) > 9:
            if r[12] is not None:
                colour = {k: float(v) for k, v in zip(COLOUR_KEYS, r[9:17], strict=True)}
            error = str(r[17] or "")
        return cls(
            index=int(r[0]),
            repeat=int(r[1]),
            theta_i_deg=float(r[2]),
            theta_r_deg=float(r[3]),
            measured_theta_i_deg=float(r[4]),
            measured_theta_r_deg=float(r[5]),
            luminance_pct=float(r[6]),
            raw=json.loads(r[7]),
            timestamp=float(r[8]),
            colour=colour,
            colour_error=error,
        )


@dataclass(frozen=True, slots=True)
class PredictedColour:
    """The predicted colour of one plan geometry (L*a*b*) and its spectrum (% of mirror)."""

    L: float
    a: float
    b: float
    spectrum_pct: tuple[float, ...] | None = None


@dataclass(frozen=True, slots=True)
class GlossRow:
    """One stored glossmeter reading (one row of ``gloss_readings``)."""

    seq: int
    values_gu: dict[int, float | None]
    temperature_c: float | None
    predicted_gu: dict[int, float] | None
    raw: str
    timestamp: float

    @classmethod
    def from_row(cls, r: Sequence[Any]) -> GlossRow:
        """From the columns seq, g20_gu, g60_gu, g85_gu, temperature_c, predicted_json,
        raw, timestamp."""
        pred = None if r[5] is None else {int(k): float(v) for k, v in json.loads(r[5]).items()}
        return cls(
            seq=int(r[0]),
            values_gu={20: r[1], 60: r[2], 85: r[3]},
            temperature_c=r[4],
            predicted_gu=pred,
            raw=str(r[6]),
            timestamp=float(r[7]),
        )
