"""The computer link behind the bus's :class:`~fcmaster.protocol.codec.DriveCodec` seam.

One instruction per transaction (protocols/mitsubishi.md §2). Nothing rides along with a
poll, so polls only read and a monitor-only drive is never commanded by one:

* The idle poll alternates the status monitor (H7A: running, direction, at frequency,
  fault, overload) with the next item of the drive's monitor list (H6F output frequency,
  H70 current, …), so the status is never more than one poll old.
* A control change is a running-frequency write (HED, RAM only: §8, no EEPROM wear) then
  a run command (HFA 02/04) for a run, and HFA alone for a stop (00) or a coast (80, MRS).
  A reset is HFD H9696, which the drive does not answer because it restarts (§2): reply
  length 0, and ``deaf_s`` tells the bus how long to leave the drive alone afterwards.
* A parameter needs the link-parameter page (HFF) set before its own code, every time
  (§9: the page is drive state and is never assumed): :meth:`MitsubishiCodec.read` and
  :meth:`MitsubishiCodec.write` return the page write and then the access, and the bus
  carries both as one command. Page-independent items take one transaction.

Timing (§7). A drive starts its reply after the waiting time (the digit in the request, or
its Pr.123) and its data check time: under 12 ms for monitors, the run command and RAM
frequency writes, under 30 ms for parameters and EEPROM writes. :func:`answer_delay_s` is
the worst of these for a line, so that the reply deadline never cuts a slow answer short.

Replies name no instruction, only the station, so :meth:`MitsubishiCodec.parse` checks the
station echo, then that the reply has the shape the request calls for (data of the width
the instruction code fixes for a read; ACK for a write; NAK with an error code for both).
The codec keeps one fact per drive: whether its last status showed a fault, because the
fault history (H74) lists past faults too and says nothing about whether one is active.
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import UnexpectedReply, UsageError
from fcmaster.protocol.codec import (
    Access,
    Condition,
    ConditionReport,
    DriveError,
    Exchange,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ, ControlIntent, Motion, pct_to_hz
from fcmaster.protocol.mitsubishi.error_codes import error_text, fault_pair, fault_text
from fcmaster.protocol.mitsubishi.framer import MitsubishiFramer
from fcmaster.protocol.mitsubishi.instructions import (
    FAULT_HISTORY,
    INVERTER_RESET,
    LINK_PAGE,
    OUTPUT_FREQUENCY,
    RESET_NO_REPLY,
    RUN_COMMAND,
    SET_FREQUENCY_EEPROM,
    SET_FREQUENCY_RAM,
    STATUS,
    STATUS_EXTENDED,
    Instruction,
    item_raw,
)
from fcmaster.protocol.mitsubishi.message import (
    Ack,
    DataReply,
    Message,
    Nak,
    Request,
    Terminator,
    decode_frame,
    encode_frame,
    frame_length,
    wait_digit,
)
from fcmaster.protocol.mitsubishi.parameters import (
    PARAMETER_DIGITS,
    ParameterSpec,
    instruction_key,
    key_value,
    parse_parameter,
    read_widths,
    resolve,
)
from fcmaster.protocol.mitsubishi.profile import (
    decode_status,
    frequency_hz,
    frequency_raw,
    run_command,
)
from fcmaster.protocol.polls import PollCache

DEFAULT_WAIT_MS: Final = 0  # the digit sent by default (§7: rely on our own turnaround)
TURNAROUND_S: Final = 0.010  # §2 step 4: 10 ms or more before the next request
PARAMETER_CHECK_S: Final = 0.030  # §7: data check time of parameter and EEPROM access
MAX_WAIT_S: Final = 0.150  # §1.1: the longest waiting time Pr.123 can set
# How long a drive takes to come back after HFD H9696. The manuals say only that it
# restarts; an inverter reset takes about a second, so the bus leaves it alone that long.
RESTART_S: Final = 1.0
ALARM_SOURCE: Final = FAULT_HISTORY.key_name

DEFAULT_MONITOR: Final = tuple(parse_parameter(code) for code in ("H6F", "H70", "H71"))


class MitsubishiCodec:
    """Mitsubishi computer-link exchanges for one bus (one terminator, one waiting time)."""

    protocol = "mitsubishi"
    can_broadcast = False  # station 0 is a real drive; the link has no broadcast
    addresses = range(0, 32)  # stations 0-31; the link has no broadcast, 0 is a drive

    def __init__(
        self,
        *,
        terminator: str = "cr",
        wait_time_ms: int | None = DEFAULT_WAIT_MS,
        nominal_hz: dict[int, float] | None = None,
    ) -> None:
        """Set up for a line whose drives have Pr.124 = ``terminator`` and Pr.123 set.

        Args:
            terminator: ``none``, ``cr`` or ``crlf`` (Pr.124/Pr.341 = 0, 1, 2).
            wait_time_ms: the waiting time every request carries (0-150 ms in 10 ms
                steps), for drives whose Pr.123/Pr.337 is 9999, the factory setting; None
                for drives whose Pr.123 sets it, so requests leave the digit out (§1.1).
            nominal_hz: per address, the frequency that 100 % reference means (default 50).
        """
        try:
            self.terminator = Terminator(terminator)
        except ValueError:
            raise UsageError(f"terminator {terminator!r} is not none, cr or crlf") from None
        if wait_time_ms is not None:
            wait_digit(wait_time_ms)  # 0-150 in 10 ms steps, or UsageError
        self.wait_time_ms = wait_time_ms
        self.nominal_hz = dict(nominal_hz or {})
        self._faulted: dict[int, bool] = {}
        self._polls = PollCache(self._build_poll)

    def new_framer(self) -> MitsubishiFramer:
        """A framer for replies on this line."""
        return MitsubishiFramer(terminator=self.terminator)

    def min_pause_s(self, char_s: float) -> float:
        """10 ms after a reply (§2), whatever the baud rate."""
        return TURNAROUND_S

    def parameter(self, text: str) -> ParameterKey:
        """``"Pr.7"``, ``"7"``, ``"H6F"``, ``"6F"`` → its key (see ``parameters``)."""
        return parse_parameter(text)

    def default_monitor(self) -> tuple[ParameterKey, ...]:
        """Output frequency, output current, output voltage."""
        return DEFAULT_MONITOR

    def poll_sequence(self, monitor: tuple[ParameterKey, ...]) -> tuple[ParameterKey | None, ...]:
        """The status (None) before each monitored item: H7A, m1, H7A, m2, and so on.

        Only page-independent items can be polled: a parameter needs two transactions.
        """
        for key in monitor:
            target = resolve(key)
            if isinstance(target, ParameterSpec) or target.read is None:
                raise UsageError(
                    f"{key.name} cannot be polled: the monitor list takes readable "
                    "instruction codes such as H6F, H70, H71, H74"
                )
        if not monitor:
            return (None,)
        return tuple(entry for key in monitor for entry in (None, key))

    def condition_parameters(self, *, alarms: bool, warnings: bool) -> tuple[ParameterKey, ...]:
        """The fault history (latest two faults) when the fault bit changed.

        The overload warning has nothing behind it to read.
        """
        return (instruction_key(FAULT_HISTORY),) if alarms else ()

    def poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        """A status read, or a read of ``read``; never a command (``intent`` is not sent).

        Built once per address and ``read``.
        """
        return self._polls.get(address, None, read)

    def _build_poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        if read is None:
            return self._exchange(address, STATUS.code, None, 0, widths=(STATUS.digits,))
        exchanges = self.read(address, read, 0, None)
        if len(exchanges) != 1:  # poll_sequence lets no parameter through
            raise UsageError(f"{read.name} needs the page first and cannot be polled")
        return exchanges[0]

    def control(self, address: int, intent: ControlIntent) -> tuple[Exchange, ...]:
        """HFD 9696 for a reset; HED then HFA for a run; HFA for a stop or a coast.

        UsageError for jog (no run-command bit) and for a frequency that four digits of
        0.01 Hz cannot carry (negative, or above 655.35 Hz): never clamped.
        """
        if intent.reset:
            return (
                self._exchange(
                    address,
                    INVERTER_RESET.code,
                    RESET_NO_REPLY,
                    INVERTER_RESET.digits,
                    control=True,
                    reply_length=0,  # the drive restarts instead of answering (§2)
                    deaf_s=RESTART_S,
                ),
            )
        command = self._exchange(
            address, RUN_COMMAND.code, run_command(intent), RUN_COMMAND.digits, control=True
        )
        if intent.motion is not Motion.RUN:
            return (command,)
        nominal = self.nominal_hz.get(address, DEFAULT_NOMINAL_HZ)
        raw = frequency_raw(pct_to_hz(intent.reference_pct, nominal))
        code = SET_FREQUENCY_RAM.write or 0
        frequency = self._exchange(address, code, raw, SET_FREQUENCY_RAM.digits, control=True)
        return (frequency, command)

    def read(
        self, address: int, parameter: ParameterKey, index: int, intent: ControlIntent | None
    ) -> tuple[Exchange, ...]:
        """HFF with the page, then the read code, for a parameter; the item's code otherwise."""
        target = _target(parameter, index)
        if isinstance(target, ParameterSpec):
            read = self._exchange(
                address, target.read_code, None, 0, widths=PARAMETER_DIGITS, parameter=parameter
            )
            return (self._page(address, target.page), read)
        if target.read is None:
            raise UsageError(f"{parameter.name} ({target.name}) can only be written")
        read = self._exchange(
            address, target.read, None, 0, widths=target.read_widths, parameter=parameter
        )
        return (read,)

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
        """HFF with the page, then the write code, for a parameter; the item's code otherwise.

        ``persist`` turns a RAM set-frequency write (H6D → HED) into HEE (RAM and EEPROM).
        Parameter writes go where Pr.342 says (EEPROM unless it is 1); ``persist`` cannot
        change that.
        """
        target = _target(parameter, index)
        if isinstance(value, str):
            raise UsageError(f"{parameter.name}: only numbers can be written")
        if isinstance(target, ParameterSpec):
            raw = target.to_raw(value)
            width = 4 if raw <= 0xFFFF else 6
            write = self._exchange(address, target.write_code, raw, width, parameter=parameter)
            return (self._page(address, target.page), write)
        if target.write is None:
            raise UsageError(f"{parameter.name} ({target.name}) is read-only")
        if not target.user_writable:
            raise UsageError(
                f"{parameter.name} ({target.name}) is not written directly: use the "
                "control commands (start, stop, coast, reset)"
            )
        code = target.write
        if persist and target is SET_FREQUENCY_RAM:
            code = SET_FREQUENCY_EEPROM.write or code
        raw = item_raw(target, value)
        return (self._exchange(address, code, raw, target.digits, parameter=parameter),)

    def parse(self, exchange: Exchange, frame: bytes) -> Reply:
        """Check that ``frame`` answers ``exchange`` and read it."""
        message = decode_frame(frame)
        request = decode_frame(exchange.request)
        assert isinstance(request, Request)  # every exchange here carries one of ours
        if isinstance(message, Request):
            raise UnexpectedReply("a request, not a reply (local echo?)", raw=frame)
        if message.station != exchange.address:
            raise UnexpectedReply(
                f"reply from station {message.station}, asked station {exchange.address}",
                raw=frame,
            )
        if isinstance(message, Nak):
            if message.error_code is None:
                raise UnexpectedReply("a NAK without error code comes from a master", raw=frame)
            code = message.error_code
            return Reply(address=exchange.address, error=DriveError(code, error_text(code)))
        if request.is_read:
            if not isinstance(message, DataReply):
                raise UnexpectedReply(f"{_kind(message)} to a read", raw=frame)
            return self._read_reply(exchange, request.instruction, message, frame)
        if not isinstance(message, Ack):
            raise UnexpectedReply(f"{_kind(message)} to a write", raw=frame)
        value = None
        if exchange.access is Access.WRITE and exchange.parameter is not None:
            assert request.data is not None  # a write
            value = key_value(exchange.parameter, request.data)
        return Reply(address=exchange.address, value=value)

    def _read_reply(
        self, exchange: Exchange, instruction: int, reply: DataReply, frame: bytes
    ) -> Reply:
        address, key = exchange.address, exchange.parameter
        widths = (STATUS.digits,) if key is None else read_widths(key)
        if reply.width not in widths:
            raise UnexpectedReply(
                f"H{instruction:02X} is answered with {' or '.join(map(str, widths))} "
                f"digits; this reply has {reply.width}",
                raw=frame,
            )
        raw = reply.data or 0
        if key is None:  # the status poll
            return self._status_reply(address, raw, extended=False, value=None)
        value = key_value(key, raw, reply.text)
        target = resolve(key)
        if target is STATUS or target is STATUS_EXTENDED:
            return self._status_reply(address, raw, extended=target is STATUS_EXTENDED, value=value)
        if target is OUTPUT_FREQUENCY:
            return Reply(address=address, output_frequency_hz=frequency_hz(raw), value=value)
        conditions = None
        if target is FAULT_HISTORY and address in self._faulted:
            latest, _ = fault_pair(raw)
            active = (Condition(latest, fault_text(latest)),) if self._faulted[address] else ()
            conditions = ConditionReport(kind="alarm", source=ALARM_SOURCE, active=active)
        return Reply(address=address, value=value, conditions=conditions)

    def _status_reply(
        self, address: int, word: int, *, extended: bool, value: ParameterValue | None
    ) -> Reply:
        status = decode_status(word, extended=extended)
        self._faulted[address] = status.fault
        # No fault: no active alarm, whatever the history says. A fault: the planner reads
        # the history (condition_parameters), whose reply names it.
        conditions = (
            None if status.fault else ConditionReport(kind="alarm", source=ALARM_SOURCE, active=())
        )
        return Reply(address=address, status=status, conditions=conditions, value=value)

    def _page(self, address: int, page: int) -> Exchange:
        return self._exchange(address, LINK_PAGE.write or 0, page, LINK_PAGE.digits)

    def _exchange(
        self,
        address: int,
        code: int,
        data: int | None,
        width: int,
        *,
        widths: tuple[int, ...] = (),
        parameter: ParameterKey | None = None,
        control: bool = False,
        reply_length: int | None = None,
        deaf_s: float = 0.0,
    ) -> Exchange:
        """A read (``data`` None, replies of ``widths``) or a write of ``data``."""
        if data is None:
            longest = DataReply(station=address, data=0, width=max(widths))
            access, expected = Access.READ, frame_length(longest, self.terminator)
        else:
            # The longer of ACK and NAK, so the deadline never cuts a refusal short.
            access, expected = Access.WRITE, frame_length(Nak(address, 0), self.terminator)
        request = Request(
            station=address, instruction=code, data=data, width=width, wait_ms=self.wait_time_ms
        )
        return Exchange(
            address=address,
            request=encode_frame(request, self.terminator),
            reply_length=expected if reply_length is None else reply_length,
            access=access if parameter is not None else Access.NONE,
            parameter=parameter,
            carries_control=control,
            deaf_s=deaf_s,
        )


def answer_delay_s(wait_time_ms: int | None) -> float:
    """The longest a drive takes from the end of a request to the start of its reply (§7).

    The waiting time (the digit, or at worst 150 ms when the drives' Pr.123 sets it and the
    line does not know it) plus the data check time of a parameter or EEPROM access.
    """
    wait_s = MAX_WAIT_S if wait_time_ms is None else wait_time_ms / 1000.0
    return wait_s + PARAMETER_CHECK_S


def _target(parameter: ParameterKey, index: int) -> Instruction | ParameterSpec:
    if index:
        raise UsageError(f"{parameter.name}: the computer link has no index; leave it out")
    return resolve(parameter)


def _kind(message: Message) -> str:
    return {Ack: "an ACK", DataReply: "a data reply", Nak: "a NAK", Request: "a request"}[
        type(message)
    ]
