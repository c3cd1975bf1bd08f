"""The bus: one half-duplex master per RS-485 line.

A :class:`BusMaster` serves one line (a :class:`LinePlan`) over a transport
(:mod:`fcmaster.transport`: a serial port, a TCP serial server, the simulator) and carries
each :class:`Command` to one :class:`CommandResult`; a :class:`BusObserver` hears what it
learns. The transports are :mod:`fcmaster.transport`'s; their two names are here too, for
the callers that build a line.

Each name is imported on first use (:mod:`fcmaster.lazy_face`): the config needs the plans,
not the master with its logging and pyserial.
"""

from typing import TYPE_CHECKING

from fcmaster.lazy_face import lazy_face

if TYPE_CHECKING:
    from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
    from fcmaster.bus.master import BusMaster, BusObserver
    from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart
    from fcmaster.bus.stats import DriveStats, LineStats
    from fcmaster.transport.pipe import Transport
    from fcmaster.transport.serial import SerialTransport

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
            "fcmaster.bus.stats": ("DriveStats", "LineStats"),
            "fcmaster.transport.pipe": ("Transport",),
            "fcmaster.transport.serial": ("SerialTransport",),
        },
    )
