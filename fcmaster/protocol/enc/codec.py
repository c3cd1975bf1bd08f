"""The ENC free protocol behind the bus's :class:`~fcmaster.protocol.codec.DriveCodec` seam.

An ENC request carries one command and nothing else, so polls never command a drive:
the idle poll reads the running state word (11/000F) and, in turn, the running frequency
(11/0001) and the monitored values, and every reply brings the drive's fault code in its
failure index (§5, §7, §9). Control goes out as run-control frames (command 12, §4.2):

============  ===========================================================
intent        frames (index of command 12)
============  ===========================================================
reset         000C fault reset first, then the frame of the motion
RUN           0005 forward / 0006 reverse with the frequency in 0.01 Hz
JOG           0009 jog forward / 000A jog reverse (the drive's jog frequency)
STOP          0007 stop (on the drive's own stop ramp)
QUICK_STOP    000D emergency stop
COAST         000D emergency stop: the protocol has no free-run command, and
              the emergency stop is its only stop that does not follow the
              ramp; whether it cuts the output at once is not documented
============  ===========================================================

A negative reference runs the other way: the frame carries a magnitude and a direction.
Address 0 means broadcast on the seam; it goes out to address 127 and gets no reply (§2).
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import MalformedReply, UnexpectedReply, UsageError
from fcmaster.protocol.codec import (
    Access,
    DriveError,
    Exchange,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ, ControlIntent, Motion, pct_to_hz
from fcmaster.protocol.enc.codes import (
    NumberEncoding,
    ResponseCode,
    encode_number,
    fault_report,
    number_encoding,
    read_fault,
    read_response,
    readings,
    response_text,
)
from fcmaster.protocol.enc.frame import (
    BROADCAST,
    LONG_LENGTH,
    Command,
    Request,
    RunControl,
    decode_request,
    decode_response,
    encode_request,
)
from fcmaster.protocol.enc.framer import EncFramer
from fcmaster.protocol.enc.parameters import (
    RUNNING_FREQUENCY,
    STATE_WORD,
    decode_status,
    key,
    lookup,
    make_code,
    parse_parameter,
    split_code,
)
from fcmaster.protocol.polls import PollCache

MAX_FREQUENCY_HZ: Final = 0xFFFF / 100  # the data area holds 0.01 Hz steps (§4.2)
REPLY_LENGTH: Final = LONG_LENGTH  # every reply has the data area (§3); frame errors are shorter
DEFAULT_MONITOR: Final = tuple(
    key(make_code(Command.READ_VALUE, index)) for index in (0x01, 0x03, 0x02, 0x04, 0x00, 0x06)
)

_ALWAYS_POLLED: Final = (STATE_WORD, RUNNING_FREQUENCY)
_NEEDS_DATA: Final = frozenset(
    (Command.READ_VALUE, Command.READ_PARAMETER, Command.SOFTWARE_VERSION)
)


class EncCodec:
    """ENC exchanges for one bus.

    Args:
        address_encoding: how addresses of 10 and above are written (§10 question 2):
            ``"hex"`` ("0A" for 10, the default) or ``"decimal"`` ("10"; addresses 1-99,
            and no broadcast, since 127 does not fit two digits). Replies are accepted in
            either reading.
        response_encoding: how the drive writes its response codes (question 1):
            ``"hex"`` (frame error 20 as "14", the default) or ``"decimal"`` ("20").
            Both are accepted; this decides only the one collision, "14" to command 10.
        fault_encoding: how the drive writes the fault code in the failure index
            (question 7): ``"hex"`` (fault 16 as "10", the default) or ``"decimal"``.
            Decides "10"-"17", which are documented faults in both readings.
        nominal_hz: address → the frequency that 100 % reference means (50 Hz if absent).
    """

    protocol = "enc"
    can_broadcast = True  # address 127 (F2.15), obeyed and never answered

    def __init__(
        self,
        *,
        address_encoding: str = "hex",
        response_encoding: str = "hex",
        fault_encoding: str = "hex",
        nominal_hz: dict[int, float] | None = None,
    ) -> None:
        self.address_encoding = number_encoding(address_encoding)
        self.response_encoding = number_encoding(response_encoding)
        self.fault_encoding = number_encoding(fault_encoding)
        self.nominal_hz = dict(nominal_hz or {})
        hex_addresses = self.address_encoding is NumberEncoding.HEX
        self.addresses = range(1, BROADCAST if hex_addresses else 100)
        self._polls = PollCache(self._build_poll)

    def new_framer(self) -> EncFramer:
        """A framer for ENC replies."""
        return EncFramer()

    def min_pause_s(self, char_s: float) -> float:
        """Two character times: the manuals set none; this lets the drive turn its line round."""
        return 2 * char_s

    def parameter(self, text: str) -> ParameterKey:
        """``"F0.01"``, ``"11/0001"``, ``"running_frequency"`` … → its key (see ``parameters``)."""
        return parse_parameter(text)

    def default_monitor(self) -> tuple[ParameterKey, ...]:
        """Running frequency, current, voltage, DC bus, set frequency and module temperature."""
        return DEFAULT_MONITOR

    def poll_sequence(self, monitor: tuple[ParameterKey, ...]) -> tuple[ParameterKey | None, ...]:
        """Every other poll reads the state word (None), the others the running frequency.

        Monitored values take every fourth poll in turn, so the state word is never more
        than one poll old and the running frequency never more than three.
        """
        extras = tuple(k for k in dict.fromkeys(monitor) if k not in _ALWAYS_POLLED)
        if not extras:
            return (None, RUNNING_FREQUENCY)
        sequence: list[ParameterKey | None] = []
        for extra in extras:
            sequence += [None, RUNNING_FREQUENCY, None, extra]
        return tuple(sequence)

    def condition_parameters(self, *, alarms: bool, warnings: bool) -> tuple[ParameterKey, ...]:
        """Nothing: every reply already carries the fault code, and the warning is in the word."""
        return ()

    def poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        """Read the state word (``read`` None) or ``read``; ENC polls never command.

        Built once per address and ``read``.
        """
        return self._polls.get(address, None, read)

    def _build_poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        if read is None:
            request = Request(
                address=self._address(address), command=Command.READ_VALUE, cmd_index=0x0F
            )
            return self._exchange(address, request)
        return self._read(address, read)

    def control(self, address: int, intent: ControlIntent) -> tuple[Exchange, ...]:
        """The run-control frames of ``intent``, in order (table in the module docstring)."""
        frames: list[tuple[RunControl, int | None]] = []
        if intent.reset:
            frames.append((RunControl.FAULT_RESET, None))
        reverse = intent.reverse != (intent.reference_pct < 0)
        match intent.motion:
            case Motion.RUN:
                index = (
                    RunControl.REVERSE_WITH_FREQUENCY
                    if reverse
                    else RunControl.FORWARD_WITH_FREQUENCY
                )
                frames.append((index, self._frequency(address, abs(intent.reference_pct))))
            case Motion.JOG:
                frames.append((RunControl.JOG_REVERSE if reverse else RunControl.JOG_FORWARD, None))
            case Motion.STOP:
                frames.append((RunControl.STOP, None))
            case Motion.QUICK_STOP | Motion.COAST:
                frames.append((RunControl.EMERGENCY_STOP, None))
        wire_address = self._address(address)
        return tuple(
            self._exchange(
                address,
                Request(
                    address=wire_address, command=Command.RUN_CONTROL, cmd_index=index, data=data
                ),
                carries_control=True,
            )
            for index, data in frames
        )

    def read(
        self, address: int, parameter: ParameterKey, index: int, intent: ControlIntent | None
    ) -> tuple[Exchange, ...]:
        """Command 10, 11, 13 or 15 by the key; ``intent`` does not ride along (§4)."""
        _check_index(index)
        return (self._read(address, parameter),)

    def _read(self, address: int, parameter: ParameterKey) -> Exchange:
        # The one read frame, also what an idle poll sends (no tuple on the hot path).
        command, item = split_code(parameter.code)
        request = Request(
            address=self._address(address),
            command=command,
            aux_index=item >> 8,
            cmd_index=item & 0xFF,
        )
        return self._exchange(address, request, access=Access.READ, parameter=parameter)

    def write(
        self,
        address: int,
        parameter: ParameterKey,
        index: int,
        value: float | str,
        intent: ControlIntent | None,
        *,
        persist: bool = False,
    ) -> tuple[Exchange, ...]:
        """Command 14 with the value in the function code's unit.

        ``persist`` changes nothing: the protocol has one write, and the manuals do not say
        whether it is stored through a power cycle.
        """
        _check_index(index)
        command, item = split_code(parameter.code)
        if command != Command.READ_PARAMETER:
            raise UsageError(f"{parameter.name} cannot be written; only function codes can")
        if isinstance(value, str):
            raise UsageError(f"{parameter.name}: only numeric values can be written")
        spec = lookup(parameter.code)
        # Compared before rounding, so that NaN and infinities are refused too.
        if not 0 <= value <= spec.to_value(0xFFFF):
            raise UsageError(
                f"{parameter.name}: {value:g} {spec.unit} is outside 0-{spec.to_value(0xFFFF):g}"
            )
        raw = min(spec.to_raw(value), 0xFFFF)
        request = Request(
            address=self._address(address),
            command=Command.WRITE_PARAMETER,
            aux_index=item >> 8,
            cmd_index=item & 0xFF,
            data=raw,
        )
        return (self._exchange(address, request, access=Access.WRITE, parameter=parameter),)

    def parse(self, exchange: Exchange, frame: bytes) -> Reply:
        """Check that ``frame`` answers ``exchange`` and read it."""
        response = decode_response(frame)
        if not exchange.expects_reply:
            raise UnexpectedReply("a reply to a frame that gets none", raw=frame)
        if exchange.address not in readings(response.address).values():
            raise UnexpectedReply(f"reply from address field {response.address:02X}", raw=frame)
        request = decode_request(exchange.request)
        has_index = response.cmd_index is not None
        try:
            code = read_response(
                response.response, request.command, self.response_encoding, has_index=has_index
            )
        except MalformedReply as exc:
            raise MalformedReply(str(exc), raw=frame) from None
        if code == ResponseCode.FRAME_ERROR:
            # The drive did not understand the request; the index area, if any, means nothing.
            return Reply(address=exchange.address, error=DriveError(code, response_text(code)))
        if response.failure_index is None or response.cmd_index is None:
            raise MalformedReply("a reply without index area that is no frame error", raw=frame)
        if response.cmd_index != request.cmd_index:
            raise UnexpectedReply(
                f"reply for command index {response.cmd_index:02X}, "
                f"asked for {request.cmd_index:02X}",
                raw=frame,
            )
        fault = read_fault(response.failure_index, self.fault_encoding)
        conditions = fault_report(fault)
        if code == ResponseCode.REFUSED:
            return Reply(
                address=exchange.address,
                conditions=conditions,
                error=DriveError(code, response_text(code)),
            )
        return self._read_reply(exchange, request, response.data, code, fault, frame)

    def _read_reply(
        self,
        exchange: Exchange,
        request: Request,
        data: int | None,
        code: int,
        fault: int,
        frame: bytes,
    ) -> Reply:
        command = request.command
        if command in _NEEDS_DATA and data is None:
            raise MalformedReply(f"the reply to command {command} has no data area", raw=frame)
        raw = data
        if command == Command.LOOK_UP_STATE:
            raw = code  # the answer is the response code itself (§5 table 1)
        elif command == Command.WRITE_PARAMETER and raw is None:
            raw = request.data
        value = None
        if exchange.parameter is not None and raw is not None:
            spec = lookup(exchange.parameter.code)
            value = ParameterValue(
                parameter=exchange.parameter,
                index=exchange.index,
                raw=raw,
                value=spec.to_value(raw),
                unit=spec.unit,
                title=spec.name,
            )
        status = frequency = None
        if command == Command.READ_VALUE and data is not None:
            if request.index == STATE_WORD.code & 0xFFFF:
                status = decode_status(data, fault)
            elif request.index == RUNNING_FREQUENCY.code & 0xFFFF:
                frequency = data / 100
        return Reply(
            address=exchange.address,
            status=status,
            output_frequency_hz=frequency,
            value=value,
            conditions=fault_report(fault),
        )

    def _address(self, address: int) -> int:
        if address == 0:
            if self.address_encoding is not NumberEncoding.HEX:
                raise UsageError("broadcast (address 127) needs the hex address encoding")
            return BROADCAST
        if address not in self.addresses:
            raise UsageError(
                f"address {address} is outside {self.addresses.start}-{self.addresses.stop - 1}"
            )
        return encode_number(address, self.address_encoding)

    def _frequency(self, address: int, reference_pct: float) -> int:
        hz = pct_to_hz(reference_pct, self._nominal(address))
        # Compared before rounding, so that NaN and infinities are refused too.
        if not 0 <= hz <= MAX_FREQUENCY_HZ:
            raise UsageError(f"{hz:g} Hz is beyond the {MAX_FREQUENCY_HZ:g} Hz a frame can carry")
        return round(hz * 100)

    def _nominal(self, address: int) -> float:
        """The Hz that 100 % means to ``address``; for a broadcast, to every drive alike."""
        if address in self.nominal_hz:
            return self.nominal_hz[address]
        known = set(self.nominal_hz.values())
        if address == 0 and len(known) > 1:
            # One frame carries one frequency in Hz: a percentage would mean a different
            # speed to each drive, so it cannot be broadcast.
            raise UsageError(
                "the drives on this line differ in nominal frequency; "
                "a broadcast reference would mean a different speed to each"
            )
        return known.pop() if address == 0 and known else DEFAULT_NOMINAL_HZ

    @staticmethod
    def _exchange(
        address: int,
        request: Request,
        *,
        access: Access = Access.NONE,
        parameter: ParameterKey | None = None,
        carries_control: bool = False,
    ) -> Exchange:
        return Exchange(
            address=address,
            request=encode_request(request),
            reply_length=0 if address == 0 else REPLY_LENGTH,
            access=access,
            parameter=parameter,
            carries_control=carries_control,
        )


def _check_index(index: int) -> None:
    if index:
        raise UsageError("ENC parameters have no array index; leave the index out")
