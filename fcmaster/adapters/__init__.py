"""Adapters to the plant: MQTT, HTTP with its dashboard, Prometheus metrics.

Each adapter is a hub subscriber plus a command source, and reaches the lines only through
the :class:`~fcmaster.adapters.gateway.Gateway` the service hands it. Each name is imported
on first use (:mod:`fcmaster.lazy_face`): the config needs an adapter's settings, not the
adapters.
"""

from typing import TYPE_CHECKING

from fcmaster.lazy_face import lazy_face

if TYPE_CHECKING:
    from fcmaster.adapters.command_json import BeyondLimits, parse_command, refusal
    from fcmaster.adapters.gateway import Gateway, LineInfo

__all__ = ["BeyondLimits", "Gateway", "LineInfo", "parse_command", "refusal"]

if not TYPE_CHECKING:
    __getattr__, __dir__ = lazy_face(
        __name__,
        __all__,
        {
            "fcmaster.adapters.command_json": ("BeyondLimits", "parse_command", "refusal"),
            "fcmaster.adapters.gateway": ("Gateway", "LineInfo"),
        },
    )
