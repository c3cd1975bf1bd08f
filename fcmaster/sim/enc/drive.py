"""A simulated ENC drive: answers "~" frames per protocols/enc.md.

The drive hears every request on its line (the :class:`~fcmaster.sim.line.SimDrive` seam)
through :class:`EncRequestFramer`, which, unlike the master's framer, lets frames with a
wrong checksum through: a drive that recognises its address in a damaged frame answers it
with a frame error (§5), which it could not do if the line threw the frame away.

What it answers (§4, §5), in the line's encodings for its address, response codes and
fault code (§10 questions 1, 2 and 7; ``LineSettings.*_encoding``):

* Not addressed (another address, or a frame too mangled to show one): nothing.
* A broadcast (address 127, §2): obeyed when it is a well-formed command, never answered.
* A frame error — wrong checksum, command outside 10-15, an index or data area that the
  command does not have or does not take, an unknown function code (§5 "index field out
  of range"): the short reply ``~ AA RR SSSS CR``, response 20 and nothing else, since the
  manual says the command, index and data areas are left out (§10 question 3 leaves the
  exact form open; this is the reading the codec expects).
* Command 10 (look up state): the answer is the response code itself (§5 table 1) — 11
  (ready, control allowed) while F0.02 is the serial port, 13 (ready, no control) when it
  is not, 10 (not ready) while tripped. It is the one command whose response code is not
  00 on success.
* Commands 11-15: 00 with the value in the data area, or 30 (refused) when the drive will
  not do it now: control not allowed, a frequency beyond the upper limit, a parameter value
  out of range or changed while running, a reset while the fault is still present.
  Every reply carries the fault code in its failure index and echoes the command index.

Replies leave after F2.17 (local response delay, 5 ms by default, §1).
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.enc.codes import NumberEncoding, ResponseCode, encode_number
from fcmaster.protocol.enc.frame import (
    BROADCAST,
    MIN_LENGTH,
    RUN_CONTROL_WITH_DATA,
    Command,
    Request,
    Response,
    RunControl,
    decode_request,
    encode_response,
    split_frame,
)
from fcmaster.protocol.enc.framer import EncFramer
from fcmaster.protocol.enc.spec import SPEC
from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from fcmaster.sim.enc.control import EncControl
from fcmaster.sim.enc.parameters import (
    BAUD_OPTIONS,
    COMMUNICATION,
    LOCAL_ADDRESS,
    PARITY_OPTIONS,
    RESPONSE_DELAY,
    RUN_CHANNEL,
    SETTINGS,
    ParameterStore,
    Refused,
    frame_error,
    overrides_from_values,
)
from fcmaster.sim.enc.readings import READINGS, raw_reading
from fcmaster.sim.motor import Motor
from fcmaster.sim.settings import DriveSettings, LineSettings

SOFTWARE_VERSION: Final = 0x0100  # what command 15 reports (1.00; not from a manual)
_KEYPAD: Final = 0  # F0.02 option for local operation
_RUN_CONTROL_INDEXES: Final = frozenset(int(index) for index in RunControl)
_COMMANDS: Final = frozenset(int(command) for command in Command)


class EncRequestFramer(EncFramer):
    """The drives' side of the line: whole frames, checksum not yet judged.

    The drive checks the checksum itself, after its address, so that it can answer a
    damaged frame meant for it with a frame error.
    """

    __slots__ = ()

    def _candidate(self, length: int) -> Frame | Skipped:
        if length < MIN_LENGTH:
            return self._skip(length, SkipReason.BAD_LENGTH)
        return Frame(self._take(length))


class EncSimDrive:
    """One simulated ENC drive (a :class:`~fcmaster.sim.line.SimDrive`)."""

    # Declared here because readings.py, which this module imports, reads them.
    parameters: ParameterStore
    motor: Motor
    control: EncControl

    def __init__(
        self,
        address: int,
        settings: DriveSettings | None = None,
        *,
        now: float,
        line: LineSettings | None = None,
    ) -> None:
        """A drive powered up at ``now`` at ``address`` (F2.15).

        ``settings`` gives the motor, load, response delay, upper-limit frequency and
        function-code values; ``line`` the character format F2.14 reports and how the
        drive writes its numbers.
        """
        settings = settings or DriveSettings()
        line = line or LineSettings(protocol="enc")
        options = SPEC.options_of(line)  # the line's encodings, defaults where it names none
        self._address_encoding = NumberEncoding(options.address_encoding)
        self._response_encoding = NumberEncoding(options.response_encoding)
        self._fault_encoding = NumberEncoding(options.fault_encoding)
        overrides = {LOCAL_ADDRESS: address}
        if line.baudrate in BAUD_OPTIONS and line.stopbits == 1:
            overrides[COMMUNICATION] = PARITY_OPTIONS[line.parity] * 10 + BAUD_OPTIONS.index(
                line.baudrate
            )
        if settings.response_delay_s is not None:
            overrides[RESPONSE_DELAY] = round(settings.response_delay_s * 1000)
        if settings.local:
            overrides[RUN_CHANNEL] = _KEYPAD
        overrides.update(overrides_from_values(settings.parameters))
        if settings.running_hz:
            overrides[0x0001] = round(abs(settings.running_hz) * 100)
            overrides[0x0003] = int(settings.running_hz < 0)
        upper = settings.max_frequency_hz or settings.rating.frequency_hz
        self.parameters = ParameterStore(overrides, upper_limit_hz=upper)
        # A drive found running was started a while ago; let its motor reach speed since.
        started = settings.started_at(now)
        self.motor = settings.motor(started)
        self.control = EncControl(self.parameters, self.motor, started)
        if settings.running_hz:
            self.control.running = True
            self.control.refresh(started)
            self.control.advance(now)
        self._settings = settings
        self._born = now
        if self._address_field() is None:
            raise UsageError(f"address {address} cannot be written in decimal (1-99)")

    @property
    def address(self) -> int:
        """F2.15 Local address."""
        return self.parameters[LOCAL_ADDRESS]

    @property
    def response_delay_s(self) -> float:
        """F2.17 Local response delay."""
        return self.parameters[RESPONSE_DELAY] / 1000.0

    def advance(self, now: float) -> None:
        """Bring ramps, counters and the communication watchdog up to ``now``."""
        self.control.advance(now)

    def handle(self, frame: bytes, now: float) -> bytes | None:
        """Act on a request that ended at ``now``; return the reply, or None."""
        try:
            field = int(frame[1:3], 16)
        except ValueError:
            return None  # not even an address to answer to
        broadcast = field == BROADCAST
        if not broadcast and field != self._address_field():
            return None
        if self._settings.warning_cycle is not None:
            self._cycle_warning(now)
        try:
            request = self._checked(frame)
            self.control.heard(now)  # brings the drive to now, once for the whole request
            code, data = self._serve(request, now)
        except Refused as refusal:
            if refusal.code == ResponseCode.FRAME_ERROR:
                return None if broadcast else self._frame_error_reply(field)
            code, data = refusal.code, 0
        if broadcast:
            return None
        return encode_response(
            Response(
                address=field,
                response=encode_number(code, self._response_encoding),
                failure_index=encode_number(self.control.fault, self._fault_encoding),
                cmd_index=request.cmd_index,
                data=data,
            )
        )

    def _address_field(self) -> int | None:
        """How this drive writes its own address (None: it cannot, in this encoding).

        Worked out from F2.15 each time rather than kept, since the bus may rewrite F2.15.
        """
        try:
            return encode_number(self.address, self._address_encoding)
        except UsageError:  # an address of 100 or more cannot be written in decimal
            return None

    # -- requests -------------------------------------------------------------------------

    @staticmethod
    def _checked(frame: bytes) -> Request:
        """The request in ``frame``, or a frame error (§5 response 20) saying what is wrong."""
        try:
            _, _, checksum_ok = split_frame(frame)
            if not checksum_ok:
                raise frame_error("checksum")
            request = decode_request(frame)
        except MalformedReply as exc:
            raise frame_error(str(exc)) from None
        command, index, data = request.command, request.index, request.data
        if command not in _COMMANDS:
            raise frame_error(f"command {command:02X} is not one of 0A-0F")
        has_data = command == Command.WRITE_PARAMETER or (
            command == Command.RUN_CONTROL and index in RUN_CONTROL_WITH_DATA
        )
        if (data is not None) != has_data:
            raise frame_error("the frame's length does not fit its command and index")
        if command in (Command.LOOK_UP_STATE, Command.SOFTWARE_VERSION) and index:
            raise frame_error(f"command {command} takes index 0000")
        if command in (Command.READ_VALUE, Command.RUN_CONTROL) and request.aux_index:
            raise frame_error(f"command {command} has no auxiliary index")
        if command == Command.RUN_CONTROL and index not in _RUN_CONTROL_INDEXES:
            raise frame_error(f"no run-control index {index:04X}")
        if command == Command.READ_VALUE and index not in READINGS:
            raise frame_error(f"no running value {index:04X}")
        if command in (Command.READ_PARAMETER, Command.WRITE_PARAMETER) and index not in SETTINGS:
            raise frame_error(f"no function code {index:04X}")
        return request

    def _serve(self, request: Request, now: float) -> tuple[int, int]:
        """The response code and data for a well-formed ``request``; Refused for 30.

        The drive has already been brought to ``now`` (:meth:`EncControl.heard`).
        """
        command, index = request.command, request.index
        if command == Command.LOOK_UP_STATE:
            if not self.control.ready:
                return ResponseCode.NOT_READY, 0
            if not self.control.accepts_control:
                return ResponseCode.READY_NO_CONTROL_13, 0
            return ResponseCode.READY_11, 0
        if command == Command.READ_VALUE:
            return ResponseCode.NORMAL, raw_reading(self, index)
        if command == Command.RUN_CONTROL:
            self.control.run_control(index, request.data, now)
            return ResponseCode.NORMAL, request.data or 0
        if command == Command.READ_PARAMETER:
            return ResponseCode.NORMAL, self.parameters[index]
        if command == Command.WRITE_PARAMETER:
            assert request.data is not None  # checked with the frame
            self.parameters.set(index, request.data, running=self.motor.output_on)
            self.control.refresh(now)
            return ResponseCode.NORMAL, request.data
        return ResponseCode.NORMAL, SOFTWARE_VERSION  # command 15

    def _frame_error_reply(self, field: int) -> bytes:
        code = encode_number(ResponseCode.FRAME_ERROR, self._response_encoding)
        return encode_response(Response(address=field, response=code))

    def _cycle_warning(self, now: float) -> None:
        """Undervoltage (state-word bit 1) for ``for_s`` at the start of every ``every_s``.

        The state word has no other warning, so the cycle's number is not used.
        """
        self.control.undervoltage = self._settings.warning_showing(now - self._born)
