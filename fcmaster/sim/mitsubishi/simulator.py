"""The simulated Mitsubishi drives, as the simulator builds a line of them."""

from __future__ import annotations

from typing import Final

from fcmaster.sim.line import SimDrive
from fcmaster.sim.mitsubishi.drive import MitsubishiSimDrive, line_parameters, line_receiver
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.simulator import SimProtocol


def _drive(address: int, settings: DriveSettings, line: LineSettings, now: float) -> SimDrive:
    return MitsubishiSimDrive(address, settings, now=now, line=line)


# One receiver reads the line for every drive (the request format is a drive setting), and
# the drives time their replies themselves: the request carries the waiting time.
SIMULATOR: Final = SimProtocol(
    line_receiver, _drive, line_parameters=line_parameters, own_timing=True
)
