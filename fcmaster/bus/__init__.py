"""The bus: one half-duplex master per RS-485 line, and the transports it talks through.

A :class:`BusMaster` serves one line (a :class:`LinePlan`) over a :class:`Transport` (a
:class:`SerialTransport` on a real port) and carries each :class:`Command` to one
:class:`CommandResult`; a :class:`BusObserver` hears what it learns.

Each name is imported on first use (:mod:`fcmaster.lazy_face`): the config needs the plans,
not the master with its logging and pyserial.
"""

from typing import TYPE_CHECKING

from fcmaster.lazy_face import lazy_face

if TYPE_CHECKING:
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

if not TYPE_CHECKING:
    __getattr__, __dir__ = lazy_face(
        __name__,
        __all__,
        {
            "fcmaster.bus.commands": ("Action", "Command", "CommandResult", "Outcome"),
            "fcmaster.bus.master": ("BusMaster", "BusObserver"),
            "fcmaster.bus.plan": ("DrivePlan", "LinePlan", "OnStart"),
            "fcmaster.bus.serial": ("SerialTransport",),
            "fcmaster.bus.stats": ("DriveStats", "LineStats"),
            "fcmaster.bus.transport": ("Transport",),
        },
    )
