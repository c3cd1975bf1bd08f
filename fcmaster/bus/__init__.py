"""The bus: one half-duplex master per RS-485 line, and the transports it talks through.

A :class:`BusMaster` serves one line (a :class:`LinePlan`) over a :class:`Transport` (a
:class:`SerialTransport` on a real port) and carries each :class:`Command` to one
:class:`CommandResult`; a :class:`BusObserver` hears what it learns.
"""

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.master import BusMaster, BusObserver
from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart
from fcmaster.bus.serial import SerialTransport
from fcmaster.bus.stats import DriveStats, LineStats
from fcmaster.bus.transport import Transport

__all__ = [
    "Action",
    "BusMaster",
    "BusObserver",
    "Command",
    "CommandResult",
    "DrivePlan",
    "DriveStats",
    "LinePlan",
    "LineStats",
    "OnStart",
    "Outcome",
    "SerialTransport",
    "Transport",
]
