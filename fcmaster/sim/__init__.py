"""Simulated drives on a timed multi-drop line, served in-process or on a pseudo-terminal.

Start a line in-process::

    clock = MonotonicClock()
    line = build_line(LineSettings(baudrate=19200), [(a, DriveSettings()) for a in range(1, 9)],
                      clock=clock)
    transport = SimTransport(line, clock)   # a fcmaster.transport.pipe.Transport

or on a pty: ``async with PtyServer(line, clock=clock, link="/tmp/ttyFC") as server: ...``.
"""

from fcmaster.sim.build import SIM_PROTOCOLS, SimProtocol, build_line
from fcmaster.sim.danfoss_fc import FcSimDrive
from fcmaster.sim.enc import EncSimDrive
from fcmaster.sim.faults import FaultPlan, parse_faults
from fcmaster.sim.line import LineCounters, RequestFramer, SimDrive, SimLine, Transaction
from fcmaster.sim.mitsubishi import MitsubishiSimDrive
from fcmaster.sim.motor import Mode, Motor, MotorCommand, MotorRating
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.transport import SIM_SCHEME, SimRegistry, SimTransport, sim_name

__all__ = [
    "SIM_PROTOCOLS",
    "SIM_SCHEME",
    "DriveSettings",
    "EncSimDrive",
    "FaultPlan",
    "FcSimDrive",
    "LineCounters",
    "LineSettings",
    "MitsubishiSimDrive",
    "Mode",
    "Motor",
    "MotorCommand",
    "MotorRating",
    "PtyServer",
    "RequestFramer",
    "SimDrive",
    "SimLine",
    "SimProtocol",
    "SimRegistry",
    "SimTransport",
    "Transaction",
    "build_line",
    "parse_faults",
    "sim_name",
]
