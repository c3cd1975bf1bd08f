"""The simulated ENC drives, as the simulator builds a line of them."""

from __future__ import annotations

from typing import Final

from fcmaster.sim.enc.drive import EncRequestFramer, EncSimDrive
from fcmaster.sim.line import SimDrive
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.simulator import SimProtocol


def _drive(address: int, settings: DriveSettings, line: LineSettings, now: float) -> SimDrive:
    return EncSimDrive(address, settings, now=now, line=line)


SIMULATOR: Final = SimProtocol(lambda _: EncRequestFramer(), _drive)
