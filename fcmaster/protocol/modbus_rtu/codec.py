"""Modbus RTU drives behind the bus's :class:`~fcmaster.protocol.codec.DriveCodec` seam.

Each address follows its drive profile (:mod:`.profile`), so one line may mix families.

Polls read: the status word, with the output frequency in the same read where the profile
puts them within a few registers of each other (ABB: 400004-400005), else the frequency in
every second poll on its own; monitored registers in turn; the fault register when the
status shows a fault came or went. A drive under bus control also gets, every fourth poll,
its steady control word written (the last word of the sequence of what it was commanded):
many families' watchdogs are fed only by control word writes (ABB 58.15 = Cw/Ref1/Ref2).

Commands write the profile's sequence of control words, one exchange each, so each step is
acknowledged before the next (and the profile's ``between_steps_s`` passes between them); a
run writes the reference first. A reference change while the drive is commanded to run
writes only the reference: sending a state machine's start sequence again would pass a
running CiA 402 drive through "shutdown".
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Final

from fcmaster.errors import MalformedReply, UnexpectedReply, UsageError
from fcmaster.protocol.codec import (
    Access,
    DriveError,
    Exchange,
    ParameterKey,
    Reply,
)
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ, ControlIntent, Motion, pct_to_hz
from fcmaster.protocol.modbus_rtu.exception_codes import exception_text
from fcmaster.protocol.modbus_rtu.frame import (
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    Request,
    WriteMultiple,
    WriteSingle,
    Written,
    decode_request,
    decode_response,
    encode_request,
    reply_length,
)
from fcmaster.protocol.modbus_rtu.framer import RtuFramer
from fcmaster.protocol.modbus_rtu.keys import (
    CONTROL_FEED,
    FAULT_CODE,
    OUTPUT_FREQUENCY,
    PROFILE_KEYS,
    key_register,
    parse_register,
    register_key,
    same_register,
)
from fcmaster.protocol.modbus_rtu.profile import DriveProfile, Register
from fcmaster.protocol.modbus_rtu.replies import read_reply, scaled, status_refused, value_of
from fcmaster.protocol.polls import PollCache

# Status and output frequency this close are read together (a few bytes more per poll
# instead of a poll of its own).
_JOINT_SPAN: Final = 8
_READS: Final = (Function.READ_HOLDING, Function.READ_INPUT)
_FIXED_T35_S: Final = 0.00175  # Serial Line §2.5.1.1: t3.5 above 19200 baud
_MOTIONS: Final = {
    Motion.STOP: "stop",
    Motion.COAST: "coast",
    Motion.QUICK_STOP: "quick_stop",
    Motion.JOG: "jog",
}


class ModbusCodec:
    """Modbus RTU exchanges for one line whose drives follow ``profiles`` (by address)."""

    protocol = "modbus-rtu"
    addresses = range(1, 248)
    # Off: one control word means different things to different profiles on a line.
    can_broadcast = False

    def __init__(
        self,
        profiles: Mapping[int, DriveProfile] | None = None,
        nominal_hz: Mapping[int, float] | None = None,
        default: DriveProfile | None = None,
    ) -> None:
        """Drives follow ``profiles`` by address, else ``default`` (the line's ``profile``).

        A drive with neither is polled only for its presence (holding register 0: any
        answer, an exception too, says it is there) and commanded not at all; its registers
        can still be read and written, unscaled.
        """
        self.profiles = dict(profiles or {})
        self.nominal_hz = dict(nominal_hz or {})
        self.default = default
        self._commanded: dict[int, ControlIntent] = {}
        self._running: dict[int, bool] = {}  # what each drive's last status said
        self._polls = PollCache(self._build_poll)

    def profile(self, address: int) -> DriveProfile:
        """The profile of the drive at ``address``; UsageError if it has none."""
        profile = self._known(address)
        if profile is None:
            raise UsageError(
                f"the Modbus drive at address {address} has no profile: give it one "
                "(profile: in the config, --profile on the command line)"
            )
        return profile

    def _known(self, address: int) -> DriveProfile | None:
        return self.profiles.get(address, self.default)

    def new_framer(self) -> RtuFramer:
        """A framer for the drives' answers."""
        return RtuFramer()

    def min_pause_s(self, char_s: float) -> float:
        """The 3.5-character silence that ends a frame: 1.75 ms at the least (§2.5.1.1)."""
        return max(3.5 * char_s, _FIXED_T35_S)

    def parameter(self, text: str) -> ParameterKey:
        """``hr106``, ``ir3204``, ``106``, ``hr16139x2`` → its key (see :mod:`.keys`)."""
        return parse_register(text)

    def default_monitor(self) -> tuple[ParameterKey, ...]:
        """The values the line's profiles list (each drive reads its own profile's)."""
        keys = (register_key(v.register) for p in self.profiles.values() for v in p.values)
        return tuple(dict.fromkeys(keys))

    def poll_sequence(self, monitor: tuple[ParameterKey, ...]) -> tuple[ParameterKey | None, ...]:
        """Status every other poll, the frequency and the control-word feed in between."""
        sequence: list[ParameterKey | None] = [None, OUTPUT_FREQUENCY, None, CONTROL_FEED]
        for extra in dict.fromkeys(monitor):
            if extra not in PROFILE_KEYS:
                sequence += [None, OUTPUT_FREQUENCY, None, extra]
        return tuple(sequence)

    def condition_parameters(self, *, alarms: bool, warnings: bool) -> tuple[ParameterKey, ...]:
        """The fault register when the fault bit changed (warnings have no code)."""
        return (FAULT_CODE,) if alarms else ()

    # ------------------------------------------------------------------ requests

    def poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        """The idle poll of ``address`` (module docstring); built once per kind."""
        if intent is not None:  # what the drive is commanded now (see control())
            before = self._commanded.get(address)
            if intent.motion is Motion.RUN and (before is None or before.motion is not Motion.RUN):
                # Just started: a status read before the start says nothing of it now.
                self._running.pop(address, None)
            self._commanded[address] = intent
        if read is not CONTROL_FEED:
            intent = None  # only the feed depends on it: one cached poll per read
        elif intent is not None:
            intent = ControlIntent(intent.motion, intent.reverse)
        return self._polls.get(address, intent, read)

    def _build_poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        profile = self._known(address)
        if profile is None:  # presence only (see __init__)
            if read is not None and read not in PROFILE_KEYS:
                return self._read(address, key_register(read), read)
            return self._read(address, Register(address=0), None)
        if read is CONTROL_FEED and intent is not None:
            word = self._words(profile, intent)[-1]
            return self._write(address, profile.control, (word,), carries_control=True)
        if read is OUTPUT_FREQUENCY and not _joint(profile):
            return self._read(address, profile.output_frequency, OUTPUT_FREQUENCY)
        if read is FAULT_CODE and profile.fault_code is not None:
            return self._read(address, profile.fault_code, FAULT_CODE)
        if read is not None and read not in PROFILE_KEYS and self._reads(profile, read):
            return self._read(address, key_register(read), read)
        return self._status_poll(address, profile)

    def _reads(self, profile: DriveProfile, key: ParameterKey) -> bool:
        """Whether a drive of ``profile`` reads ``key`` in its polls.

        A value another profile on the line lists, and this one does not, is not this
        drive's: the default monitor holds every profile's values.
        """
        register = key_register(key)
        if any(same_register(v.register, register) for v in profile.values):
            return True
        others = (v for p in self.profiles.values() if p is not profile for v in p.values)
        return not any(same_register(v.register, register) for v in others)

    def _status_poll(self, address: int, profile: DriveProfile) -> Exchange:
        status, frequency = profile.status, profile.output_frequency
        if not _joint(profile):
            return self._read(address, status, None)
        start = min(status.address, frequency.address)
        end = max(status.address + 1, frequency.address + frequency.words)
        return self._read(
            address, Register(address=start, input=status.input, words=1), None, end - start
        )

    def control(self, address: int, intent: ControlIntent) -> tuple[Exchange, ...]:
        """The writes that command ``intent``, in order; UsageError for what the profile lacks.

        The same every time it is asked (the bus asks again for each step): what the drive
        was commanded before is what its polls carry (:meth:`poll`), not what was asked here.
        """
        profile = self.profile(address)
        previous = self._commanded.get(address)
        words: list[int] = []
        if intent.reset:
            words += _sequence(profile, "reset")
        exchanges = [
            self._write(address, profile.control, (w,), carries_control=True) for w in words
        ]
        if intent.motion is Motion.RUN:
            exchanges.append(self._reference(address, profile, intent))
            still_running = (
                previous is not None
                and previous.motion is Motion.RUN
                and previous.reverse == intent.reverse
                and not intent.reset
                # Commanded to run is not running: a drive stopped behind the gateway's back
                # (a local stop, STO, a power cut) is walked through its sequence again.
                and self._running.get(address, True)
            )
            if still_running:  # the state machine is where it should be: the reference only
                return tuple(exchanges)
        exchanges += (
            self._write(address, profile.control, (w,), carries_control=True)
            for w in self._words(profile, intent)
        )
        between = profile.pacing.between_steps_s
        if between:  # the family's wait between the steps of a sequence, not after the last
            exchanges[:-1] = [dataclasses.replace(e, settle_s=between) for e in exchanges[:-1]]
        return tuple(exchanges)

    def _words(self, profile: DriveProfile, intent: ControlIntent) -> tuple[int, ...]:
        """The control words of ``intent``'s motion (and direction)."""
        if intent.motion is Motion.RUN:
            if self._reverse(profile, intent):
                return _sequence(profile, "start_reverse")
            return _sequence(profile, "start")
        return _sequence(profile, _MOTIONS[intent.motion])

    @staticmethod
    def _reverse(profile: DriveProfile, intent: ControlIntent) -> bool:
        """Whether reverse takes the profile's reverse start (else a negative reference)."""
        return intent.reverse and "start_reverse" in profile.commands

    def _reference(self, address: int, profile: DriveProfile, intent: ControlIntent) -> Exchange:
        register = profile.reference
        percent = abs(intent.reference_pct)
        if intent.reverse and not self._reverse(profile, intent):
            if not register.signed:
                raise UsageError(f"profile {profile.name} has no way to run in reverse")
            percent = -percent
        nominal = self.nominal_hz.get(address, DEFAULT_NOMINAL_HZ)
        value = percent if register.unit == "%" else pct_to_hz(percent, nominal)
        return self._write(address, register, register.raw(value), carries_control=True)

    def read(
        self, address: int, parameter: ParameterKey, index: int, intent: ControlIntent | None
    ) -> tuple[Exchange, ...]:
        """Read one register (or a 32-bit pair)."""
        _no_index(index)
        return (self._read(address, key_register(parameter), parameter),)

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
        """Write one register (FC 6) or a 32-bit pair (FC 16), in the profile's scaling.

        ``persist`` changes nothing: whether a register write survives a power cycle is
        each family's own rule (ABB: never, until 96.07 saves it). The exchange carries the
        profile's wait after a parameter write (``settle_s``), which the bus keeps.
        """
        _no_index(index)
        if isinstance(value, str):
            raise UsageError(f"{parameter.name}: only numbers can be written to a register")
        profile = self._known(address)
        register = scaled(profile, key_register(parameter))
        if profile is not None:
            _not_a_command_register(profile, register)
        exchange = self._write(address, register, register.raw(value), parameter=parameter)
        if profile is not None and profile.pacing.after_write_s:
            exchange = dataclasses.replace(exchange, settle_s=profile.pacing.after_write_s)
        return (exchange,)

    # ------------------------------------------------------------------ replies

    def parse(self, exchange: Exchange, frame: bytes) -> Reply:
        """Check that ``frame`` answers ``exchange`` and read it."""
        response = decode_response(frame)
        if response.address != exchange.address:
            raise UnexpectedReply(f"answer from address {response.address}", raw=frame)
        request = decode_request(exchange.request)
        function = _function(request)
        if isinstance(response, ExceptionReply):
            if response.function != function:
                raise UnexpectedReply(f"exception to function {response.function}", raw=frame)
            code, text = response.code, exception_text(response.code)
            profile = self._known(exchange.address)
            conditions = None
            if profile is not None and exchange.parameter is None and function in _READS:
                conditions = status_refused(profile, code, text)  # its state cannot be read
            return Reply(
                address=exchange.address, error=DriveError(code, text), conditions=conditions
            )
        if isinstance(request, ReadRequest):
            if not isinstance(response, Registers) or response.function != function:
                raise UnexpectedReply("not the answer to a read", raw=frame)
            if len(response.values) != request.count:
                raise MalformedReply(
                    f"{len(response.values)} registers for {request.count} asked", raw=frame
                )
            nominal = self.nominal_hz.get(exchange.address, DEFAULT_NOMINAL_HZ)
            profile = self._known(exchange.address)
            reply = read_reply(exchange, request, response.values, profile, nominal)
            if reply.status is not None:
                self._running[exchange.address] = reply.status.running
            return reply
        if response != _echo(request):
            raise UnexpectedReply("the write was not confirmed as sent", raw=frame)
        value = None
        if exchange.parameter is not None and exchange.parameter not in PROFILE_KEYS:
            words = request.values if isinstance(request, WriteMultiple) else (request.value,)
            value = value_of(self._known(exchange.address), exchange.parameter, words)
        return Reply(address=exchange.address, value=value)

    # ------------------------------------------------------------------ building

    def _read(
        self, address: int, register: Register, key: ParameterKey | None, count: int | None = None
    ) -> Exchange:
        function = Function.READ_INPUT if register.input else Function.READ_HOLDING
        request = ReadRequest(
            address=address,
            function=function,
            start=register.address,
            count=count or register.words,
        )
        access = Access.NONE if key is None else Access.READ
        return self._exchange(request, access=access, parameter=key)

    def _write(
        self,
        address: int,
        register: Register,
        words: tuple[int, ...],
        *,
        parameter: ParameterKey | None = None,
        carries_control: bool = False,
    ) -> Exchange:
        request: Request
        if len(words) == 1:
            request = WriteSingle(address=address, register=register.address, value=words[0])
        else:
            request = WriteMultiple(address=address, start=register.address, values=words)
        access = Access.NONE if parameter is None else Access.WRITE
        return self._exchange(
            request, access=access, parameter=parameter, carries_control=carries_control
        )

    @staticmethod
    def _exchange(
        request: Request,
        *,
        access: Access,
        parameter: ParameterKey | None,
        carries_control: bool = False,
    ) -> Exchange:
        return Exchange(
            address=request.address,
            request=encode_request(request),
            reply_length=reply_length(request),
            access=access,
            parameter=parameter,
            carries_control=carries_control,
        )


def _joint(profile: DriveProfile) -> bool:
    """Whether status and output frequency are read together (same table, close by)."""
    status, frequency = profile.status, profile.output_frequency
    low = min(status.address, frequency.address)
    high = max(status.address + 1, frequency.address + frequency.words)
    return status.input == frequency.input and high - low <= _JOINT_SPAN


def _not_a_command_register(profile: DriveProfile, register: Register) -> None:
    """Refuse a parameter write to where the drive takes its commands (UsageError).

    Its control word and reference are the command path's alone: written as a parameter, a
    word would start the motor unaudited and a reference would pass the drive's configured
    limits, which only commands are held to.
    """
    span = set(range(register.address, register.address + register.words))
    for role, held in (("control word", profile.control), ("reference", profile.reference)):
        taken = range(held.address, held.address + held.words)
        if held.input == register.input and span.intersection(taken):
            raise UsageError(
                f"register {register.address} is {profile.name}'s {role}: "
                + ("command the drive instead" if role == "control word" else
                   "set it with set_reference, within the drive's configured limits")
            )  # fmt: skip


def _sequence(profile: DriveProfile, command: str) -> tuple[int, ...]:
    words = profile.commands.get(command)
    if not words:
        raise UsageError(f"drive profile {profile.name} has no {command.replace('_', ' ')} command")
    return words


def _function(request: Request) -> int:
    if isinstance(request, ReadRequest):
        return request.function
    return Function.WRITE_SINGLE if isinstance(request, WriteSingle) else Function.WRITE_MULTIPLE


def _echo(request: Request) -> WriteSingle | Written | None:
    if isinstance(request, WriteSingle):
        return request
    if isinstance(request, WriteMultiple):
        return Written(address=request.address, start=request.start, count=len(request.values))
    return None


def _no_index(index: int) -> None:
    if index:
        raise UsageError("a Modbus register has no index; leave it out")
