"""The commissioning tools, tried as a new user tries them: each defect found that way.

Every command runs as its own ``python -m fcmaster`` process, against simulated drives on a
pseudo-terminal, a real socket, or the files a user has.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import signal
import socket
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from fcmaster.errors import UsageError
from fcmaster.sim import DriveSettings, LineSettings
from fcmaster.subcommands import monitor
from tests.integration import commissioning
from tests.integration.daemon_harness import START_S, child
from tests.integration.ports import free_port

REPO = Path(__file__).resolve().parents[2]


async def test_control_refused_by_the_drive_says_so_without_a_traceback() -> None:
    # A Mitsubishi drive kept out of network operation answers a run command with NAK A.
    line = LineSettings(protocol="mitsubishi", baudrate=19200, parity="E", stopbits=2)
    async with commissioning.served(line, [(3, DriveSettings(local=True))]) as server:
        code, _, err = await commissioning.fcmaster(
            server, "mitsubishi", "control", "--address", "3", "start", "--frequency", "20"
        )
    assert code == 1, err
    assert "Traceback" not in err
    assert err.startswith("fcmaster control: start: the drive refused")
    assert "mode error" in err.lower()


async def test_scan_in_address_format_31_tries_1_to_31_by_default() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=38400, parity="E")
    async with commissioning.served(line, [(31, DriveSettings(response_delay_s=0.005))]) as server:
        code, out, err = await commissioning.fcmaster(
            server, "danfoss-fc", "scan", "--baudrate", "38400", "--address-format", "31",
            "--timeout", "0.03", "--json",
        )  # fmt: skip
    assert code == 0, err
    assert [entry["address"] for entry in json.loads(out)] == [31]


async def test_scan_of_enc_drives_with_decimal_addresses_tries_1_to_99_by_default() -> None:
    line = LineSettings(
        protocol="enc",
        baudrate=38400,
        parity="N",
        protocol_options=(("address_encoding", "decimal"),),
    )
    async with commissioning.served(line, [(99, DriveSettings(response_delay_s=0.005))]) as server:
        code, out, err = await commissioning.fcmaster(
            server, "enc", "scan", "--baudrate", "38400", "--parity", "N",
            "--address-encoding", "decimal", "--timeout", "0.03", "--json",
        )  # fmt: skip
    assert code == 0, err
    assert [entry["address"] for entry in json.loads(out)] == [99]


async def test_ctrl_c_in_a_scan_lists_the_drives_found_and_ends_the_progress_line() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=19200, parity="E")
    async with commissioning.served(line, [(2, DriveSettings())]) as server:
        # stderr on a terminal, as a technician sees it: the progress bar is drawn there.
        terminal, tty_side = os.openpty()
        try:
            process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "fcmaster", "scan", "--port", server.device,
                "--baudrate", "19200", "--timeout", "0.2",
                stdout=asyncio.subprocess.PIPE, stderr=tty_side,
            )  # fmt: skip
            os.close(tty_side)
            shown = b""
            while b"found 1" not in shown:  # drive 2 answered; addresses 3… take 0.4 s each
                shown += await asyncio.wait_for(asyncio.to_thread(os.read, terminal, 4096), 30)
            process.send_signal(signal.SIGINT)
            out, _ = await asyncio.wait_for(process.communicate(), 30)
            with contextlib.suppress(OSError):  # EIO once the child has closed its side
                while chunk := os.read(terminal, 4096):
                    shown += chunk
        finally:
            os.close(terminal)
    assert process.returncode == 130
    assert re.fullmatch(r"\s+2  status 0x[0-9A-F]{4}  \w+.*\n", out.decode()), out
    after_bar = shown.decode().rpartition("found 1")[2]
    assert re.match(r"\r?\ninterrupted at \d+ of 126 addresses\r?\n", after_bar), shown


SIM_CONFIG = """
buses:
  - name: north
    port: {port}
    drives:
      - {{name: pump-1, address: 1}}
http:
  listen: 127.0.0.1:{http_port}
  tokens:
    - {{name: scada, role: viewer, token: "${{FCM_TEST_UNSET_TOKEN}}"}}
"""


async def test_sim_config_serves_without_the_daemons_secrets(tmp_path: Path) -> None:
    config = tmp_path / "plant.yaml"
    port = tmp_path / "ttyNORTH"
    config.write_text(SIM_CONFIG.format(port=port, http_port=free_port()))
    env = {k: v for k, v in os.environ.items() if k != "FCM_TEST_UNSET_TOKEN"}
    os.environ.pop("FCM_TEST_UNSET_TOKEN", None)
    assert env.get("FCM_TEST_UNSET_TOKEN") is None
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split() == ["north", str(port)]
        assert os.readlink(port).startswith("/dev/pts/")
        code, _ = await sim.stop()
    assert code == 0
    # The daemon still insists: it would use the token.
    async with child("check", "--config", str(config), log=tmp_path / "check.log") as check:
        assert await asyncio.wait_for(check.process.wait(), START_S) == 2
    assert "environment variable FCM_TEST_UNSET_TOKEN is not set" in check.tail()


async def test_sim_config_leaves_an_existing_link_at_a_port_alone(tmp_path: Path) -> None:
    adapter = tmp_path / "ttyUSB0"  # stands for the device a by-id link leads to
    adapter.write_text("")
    by_id = tmp_path / "usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"
    by_id.symlink_to(adapter)
    config = tmp_path / "plant.yaml"
    config.write_text(SIM_CONFIG.format(port=by_id, http_port=free_port()))
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert await asyncio.wait_for(sim.process.wait(), START_S) == 1
    assert f"{by_id} already links to {adapter}; not replacing it" in sim.tail()
    assert os.readlink(by_id) == str(adapter)


async def test_sim_replaces_a_dangling_link_a_killed_simulator_left(tmp_path: Path) -> None:
    link = tmp_path / "ttyFC"
    link.symlink_to("/dev/pts/no-such-pty")
    args = ("sim", "--link", str(link))
    async with child(*args, log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split() == ["line1", str(link)]
        assert os.readlink(link).startswith("/dev/pts/")
        code, _ = await sim.stop()
    assert code == 0
    assert not link.is_symlink()


@contextlib.asynccontextmanager
async def http_answering(status: str) -> AsyncIterator[str]:
    """A real HTTP server that answers every request with ``status``; its URL."""

    async def answer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.readuntil(b"\r\n\r\n")
        writer.write(
            f"HTTP/1.1 {status}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".encode()
        )
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(answer, "127.0.0.1", 0)
    async with server:
        yield f"http://127.0.0.1:{server.sockets[0].getsockname()[1]}"


async def test_monitor_at_a_url_that_is_not_fcmaster_blames_the_url_not_the_token() -> None:
    async with http_answering("404 Not Found") as url:
        with pytest.raises(UsageError) as refused:
            await monitor.run(url, "a-token-that-is-fine", once=True)
    message = str(refused.value)
    assert "HTTP 404" in message
    assert "--url" in message
    assert "token" not in message


@pytest.mark.parametrize("token", [None, "not-a-known-token"], ids=["no-token", "wrong-token"])
async def test_monitor_refused_for_its_token_says_so(
    token: str | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("FCM_TOKEN", raising=False)
    async with http_answering("401 Unauthorized") as url:
        with pytest.raises(UsageError) as refused:
            await monitor.run(url, token, once=True)
    message = str(refused.value)
    assert "HTTP 401" in message
    assert ("does not accept this token" if token else "wants a viewer token") in message


RUN_CONFIG = """
buses:
  - name: north
    port: {port}
    drives:
      - {{name: pump-1, address: 1}}
http:
  listen: 127.0.0.1:{http_port}
"""


@pytest.mark.parametrize("override", [False, True], ids=["http.listen", "--http-listen"])
async def test_a_taken_http_port_is_reported_before_any_line_opens(
    tmp_path: Path, override: bool
) -> None:
    device = tmp_path / "ttyUSB7"  # absent: a line opened would log that it cannot open it
    with socket.create_server(("127.0.0.1", 0)) as taken:
        busy = taken.getsockname()[1]
        config = tmp_path / "plant.yaml"
        listen = free_port() if override else busy
        config.write_text(RUN_CONFIG.format(port=device, http_port=listen))
        extra = ("--http-listen", f"127.0.0.1:{busy}") if override else ()
        args = ("run", "--config", str(config), *extra)
        async with child(*args, log=tmp_path / "run.log") as run:
            assert await asyncio.wait_for(run.process.wait(), START_S) == 2
    said = run.log.read_text()
    where = "--http-listen" if override else "http.listen"
    assert f"fcmaster run: cannot serve HTTP at 127.0.0.1:{busy} ({where}): it is taken" in said
    assert f"pass --http-listen 127.0.0.1:{busy + 1}" in said
    assert "ttyUSB7" not in said  # no line was opened first
    assert "invalid configuration" not in said


async def test_run_with_the_demo_config_named_is_the_demo(tmp_path: Path) -> None:
    port = free_port()
    args = ("run", "--config", str(REPO / "config" / "demo.yaml"), "--http-listen",
            f"127.0.0.1:{port}")  # fmt: skip
    async with child(*args, log=tmp_path / "run.log") as demo:
        banner = await demo.readline()
        code, _ = await demo.stop()
    assert re.fullmatch(rf"fcmaster demo: dashboard at http://127\.0\.0\.1:{port}/#token=\S+\n",
                        banner), banner  # fmt: skip
    assert code == 0


async def test_the_readme_shows_what_sim_prints(tmp_path: Path) -> None:
    async with child("sim", "--addresses", "1-2", log=tmp_path / "sim.log") as sim:
        name, path = (await sim.readline()).split()
        await sim.stop()
    assert path.startswith("/dev/pts/")
    readme = (REPO / "README.md").read_text()
    assert f"prints `{name} /dev/pts/N`" in readme


def test_the_readme_links_only_to_files_in_the_repository() -> None:
    readme = (REPO / "README.md").read_text()
    assert "../" not in readme  # a clone has nothing beside it
    for target in re.findall(r"\]\(([^)#:]+)\)", readme):
        assert (REPO / target).exists(), target
