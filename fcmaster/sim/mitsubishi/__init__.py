"""A simulated Mitsubishi FR inverter on the computer link (protocols/mitsubishi.md)."""

from fcmaster.sim.mitsubishi.control import MitsubishiControl
from fcmaster.sim.mitsubishi.drive import MitsubishiSimDrive, line_parameters, line_receiver
from fcmaster.sim.mitsubishi.parameters import ParameterStore, Setting
from fcmaster.sim.mitsubishi.receiver import RequestReceiver

__all__ = [
    "MitsubishiControl",
    "MitsubishiSimDrive",
    "ParameterStore",
    "RequestReceiver",
    "Setting",
    "line_parameters",
    "line_receiver",
]
