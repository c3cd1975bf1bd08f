"""Simulated Modbus RTU drives, one per drive profile, each enforcing its state machine."""

from fcmaster.sim.modbus_rtu.drive import ModbusSimDrive, profile_for
from fcmaster.sim.modbus_rtu.machine import Machine, State

__all__ = ["Machine", "ModbusSimDrive", "State", "profile_for"]
