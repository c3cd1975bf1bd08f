"""A real mosquitto broker for the MQTT tests, and a client that records what it hears.

Each test starts its own broker on a free loopback port (config and logs in ``tmp_path``)
and kills it afterwards. A missing mosquitto fails the test: .ci/run installs it.
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import json
import shutil
import signal
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any

import aiomqtt
import pytest

from tests.integration.ports import free_port

START_TIMEOUT_S = 10.0


def mosquitto_binary() -> str:
    """The mosquitto executable; fails the test when it is not installed."""
    found = shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()),
        None,
    )
    if found is None:
        pytest.fail("mosquitto is not installed (apt-get install mosquitto; .ci/run does it)")
    return found


class Broker:
    """One mosquitto process on 127.0.0.1; start, stop and restart it on the same port."""

    def __init__(self, directory: Path, *, persistence: bool = False, extra: str = "") -> None:
        self.directory = directory
        self.port = free_port()
        self.host = "127.0.0.1"
        self.config = directory / "mosquitto.conf"
        self.log = directory / "mosquitto.log"
        lines = [
            f"listener {self.port} 127.0.0.1",
            "allow_anonymous true" if "allow_anonymous" not in extra else "",
            f"user {getpass.getuser()}",  # as root, mosquitto would become "mosquitto"
            f"log_dest file {self.log}",
            "log_type all",
        ]
        if persistence:
            lines += ["persistence true", f"persistence_location {directory}/"]
        self.config.write_text("\n".join([*lines, extra, ""]))
        self._process: asyncio.subprocess.Process | None = None

    @property
    def url(self) -> str:
        """``mqtt://127.0.0.1:PORT``."""
        return f"mqtt://{self.host}:{self.port}"

    async def start(self) -> None:
        """Start mosquitto and wait until it accepts connections."""
        self._process = await asyncio.create_subprocess_exec(
            mosquitto_binary(),
            "-c",
            str(self.config),
            stdout=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.DEVNULL,
        )
        async with asyncio.timeout(START_TIMEOUT_S):
            while True:
                if self._process.returncode is not None:
                    log = self.log.read_text() if self.log.exists() else ""
                    pytest.fail(f"mosquitto exited with {self._process.returncode}: {log}")
                try:
                    _, writer = await asyncio.open_connection(self.host, self.port)
                except OSError:
                    await asyncio.sleep(0.02)
                    continue
                writer.close()
                await writer.wait_closed()
                return

    async def stop(self, *, graceful: bool = False) -> None:
        """Kill mosquitto (SIGKILL), or with ``graceful`` let it save its state (SIGTERM)."""
        process, self._process = self._process, None
        if process is None or process.returncode is not None:
            return
        process.send_signal(signal.SIGTERM if graceful else signal.SIGKILL)
        process.send_signal(signal.SIGCONT)  # in case it was paused
        async with asyncio.timeout(START_TIMEOUT_S):
            await process.wait()

    def pause(self) -> None:
        """Freeze mosquitto (SIGSTOP): connections stay open, nothing is answered."""
        assert self._process is not None
        self._process.send_signal(signal.SIGSTOP)

    def resume(self) -> None:
        """Let a paused mosquitto go on (SIGCONT)."""
        assert self._process is not None
        self._process.send_signal(signal.SIGCONT)

    async def __aenter__(self) -> Broker:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()


Check = Callable[[aiomqtt.Message], bool]


class Recorder:
    """A test client that records every message on ``topics`` and waits for the ones it needs."""

    def __init__(
        self,
        broker: Broker,
        *topics: str,
        identifier: str | None = None,
        clean: bool = True,
        **options: Any,
    ) -> None:
        self.broker = broker
        self.topics = topics or ("#",)
        self.messages: list[aiomqtt.Message] = []
        self._identifier = identifier
        self._clean = clean
        self._options = options  # more aiomqtt.Client options: username, tls_context, …
        self._arrived = asyncio.Event()
        self._stack = contextlib.AsyncExitStack()
        self.client: aiomqtt.Client | None = None

    async def __aenter__(self) -> Recorder:
        client = aiomqtt.Client(
            self.broker.host,
            self.broker.port,
            identifier=self._identifier,
            clean_session=self._clean,
            **self._options,
        )
        self.client = await self._stack.enter_async_context(client)
        for topic in self.topics:
            await client.subscribe(topic, qos=1)
        task = asyncio.create_task(self._collect(client))
        self._stack.push_async_callback(_cancel, task)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._stack.aclose()

    async def _collect(self, client: aiomqtt.Client) -> None:
        with contextlib.suppress(aiomqtt.MqttError):  # the broker went away
            async for message in client.messages:
                self.messages.append(message)
                self._arrived.set()

    def on(self, topic: str) -> list[aiomqtt.Message]:
        """Messages received so far whose topic matches ``topic`` (wildcards allowed)."""
        return [m for m in self.messages if m.topic.matches(topic)]

    def json_on(self, topic: str) -> list[Any]:
        """Payloads on ``topic`` decoded as JSON."""
        return [json.loads(_bytes(m)) for m in self.on(topic)]

    async def wait(
        self, topic: str, check: Check | None = None, *, start: int = 0
    ) -> aiomqtt.Message:
        """The first message (from index ``start`` on) on ``topic`` that passes ``check``."""
        index = start
        while True:
            while index < len(self.messages):
                message = self.messages[index]
                index += 1
                if message.topic.matches(topic) and (check is None or check(message)):
                    return message
            self._arrived.clear()
            await self._arrived.wait()

    async def wait_json(
        self, topic: str, check: Callable[[Any], bool] | None = None, *, start: int = 0
    ) -> Any:
        """Like :meth:`wait`, with ``check`` on the decoded JSON payload; returns the JSON."""
        message = await self.wait(
            topic, lambda m: check is None or check(json.loads(_bytes(m))), start=start
        )
        return json.loads(_bytes(message))

    async def wait_count(self, topic: str, count: int) -> list[aiomqtt.Message]:
        """Wait until ``count`` messages on ``topic`` have arrived; return them."""
        while len(found := self.on(topic)) < count:
            self._arrived.clear()
            await self._arrived.wait()
        return found

    async def publish(self, topic: str, payload: bytes | str, *, retain: bool = False) -> None:
        """Publish at QoS 1."""
        assert self.client is not None
        await self.client.publish(topic, payload, qos=1, retain=retain)

    async def command(self, topic: str, payload: dict[str, Any]) -> Any:
        """Publish a command on ``topic`` and return its result (matched by ``id``)."""
        start = len(self.messages)
        await self.publish(topic, json.dumps(payload))
        return await self.wait_json(
            f"{topic}/result", lambda r: r["id"] == payload["id"], start=start
        )


def payload_text(message: aiomqtt.Message) -> str:
    """A message's payload as text."""
    return _bytes(message).decode()


def _bytes(message: aiomqtt.Message) -> bytes:
    payload = message.payload
    assert isinstance(payload, bytes | bytearray)
    return bytes(payload)


async def _cancel(task: asyncio.Task[None]) -> None:
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
