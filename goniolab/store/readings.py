"""The readings of runs: one row per reading in ``points`` (with its measured colour), the
model's ``predictions`` per plan geometry (with predicted colour and spectrum), and the
glossmeter's ``gloss_readings``; each write is its own committed transaction.

:class:`ReadingTables` is a part of :class:`goniolab.store.RunStore` (its reading methods),
kept apart from the run rows, the backends and the claims.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from goniolab.store.connection import Connection
from goniolab.store.exceptions import StoreDamaged
from goniolab.store.records import COLOUR_KEYS, GlossRow, PointRow, PredictedColour, json_text

__all__ = ["ReadingTables"]


class ReadingTables:
    """The reading methods of a store: what a runner writes per reading, what exports read.

    A class that mixes it in sets :attr:`db` and :attr:`location`.
    """

    #: The store's connection.
    db: Connection
    #: How the store names itself in messages.
    location: str

    @property
    def has_colour(self) -> bool:
        """Whether this store has the colour columns (an old read-only store may not)."""
        return self.db.has_column("points", "colour_L")

    # ------------------------------------------------------------------ points
    def add_point(
        self,
        run_id: int,
        *,
        index: int,
        repeat: int,
        theta_i_deg: float,
        theta_r_deg: float,
        measured_theta_i_deg: float,
        measured_theta_r_deg: float,
        luminance_pct: float,
        raw: Mapping[str, Any],
        timestamp: float,
        colour: Mapping[str, float] | None = None,
        colour_error: str = "",
    ) -> None:
        """Commit one reading. A second reading of the same (index, repeat) is refused.

        ``colour`` (keys of :data:`COLOUR_KEYS`) is the reading's measured colour, stored in
        the same row; ``colour_error`` says why there is none (a bad spectrum).

        Raises
        ------
        sqlite3.IntegrityError
            When (run_id, index, repeat) is already stored.
        """
        with self.db.transaction() as db:
            db.execute(
                "INSERT INTO points(run_id, idx, repeat, theta_i_deg, theta_r_deg,"
                " measured_theta_i_deg, measured_theta_r_deg, luminance_pct, raw_json, timestamp)"
                " VALUES (?,?,?,?,?,?,?,?,?,?)",
                (run_id, index, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,
                 measured_theta_r_deg, luminance_pct, json_text(dict(raw)), timestamp),
            )  # fmt: skip
            if colour is not None or colour_error:
                values = [None if colour is None else float(colour[k]) for k in COLOUR_KEYS]
                db.execute(
                    "UPDATE points SET colour_X = ?, colour_Y = ?, colour_Z = ?, colour_L = ?,"
                    " colour_a = ?, colour_b = ?, colour_C = ?, colour_h_deg = ?,"
                    " colour_error = ? WHERE run_id = ? AND idx = ? AND repeat = ?",
                    (*values, colour_error or None, run_id, index, repeat),
                )

    def done_keys(self, run_id: int) -> set[tuple[int, int]]:
        """Return the (index, repeat) pairs already stored for ``run_id``."""
        rows = self.db.execute("SELECT idx, repeat FROM points WHERE run_id = ?", (run_id,))
        return {(int(i), int(r)) for i, r in rows.fetchall()}

    def points(self, run_id: int) -> list[PointRow]:
        """Return every stored reading of ``run_id`` ordered by (index, repeat)."""
        colour_sql = (
            ", colour_X, colour_Y, colour_Z, colour_L, colour_a, colour_b, colour_C,"
            " colour_h_deg, colour_error"
            if self.has_colour
            else ""
        )
        rows = self.db.execute(
            "SELECT idx, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,"
            " measured_theta_r_deg, luminance_pct, raw_json, timestamp"
            + colour_sql
            + " FROM points WHERE run_id = ? ORDER BY idx, repeat",
            (run_id,),
        ).fetchall()
        return [self._decoded(PointRow.from_row, run_id, "reading", r) for r in rows]

    def count_points(self, run_id: int) -> int:
        """Return the number of stored readings of ``run_id``."""
        row = self.db.execute("SELECT COUNT(*) FROM points WHERE run_id = ?", (run_id,))
        return int(row.fetchone()[0])

    # ------------------------------------------------------------------ predictions
    def add_predictions(self, run_id: int, rows: Sequence[tuple[int, float, float, float]]) -> None:
        """Store predictions ``(index, theta_i_deg, theta_r_deg, predicted_pct)`` (upsert)."""
        with self.db.transaction() as db:
            db.executemany(
                "INSERT INTO predictions(run_id, idx, theta_i_deg, theta_r_deg,"
                " predicted_pct) VALUES (?,?,?,?,?) ON CONFLICT (run_id, idx) DO UPDATE SET"
                " theta_i_deg = excluded.theta_i_deg, theta_r_deg = excluded.theta_r_deg,"
                " predicted_pct = excluded.predicted_pct",
                [(run_id, int(i), float(ti), float(tr), float(p)) for i, ti, tr, p in rows],
            )

    def add_predicted_colours(
        self, run_id: int, rows: Sequence[tuple[int, PredictedColour]]
    ) -> None:
        """Store the predicted colour (and spectrum) of geometries already predicted."""
        with self.db.transaction() as db:
            db.executemany(
                "UPDATE predictions SET predicted_L = ?, predicted_a = ?, predicted_b = ?,"
                " predicted_spectrum_json = ? WHERE run_id = ? AND idx = ?",
                [
                    (
                        c.L,
                        c.a,
                        c.b,
                        None if c.spectrum_pct is None else json.dumps(list(c.spectrum_pct)),
                        run_id,
                        int(i),
                    )
                    for i, c in rows
                ],
            )

    def predicted_colours(self, run_id: int) -> dict[int, PredictedColour]:
        """Return ``{index: PredictedColour}`` for the geometries with a predicted colour."""
        if not self.has_colour:
            return {}
        rows = self.db.execute(
            "SELECT idx, predicted_L, predicted_a, predicted_b, predicted_spectrum_json"
            " FROM predictions WHERE run_id = ? AND predicted_L IS NOT NULL",
            (run_id,),
        ).fetchall()
        return {
            int(i): PredictedColour(
                float(lv), float(av), float(bv), None if sj is None else tuple(json.loads(sj))
            )
            for i, lv, av, bv, sj in rows
        }

    def predictions(self, run_id: int) -> dict[int, float]:
        """Return ``{index: predicted_pct}`` for ``run_id``."""
        rows = self.db.execute(
            "SELECT idx, predicted_pct FROM predictions WHERE run_id = ?", (run_id,)
        ).fetchall()
        return {int(i): float(p) for i, p in rows}

    # ------------------------------------------------------------------ gloss
    def add_gloss_reading(
        self,
        run_id: int,
        *,
        values_gu: Mapping[int, float | None],
        temperature_c: float | None,
        predicted_gu: Mapping[int, float] | None,
        raw: str,
        timestamp: float,
    ) -> int:
        """Commit one glossmeter reading; returns its sequence number within the run."""
        with self.db.transaction() as db:
            seq = int(
                db.execute(
                    "SELECT COALESCE(MAX(seq), -1) + 1 FROM gloss_readings WHERE run_id = ?",
                    (run_id,),
                ).fetchone()[0]
            )
            pred = (
                None
                if predicted_gu is None
                else json_text({str(k): v for k, v in predicted_gu.items()})
            )
            db.execute(
                "INSERT INTO gloss_readings(run_id, seq, g20_gu, g60_gu, g85_gu, temperature_c,"
                " predicted_json, raw, timestamp) VALUES (?,?,?,?,?,?,?,?,?)",
                (run_id, seq, values_gu.get(20), values_gu.get(60), values_gu.get(85),
                 temperature_c, pred, raw, timestamp),
            )  # fmt: skip
        return seq

    def gloss_readings(self, run_id: int) -> list[GlossRow]:
        """Return the glossmeter readings of ``run_id`` in the order they were read."""
        rows = self.db.execute(
            "SELECT seq, g20_gu, g60_gu, g85_gu, temperature_c, predicted_json, raw, timestamp"
            " FROM gloss_readings WHERE run_id = ? ORDER BY seq",
            (run_id,),
        ).fetchall()
        return [self._decoded(GlossRow.from_row, run_id, "gloss reading", r) for r in rows]

    def _decoded(self, build: Callable[[Any], Any], run_id: int, what: str, row: Any) -> Any:
        """``build(row)``, or :class:`StoreDamaged` naming the store, run and row."""
        try:
            return build(row)
        except (TypeError, ValueError, IndexError) as exc:
            raise StoreDamaged(
                f"store {self.location}: run {run_id} is damaged: {what} {row[0]}: {exc}"
            ) from None
