"""`fcmaster run` under a low open-file limit, flooded with connections: a stop still gets
through, and the log says what it must once, not once per refused connection.

The daemon runs as a subprocess whose hard limit is set low (as a container or a unit's
``LimitNOFILE`` might), and the flood comes from many loopback addresses over real sockets.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
from pathlib import Path

import httpx

from tests.integration.daemon_harness import START_S, Child, until
from tests.integration.ports import free_port

LIMIT = 200  # open files, soft and hard: fewer than the HTTP guard holds by default
FLOOD = 300  # connections from 100 addresses
OPERATOR = "operator-token-0123456789abcdef"
CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {{name: pump-1, address: 1, control: bus, nominal_frequency_hz: 50}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: ops, role: operator, token: {operator}}}
"""
LIMITED = """
import resource, runpy, sys
resource.setrlimit(resource.RLIMIT_NOFILE, ({limit}, {limit}))
sys.argv = ["fcmaster", "run", "--config", {config!r}]
runpy.run_module("fcmaster", run_name="__main__", alter_sys=True)
"""


async def _flood(port: int) -> list[asyncio.StreamWriter]:
    opened = []
    for n in range(FLOOD):
        with contextlib.suppress(OSError, TimeoutError):
            _, writer = await asyncio.wait_for(
                asyncio.open_connection(
                    "127.0.0.1", port, local_addr=(f"127.0.0.{2 + n % 100}", 0)
                ),
                2,
            )
            opened.append(writer)
    return opened


async def test_a_stop_gets_through_at_a_low_file_limit_and_the_log_stays_small(
    tmp_path: Path,
) -> None:
    port = free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=port, operator=OPERATOR))
    log = tmp_path / "daemon.log"
    with log.open("ab") as stderr:
        process = await asyncio.create_subprocess_exec(
            sys.executable, "-c", LIMITED.format(limit=LIMIT, config=str(config)),
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.DEVNULL, stderr=stderr,
        )  # fmt: skip
    daemon = Child(process, log, "fcmaster run")
    headers = {"Authorization": f"Bearer {OPERATOR}"}
    opened: list[asyncio.StreamWriter] = []
    try:
        async with httpx.AsyncClient(
            base_url=f"http://127.0.0.1:{port}", headers=headers, timeout=20
        ) as client:

            async def online() -> bool:
                response = await client.get("/api/v1/drives/pump-1")
                return response.status_code == 200 and bool(response.json()["online"])

            await until(online, "pump-1 online", alive=daemon, timeout_s=START_S)
        opened = await _flood(port)
        daemon.check_alive()
        async with httpx.AsyncClient(  # a new connection, as an operator's browser would open
            base_url=f"http://127.0.0.1:{port}",
            headers=headers,
            timeout=20,
            transport=httpx.AsyncHTTPTransport(local_address="127.0.0.250"),
        ) as client:
            response = await client.post("/api/v1/drives/pump-1/commands", json={"action": "stop"})
            assert response.status_code == 200, response.text
            assert response.json()["outcome"] == "done"
    finally:
        for writer in opened:
            writer.close()
        if process.returncode is None:
            process.kill()
        await process.wait()
    events = daemon.log_events()
    [limit] = [e for e in events if e["event"] == "process.file_limit"]
    assert (limit["soft"], limit["hard"]) == (LIMIT, LIMIT)
    [fitted] = [e for e in events if e["event"] == "http.connections_fitted"]
    assert fitted["max_connections"] + 16 <= LIMIT - 160
    text = log.read_text()
    assert text.count("out of system resource") <= 2, daemon.tail(40)
    assert len([e for e in events if e["event"].startswith("loop.error")]) <= 2
