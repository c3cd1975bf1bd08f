"""`fcmaster run` while one address holds many OPC UA connections that never log in.

asyncua alone took a thousand idle sockets before it refused the next connection, and
closed them only after 30 s: SCADA stayed out. Here an address keeps only so many
connections not logged in (its oldest make way), so a client from that very address still
logs in while 60 idle sockets are held; and one connection creates only so many sessions.
"""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

import httpx
from asyncua import Client, ua

from fcmaster.opcua.limits import PENDING_PER_ADDRESS, SESSIONS_PER_CONNECTION
from tests.integration.daemon_harness import by_name, child, get_json, until
from tests.integration.ports import free_port
from tests.integration.test_opcua_none_channel import CONFIG, OPERATOR, _over_none, _session

IDLE = 60


def _closed(sockets: list[socket.socket]) -> int:
    """How many of ``sockets`` the server closed."""
    count = 0
    for sock in sockets:
        try:
            count += sock.recv(16) == b""
        except BlockingIOError:
            pass
        except OSError:
            count += 1
    return count


async def _sessions(url: str, count: int) -> list[str]:
    """Create ``count`` sessions on one None channel: each one's outcome."""
    client = Client(url, timeout=10)
    await client.connect_socket()
    outcomes = []
    try:
        await client.send_hello()
        await client.open_secure_channel()
        for _ in range(count):
            try:
                await client.uaclient.create_session(_session(url))
                outcomes.append("Good")
            except ua.UaStatusCodeError as exc:
                outcomes.append(type(exc).__name__)
    finally:
        client.uaclient.disconnect_socket()
    return outcomes


async def test_idle_connections_from_one_address_make_way_for_a_client(tmp_path: Path) -> None:
    port, http, opcua = tmp_path / "ttyFC", free_port(), free_port()
    config = tmp_path / "plant.yaml"
    security = '[None, "Basic256Sha256:SignAndEncrypt"]'
    config.write_text(CONFIG.format(port=port, http=http, opcua=opcua, operator=OPERATOR,
                                    security=security, commands="false"))  # fmt: skip
    url = f"opc.tcp://127.0.0.1:{opcua}/"
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "line1"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=15) as api,
        ):

            async def online() -> bool | None:
                return by_name(await get_json(api, "/api/v1/drives"))["pump-1"]["online"] or None

            await until(online, "pump-1 online", alive=daemon, timeout_s=60)

            async def listening() -> bool | None:
                return (await get_json(api, "/api/v1/status"))["opcua"]["up"] or None

            await until(listening, "the OPC UA server up", alive=daemon, timeout_s=60)
            idle = [socket.create_connection(("127.0.0.1", opcua), timeout=5) for _ in range(IDLE)]
            try:
                for sock in idle:
                    sock.setblocking(False)

                async def made_way() -> int | None:
                    closed = _closed(idle)
                    return closed if closed >= IDLE - PENDING_PER_ADDRESS else None

                # well before asyncua's own 30 s (and this server's 10 s handshake)
                await until(made_way, "the oldest idle sockets closed", alive=daemon,
                            timeout_s=5)  # fmt: skip
                seen = await asyncio.wait_for(_over_none(url), 20)
                assert (seen["create"], seen["activate"]) == ("Good", "Good"), seen
                assert seen["running"] == ("Good", False), seen
            finally:
                for sock in idle:
                    sock.close()
            outcomes = await _sessions(url, SESSIONS_PER_CONNECTION + 2)
            assert outcomes == ["Good"] * SESSIONS_PER_CONNECTION + ["BadTooManySessions"] * 2
            code, _ = await daemon.stop()
            assert code == 0, daemon.tail()
