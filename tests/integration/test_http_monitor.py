"""`fcmaster monitor` against a live HTTP adapter, and its table."""

from __future__ import annotations

import asyncio
import io

import pytest

from fcmaster.cli import COMMANDS, build_parser
from fcmaster.errors import FcmasterError, UsageError
from fcmaster.subcommands.monitor import Fleet, render_table, run, stream_url
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import VIEWER_TOKEN, http_settings, serving
from tests.integration.ports import free_port


class _Terminal(io.StringIO):
    """A terminal that tells when something was written."""

    def __init__(self) -> None:
        super().__init__()
        self.written = asyncio.Event()

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> int:
        self.written.set()
        return super().write(text)

    async def shows(self, text: str) -> None:
        while text not in self.getvalue():
            self.written.clear()
            await self.written.wait()


async def test_once_prints_the_fleet_with_states_and_alarm_texts() -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=True, hz=42.5)
    gateway.reply("fan-1", alarms=((14, "Earth fault"),))
    gateway.stats["line1"].requests = 1234
    async with serving(gateway) as adapter:
        out = io.StringIO()
        async with asyncio.timeout(10):
            assert await run(adapter.url, VIEWER_TOKEN, once=True, out=out) == 0
    text = out.getvalue()
    assert "fcmaster monitor · 2 drives · live" in text
    assert "line1 up  req 1234" in text
    pump = next(line for line in text.splitlines() if line.startswith("pump-1"))
    assert "run fwd" in pump
    assert "42.50" in pump
    fan = next(line for line in text.splitlines() if line.startswith("fan-1"))
    assert "FAULT" in fan
    assert "14 Earth fault" in fan


async def test_live_mode_redraws_in_place_on_a_terminal() -> None:
    gateway = FakeGateway()
    async with serving(gateway) as adapter:
        out = _Terminal()
        task = asyncio.create_task(run(adapter.url, VIEWER_TOKEN, interval_s=0.01, out=out))
        async with asyncio.timeout(10):
            await out.shows("pump-1")
            gateway.reply("pump-1", running=True, hz=17.25)
            await out.shows("17.25")
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    assert out.getvalue().startswith("\x1b[H")  # cursor home: the table is redrawn in place
    assert "\x1b[J" in out.getvalue()


async def test_a_refused_stream_asks_for_a_token() -> None:
    async with serving(FakeGateway()) as adapter:
        with pytest.raises(UsageError, match="--token"):
            await run(adapter.url, "not-a-token-at-all", once=True, out=io.StringIO())


async def test_an_unreachable_daemon_is_a_failure_in_once_mode() -> None:
    with pytest.raises(FcmasterError, match="cannot reach"):
        await run(f"http://127.0.0.1:{free_port()}", None, once=True, out=io.StringIO())


def test_the_cli_runs_monitor_and_a_bad_url_is_a_usage_error() -> None:
    # main() maps UsageError to exit 2; it also configures logging for the whole process,
    # which the other tests here must not inherit, so the command is called directly.
    args = build_parser().parse_args(["monitor", "--url", "ftp://x", "--once"])
    assert (args.url, args.once, args.interval) == ("ftp://x", True, 0.5)
    with pytest.raises(UsageError, match="--url"):
        COMMANDS[args.command](args)


def test_stream_urls() -> None:
    assert stream_url("http://127.0.0.1:8080") == "ws://127.0.0.1:8080/api/v1/stream"
    assert stream_url("https://gw.example/") == "wss://gw.example/api/v1/stream"
    assert stream_url("127.0.0.1:9000") == "ws://127.0.0.1:9000/api/v1/stream"
    assert stream_url("ws://h/api/v1/stream?bus=line1") == "ws://h/api/v1/stream?bus=line1"


def test_the_table_marks_offline_and_disconnected_and_fits_the_width() -> None:
    fleet = Fleet()
    fleet.apply(
        {
            "type": "snapshot",
            "drives": [
                {
                    "name": "a-very-long-drive-name",
                    "bus": "line1",
                    "address": 7,
                    "online": False,
                    "alarms": [],
                    "warnings": [{"code": 59, "text": "Current limit " * 20}],
                },
            ],
            "buses": [{"name": "line1", "up": False}],
        }
    )
    text = render_table(fleet, width=80, now=1.0)
    assert "disconnected" in text
    assert "line1 DOWN" in text
    row = next(line for line in text.splitlines() if line.startswith("a-very"))
    assert "offline" in row
    assert len(row) == 80


async def test_the_monitor_can_share_a_model_with_anonymous_reads() -> None:
    async with serving(FakeGateway(), http_settings(anonymous="viewer")) as adapter:
        out = io.StringIO()
        async with asyncio.timeout(10):
            assert await run(adapter.url, None, once=True, out=out) == 0
    assert "pump-1" in out.getvalue()
