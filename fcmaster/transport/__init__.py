"""Transports: the byte pipes a line master talks through, below the bus.

:class:`~fcmaster.transport.pipe.Transport` is the seam (a ``typing.Protocol``); a real line
is a :class:`~fcmaster.transport.serial.SerialTransport` over a local port or a pyserial URL
(:mod:`~fcmaster.transport.ports` drives the open port, :mod:`~fcmaster.transport.receiver`
hands what arrives to the one reader, :mod:`~fcmaster.transport.usb` tunes a USB adapter's
latency, :mod:`~fcmaster.transport.portlock` and :mod:`~fcmaster.transport.open_errors` say
why a port did not open); :mod:`~fcmaster.transport.echo` drops a two-wire adapter's own
transmission. A transport moves bytes and nothing else: framing rules come from the
protocol's framer, timing policy from the bus.
"""

from typing import TYPE_CHECKING

from fcmaster.lazy_face import lazy_face

if TYPE_CHECKING:
    from fcmaster.transport.pipe import Transport
    from fcmaster.transport.serial import SerialTransport

__all__ = ["SerialTransport", "Transport"]

if not TYPE_CHECKING:
    __getattr__, __dir__ = lazy_face(
        __name__,
        __all__,
        {
            "fcmaster.transport.pipe": ("Transport",),
            "fcmaster.transport.serial": ("SerialTransport",),
        },
    )
