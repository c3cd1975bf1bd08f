"""Simulated ENC drives speaking the free protocol (protocols/enc.md)."""

from fcmaster.sim.enc.control import COMMUNICATION_FAULT, JOG_HZ, EncControl
from fcmaster.sim.enc.drive import SOFTWARE_VERSION, EncRequestFramer, EncSimDrive
from fcmaster.sim.enc.parameters import SETTINGS, ParameterStore, Refused
from fcmaster.sim.enc.readings import READINGS, state_word

__all__ = [
    "COMMUNICATION_FAULT",
    "JOG_HZ",
    "READINGS",
    "SETTINGS",
    "SOFTWARE_VERSION",
    "EncControl",
    "EncRequestFramer",
    "EncSimDrive",
    "ParameterStore",
    "Refused",
    "state_word",
]
