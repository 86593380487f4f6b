"""``runs migrate``: copy a run between stores (an instrument's SQLite file into a lab's
PostgreSQL, or any two stores), matched by the run's UUID so that a copy can be repeated.

:meth:`goniolab.store.RunStore.copy_run_from` is the entry point; :func:`copy_run` does the
work with the two stores' connections.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from goniolab.redact import redact_obj
from goniolab.store.records import json_text

if TYPE_CHECKING:  # pragma: no cover - typing only
    from goniolab.store.runstore import RunStore

__all__ = ["CHILD_KEYS", "copy_run"]

#: The conflict target of each child table (what makes a row "already there").
CHILD_KEYS: dict[str, str] = {
    "points": "run_id, idx, repeat",
    "predictions": "run_id, idx",
    "gloss_readings": "run_id, seq",
}


def copy_run(dst: RunStore, src: RunStore, run_id: int) -> tuple[int, str]:
    """Copy run ``run_id`` of ``src`` (with its readings, predictions and gloss readings)
    into ``dst`` in one transaction; returns ``(id in dst, action)``.

    A run is matched by its UUID: a run not in ``dst`` yet is ``"copied"`` (a new id); a
    copy that is behind its source (copied while it was aborted or still running, finished
    later) is ``"updated"``: its row takes the source's status, reason and metadata and the
    readings it lacks are added; an up-to-date copy is ``"unchanged"``. A copy made by an
    older goniolab (remembered in ``meta`` by the source's path and id) is matched only when
    its creation time is the source run's too (another PC's store at the same path holds
    other runs). Columns both stores have are copied; passwords in the config snapshot are
    blanked (:func:`goniolab.redact.redact_obj`).

    Raises
    ------
    StoreDamaged
        The source run's row cannot be read (nothing is written).
    """
    rec = src.get_run(run_id)
    src_run = src.db.execute("SELECT * FROM runs WHERE id = ?", (run_id,))
    names = [d[0] for d in src_run.description]
    record = dict(zip(names, src_run.fetchone(), strict=True))
    record["uuid"] = rec.uuid
    record["config_json"] = json_text(redact_obj(rec.config))
    existing = dst.find_uuid(rec.uuid)
    if existing is None:
        legacy = dst.db.execute(
            "SELECT value FROM meta WHERE key = ?", (f"migrated:{src.location}:{run_id}",)
        ).fetchone()
        if legacy is not None:
            row = dst.db.execute(
                "SELECT created_at FROM runs WHERE id = ?", (int(legacy[0]),)
            ).fetchone()
            if row is not None and float(row[0]) == rec.created_at:
                existing = int(legacy[0])
    run_cols = [c for c in dst.table_columns("runs") if c in record and c != "id"]
    with dst.db.transaction() as db:
        if existing is None:
            here = int(
                db.execute(
                    f"INSERT INTO runs({', '.join(run_cols)}) VALUES"
                    f" ({', '.join('?' for _ in run_cols)}) RETURNING id",
                    [record[c] for c in run_cols],
                ).fetchone()[0]
            )
            action = "copied"
        else:
            here = existing
            mine = db.execute(
                f"SELECT {', '.join(run_cols)} FROM runs WHERE id = ?", (here,)
            ).fetchone()
            theirs = [record[c] for c in run_cols]
            changed = list(mine) != theirs
            if changed:
                upd = [c for c in run_cols if c not in ("created_at",)]
                db.execute(
                    f"UPDATE runs SET {', '.join(f'{c} = ?' for c in upd)} WHERE id = ?",
                    [*(record[c] for c in upd), here],
                )
            action = "updated" if changed else "unchanged"
        added = _copy_children(dst, src, run_id, here)
        if action == "unchanged" and added:
            action = "updated"
    return here, action


def _copy_children(dst: RunStore, src: RunStore, run_id: int, here: int) -> int:
    """Add the readings, predictions and gloss readings of ``src``'s run ``run_id`` that
    run ``here`` of ``dst`` lacks (inside the caller's transaction); return how many were
    added."""
    added = 0
    for table, key in CHILD_KEYS.items():
        theirs = {c.lower() for c in src.table_columns(table)}
        cols = [c for c in dst.table_columns(table) if c.lower() in theirs and c != "id"]
        rows = src.db.execute(
            f"SELECT {', '.join(cols)} FROM {table} WHERE run_id = ?", (run_id,)
        ).fetchall()
        if not rows:
            continue
        count = f"SELECT COUNT(*) FROM {table} WHERE run_id = ?"
        before = dst.db.execute(count, (here,)).fetchone()[0]
        at = cols.index("run_id")
        values = [[here if k == at else v for k, v in enumerate(r)] for r in rows]
        dst.db.executemany(
            f"INSERT INTO {table}({', '.join(cols)}) VALUES"
            f" ({', '.join('?' for _ in cols)}) ON CONFLICT ({key}) DO NOTHING",
            values,
        )
        added += int(dst.db.execute(count, (here,)).fetchone()[0]) - int(before)
    return added
