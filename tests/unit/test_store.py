"""The sequence store and its writer thread: order, filters, bounds, and failing disks."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import MutableMapping
from pathlib import Path
from typing import Any

import structlog.testing

from fcmaster.store import BackgroundWriter, Row, SequenceStore

DAY_S = 86400.0


def _store(
    path: Path | None, *, max_bytes: int = 1 << 30, max_age_s: float = 90 * DAY_S
) -> SequenceStore:
    store = SequenceStore(path, table="journal", max_bytes=max_bytes, max_age_s=max_age_s)
    store.open()
    return store


def _row(at: float, n: int, *, kind: str = "command", drive: str | None = "pump-1") -> Row:
    return Row(at, kind, "line1", drive, f'{{"n":{n},"pad":"{"x" * 150}"}}')


def test_records_come_back_in_sequence_filtered_and_the_newest_last(tmp_path: Path) -> None:
    store = _store(tmp_path / "j.db")
    store.append([_row(100.0 + n, n, drive=f"pump-{n % 2}") for n in range(10)])
    store.append([_row(200.0, 10, kind="alarm", drive=None)])
    everything = store.read(limit=100)
    assert [s.seq for s in everything] == list(range(1, 12))
    assert [s.seq for s in store.read(after=8, limit=100)] == [9, 10, 11]
    newest = store.read(drive="pump-1", limit=2, newest=True)
    assert [s.seq for s in newest] == [8, 10]  # the last two of pump-1, oldest first
    assert [s.kind for s in store.read(kind="alarm")] == ["alarm"]
    assert [s.seq for s in store.read(since=108.0)] == [9, 10, 11]
    store.delete_through(9)
    assert [s.seq for s in store.read()] == [10, 11]
    store.append([_row(300.0, 11)])
    assert store.read(newest=True, limit=1)[0].seq == 12  # sequence numbers are never reused
    store.close()


def test_a_flooded_store_stays_within_its_size_and_keeps_the_newest(tmp_path: Path) -> None:
    path = tmp_path / "j.db"
    store = _store(path, max_bytes=256 * 1024)
    for batch in range(60):
        store.append([_row(1000.0 + batch, batch * 100 + n) for n in range(100)])
        store.prune(2000.0, by_age=False)
    assert store.used_bytes() <= 256 * 1024
    kept = store.read(limit=10_000)
    assert kept[-1].seq == 6000  # the newest is there
    assert 500 < len(kept) < 6000  # the oldest went
    assert [s.seq for s in kept] == list(range(kept[0].seq, 6001))  # from the oldest on, whole
    store.close()
    wal = path.with_name(path.name + "-wal")
    total = path.stat().st_size + (wal.stat().st_size if wal.exists() else 0)
    assert total < 3 * 256 * 1024, total


def test_records_older_than_the_age_bound_go() -> None:
    store = _store(None, max_age_s=10 * DAY_S)
    store.append([_row(DAY_S * n, n) for n in range(20)])
    store.prune(DAY_S * 20)
    assert [int(s.at // DAY_S) for s in store.read(limit=100)] == list(range(10, 20))


def test_a_store_that_cannot_be_opened_is_one_logged_error_and_put_never_blocks(
    tmp_path: Path,
) -> None:
    (tmp_path / "a-file").write_text("")
    writer = BackgroundWriter(
        SequenceStore(tmp_path / "a-file" / "j.db", max_bytes=1 << 20, max_age_s=DAY_S)
    )
    logs: list[MutableMapping[str, Any]]
    with structlog.testing.capture_logs() as logs:
        writer.start()
        started = time.monotonic()
        for n in range(5000):
            writer.put(_row(1.0, n))
        took = time.monotonic() - started
        writer.close()
    failed = [e for e in logs if e["event"] == "store.write_failed"]
    assert len(failed) == 1, logs
    assert failed[0]["log_level"] == "error"
    assert "a-file" in failed[0]["error"]
    assert writer.dropped == 5000
    assert writer.written == 0
    assert took < 5.0  # (a generous bound: a blocking put would wait on the disk's retries)


def test_a_full_disk_part_way_is_one_logged_error_and_the_writes_before_it_are_kept(
    tmp_path: Path,
) -> None:
    # A real "file too large" from the kernel: the writer runs in a process whose files may
    # not grow past 256 KiB (RLIMIT_FSIZE, with SIGXFSZ ignored so the write fails instead).
    path = tmp_path / "j.db"
    script = textwrap.dedent(
        f"""
        import resource, signal, sys, time
        import structlog
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (256 * 1024, 256 * 1024))
        structlog.configure(logger_factory=structlog.PrintLoggerFactory(sys.stdout))
        from fcmaster.store import BackgroundWriter, Row, SequenceStore
        writer = BackgroundWriter(SequenceStore({str(path)!r}, max_bytes=1 << 30, max_age_s=1e9))
        writer.start()
        for n in range(20000):
            writer.put(Row(time.time(), "command", "line1", "pump-1", "x" * 100))
            if n % 200 == 199:
                time.sleep(0.05)  # several batches, so that some are written before the limit
        writer.close()
        print("written", writer.written, "dropped", writer.dropped)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
        env={**os.environ, "PYTHONPATH": os.getcwd()},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert sum("store.write_failed" in line for line in lines) == 1, done.stdout
    written, dropped = (int(word) for word in lines[-1].split()[1::2])
    assert written > 0
    assert dropped > 0
    assert written + dropped == 20000
    store = SequenceStore(path, max_bytes=1 << 30, max_age_s=1e9, readonly=True)
    store.open()
    assert len(store.read(limit=100_000)) == written  # what was committed is all there
    store.close()


def test_reads_run_beside_the_writer_under_its_lock() -> None:
    writer = BackgroundWriter(SequenceStore(None, max_bytes=1 << 20, max_age_s=DAY_S))
    writer.start()
    for n in range(100):
        writer.put(_row(time.time(), n))
    deadline = time.monotonic() + 10
    while writer.written < 100 and time.monotonic() < deadline:
        time.sleep(0.01)  # noqa: TID251  # a plain test, polling a thread: no loop to block
    seen: list[int] = []
    reader = threading.Thread(target=lambda: seen.extend(
        s.seq for s in writer.call(lambda store: store.read(limit=1000))
    ))  # fmt: skip
    reader.start()
    reader.join()
    writer.close()
    assert seen == list(range(1, 101))
