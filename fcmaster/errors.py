"""The one exception hierarchy of fcmaster.

Everything fcmaster raises on purpose derives from :class:`FcmasterError` and carries
its facts as attributes, not only in the message::

    FcmasterError
    ├── ConfigError            invalid YAML or settings, with the key path      (exit 2)
    ├── UsageError             a bad argument or value from the user             (exit 2)
    │   └── BeyondLimits       a reference beyond the drive's limits  (adapters.command_json)
    ├── ProtocolError          a checked frame whose content we cannot accept
    │   ├── MalformedReply     fields out of range or inconsistent
    │   ├── UnexpectedReply    from the wrong address, or of the wrong kind
    │   └── PcapngError        a capture file this reader cannot read      (protocol.pcapng)
    ├── BusError                                                                 (exit 1)
    │   ├── PortError          open/read/write failed (pyserial and OS errors mapped here)
    │   │   └── PortInUse      another program holds the port
    │   └── ReplyTimeout       no valid frame before the deadline
    ├── CommandError                                                             (exit 1)
    │   ├── ControlNotAllowed  monitor-only drive, or a value beyond its configured limits
    │   ├── DriveRejected      the drive refused, with its error code
    │   ├── CommandTimedOut    no answer after the configured retries
    │   ├── CommandCancelled   the line shut down or was lost before the command ran
    │   ├── CommandUnconfirmed acknowledged, but the status never showed the result
    │   ├── CommandSuperseded  replaced by a newer command before it reached the wire
    │   └── ReadFailed         a read of a parameter set ended neither done nor refused
    │                                                          (adapters.parameter_sets)
    ├── AuthError              a request without the token or role it needs, 401/403
    │                                                                    (adapters.auth)
    ├── ReadsBusy              too many viewer reads wait on a line, 429  (adapters.readlimit)
    ├── WireError              the OPC UA server process's pipe carried no message
    │                                                                    (opcua.wire)
    └── Refused                a simulated drive's refusal, answered on the wire as its
                               vendor's error code (sim.danfoss_fc, sim.enc,
                               sim.modbus_rtu; private in sim.mitsubishi and in the
                               Modbus server, adapters.modbus)

The classes named with a module live there, beside the one place that raises them; the
rest are here. ``tests/unit/test_errors.py`` checks that no exception class of the package
stands outside this tree.

Codecs raise only :class:`ProtocolError` (and :class:`UsageError` for requests that cannot
be encoded); framers raise nothing. Foreign exceptions are translated at the boundary with
``raise PortError(...) from exc``.
"""

from __future__ import annotations


class FcmasterError(Exception):
    """Base of every error fcmaster raises on purpose."""


class ConfigError(FcmasterError):
    """The configuration is invalid; ``problems`` lists ``(key_path, reason)`` pairs."""

    def __init__(self, problems: list[tuple[str, str]]) -> None:
        self.problems = problems
        super().__init__("; ".join(f"{path}: {reason}" for path, reason in problems))


class UsageError(FcmasterError, ValueError):
    """A value given by the user cannot be used (bad address, unknown parameter, …)."""


class ProtocolError(FcmasterError):
    """A checked frame whose content cannot be accepted."""

    def __init__(self, message: str, *, raw: bytes = b"") -> None:
        self.raw = raw
        super().__init__(message)


class MalformedReply(ProtocolError):
    """Fields out of range or inconsistent with each other."""


class UnexpectedReply(ProtocolError):
    """A valid frame, but from the wrong address or of the wrong kind."""


class BusError(FcmasterError):
    """The line failed to carry a transaction."""

    def __init__(self, message: str, *, bus: str = "", address: int | None = None) -> None:
        self.bus = bus
        self.address = address
        super().__init__(message)


class PortError(BusError):
    """Opening, reading or writing the port failed."""


class PortInUse(PortError):
    """Another program holds the port (it is opened exclusively)."""


class ReplyTimeout(BusError):
    """No valid frame arrived before the deadline."""


class CommandError(FcmasterError):
    """A command did not end in ``done``."""

    def __init__(self, message: str, *, drive: str = "", address: int | None = None) -> None:
        self.drive = drive
        self.address = address
        super().__init__(message)


class ControlNotAllowed(CommandError):
    """The drive is monitor-only, or the command is beyond its configured limits."""


class DriveRejected(CommandError):
    """The drive refused the request; ``code`` and ``text`` are its error."""

    def __init__(
        self, message: str, *, code: int, text: str, drive: str = "", address: int | None = None
    ) -> None:
        self.code = code
        self.text = text
        super().__init__(message, drive=drive, address=address)


class CommandTimedOut(CommandError):
    """No answer after the configured retries."""


class CommandCancelled(CommandError):
    """The line shut down or was lost before the command was carried out."""


class CommandUnconfirmed(CommandError):
    """The drive acknowledged the command but its status never showed the result in time."""


class CommandSuperseded(CommandError):
    """A newer command for the same drive replaced this one before it reached the wire."""
