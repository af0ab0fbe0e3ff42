"""The event store: every event of every rig as a row of one SQLite file (WAL mode), written
before the event is published, and the outbox: each event's row per output that delivers
from it (the MQTT broker, each notification target: its ``target``, the output's name) until
that output has it delivered, so that it survives the receiver's absence and the monitor's
restart; each output reads and clears its own rows.

The schema is versioned (SQLite's ``user_version``) and migrated on open: each entry of
:data:`MIGRATIONS` takes a file from one version to the next, in one transaction. A file of a
newer version than this program knows is refused with one line. Rows are never deleted by
the monitor (the storage rule deletes recordings and clips, not events).

The readings: each rig's ROIs a row a minute (``max_c``, ``mean_c``, ``min_c`` over the
minute's frames, C; ``distance_m``, the ROI's median distance, m; :mod:`.readings`), deleted
by age with the storage's ``retention_days``; what the inspection report's trends are made of.
"""

from __future__ import annotations

import json
import sqlite3
import threading
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.measurements import jsonable

MIGRATIONS: tuple[str, ...] = (
    """
    CREATE TABLE events (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        rig TEXT NOT NULL,
        rule TEXT NOT NULL,
        level TEXT NOT NULL,
        state TEXT NOT NULL,
        time_utc TEXT NOT NULL,
        time_s REAL,
        frame INTEGER,
        value_c REAL,
        condition TEXT,
        fault TEXT,
        clip TEXT,
        clip_kept INTEGER NOT NULL DEFAULT 1,
        by TEXT,
        at_utc TEXT,
        body TEXT NOT NULL
    );
    CREATE INDEX events_by_rig ON events (rig, id);
    CREATE INDEX events_by_clip ON events (clip);
    CREATE TABLE outbox (event_id INTEGER PRIMARY KEY REFERENCES events (id));
    """,
    # a central dashboard's copy of an event names where it came from, and keeps it once
    """
    ALTER TABLE events ADD COLUMN origin TEXT;
    CREATE UNIQUE INDEX events_by_origin ON events (origin);
    """,
    # an outbox row per output (the broker, each notification target): the rows there were
    # the broker's, the only output that delivered from it
    """
    CREATE TABLE deliveries (
        target TEXT NOT NULL,
        event_id INTEGER NOT NULL REFERENCES events (id),
        PRIMARY KEY (target, event_id)
    ) WITHOUT ROWID;
    INSERT INTO deliveries (target, event_id) SELECT 'mqtt', event_id FROM outbox;
    DROP TABLE outbox;
    ALTER TABLE deliveries RENAME TO outbox;
    """,
    # the readings of each rig's ROIs, a row per ROI per minute (reports' trends); the
    # storage rule deletes them by age
    """
    CREATE TABLE readings (
        rig TEXT NOT NULL,
        roi TEXT NOT NULL,
        minute_utc TEXT NOT NULL,
        max_c REAL,
        mean_c REAL,
        min_c REAL,
        frames INTEGER NOT NULL,
        distance_m REAL,
        PRIMARY KEY (rig, roi, minute_utc)
    ) WITHOUT ROWID;
    CREATE INDEX readings_by_minute ON readings (minute_utc);
    """,
)
"""Version N+1 of the schema from version N (the first: from an empty file)."""

COLUMNS = (
    *("rig", "rule", "level", "state", "time_utc", "time_s", "frame", "value_c"),
    *("condition", "fault", "clip", "by", "at_utc", "origin"),
)

READING_COLUMNS = ("rig", "roi", "minute_utc", "max_c", "mean_c", "min_c", "frames", "distance_m")


class EventStore:
    """The events of a monitor in the SQLite file at ``path`` (module docstring); safe to use
    from several threads. ``migrations``: the schema's steps (:data:`MIGRATIONS`)."""

    def __init__(self, path: str | Path, migrations: Sequence[str] = MIGRATIONS) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            self.db.execute("PRAGMA journal_mode=WAL")
            # in WAL mode a commit survives the process's crash without an fsync of its own
            # (SQLite's advice for WAL); FULL would fsync each row, seconds on a busy disk
            self.db.execute("PRAGMA synchronous=NORMAL")
            self.db.execute("PRAGMA busy_timeout=5000")
            self.version = self._migrate(migrations)
        except sqlite3.DatabaseError as exc:
            raise InputError(f"{self.path}: not an event store ({exc})") from None
        except OSError as exc:
            raise InputError(f"{self.path}: cannot open ({exc.strerror or exc})") from None

    def _migrate(self, migrations: Sequence[str]) -> int:
        """Bring the file to the newest version; returns it."""
        version = int(self.db.execute("PRAGMA user_version").fetchone()[0])
        if version > len(migrations):
            raise InputError(
                f"{self.path}: event store of version {version}, newer than this thermodepth "
                f"reads ({len(migrations)}): upgrade thermodepth"
            )
        for step in range(version, len(migrations)):
            try:
                self.db.executescript(
                    f"BEGIN; {migrations[step]}; PRAGMA user_version = {step + 1}; COMMIT;"
                )
            except sqlite3.Error as exc:
                if self.db.in_transaction:
                    self.db.execute("ROLLBACK")  # the file stays at the version before
                raise InputError(
                    f"{self.path}: cannot migrate the event store from version {step} to "
                    f"{step + 1} ({exc})"
                ) from None
        return len(migrations)

    def add(self, event: dict[str, Any], outbox: Collection[str] = ()) -> int:
        """Write an event (a dict with ``rig``, ``rule``, ``level``, ``event``, ``time_utc``
        and what else it tells); it also waits in the outbox for each target of ``outbox``
        (the outputs' names) until :meth:`delivered` to it. Returns its id. sqlite3.Error
        when it cannot be written (a full disk); sqlite3.IntegrityError when one of the same
        ``origin`` is there already."""
        row = {k: event.get(k) for k in COLUMNS}
        row["state"] = event["event"]
        values = [row[k] for k in COLUMNS]
        body = json.dumps(jsonable(event))
        with self._lock:
            self.db.execute("BEGIN IMMEDIATE")  # a full disk may refuse even this: raised
            try:
                cur = self.db.execute(
                    f"INSERT INTO events ({', '.join(COLUMNS)}, body) "
                    f"VALUES ({', '.join('?' * (len(COLUMNS) + 1))})",
                    [*values, body],
                )
                event_id = int(cur.lastrowid or 0)
                if outbox:
                    self.db.executemany(
                        "INSERT INTO outbox (target, event_id) VALUES (?, ?)",
                        [(target, event_id) for target in outbox],
                    )
                self.db.execute("COMMIT")
            except BaseException:
                if self.db.in_transaction:  # else ROLLBACK's own error would hide the cause
                    self.db.execute("ROLLBACK")
                raise
        return event_id

    def _rows(self, sql: str, args: Sequence[Any]) -> list[dict[str, Any]]:
        with self._lock:
            rows = self.db.execute(sql, args).fetchall()
        out = []
        for event_id, body, kept in rows:
            event = json.loads(body)
            event["id"] = event_id
            if event.get("clip") is not None:
                event["clip_kept"] = bool(kept)
            out.append(event)
        return out

    def events(
        self,
        limit: int = 100,
        rig: str | None = None,
        before_id: int | None = None,
        level: str | None = None,
        state: str | None = None,
    ) -> list[dict[str, Any]]:
        """The newest events (of one rig, level, state, older than an id), newest first,
        each with its ``id`` and, where it has a clip, whether the clip is still kept."""
        where: list[str] = []
        args: list[Any] = []
        for column, value in (("rig", rig), ("level", level), ("state", state)):
            if value is not None:
                where.append(f"{column} = ?")
                args.append(value)
        if before_id is not None:
            where.append("id < ?")
            args.append(before_id)
        sql = "SELECT id, body, clip_kept FROM events"
        if where:
            sql += " WHERE " + " AND ".join(where)
        return self._rows(sql + " ORDER BY id DESC LIMIT ?", [*args, limit])

    def event(self, event_id: int) -> dict[str, Any] | None:
        """One event by its id (None: no such event)."""
        found = self._rows("SELECT id, body, clip_kept FROM events WHERE id = ?", [event_id])
        return found[0] if found else None

    def outbox(
        self, limit: int = 1000, after_id: int = 0, target: str | None = None
    ) -> list[dict[str, Any]]:
        """Events waiting for ``target`` (None: for any), oldest first."""
        where, args = ("AND target = ?", [target]) if target is not None else ("", [])
        return self._rows(
            "SELECT id, body, clip_kept FROM events WHERE id IN (SELECT event_id FROM outbox "
            f"WHERE event_id > ? {where}) ORDER BY id LIMIT ?",
            [after_id, *args, limit],
        )

    def waiting(self, target: str) -> int:
        """How many events wait for ``target``."""
        with self._lock:
            found = self.db.execute("SELECT count(*) FROM outbox WHERE target = ?", (target,))
            return int(found.fetchone()[0])

    def delivered(self, event_id: int, target: str) -> None:
        """``target`` has the event (or gave it up): out of its outbox."""
        with self._lock:
            self.db.execute(
                "DELETE FROM outbox WHERE target = ? AND event_id = ?", (target, event_id)
            )

    def clip_deleted(self, clip: str) -> None:
        """The events whose clip the storage rule deleted say so."""
        with self._lock:
            self.db.execute("UPDATE events SET clip_kept = 0 WHERE clip = ?", (clip,))

    def events_between(self, start_utc: str, end_utc: str) -> list[dict[str, Any]]:
        """The events of ``start_utc`` <= ``time_utc`` < ``end_utc`` (ISO 8601 UTC, as
        stored), oldest first."""
        return self._rows(
            "SELECT id, body, clip_kept FROM events WHERE time_utc >= ? AND time_utc < ? "
            "ORDER BY time_utc, id",
            [start_utc, end_utc],
        )

    def add_readings(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Readings (each a dict of the readings table's columns); a minute written again
        replaces the one there."""
        with self._lock:
            self.db.executemany(
                f"INSERT OR REPLACE INTO readings ({', '.join(READING_COLUMNS)}) "
                f"VALUES ({', '.join('?' * len(READING_COLUMNS))})",
                [[row.get(k) for k in READING_COLUMNS] for row in rows],
            )

    def readings(self, start_utc: str, end_utc: str) -> list[dict[str, Any]]:
        """The readings of the minutes ``start_utc`` <= ``minute_utc`` < ``end_utc``, by rig,
        ROI and minute."""
        with self._lock:
            rows = self.db.execute(
                f"SELECT {', '.join(READING_COLUMNS)} FROM readings WHERE minute_utc >= ? "
                "AND minute_utc < ? ORDER BY rig, roi, minute_utc",
                (start_utc, end_utc),
            ).fetchall()
        return [dict(zip(READING_COLUMNS, row, strict=True)) for row in rows]

    def forget_readings(self, before_utc: str) -> int:
        """Delete the readings of the minutes before ``before_utc``; how many."""
        with self._lock:
            cur = self.db.execute("DELETE FROM readings WHERE minute_utc < ?", (before_utc,))
            return cur.rowcount

    def count(self) -> int:
        with self._lock:
            return int(self.db.execute("SELECT count(*) FROM events").fetchone()[0])

    def size_bytes(self) -> int:
        """The file's size with its write-ahead log."""
        wal = self.path.with_name(self.path.name + "-wal")
        return sum(p.stat().st_size for p in (self.path, wal) if p.exists())

    def close(self) -> None:
        with self._lock:
            self.db.close()


def counts_by_rig(counts: Mapping[tuple[str, str], int]) -> dict[str, dict[str, int]]:
    """Events counted by (rig, kind) as ``{rig: {kind: n}}``, rigs in order (``/api/status``)."""
    out: dict[str, dict[str, int]] = {}
    for (rig, kind), n in sorted(counts.items()):
        out.setdefault(rig, {})[kind] = n
    return out
