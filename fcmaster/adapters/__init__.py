"""Adapters to the plant: MQTT, HTTP with its dashboard, Prometheus metrics.

Each adapter is a hub subscriber plus a command source, and reaches the lines only through
the :class:`~fcmaster.adapters.gateway.Gateway` the service hands it.
"""

from fcmaster.adapters.command_json import BeyondLimits, parse_command, refusal
from fcmaster.adapters.gateway import Gateway, LineInfo

__all__ = ["BeyondLimits", "Gateway", "LineInfo", "parse_command", "refusal"]
