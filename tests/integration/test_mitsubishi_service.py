"""The daemon's Service runs a `protocol: mitsubishi` line on the simulator, from a config file."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.config import load
from fcmaster.service import Service
from fcmaster.state import DriveState
from tests.integration.waiting import drive_where

CONFIG = """
buses:
  - name: mitsu
    port: sim://mitsu
    protocol: mitsubishi
    baudrate: 19200
    parity: E
    stopbits: 2
    terminator: crlf
    wait_time_ms: 10
    drives:
      - {name: pump, address: 0, control: bus, nominal_frequency_hz: 50}
      - {name: fan, address: 10, nominal_frequency_hz: 60, max_frequency_hz: 60,
         monitor: [H6F, H70, H74]}
      - {name: press, address: 31, control: bus}
    simulation:
      drives:
        10: {running_hz: 45}
        31: {parameters: {Pr.122: 0.5}}
"""


async def wait_for(
    service: Service, name: str, check: Callable[[DriveState], object], timeout_s: float = 15.0
) -> DriveState:
    """Until drive ``name``'s state satisfies ``check``; that state."""
    return await drive_where(service.hub, service.fleet, "mitsu", name, check, timeout_s)


async def test_a_simulated_mitsubishi_line_shows_drive_states_and_obeys_commands(
    tmp_path: Path,
) -> None:
    config = tmp_path / "mitsubishi.yaml"
    config.write_text(CONFIG)
    loaded = load(config)
    (line,) = loaded.lines
    assert line.response_delay_s == 0.040  # waiting time 10 ms + data check 30 ms
    service = Service(loaded)
    runner = asyncio.create_task(service.run(install_signals=False))
    try:
        fan = await wait_for(service, "fan", lambda s: s.output_frequency_hz and "H70" in s.values)
        fan_state = fan.to_json()
        assert fan_state["protocol"] == "mitsubishi"
        assert fan_state["control"] == "monitor"
        assert (fan_state["running"], fan_state["direction"]) == (True, "forward")
        assert fan_state["output_frequency_hz"] == 45.0
        assert fan_state["values"]["H70"]["unit"] == "A"
        assert fan_state["alarms"] == []

        result = await service.execute(
            "pump", Command(action=Action.START, reference_pct=60.0, actor="test")
        )
        assert result.outcome is Outcome.DONE, result.reason
        pump = await wait_for(service, "pump", lambda s: s.output_frequency_hz == 30.0)
        assert pump.running  # 60 % of 50 Hz
        read = await service.execute(
            "pump", Command(action=Action.READ, parameter="Pr.7", actor="test")
        )
        assert read.outcome is Outcome.DONE
        assert read.value is not None
        assert read.value.value == 5.0

        refused = await service.execute("fan", Command(action=Action.STOP, actor="test"))
        assert refused.outcome is Outcome.NOT_ALLOWED  # monitor-only
        stopped = await service.execute("pump", Command(action=Action.STOP, actor="test"))
        assert stopped.outcome is Outcome.DONE
        await wait_for(service, "pump", lambda s: not s.running)

        # The press's communication check (0.5 s) never runs out while the daemon polls.
        await asyncio.sleep(1.0)
        press = service.fleet.get("mitsu", "press")
        assert press is not None
        assert press.online
        assert not press.fault
    finally:
        service.stop()
        await asyncio.wait_for(runner, 10)
