"""A simulated Mitsubishi FR inverter on the computer link (protocols/mitsubishi.md).

The drive hears every request candidate on its line (the :class:`~fcmaster.sim.line.
SimDrive` seam) and answers those for its station (Pr.117), judging each the way §5 says an
inverter does, first failure wins:

1. the terminator is not the one Pr.124 selects → NAK 3 (protocol error);
2. a character other than 0-9 or A-F → NAK 7 (character error);
3. the request has no known shape: its length does not fit the instruction code and the
   waiting-time digit that Pr.123 calls for → NAK 3;
4. the sum check is wrong → NAK 2 (sum check error);
5. the instruction code does not exist, or names no parameter on the page → NAK B;
6. a write outside network operation, or a write that needs the motor stopped while it
   turns → NAK A (mode error);
7. data out of range → NAK C (data range error).

Errors 0-5 in a row beyond Pr.121 trip the drive with E.PUE (and it answers NAK 0); a good
request ends the run. Reads answer STX data ETX sum, writes ACK; the inverter reset HFD
H9696 gets no answer and the drive is deaf while it restarts (H9966: ACK first).

Timing (§7): the reply starts after the waiting time — the request's digit, or Pr.123 when
that is not 9999 — plus the data check time: ``DriveSettings.response_delay_s`` (default
5 ms, inside the manual's 12 ms) for monitors, the run command and RAM frequency writes,
and 15 ms more for parameters and EEPROM writes (inside 30 ms). The line reads
:attr:`MitsubishiSimDrive.response_delay_s` right after :meth:`handle`, so it is the delay
of the request just handled.

Line settings a drive takes at power-up and at each reset, not at once when written: the
station (Pr.117), the waiting time (Pr.123) and the terminator (Pr.124), as the manuals ask
for a reset after changing the communication parameters.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from fcmaster.bus.plan import LinePlan
from fcmaster.errors import FcmasterError, UsageError
from fcmaster.protocol.mitsubishi.error_codes import (
    COUNTS_TOWARD_TRIP,
    DATA_RANGE_ERROR,
    INSTRUCTION_CODE_ERROR,
    MODE_ERROR,
)
from fcmaster.protocol.mitsubishi.instructions import (
    RESET_AFTER_ACK,
    RESET_NO_REPLY,
    request_widths,
)
from fcmaster.protocol.mitsubishi.message import (
    ENQ,
    HEX_DIGITS,
    TEXT_WIDTH,
    Ack,
    DataReply,
    Nak,
    Terminator,
    encode_frame,
    split_terminator,
    sum_check,
)
from fcmaster.protocol.mitsubishi.parameters import SETTING_9999
from fcmaster.protocol.mitsubishi.profile import OperationMode
from fcmaster.protocol.mitsubishi.spec import SPEC
from fcmaster.sim.mitsubishi.control import MitsubishiControl
from fcmaster.sim.mitsubishi.parameters import (
    SETTINGS,
    WAIT_STEP_MS,
    ParameterStore,
    overrides_from_values,
)
from fcmaster.sim.mitsubishi.receiver import RequestReceiver
from fcmaster.sim.settings import DriveSettings, LineSettings

DEFAULT_CHECK_S: Final = 0.005  # data check time of a monitor read or a RAM write
PARAMETER_EXTRA_S: Final = 0.015  # more for parameters and EEPROM writes
RESTART_S: Final = 0.6  # deaf after an inverter reset (the master waits longer)
MODEL_NAME: Final = "FR-E720-5.5K SIM"
PROTOCOL_ERROR: Final = 0x3
SUM_ERROR: Final = 0x2
CHARACTER_ERROR: Final = 0x7
COMPUTER_NAK: Final = 0x0
_TERMINATORS: Final = (Terminator.NONE, Terminator.CR, Terminator.CRLF)  # Pr.124 = 0, 1, 2
_BAUD: Final = (4800, 9600, 19200, 38400)  # Pr.118 × 100
_CLEARS: Final = {0x9696: False, 0x9966: False, 0x5A5A: True, 0x55AA: True}  # keep comm?
_SPECIAL_MONITORS: Final = frozenset((0x01, 0x02, 0x03, 0x05, 0x06, 0x08, 0x0D, 0x0E))


class _Refused(FcmasterError):
    """A request the drive answers with NAK ``code``."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


class MitsubishiSimDrive:
    """One simulated Mitsubishi inverter (a :class:`~fcmaster.sim.line.SimDrive`)."""

    def __init__(
        self,
        address: int,
        settings: DriveSettings | None = None,
        *,
        now: float,
        line: LineSettings | None = None,
    ) -> None:
        """A drive powered up at ``now`` at station ``address`` (see the module docstring)."""
        settings = settings or DriveSettings()
        line = line or LineSettings()
        overrides = {117: address, 120: {"N": 0, "O": 1, "E": 2}[line.parity]}
        overrides[119] = (line.stopbits - 1) + (10 if line.databits == 7 else 0)
        if line.baudrate in _BAUD:
            overrides[118] = line.baudrate // 100
        if settings.max_frequency_hz is not None:
            overrides[1] = round(min(settings.max_frequency_hz, 120.0) * 100)
        overrides.update(overrides_from_values(settings.parameters))
        self.parameters = ParameterStore(overrides)
        self._check_s = (
            DEFAULT_CHECK_S if settings.response_delay_s is None else settings.response_delay_s
        )
        started = settings.started_at(now)
        self.motor = settings.motor(started)
        port = SPEC.options_of(line).drive_port  # the line's drive_port key (Pr.122 or Pr.336)
        self.control = MitsubishiControl(
            self.parameters, self.motor, started, local=settings.local, port=port
        )
        self._page = 0
        self._second = 0  # HEC: second parameter changing
        self._monitor = 0x01  # HF3: special monitor selection
        self._errors = 0  # consecutive reception errors (codes 0-5)
        self._deaf_until = now
        self._delay_s = self._check_s
        self._settings = settings
        self._born = now
        self._take_line_settings()
        if settings.running_hz:
            self.control.set_frequency(settings.running_hz, started, eeprom=False)
            self.control.command(0x02, started)  # STF, as a former master left it
            self.control.advance(now)

    @property
    def address(self) -> int:
        """The station number (Pr.117 as of the last power-up or reset)."""
        return self._station

    @property
    def response_delay_s(self) -> float:
        """Waiting time and data check time of the request last handled."""
        return self._delay_s

    @property
    def deaf_until(self) -> float:
        """When the drive hears requests again after its last reset (past: it hears now)."""
        return self._deaf_until

    def advance(self, now: float) -> None:
        """Bring ramps and the communication check up to ``now``."""
        self.control.advance(now)
        if self._settings.warning_cycle is not None:
            self.control.warning = self._settings.warning_showing(now - self._born)

    def handle(self, frame: bytes, now: float) -> bytes | None:
        """Act on a request candidate that ended at ``now``; return the reply, or None."""
        if now < self._deaf_until or len(frame) < 3 or frame[0] != ENQ:
            return None  # restarting, or the master's own ACK/NAK to a data reply
        if not HEX_DIGITS.issuperset(frame[1:3]) or int(frame[1:3], 16) != self._station:
            return None
        self._delay_s = self._check_s
        self.advance(now)
        try:
            code, data, wait_ms = self._judge(frame)
        except _Refused as refused:
            return self._reception_error(refused.code, now)
        self._errors = 0
        self.control.heard(now)
        self._delay_s = wait_ms / 1000.0 + self._check_s
        try:
            reply = self._serve(code, data, now)
        except _Refused as refused:
            return self._nak(refused.code)
        if _is_slow(code):
            self._delay_s += PARAMETER_EXTRA_S  # parameter and EEPROM access (§7)
        return reply

    # -- judging the request ----------------------------------------------------------------

    def _judge(self, frame: bytes) -> tuple[int, int | None, int]:
        """Instruction code, data and waiting time of a good request; _Refused otherwise."""
        body, terminator = split_terminator(frame)
        if terminator is not self._terminator and not (
            self._terminator is Terminator.CRLF and terminator is Terminator.CR
        ):
            raise _Refused(PROTOCOL_ERROR)
        chars = body[1:]
        if not HEX_DIGITS.issuperset(chars):
            raise _Refused(CHARACTER_ERROR)
        has_wait = self._wait_ms is None
        width = len(chars) - 6 - has_wait
        if width < 0:
            raise _Refused(PROTOCOL_ERROR)
        code = int(chars[2:4], 16)
        if width not in request_widths(code):
            raise _Refused(PROTOCOL_ERROR)
        checked = chars[:-2]
        if int(chars[-2:], 16) != sum_check(checked):
            raise _Refused(SUM_ERROR)
        wait_ms = int(chars[4:5], 16) * WAIT_STEP_MS if has_wait else (self._wait_ms or 0)
        data = int(checked[4 + has_wait :], 16) if width else None
        return code, data, wait_ms

    def _reception_error(self, code: int, now: float) -> bytes:
        """NAK a broken request; too many in a row trip the drive (Pr.121).

        Only errors 0-5 count toward the trip (§5): a character error (7) does not.
        """
        if code in COUNTS_TOWARD_TRIP:
            self._errors += 1
        allowed = self.parameters[self.control.retry_parameter]  # Pr.121 or Pr.335
        if allowed != SETTING_9999 and self._errors > allowed:
            self.control.trip(self.control.link_trip, now)
            return self._nak(COMPUTER_NAK)
        return self._nak(code)

    # -- serving it -------------------------------------------------------------------------

    def _serve(self, code: int, data: int | None, now: float) -> bytes | None:
        if data is None:
            return self._read(code)
        return self._write(code, data, now)

    def _read(self, code: int) -> bytes:
        if code <= 0x63:
            return self._data(self.parameters[self._parameter(code)], 4)
        if code == 0x7C:
            text = MODEL_NAME.ljust(TEXT_WIDTH)[:TEXT_WIDTH]
            reply = DataReply(station=self._station, data=None, width=TEXT_WIDTH, text=text)
            return encode_frame(reply, self._terminator)
        if code not in _MONITORS:
            raise _Refused(INSTRUCTION_CODE_ERROR)
        value, width = _MONITORS[code]
        return self._data(value(self), width)

    def _write(self, code: int, data: int, now: float) -> bytes | None:
        control = self.control
        if 0x80 <= code <= 0xE3:
            self._write_parameter(self._parameter(code - 0x80), data, now)
        elif code in (0xED, 0xEE):
            self._network_only()
            highest = self.parameters.value(1)  # Pr.1, the maximum frequency
            if data * 0.01 > highest + 1e-9:
                raise _Refused(DATA_RANGE_ERROR)
            control.set_frequency(data * 0.01, now, eeprom=code == 0xEE)
        elif code in (0xFA, 0xF9):
            self._network_only()
            control.command(data, now)
        elif code == 0xFB:
            if data not in tuple(OperationMode):
                raise _Refused(DATA_RANGE_ERROR)
            if control.local:
                raise _Refused(MODE_ERROR)  # the operator holds it in PU/external operation
            self._stopped_only()
            control.mode = OperationMode(data)
        elif code == 0xFD:
            return self._reset(data, now)
        elif code == 0xFC:
            if data not in _CLEARS:
                raise _Refused(DATA_RANGE_ERROR)
            self._network_only()
            self._stopped_only()
            self.parameters.clear(keep_communication=_CLEARS[data])
            control.refresh(now)
        elif code == 0xF4:
            if data != RESET_NO_REPLY:
                raise _Refused(DATA_RANGE_ERROR)
            control.history.clear()
        elif code == 0xFF:
            if data > 9:
                raise _Refused(DATA_RANGE_ERROR)
            self._page = data
        elif code == 0xF3:
            if data not in _SPECIAL_MONITORS:
                raise _Refused(DATA_RANGE_ERROR)
            self._monitor = data
        elif code == 0xEC:
            if data > 2:
                raise _Refused(DATA_RANGE_ERROR)
            self._second = data
        else:
            raise _Refused(INSTRUCTION_CODE_ERROR)
        return encode_frame(Ack(self._station), self._terminator)

    def _write_parameter(self, number: int, raw: int, now: float) -> None:
        setting = SETTINGS[number]
        self._network_only()
        if setting.stopped_only:
            self._stopped_only()
        if not setting.accepts(raw) or (number == 123 and raw != SETTING_9999 and raw % 10):
            raise _Refused(DATA_RANGE_ERROR)
        self.parameters.set(number, raw)
        self.control.refresh(now)

    def _reset(self, data: int, now: float) -> bytes | None:
        if data not in (RESET_NO_REPLY, RESET_AFTER_ACK):
            raise _Refused(DATA_RANGE_ERROR)
        ack = encode_frame(Ack(self._station), self._terminator)
        self.control.power_up(now)
        self._page = 0
        self._errors = 0
        self._take_line_settings()
        self._deaf_until = now + RESTART_S  # an ACK (H9966) is on the wire already
        return ack if data == RESET_AFTER_ACK else None

    def _parameter(self, code: int) -> int:
        """The parameter a page-relative code names now; NAK B if the drive has none."""
        number = self._page * 100 + code
        if number not in SETTINGS:
            raise _Refused(INSTRUCTION_CODE_ERROR)
        return number

    def _network_only(self) -> None:
        if self.control.mode is not OperationMode.NETWORK:
            raise _Refused(MODE_ERROR)

    def _stopped_only(self) -> None:
        if self.motor.output_on and self.parameters[77] != 2:
            raise _Refused(MODE_ERROR)

    def _special(self) -> int:
        motor, control = self.motor, self.control
        values = {
            0x01: abs(motor.frequency_hz) * 100,
            0x02: motor.current_a * 100,
            0x03: motor.voltage_v * 10,
            0x05: control.set_hz * 100,
            0x06: abs(motor.speed_rpm),
            0x08: motor.dc_link_v * 10,
            0x0D: max(motor.power_kw, 0.0) * 100,
            0x0E: max(motor.power_kw, 0.0) * 100 * 0.95,
        }
        return _fit(values[self._monitor])

    def _take_line_settings(self) -> None:
        p = self.parameters
        self._station = p[117]
        self._wait_ms = None if p[123] == SETTING_9999 else p[123]
        self._terminator = _TERMINATORS[p[124]]

    def _data(self, value: int, width: int) -> bytes:
        reply = DataReply(station=self._station, data=value & (16**width - 1), width=width)
        return encode_frame(reply, self._terminator)

    def _nak(self, code: int) -> bytes:
        return encode_frame(Nak(self._station, code), self._terminator)


def _is_slow(code: int) -> bool:
    """Parameter access, EEPROM frequency writes and clears take the longer check (§7)."""
    return code <= 0x63 or 0x80 <= code <= 0xE3 or code in (0xEE, 0xFC)


def _hz(frequency: float) -> int:
    return _fit(frequency * 100)


def _fit(value: float) -> int:
    return min(max(round(value), 0), 0xFFFF)


# Page-independent reads (H6C-H7F but H7C, the model name): the value, read only for the
# code asked, and its width in digits. Built once; the getters see the drive's state now.
_MONITORS: Final[dict[int, tuple[Callable[[MitsubishiSimDrive], int], int]]] = {
    0x6C: (lambda d: d._second, 2),
    0x6D: (lambda d: _hz(d.control.set_hz), 4),
    0x6E: (lambda d: _hz(d.control.set_hz_eeprom), 4),
    0x6F: (lambda d: _hz(abs(d.motor.frequency_hz)), 4),
    0x70: (lambda d: _fit(d.motor.current_a * 100), 4),
    0x71: (lambda d: _fit(d.motor.voltage_v * 10), 4),
    0x72: (MitsubishiSimDrive._special, 4),
    0x73: (lambda d: d._monitor, 2),
    0x74: (lambda d: d.control.fault_word(0), 4),
    0x75: (lambda d: d.control.fault_word(2), 4),
    0x76: (lambda d: d.control.fault_word(4), 4),
    0x77: (lambda d: d.control.fault_word(6), 4),
    0x79: (lambda d: d.control.status(extended=True), 4),
    0x7A: (lambda d: d.control.status(extended=False), 2),
    0x7B: (lambda d: int(d.control.mode), 4),
    0x7F: (lambda d: d._page, 2),
}


def line_receiver(drives: list[DriveSettings]) -> RequestReceiver:
    """The one receiver of a line whose drives have ``drives``' settings.

    UsageError when they disagree on Pr.123 (9999 or not) or Pr.124: one receiver stands
    for every drive on the line, as the protocol document asks of a line anyway (§1.1).
    """
    seen: set[tuple[Terminator, bool]] = set()
    for settings in drives or [DriveSettings()]:
        store = ParameterStore(overrides_from_values(settings.parameters))
        seen.add((_TERMINATORS[store[124]], store[123] == SETTING_9999))
    if len(seen) > 1:
        raise UsageError("the drives of one line must agree on Pr.123 (9999 or not) and Pr.124")
    terminator, wait_digit = seen.pop()
    return RequestReceiver(terminator=terminator, wait_digit=wait_digit)


def line_parameters(plan: LinePlan) -> dict[str, float]:
    """The drive settings a bus's config implies: Pr.124 from ``terminator``, and Pr.123.

    A ``wait_time_ms`` number means the drives expect the digit (Pr.123 = 9999); null means
    their Pr.123 sets the waiting time, here 0 ms unless the simulation section says more.
    """
    return {
        "Pr.124": float(_TERMINATORS.index(Terminator(plan.terminator))),
        "Pr.123": 9999.0 if plan.wait_time_ms is not None else 0.0,
    }
