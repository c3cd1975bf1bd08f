"""The daemon's Service runs a `protocol: enc` line on the simulator, from a config file."""

from __future__ import annotations

import asyncio
from pathlib import Path

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.config import load
from fcmaster.service import Service

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
    async with asyncio.timeout(timeout_s):
        while not all(getattr(s, check) for s in service.fleet.snapshot()):  # noqa: ASYNC110
            await asyncio.sleep(0.05)  # the fleet's state signals nothing to wait on


async def test_a_simulated_enc_line_shows_drive_states_and_obeys_commands(tmp_path: Path) -> None:
    config = tmp_path / "enc.yaml"
    config.write_text(CONFIG)
    service = Service(load(config))
    runner = asyncio.create_task(service.run(install_signals=False))
    try:
        await wait_for_state(service, "online")
        async with asyncio.timeout(15):
            while (fan := service.fleet.get("enc-line", "fan")) is None or (  # noqa: ASYNC110
                fan.output_frequency_hz is None or "F0.08" not in fan.to_json()["values"]
            ):
                await asyncio.sleep(0.05)
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
        async with asyncio.timeout(15):
            while True:
                conveyor = service.fleet.get("enc-line", "conveyor")
                assert conveyor is not None
                if conveyor.output_frequency_hz == 30.0:  # 60 % of 50 Hz
                    break
                await asyncio.sleep(0.05)
        assert conveyor.running

        refused = await service.execute("fan", Command(action=Action.STOP, actor="test"))
        assert refused.outcome is Outcome.NOT_ALLOWED  # monitor-only
        stopped = await service.execute("conveyor", Command(action=Action.QUICK_STOP))
        assert stopped.outcome is Outcome.DONE
    finally:
        service.stop()
        await asyncio.wait_for(runner, 10)
