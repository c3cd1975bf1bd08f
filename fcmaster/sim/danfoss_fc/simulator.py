"""The simulated Danfoss FC drives, as the simulator builds a line of them."""

from __future__ import annotations

from typing import Final

from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.danfoss_fc.replay import RULES
from fcmaster.sim.line import SimDrive
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.simulator import SimProtocol


def _drive(address: int, settings: DriveSettings, line: LineSettings, now: float) -> SimDrive:
    return FcSimDrive(address, settings, now=now, line=line)


SIMULATOR: Final = SimProtocol(lambda _: FcFramer(), _drive, replay=RULES)
