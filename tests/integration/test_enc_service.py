"""The daemon's Service runs a `protocol: enc` line on the simulator, from a config file."""

from __future__ import annotations

import asyncio
from pathlib import Path

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.config import load
from fcmaster.service import Service
from tests.integration.waiting import drive_where

CONFIG = """
buses:
  - name: enc-line
    port: sim://enc-line
    protocol: enc
    baudrate: 19200
    parity: N
    fault_encoding: decimal
    drives:
      - {name: conveyor, address: 1, control: bus, nominal_frequency_hz: 50}
      - {name: fan, address: 12, nominal_frequency_hz: 60, max_frequency_hz: 60,
         monitor: [running_frequency, output_current, F0.08]}
      - {name: mixer, address: 20}
    simulation:
      response_delay_ms: 5
      drives:
        1: {parameters: {F0.08: 1.0, F0.09: 1.0}}
        12: {running_hz: 45}
"""


async def wait_for_state(service: Service, check: str, timeout_s: float = 15.0) -> None:
    """Until every drive state satisfies ``check`` (a key that must be true)."""
    await service.hub.wait_for(
        lambda: all(getattr(s, check) for s in service.fleet.snapshot()), timeout_s=timeout_s
    )


async def test_a_simulated_enc_line_shows_drive_states_and_obeys_commands(tmp_path: Path) -> None:
    config = tmp_path / "enc.yaml"
    config.write_text(CONFIG)
    service = Service(load(config))
    runner = asyncio.create_task(service.run(install_signals=False))
    try:
        await wait_for_state(service, "online")
        fan = await drive_where(
            service.hub,
            service.fleet,
            "enc-line",
            "fan",
            lambda s: s.output_frequency_hz is not None and "F0.08" in s.to_json()["values"],
        )
        fan_state = fan.to_json()
        assert fan_state["protocol"] == "enc"
        assert fan_state["control"] == "monitor"
        assert fan_state["running"] is True  # found running, never commanded
        assert fan_state["output_frequency_hz"] == 45.0
        assert fan_state["values"]["F0.08"]["unit"] == "s"

        result = await service.execute(
            "conveyor", Command(action=Action.START, reference_pct=60.0, actor="test")
        )
        assert result.outcome is Outcome.DONE
        conveyor = await drive_where(
            service.hub,
            service.fleet,
            "enc-line",
            "conveyor",
            lambda s: s.output_frequency_hz == 30.0,  # 60 % of 50 Hz
        )
        assert conveyor.running

        refused = await service.execute("fan", Command(action=Action.STOP, actor="test"))
        assert refused.outcome is Outcome.NOT_ALLOWED  # monitor-only
        stopped = await service.execute("conveyor", Command(action=Action.QUICK_STOP))
        assert stopped.outcome is Outcome.DONE
    finally:
        service.stop()
        await asyncio.wait_for(runner, 10)
