"""Records kept in order on disk: SQLite, append, read by sequence, prune; off the loop.

Theory of operation
-------------------
A :class:`SequenceStore` is one SQLite table of records, each numbered by an increasing
sequence (``seq``) and stamped with its wall time (``at``), a ``kind``, the ``bus`` and
``drive`` it belongs to (either may be None) and a ``body`` (text or bytes, the user's
encoding). It knows nothing of fleets or events: the journal keeps audit records in it, and
a store-and-forward queue can keep messages waiting for a broker in another (append,
:meth:`~SequenceStore.read` after the last one sent, :meth:`~SequenceStore.delete_through`
once acknowledged).

The file is in WAL mode with ``synchronous=FULL``: a committed batch survives the process
being killed and the power going off, and readers in other processes (``fcmaster events``)
never wait for the writer. The table is bounded by age (records older than ``max_age_s``
go) and by size: when its pages in use pass ``max_bytes``, the oldest records go until it is
under nine tenths of it; SQLite reuses the freed pages, so the file stops growing there.

Nothing here may run on the event loop: a disk can stall for seconds. A
:class:`BackgroundWriter` owns the store on a thread of its own. :meth:`~BackgroundWriter.put`
only appends to a queue (never blocks, never raises); the thread makes rows of what was put
(its ``encode``, so that even that work is off the loop) and commits what has gathered in
one transaction, and a failure (a full disk, an unwritable path) is one logged error,
repeated at most every few minutes; what could not be written is counted
(``dropped``) and the queue stays bounded, so a dead disk never grows memory either.
"""

from __future__ import annotations

import contextlib
import queue
import sqlite3
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import structlog

from fcmaster.offloop import brisk
from fcmaster.store_settings import MEMORY

log = structlog.get_logger("fcmaster.store")

MAX_PENDING = 20_000  # records queued for the writer; past this they are dropped and counted
BATCH = 1000  # records per transaction at most
PRUNE_AGE_EVERY_S = 60.0
REOPEN_EVERY_S = 30.0  # a store that could not be opened is tried again this often
# A disk that is full comes and goes as records are pruned: its error is logged again only
# after this long, however often writes succeed in between.
REPEAT_ERROR_S = 300.0
T = TypeVar("T")

Body = str | bytes


@dataclass(slots=True, frozen=True)
class Row:
    """One record to append."""

    at: float  # wall time, seconds since the epoch
    kind: str
    bus: str | None
    drive: str | None
    body: Body


@dataclass(slots=True, frozen=True)
class Stored:
    """One record as read back, with its sequence number."""

    seq: int
    at: float
    kind: str
    bus: str | None
    drive: str | None
    body: Body


class SequenceStore:
    """One SQLite table of records in sequence; bounded by ``max_bytes`` and ``max_age_s``.

    Not thread-safe by itself: :class:`BackgroundWriter` serialises every use.
    """

    def __init__(
        self,
        path: Path | str | None,
        *,
        table: str = "records",
        max_bytes: int,
        max_age_s: float,
        readonly: bool = False,
    ) -> None:
        if not table.isidentifier():
            raise ValueError(f"not a table name: {table!r}")
        self.path = MEMORY if path is None else str(path)
        self.table = table
        self.max_bytes = max_bytes
        self.max_age_s = max_age_s
        self.readonly = readonly
        self._db: sqlite3.Connection | None = None

    def open(self) -> None:
        """Open (and create) the file and its table; sqlite3.Error or OSError if it cannot."""
        if self.readonly:
            uri = f"{Path(self.path).resolve().as_uri()}?mode=ro"
            db = sqlite3.connect(uri, uri=True, check_same_thread=False)
        else:
            if self.path != MEMORY:
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        try:
            if not self.readonly:
                db.execute("PRAGMA journal_mode=WAL")
                db.execute("PRAGMA synchronous=FULL")
                db.execute(f"PRAGMA journal_size_limit={max(self.max_bytes // 4, 1 << 20)}")
                db.execute(
                    f"CREATE TABLE IF NOT EXISTS {self.table} ("
                    "seq INTEGER PRIMARY KEY AUTOINCREMENT, at REAL NOT NULL, "
                    "kind TEXT NOT NULL, bus TEXT, drive TEXT, body NOT NULL)"
                )
                db.execute(f"CREATE INDEX IF NOT EXISTS {self.table}_at ON {self.table}(at)")
                db.execute(
                    f"CREATE INDEX IF NOT EXISTS {self.table}_drive ON {self.table}(drive, seq)"
                )
        except BaseException:
            db.close()
            raise
        self._db = db

    @property
    def is_open(self) -> bool:
        """Whether :meth:`open` succeeded (and :meth:`close` has not been called)."""
        return self._db is not None

    def close(self) -> None:
        """Close the file (a no-op when it is not open)."""
        db, self._db = self._db, None
        if db is not None:
            db.close()

    def _conn(self) -> sqlite3.Connection:
        if self._db is None:
            raise sqlite3.OperationalError(f"{self.path} is not open")
        return self._db

    def append(self, rows: Sequence[Row]) -> int:
        """Append ``rows`` in one transaction; the last sequence number given (0: none)."""
        db = self._conn()
        with _transaction(db):
            db.executemany(
                f"INSERT INTO {self.table} (at, kind, bus, drive, body) VALUES (?, ?, ?, ?, ?)",
                [(r.at, r.kind, r.bus, r.drive, r.body) for r in rows],
            )
            (last,) = db.execute("SELECT coalesce(max(seq), 0) FROM " + self.table).fetchone()
        return int(last)

    def read(
        self,
        *,
        after: int = 0,
        since: float | None = None,
        kind: str | None = None,
        drive: str | None = None,
        limit: int = 100,
        newest: bool = False,
    ) -> list[Stored]:
        """Records after sequence ``after``, oldest first, matching the filters.

        ``newest``: the last ``limit`` that match (still oldest first), else the first.
        """
        where, args = ["seq > ?"], [after]
        for column, value in (("kind", kind), ("drive", drive)):
            if value is not None:
                where.append(f"{column} = ?")
                args.append(value)  # type: ignore[arg-type]  # str beside int: both bind
        if since is not None:
            where.append("at >= ?")
            args.append(since)  # type: ignore[arg-type]
        order = "DESC" if newest else "ASC"
        rows = (
            self._conn()
            .execute(
                f"SELECT seq, at, kind, bus, drive, body FROM {self.table} "
                f"WHERE {' AND '.join(where)} ORDER BY seq {order} LIMIT ?",
                (*args, limit),
            )
            .fetchall()
        )
        if newest:
            rows.reverse()
        return [Stored(*row) for row in rows]

    def delete_through(self, seq: int) -> None:
        """Forget every record up to and including ``seq`` (sent and acknowledged)."""
        db = self._conn()
        with _transaction(db):
            db.execute(f"DELETE FROM {self.table} WHERE seq <= ?", (seq,))

    def used_bytes(self) -> int:
        """Bytes of the file's pages in use (freed pages are reused, not counted)."""
        db = self._conn()
        (pages,) = db.execute("PRAGMA page_count").fetchone()
        (free,) = db.execute("PRAGMA freelist_count").fetchone()
        (size,) = db.execute("PRAGMA page_size").fetchone()
        return int((pages - free) * size)

    def prune(self, now: float, *, by_age: bool = True) -> int:
        """Delete what is past the bounds (age, then size); how many records went."""
        db = self._conn()
        deleted = 0
        if by_age:
            with _transaction(db):
                cursor = db.execute(
                    f"DELETE FROM {self.table} WHERE at < ?", (now - self.max_age_s,)
                )
            deleted += cursor.rowcount
        for _ in range(20):  # each pass deletes about what is over; a few passes at most
            used = self.used_bytes()
            if used <= self.max_bytes:
                break
            first, last = db.execute(f"SELECT min(seq), max(seq) FROM {self.table}").fetchone()
            if first is None:
                break
            excess = 1.0 - 0.9 * self.max_bytes / used
            count = max(1, int((last - first + 1) * excess))
            with _transaction(db):
                cursor = db.execute(f"DELETE FROM {self.table} WHERE seq < ?", (first + count,))
            deleted += cursor.rowcount
        return deleted


@contextlib.contextmanager
def _transaction(db: sqlite3.Connection) -> Any:
    db.execute("BEGIN IMMEDIATE")
    try:
        yield
    except BaseException:
        db.execute("ROLLBACK")
        raise
    db.execute("COMMIT")


class BackgroundWriter:
    """A :class:`SequenceStore` owned by a thread: appends queued, batched, never blocking.

    Reads (:meth:`call`) run on the caller's thread under the same lock: call them from a
    worker thread (``asyncio.to_thread``), never from the event loop.
    """

    def __init__(
        self,
        store: SequenceStore,
        *,
        name: str = "store",
        encode: Callable[[Any], Row | None] | None = None,
        max_pending: int = MAX_PENDING,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.store = store
        self.name = name
        # Items put are made into rows on the writer's thread, not on the caller's loop:
        # ``encode`` (None: items are rows) gives an item's row, or None to keep nothing.
        self._encode = encode
        self._max_pending = max_pending
        self._wall = wall
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._failing = False  # the last write failed
        self._told_at = -REPEAT_ERROR_S  # when a failure was last logged (monotonic)
        self._opened_at = -REOPEN_EVERY_S
        self._pruned_at = 0.0
        self.written = 0
        self.dropped = 0
        self.last_error: str | None = None

    def start(self) -> None:
        """Start the writer thread; it opens the store (a failure is logged, not raised)."""
        self._thread = threading.Thread(target=self._run, name=f"{self.name}.writer", daemon=True)
        self._thread.start()

    def put(self, item: Any) -> None:
        """Queue ``item`` (a row, or what ``encode`` takes) for writing; returns at once.

        Past ``max_pending`` waiting, the item is dropped and counted.
        """
        if self._queue.qsize() >= self._max_pending:
            self.dropped += 1
            return
        self._queue.put(item)

    def close(self, timeout_s: float = 5.0) -> None:
        """Write what is queued, stop the thread (bounded by ``timeout_s``), close the store."""
        thread, self._thread = self._thread, None
        if thread is not None:
            self._queue.put(None)
            thread.join(timeout_s)
            if thread.is_alive():  # a stalled disk: leave it to die with the process
                log.error("store.close_timed_out", store=self.name, path=self.store.path)
                return
        with self._lock:
            self.store.close()

    def call(self, work: Callable[[SequenceStore], T]) -> T:
        """Run ``work`` on the store under the writer's lock (sqlite3.Error if not open)."""
        with self._lock:
            return work(self.store)

    def _run(self) -> None:
        stopping = False
        while not stopping:
            first = self._queue.get()
            batch: list[Any] = []
            if first is None:
                stopping = True
            else:
                batch.append(first)
            while len(batch) < BATCH:
                try:
                    row = self._queue.get_nowait()
                except queue.Empty:
                    break
                if row is None:
                    stopping = True
                else:
                    batch.append(row)
            if batch:
                with brisk():  # the loop that serves the lines gets the interpreter at once
                    self._write(self._rows(batch))

    def _rows(self, items: list[Any]) -> list[Row]:
        encode = self._encode
        if encode is None:
            return items
        rows: list[Row] = []
        for item in items:
            try:
                row = item if isinstance(item, Row) else encode(item)
            except Exception as exc:  # a bug: the item is lost, the writer goes on
                self.dropped += 1
                log.error("store.encode_failed", store=self.name, error=repr(exc))
                continue
            if row is not None:
                rows.append(row)
        return rows

    def _write(self, batch: list[Row]) -> None:
        if not batch:
            return
        with self._lock:
            try:
                if not self.store.is_open:
                    if time.monotonic() - self._opened_at < REOPEN_EVERY_S:
                        self.dropped += len(batch)
                        return
                    self._opened_at = time.monotonic()
                    self.store.open()
                self.store.append(batch)
                now = self._wall()
                by_age = now - self._pruned_at >= PRUNE_AGE_EVERY_S
                if by_age:
                    self._pruned_at = now
                self.store.prune(now, by_age=by_age)
            except (sqlite3.Error, OSError) as exc:
                self.dropped += len(batch)
                self.last_error = f"{type(exc).__name__}: {exc}"
                if not self._failing and time.monotonic() - self._told_at >= REPEAT_ERROR_S:
                    self._told_at = time.monotonic()
                    log.error(
                        "store.write_failed",
                        store=self.name,
                        path=self.store.path,
                        error=self.last_error,
                        dropped=len(batch),
                    )
                self._failing = True
                return
            self.written += len(batch)
            self._failing = False
