"""`fcmaster` commands as real subprocesses, for the end-to-end daemon tests.

Every process is started with ``sys.executable -m fcmaster``, so the tests run the code of
this checkout; its stderr (the daemon's JSON logs) goes to a file, so a chatty process never
blocks on a full pipe and a failing test can show what it said. :func:`until` polls with a
deadline: these tests share a loaded CI machine, so deadlines are generous upper bounds and
never the thing under test.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import httpx

T = TypeVar("T")

START_S = 30.0  # a cold interpreter importing FastAPI on a busy 2-core machine
EXIT_S = 10.0  # "promptly": the upper bound a SIGTERM must beat


class Child:
    """One ``python -m fcmaster …`` subprocess; stdout piped, stderr to ``log``."""

    def __init__(self, process: asyncio.subprocess.Process, log: Path, name: str) -> None:
        self.process = process
        self.log = log
        self.name = name

    @property
    def running(self) -> bool:
        """Whether it has not exited yet."""
        return self.process.returncode is None

    def tail(self, lines: int = 15) -> str:
        """The end of what it logged, for assertion messages."""
        text = self.log.read_text(encoding="utf-8", errors="replace") if self.log.exists() else ""
        return "\n".join(text.splitlines()[-lines:])

    def log_events(self) -> list[dict[str, Any]]:
        """Its stderr as JSON log records (json.loads fails the test on any other line)."""
        text = self.log.read_text(encoding="utf-8")
        return [json.loads(line) for line in text.splitlines() if line.strip()]

    def check_alive(self) -> None:
        """Fail the test, with the log, if the process has died."""
        if not self.running:
            raise AssertionError(
                f"{self.name} exited with {self.process.returncode}:\n{self.tail()}"
            )

    async def readline(self, timeout_s: float = START_S) -> str:
        """The next line it printed on stdout."""
        assert self.process.stdout is not None
        line = await asyncio.wait_for(self.process.stdout.readline(), timeout_s)
        if not line:
            raise AssertionError(f"{self.name} closed stdout:\n{self.tail()}")
        return line.decode()

    async def stop(self, signum: signal.Signals = signal.SIGTERM) -> tuple[int, float]:
        """Send ``signum``; return the exit code and the seconds it took (at most EXIT_S)."""
        loop = asyncio.get_running_loop()
        started = loop.time()
        self.process.send_signal(signum)
        try:
            code = await asyncio.wait_for(self.process.wait(), EXIT_S)
        except TimeoutError:
            raise AssertionError(
                f"{self.name} still running {EXIT_S} s after {signum.name}:\n{self.tail()}"
            ) from None
        return code, loop.time() - started


@contextlib.asynccontextmanager
async def child(
    *args: str,
    log: Path,
    cwd: Path | None = None,
    name: str | None = None,
    env: dict[str, str] | None = None,
) -> AsyncIterator[Child]:
    """Run ``fcmaster ARGS`` (``env``: added to ours); kill it on the way out if left running."""
    with log.open("ab") as stderr:
        process = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "fcmaster", *args,
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE, stderr=stderr,
            cwd=cwd, env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
        )  # fmt: skip
    try:
        yield Child(process, log, name or " ".join(args[:1]))
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()


async def until(
    probe: Callable[[], Awaitable[T | None]],
    what: str,
    *,
    alive: Child | None = None,
    timeout_s: float = START_S,
) -> T:
    """Poll ``probe`` until it returns something truthy; fail naming ``what`` at the deadline.

    Connection errors count as "not yet" (the daemon may not listen yet), but ``alive``
    must keep running meanwhile.
    """
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    last: object = None
    while True:
        if alive is not None:
            alive.check_alive()
        try:
            value = await probe()
        except httpx.TransportError as exc:
            value, last = None, exc
        if value:
            return value
        if value is not None:
            last = value
        if loop.time() > deadline:
            tail = f"\n{alive.name} logged:\n{alive.tail()}" if alive else ""
            raise AssertionError(f"no {what} within {timeout_s} s; last: {last!r}{tail}")
        await asyncio.sleep(0.1)


async def get_json(client: httpx.AsyncClient, path: str) -> Any:
    """GET ``path``; its JSON body (an HTTP error fails the test)."""
    response = await client.get(path)
    response.raise_for_status()
    return response.json()


def by_name(items: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Drive states or bus infos keyed by their name."""
    return {item["name"]: item for item in items}
