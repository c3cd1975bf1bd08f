"""The Sparkplug edge node of a real daemon, with simulated drives on a pty line: bdSeq kept
across restarts and a SIGKILL (the broker's Will), and DCMD through every safety rule.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Callable
from pathlib import Path

from fcmaster.adapters.sparkplug.payload import DataType, Metric
from tests.integration.daemon_harness import Child, child
from tests.integration.mosquitto import Broker
from tests.integration.sparkplug_host import Received, SparkplugHost

LIMIT_S = 90.0
CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1, control: bus, max_frequency_hz: 45}}
      - {{name: pump-2, address: 2}}
sparkplug:
  url: {url}
  group_id: Plant
  edge_node_id: gw-1
  primary_host_id: scada
  commands: true
  store: spool/sparkplug.db
  keepalive_s: 5
  reconnect_min_s: 0.1
  reconnect_max_s: 1
"""


def outcome(received: Received) -> tuple[object, object]:
    values = received.values()
    return values.get("Control/Last Outcome"), values.get("Control/Last Reason")


def answered(device: str) -> Callable[[Received], bool]:
    def check(received: Received) -> bool:
        return received.device == device and "Control/Last Outcome" in received.values()

    return check


async def born(host: SparkplugHost, daemon: Child, start: int) -> int:
    """Wait for the node's NBIRTH and both drives' DBIRTHs from ``start``; the NBIRTH's bdSeq."""
    birth = await host.wait("NBIRTH", start=start)
    births = [r.device for r in await host.wait_count("DBIRTH", 2, start=birth.index)]
    assert sorted(map(str, births)) == ["pump-1", "pump-2"]
    daemon.check_alive()
    bd_seq = birth.values()["bdSeq"]
    assert isinstance(bd_seq, int)
    return bd_seq


async def test_bdseq_pairs_births_with_deaths_across_restarts_and_a_sigkill_and_dcmd_is_guarded(
    tmp_path: Path,
) -> None:
    config = tmp_path / "plant.yaml"
    async with asyncio.timeout(LIMIT_S), Broker(tmp_path) as broker:
        config.write_text(CONFIG.format(north=tmp_path / "ttyNORTH", url=broker.url))
        async with (
            SparkplugHost(broker, "Plant") as host,
            child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim,
        ):
            await sim.readline()
            run = ("run", "--config", str(config))
            async with child(*run, log=tmp_path / "run-1.log") as daemon:
                assert await born(host, daemon, 0) == 0

                write = Metric(name="Control/Reference Hz", datatype=DataType.DOUBLE, value=20.0)
                await host.dcmd("gw-1", "pump-1", write)
                done = await host.wait("DDATA", answered("pump-1"))
                assert outcome(done) == ("done", ""), daemon.tail()
                beyond = Metric(name="Control/Reference Hz", datatype=DataType.DOUBLE, value=46.0)
                await host.dcmd("gw-1", "pump-1", beyond)
                refused = await host.wait("DDATA", answered("pump-1"), start=done.index + 1)
                assert outcome(refused)[0] == "not_allowed"
                run_it = Metric(name="Control/Run", datatype=DataType.BOOLEAN, value=True)
                await host.dcmd("gw-1", "pump-2", run_it)  # monitor-only
                monitor = await host.wait("DDATA", answered("pump-2"))
                assert outcome(monitor)[0] == "not_allowed"

                mark = len(host.received)
                code, _ = await daemon.stop(signal.SIGTERM)
                assert code == 0
            death = await host.wait("NDEATH", start=mark)
            assert host.deaths[-1] == (0, True), death

            async with child(*run, log=tmp_path / "run-2.log") as daemon:
                assert await born(host, daemon, death.index) == 1  # kept across the restart
                mark = len(host.received)
                daemon.process.send_signal(signal.SIGKILL)  # no NDEATH of its own
                await daemon.process.wait()
            # the broker's Will, after one and a half keep-alives without a word
            will = await host.wait("NDEATH", start=mark)
            assert host.deaths[-1] == (1, True), will

            async with child(*run, log=tmp_path / "run-3.log") as daemon:
                assert await born(host, daemon, will.index) == 2
    assert host.problems == []
