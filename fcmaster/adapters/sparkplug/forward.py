"""Store and forward: every change on disk until the broker is known to have it.

Theory of operation
-------------------
Every change of a drive's metrics is numbered (``n``, increasing in this process) and put
in a :class:`~fcmaster.store.SequenceStore` by a
:class:`~fcmaster.store.BackgroundWriter` — all of them, connected or not, because a
connection that fails has already swallowed what was written to its socket in the seconds
before anyone noticed (a keep-alive and a half, on a silent network). Sparkplug data goes at
QoS 0, which the broker never acknowledges; so the adapter proves delivery with a barrier:
an UNSUBSCRIBE answered by the broker after everything published before it on the same
connection has been taken in (MQTT keeps a connection's packets in order). Then
:meth:`Forward.confirm` marks every change numbered up to the last one published before the
barrier as delivered.

Each session that got online has a range of changes published live: from the first change
after its births (``live_from``) to the last one confirmed. The drain reads the store in
order from its cursor: a row inside a session's confirmed range is skipped (delivered live,
or told by a birth), a row of the current session not yet confirmed stops the read (it is
live, and will be confirmed or, if the connection fails, become history), and every other
row — written while the broker or the primary host was away, lost with a failing
connection, or left from before a restart — is history: published again with
``is_historical``, oldest first, and deleted once a barrier after it has been answered.

The store is bounded as the journal's is (size and age, oldest first); the writer runs off the
loop, and the reads (with their parsing) and deletes here go to a worker thread.
"""

from __future__ import annotations

import asyncio
import json
import os
import sqlite3
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from fcmaster.adapters.sparkplug.metrics import Reading
from fcmaster.adapters.sparkplug.payload import DataType
from fcmaster.offloop import run_off_loop
from fcmaster.store import BackgroundWriter, Row, SequenceStore, Stored

__all__ = ["Change", "Forward", "bd_seq_path", "next_bd_seq"]

KIND = "ddata"
READ_ROWS = 500  # rows per read of the backlog


@dataclass(slots=True, frozen=True)
class Change:
    """One stored change: the device and its changed readings, oldest first."""

    seq: int  # the store's
    device: str
    readings: list[tuple[str, Reading]]


class Forward:
    """The store-and-forward queue of one edge node (see the module docstring)."""

    def __init__(self, path: str | None, *, max_bytes: int, max_age_s: float) -> None:
        store = SequenceStore(path, table="sparkplug", max_bytes=max_bytes, max_age_s=max_age_s)
        self.writer = BackgroundWriter(store, name="sparkplug", encode=_row)
        self.epoch = os.urandom(6).hex()  # tells this process's rows from a previous one's
        self.last_n = 0  # the last change numbered
        self._live: list[int] | None = None  # [live_from, confirmed] of the current session
        self._closed: list[tuple[int, int]] = []  # the same of ended sessions
        self._cursor = 0  # every stored row up to this seq is settled
        self.replayed = 0  # rows published again as history
        self.unborn = 0  # history rows for a device not born now: left out

    def start(self) -> None:
        """Start the writer (it opens the store on its thread)."""
        self.writer.start()

    def close(self) -> None:
        """Write what is queued and close the store."""
        self.writer.close()

    def record(self, bus: str, device: str, changes: Mapping[str, Reading], at: float) -> int:
        """Keep ``changes`` of ``device`` (never blocks); the change's number."""
        self.last_n += 1
        # made into a row on the writer's thread: the loop only queues it
        self.writer.put((at, bus, device, self.epoch, self.last_n, dict(changes)))
        return self.last_n

    # -- sessions -------------------------------------------------------------------------

    def session_live(self) -> None:
        """The node is online: changes from the next one on are published live."""
        self._live = [self.last_n + 1, self.last_n]

    def session_ended(self) -> None:
        """The session ended: what it did not confirm is history now."""
        if self._live is not None:
            low, high = self._live
            if high >= low:
                self._closed.append((low, high))
            self._live = None

    def confirm(self, through: int) -> None:
        """The broker has every change published live up to number ``through``."""
        if self._live is not None:
            self._live[1] = max(self._live[1], min(through, self.last_n))

    @property
    def confirmed(self) -> int:
        """The last change number the broker is known to have (0: none in this session)."""
        return 0 if self._live is None else self._live[1]

    def _delivered(self, n: int) -> bool:
        return any(low <= n <= high for low, high in self._closed) or (
            self._live is not None and self._live[0] <= n <= self._live[1]
        )

    def _pending_live(self, n: int) -> bool:
        return self._live is not None and n > self._live[1] and n >= self._live[0]

    # -- the drain ------------------------------------------------------------------------

    async def backlog(self) -> tuple[list[Change], int]:
        """The next stored changes to publish as history, and the seq they settle through.

        Reads at most :data:`READ_ROWS`, and parses them, on a worker thread (the loop only
        sorts them); empty with the cursor when there is nothing to do.
        """
        cursor = self._cursor

        def read() -> list[tuple[int, tuple[str, int, Change] | None]]:
            rows = self.writer.call(lambda s: s.read(after=cursor, limit=READ_ROWS))
            return [(row.seq, _parse(row)) for row in rows]

        try:
            rows = await run_off_loop(read)
        except sqlite3.Error:  # not open yet, or the disk failed (the writer logs it)
            return [], self._cursor
        changes: list[Change] = []
        through = self._cursor
        for seq, parsed in rows:
            if parsed is None:
                through = seq
                continue
            epoch, n, change = parsed
            if epoch == self.epoch and self._pending_live(n):
                break
            if epoch != self.epoch or not self._delivered(n):
                changes.append(change)
            through = seq
        return changes, through

    async def settle(self, through: int) -> None:
        """Rows up to ``through`` are delivered: forget them."""
        if through <= self._cursor:
            return
        self._cursor = through
        try:
            await asyncio.to_thread(self.writer.call, lambda s: s.delete_through(through))
        except sqlite3.Error:
            return

    async def size_bytes(self) -> int:
        """The store's pages in use, in bytes (0 while it is not open)."""
        try:
            return await asyncio.to_thread(self.writer.call, lambda s: s.used_bytes())
        except sqlite3.Error:
            return 0


def _row(item: tuple[float, str, str, str, int, dict[str, Reading]]) -> Row:
    at, bus, device, epoch, n, changes = item
    items = [[name, r.datatype.value, r.value, r.at_ms] for name, r in changes.items()]
    body = json.dumps([epoch, n, items], separators=(",", ":"))
    return Row(at=at, kind=KIND, bus=bus, drive=device, body=body)


def _parse(row: Stored) -> tuple[str, int, Change] | None:
    try:
        epoch, n, items = json.loads(row.body)
        readings = [
            (str(name), Reading(DataType(datatype), value, "", at_ms))
            for name, datatype, value, at_ms in items
        ]
    except (ValueError, TypeError):  # not one of ours: skipped
        return None
    return str(epoch), int(n), Change(row.seq, row.drive or "", readings)


def bd_seq_path(store: str | None) -> Path | None:
    """The file beside the store that keeps the last ``bdSeq`` used (None: in memory)."""
    return None if store is None else Path(f"{store}.bdseq")


def next_bd_seq(path: Path | None, current: int | None) -> int:
    """The ``bdSeq`` of the next connection, kept in ``path`` before it is used.

    It follows the last one used (``current``, or the file's after a restart), modulo 256;
    0 the first time. Written and synced before the CONNECT, so a process killed at any
    moment never reuses the number of a Will the broker may still hold.
    """
    last = current
    if last is None and path is not None:
        try:
            last = int(path.read_text().strip())
        except (OSError, ValueError):
            last = None
    value = 0 if last is None else (last + 1) % 256
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary = path.with_name(path.name + ".tmp")
        with temporary.open("w") as file:
            file.write(f"{value}\n")
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    return value
