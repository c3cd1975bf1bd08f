"""The simulated Modbus RTU drives, as the simulator builds a line of them."""

from __future__ import annotations

from typing import Final

from fcmaster.protocol.modbus_rtu.framer import Direction, RtuFramer
from fcmaster.sim.line import SimDrive
from fcmaster.sim.modbus_rtu.drive import ModbusSimDrive
from fcmaster.sim.modbus_rtu.replay import RULES
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.simulator import SimProtocol


def _drive(address: int, settings: DriveSettings, line: LineSettings, now: float) -> SimDrive:
    return ModbusSimDrive(address, settings, now=now, line=line)


SIMULATOR: Final = SimProtocol(lambda _: RtuFramer(Direction.REQUESTS), _drive, replay=RULES)
