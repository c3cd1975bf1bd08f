"""Simulated Danfoss FC drives (protocols/danfoss-fc.md)."""

from fcmaster.sim.danfoss_fc.control import ALARM_BITS, TRIP_LOCK_ALARMS, WARNING_BITS, FcControl
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.danfoss_fc.parameters import SETTINGS, ParameterStore, Refused

__all__ = [
    "ALARM_BITS",
    "SETTINGS",
    "TRIP_LOCK_ALARMS",
    "WARNING_BITS",
    "FcControl",
    "FcSimDrive",
    "ParameterStore",
    "Refused",
]
