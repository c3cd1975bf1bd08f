"""The bus: one half-duplex master per RS-485 line, and the transports it talks through."""

from fcmaster.bus.transport import Transport

__all__ = ["Transport"]
