"""Sans-I/O drive protocol codecs: bytes in, typed messages out, and back."""

from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.framing import Frame, Framer, Skipped, SkipReason

__all__ = ["ControlIntent", "Frame", "Framer", "Motion", "SkipReason", "Skipped"]
