"""The FC protocol behind the bus's :class:`~fcmaster.protocol.codec.DriveCodec` seam.

Every FC request carries PCD1/PCD2, so every exchange — idle poll, parameter access or
control change — either commands the drive (CTW bit 10 = 1 with the commanded word and
reference) or tells it to ignore the word (bit 10 = 0) for a monitor-only drive. An idle
poll with something to read is a parameter telegram (16 bytes each way); with nothing to
read it is a process telegram (8 bytes each way).
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import MalformedReply, UnexpectedReply, UsageError
from fcmaster.protocol.codec import (
    Access,
    Condition,
    ConditionReport,
    DriveError,
    DriveStatus,
    Exchange,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.danfoss_fc.error_codes import error_text
from fcmaster.protocol.danfoss_fc.framer import DEFAULT_MAX_TEXT_LENGTH, FcFramer
from fcmaster.protocol.danfoss_fc.parameters import (
    DataType,
    ParameterSpec,
    format_parameter,
    lookup,
    parse_parameter,
)
from fcmaster.protocol.danfoss_fc.profile import (
    IGNORED_CONTROL_WORD,
    StatusWord,
    control_word,
    decode_reference,
    encode_reference,
)
from fcmaster.protocol.danfoss_fc.telegram import (
    IND_TEXT_READ,
    LGE_TEXT_BASE,
    PARAMETER_LENGTH,
    PROCESS_LENGTH,
    AddressFormat,
    RequestAk,
    ResponseAk,
    Telegram,
    decode_telegram,
    encode_telegram,
    make_pke,
)
from fcmaster.protocol.danfoss_fc.words import (
    decode_alarm_word,
    decode_alarm_word_2,
    decode_warning_word,
    decode_warning_word_2,
)
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ, ControlIntent, pct_to_hz
from fcmaster.protocol.polls import PollCache

# Plain ints: a reply is decoded on every transaction, and masking an int with an IntFlag
# member builds a new flag object each time.
_RUNNING: Final = int(StatusWord.RUNNING)
_FAULT_BITS: Final = int(StatusWord.TRIP | StatusWord.TRIP_LOCK | StatusWord.ERROR)
_WARNING: Final = int(StatusWord.WARNING)
_AT_REFERENCE: Final = int(StatusWord.AT_REFERENCE)
_BUS_CONTROL: Final = int(StatusWord.BUS_CONTROL)
_TEXT_REPLY_LENGTH: Final = LGE_TEXT_BASE + DEFAULT_MAX_TEXT_LENGTH + 2
_INFINITY: Final = float("inf")
_PCT_PER_STEP: Final = decode_reference(1)
_DEFAULT_HZ_PER_STEP: Final = pct_to_hz(_PCT_PER_STEP, DEFAULT_NOMINAL_HZ)

# parameter → (kind, decoder) for the words that carry alarms and warnings (§9)
_CONDITION_WORDS: Final = {
    1690: ("alarm", decode_alarm_word),
    1691: ("alarm", decode_alarm_word_2),
    1692: ("warning", decode_warning_word),
    1693: ("warning", decode_warning_word_2),
}


def _key(pnu: int) -> ParameterKey:
    return ParameterKey(format_parameter(pnu), pnu)


ALARM_WORD: Final = _key(1690)
WARNING_WORD: Final = _key(1692)
DEFAULT_MONITOR: Final = tuple(_key(p) for p in (1613, 1614, 1612, 1610, 1630, 1690, 1692))


def decode_status(word: int, output: float) -> DriveStatus:
    """The vendor-neutral reading of an FC status word (§8.4).

    The status word has no direction bit; the sign of the main actual value (``output``,
    in any unit) tells it while the motor turns.
    """
    return DriveStatus(
        word=word,
        running=bool(word & _RUNNING),
        fault=bool(word & _FAULT_BITS),
        warning=bool(word & _WARNING),
        at_reference=bool(word & _AT_REFERENCE),
        reverse=None if output == 0 else output < 0,
        accepts_bus_control=bool(word & _BUS_CONTROL),
    )


class FcCodec:
    """Danfoss FC exchanges for one bus (one address format)."""

    protocol = "danfoss-fc"
    can_broadcast = True  # ADR 0x80 / 0x20, obeyed and never answered (§5.2)

    def __init__(
        self,
        address_format: AddressFormat = AddressFormat.FORMAT_126,
        *,
        nominal_hz: dict[int, float] | None = None,
    ) -> None:
        """Set up for a line of ``address_format``.

        ``nominal_hz``: per address, the frequency that 100 % means (default 50). The
        main actual value is a percentage of it; replies carry it in Hz.
        """
        self.address_format = address_format
        # Hz per step of the main actual value, worked out once per drive, so a reply pays
        # one multiplication (exact for a whole-Hz nominal: the step is a power of two).
        nominal_hz = nominal_hz or {}
        self._hz_per_step = {a: pct_to_hz(_PCT_PER_STEP, hz) for a, hz in nominal_hz.items()}
        self.addresses = range(1, 127 if address_format is AddressFormat.FORMAT_126 else 32)
        self._polls = PollCache(self._build_poll)

    def new_framer(self) -> FcFramer:
        """A framer for FC replies."""
        return FcFramer()

    def min_pause_s(self, char_s: float) -> float:
        """Two character times (the VLT 8000 floor, §11)."""
        return 2 * char_s

    def parameter(self, text: str) -> ParameterKey:
        """``"16-13"`` → its key; UsageError if it is not written like that."""
        return _key(parse_parameter(text))

    def default_monitor(self) -> tuple[ParameterKey, ...]:
        """Frequency, current, voltage, power, DC link, alarm word, warning word."""
        return DEFAULT_MONITOR

    def poll_sequence(self, monitor: tuple[ParameterKey, ...]) -> tuple[ParameterKey | None, ...]:
        """Each poll reads the next monitored parameter; status rides in every reply."""
        return monitor or (None,)

    def condition_parameters(self, *, alarms: bool, warnings: bool) -> tuple[ParameterKey, ...]:
        """16-90 when the trip bits changed, 16-92 when the warning bit did."""
        return (ALARM_WORD,) * alarms + (WARNING_WORD,) * warnings

    def poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        """A process telegram, or a parameter telegram reading ``read`` (built once)."""
        return self._polls.get(address, intent, read)

    def _build_poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        if read is None:
            return self.control(address, intent)[0]
        return self._read(address, read, 0, intent)

    def control(self, address: int, intent: ControlIntent | None) -> tuple[Exchange, ...]:
        """One process telegram with the control word and reference of ``intent``."""
        ctw, ref = _pcd(intent)
        telegram = Telegram(address=address, address_format=self.address_format, pcd1=ctw, pcd2=ref)
        return (
            Exchange(
                address=address,
                request=encode_telegram(telegram),
                reply_length=0 if address == 0 else PROCESS_LENGTH,
                carries_control=intent is not None,
            ),
        )

    def read(
        self, address: int, parameter: ParameterKey, index: int, intent: ControlIntent | None
    ) -> tuple[Exchange, ...]:
        """AK 1 (or AK F for a text parameter) with the given IND: one telegram."""
        return (self._read(address, parameter, index, intent),)

    def _read(
        self, address: int, parameter: ParameterKey, index: int, intent: ControlIntent | None
    ) -> Exchange:
        # The one read telegram, also what an idle poll sends (no tuple on the hot path).
        spec = lookup(parameter.code)
        _check_index(spec, index)
        if spec.is_text:
            ak, ind, reply_length = RequestAk.TEXT, IND_TEXT_READ | index, _TEXT_REPLY_LENGTH
        else:
            ak, ind, reply_length = RequestAk.READ, index, PARAMETER_LENGTH
        return self._parameter(address, ak, parameter, ind, 0, intent, Access.READ, reply_length)

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
        """AK 2/3 (RAM) or E/D (RAM + EEPROM), by the parameter's width: one telegram."""
        spec = lookup(parameter.code)
        _check_index(spec, index)
        if spec.is_text or isinstance(value, str):
            raise UsageError(f"{parameter.name}: only numeric values can be written")
        if not -_INFINITY < value < _INFINITY:  # NaN too; round() would raise ValueError
            raise UsageError(f"{parameter.name}: {value} is not a number that can be written")
        try:
            raw = spec.to_raw(value)
        except OverflowError:  # finite, but infinite once scaled (1e306 s in 0.01 s steps)
            raise UsageError(f"{parameter.name}: {value:g} is far outside its range") from None
        pwe = spec.pwe_from_raw(raw)
        ak = spec.write_ak(raw, eeprom=persist)
        return (
            self._parameter(
                address, ak, parameter, index, pwe, intent, Access.WRITE, PARAMETER_LENGTH
            ),
        )

    def parse(self, exchange: Exchange, frame: bytes) -> Reply:
        """Check that ``frame`` answers ``exchange`` and read it."""
        if len(frame) < 3 or frame[2] != exchange.request[2]:
            raise UnexpectedReply("reply from another address", raw=frame)
        telegram = decode_telegram(frame, from_drive=True)
        mav = telegram.pcd2  # two's complement, 0x4000 = 100 % of nominal (§8.5)
        output_hz = (mav - 0x10000 if mav & 0x8000 else mav) * self._hz_per_step.get(
            exchange.address, _DEFAULT_HZ_PER_STEP
        )
        status = decode_status(telegram.pcd1, output_hz)
        if exchange.access is Access.NONE:
            if telegram.pke is not None:
                raise UnexpectedReply("parameter reply to a process telegram", raw=frame)
            return Reply(
                address=exchange.address,
                status=status,
                output_frequency_hz=output_hz,
                output_signed=True,
            )
        if telegram.pke is None or exchange.parameter is None:
            raise UnexpectedReply("process reply to a parameter telegram", raw=frame)
        ak = telegram.ak
        if ak == ResponseAk.ERROR:
            code = telegram.pwe & 0xFFFF
            return Reply(
                address=exchange.address,
                status=status,
                output_frequency_hz=output_hz,
                output_signed=True,
                error=DriveError(code, error_text(code)),
            )
        if telegram.pnu != exchange.parameter.code:
            raise UnexpectedReply(
                f"reply for parameter {format_parameter(telegram.pnu)}, "
                f"asked for {exchange.parameter.name}",
                raw=frame,
            )
        value = _value(exchange, telegram, ak, frame)
        conditions = None
        if value.raw is not None and telegram.pnu in _CONDITION_WORDS:
            kind, decode = _CONDITION_WORDS[telegram.pnu]
            active = tuple(Condition(code, text) for code, text in decode(value.raw))
            conditions = ConditionReport(kind=kind, source=value.parameter.name, active=active)
        return Reply(
            address=exchange.address,
            status=status,
            output_frequency_hz=output_hz,
            output_signed=True,
            value=value,
            conditions=conditions,
        )

    def _parameter(
        self,
        address: int,
        ak: RequestAk,
        parameter: ParameterKey,
        ind: int,
        pwe: int,
        intent: ControlIntent | None,
        access: Access,
        reply_length: int,
    ) -> Exchange:
        ctw, ref = _pcd(intent)
        telegram = Telegram(
            address=address,
            address_format=self.address_format,
            pcd1=ctw,
            pcd2=ref,
            pke=make_pke(ak, parameter.code),
            ind=ind,
            pwe=pwe,
        )
        return Exchange(
            address=address,
            request=encode_telegram(telegram),
            reply_length=0 if address == 0 else reply_length,
            access=access,
            parameter=parameter,
            index=ind & 0xFF,
            carries_control=intent is not None,
        )


def _pcd(intent: ControlIntent | None) -> tuple[int, int]:
    if intent is None:
        return IGNORED_CONTROL_WORD, 0
    return control_word(intent), encode_reference(intent.reference_pct)


def _check_index(spec: ParameterSpec, index: int) -> None:
    if not 0 <= index <= 0xFF:
        raise UsageError(f"index {index} is outside 0-255")
    if index and spec.data_type is not None and not spec.array_length and not spec.is_text:
        raise UsageError(f"{spec.number} is not an array; leave the index out")


def _value(exchange: Exchange, telegram: Telegram, ak: int, frame: bytes) -> ParameterValue:
    assert exchange.parameter is not None  # checked by the caller
    spec = lookup(telegram.pnu)
    if telegram.text is not None:
        return ParameterValue(
            parameter=exchange.parameter,
            index=exchange.index,
            raw=None,
            value=telegram.text.decode("latin-1").rstrip("\x00 "),
            unit="",
            title=spec.name,
        )
    if ak not in (ResponseAk.VALUE_WORD, ResponseAk.VALUE_DWORD) or spec.data_type is DataType.TEXT:
        raise MalformedReply(f"AK {ak} does not carry a value", raw=frame)
    raw = spec.raw_from_pwe(telegram.pwe, double_word=ak == ResponseAk.VALUE_DWORD)
    return ParameterValue(
        parameter=exchange.parameter,
        index=exchange.index,
        raw=raw,
        value=spec.to_value(raw),
        unit=spec.unit,
        title=spec.name,
    )
