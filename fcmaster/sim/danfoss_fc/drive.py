"""A simulated Danfoss FC drive: answers telegrams per protocols/danfoss-fc.md.

The drive hears every checked request on its line (the :class:`~fcmaster.sim.line.SimDrive`
seam). It answers only telegrams addressed to it, in either address format, copying the
ADR byte; a broadcast is obeyed and never answered. Every telegram's PCD1/PCD2 go to the
control logic (:mod:`fcmaster.sim.danfoss_fc.control`), then the parameter channel is
served, and the reply carries the status word and main actual value of the state after
both — the immediate reply shows the status before a command has taken full effect (§12.6).

Parameter access (§6): a read answers AK 1, or AK 2 for 32-bit types; a write answers
with the value written. Refusals answer AK 7 with the error code in PWElow and the PNU
echoed: 0 unknown parameter, 1 read-only, 2 out of range, 3 no such array index, 4 not an
array, 5 a word write to a 32-bit parameter, 15 text access to a value parameter, 17 motor
data changed while running, 253 request not supported (AK 4 and undefined AKs). Array
index 0 is the first entry (§6.4 leaves this open).
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import ProtocolError
from fcmaster.protocol.danfoss_fc.error_codes import (
    BAD_INDEX,
    ILLEGAL_PARAMETER,
    NO_TEXT,
    NOT_AN_ARRAY,
    NOT_WHILE_RUNNING,
    READ_ONLY,
    REQUEST_NOT_SUPPORTED,
    WRONG_DATA_TYPE,
)
from fcmaster.protocol.danfoss_fc.parameters import PARAMETERS, DataType, ParameterSpec
from fcmaster.protocol.danfoss_fc.profile import encode_reference
from fcmaster.protocol.danfoss_fc.telegram import (
    IND_TEXT_WRITE,
    RequestAk,
    ResponseAk,
    Telegram,
    decode_telegram,
    encode_telegram,
    make_pke,
)
from fcmaster.sim.danfoss_fc.control import FcControl
from fcmaster.sim.danfoss_fc.parameters import (
    BAUD_OPTIONS,
    MOTOR_SPECS,
    PARITY_OPTIONS,
    SETTINGS,
    ParameterStore,
    Refused,
    overrides_from_values,
)
from fcmaster.sim.danfoss_fc.readings import READINGS, identification_texts
from fcmaster.sim.motor import Motor, MotorRating
from fcmaster.sim.settings import DriveSettings, LineSettings

_WRITES: Final = {
    RequestAk.WRITE_WORD: False,
    RequestAk.WRITE_DWORD: True,
    RequestAk.WRITE_WORD_EEPROM: False,
    RequestAk.WRITE_DWORD_EEPROM: True,
}
_MOTOR_DATA: Final = frozenset(MOTOR_SPECS)
_BOUNDS: Final[dict[DataType | None, tuple[int, int]]] = {
    DataType.INT16: (-0x8000, 0x7FFF),
    DataType.N2: (-0x8000, 0x7FFF),
    DataType.INT32: (-0x8000_0000, 0x7FFF_FFFF),
    DataType.UINT8: (0, 0xFF),
    DataType.UINT16: (0, 0xFFFF),
    DataType.V2: (0, 0xFFFF),
    DataType.UINT32: (0, 0xFFFF_FFFF),
}


_RUNNING_WORD: Final = 0x047C  # start, ramp 1, data valid (§8.3)


class FcSimDrive:
    """One simulated FC drive (a :class:`~fcmaster.sim.line.SimDrive`)."""

    # Declared here because readings.py, which this module imports, reads them.
    parameters: ParameterStore
    motor: Motor
    control: FcControl
    texts: dict[int, str]

    def __init__(
        self,
        address: int,
        settings: DriveSettings | None = None,
        *,
        now: float,
        line: LineSettings | None = None,
    ) -> None:
        """A drive powered up at ``now`` at ``address``.

        ``settings`` gives the motor, load, response delay and parameter values; ``line``
        the character format that 8-32/8-33 report.
        """
        settings = settings or DriveSettings()
        line = line or LineSettings()
        rating = settings.rating
        overrides = {
            831: address,
            120: round(rating.power_kw * 100),
            122: round(rating.voltage_v),
            123: round(rating.frequency_hz),
            124: round(rating.current_a * 100),
            125: round(rating.speed_rpm),
        }
        if line.baudrate in BAUD_OPTIONS:
            overrides[832] = BAUD_OPTIONS.index(line.baudrate)
        if (line.parity, line.stopbits) in PARITY_OPTIONS:
            overrides[833] = PARITY_OPTIONS[line.parity, line.stopbits]
        if settings.response_delay_s is not None:
            overrides[835] = round(settings.response_delay_s * 1000)
        if settings.reference_100_hz is not None:
            overrides[303] = round(settings.reference_100_hz * 1000)
        if settings.max_frequency_hz is not None:
            overrides[414] = round(settings.max_frequency_hz * 10)
        overrides.update(overrides_from_values(settings.parameters))
        self.parameters = ParameterStore(overrides)
        # A drive found running was started a while ago; let its motor reach speed since.
        started = settings.started_at(now)
        self.motor = settings.motor(started, self._rating(rating))
        self.control = FcControl(self.parameters, self.motor, started, local=settings.local)
        if settings.running_hz:
            reference = settings.running_hz / (self.parameters[303] / 1000.0) * 100.0
            self.control.apply(_RUNNING_WORD, encode_reference(reference), started)
            self.control.advance(now)
        self.texts = identification_texts(address, rating)
        self._settings = settings
        self._born = now

    @property
    def address(self) -> int:
        """8-31 Address."""
        return self.parameters[831]

    @property
    def response_delay_s(self) -> float:
        """8-35 Minimum Response Delay."""
        return self.parameters[835] / 1000.0

    def advance(self, now: float) -> None:
        """Bring ramps, counters and the control-word timeout up to ``now``."""
        self.control.advance(now)

    def handle(self, frame: bytes, now: float) -> bytes | None:
        """Act on a request that ended at ``now``; return the reply, or None."""
        if len(frame) < 3 or not self._is_for_me(frame[2]):
            return None  # cheap: most frames on a busy line are for another drive
        try:
            request = decode_telegram(frame, from_drive=False)
        except ProtocolError:
            return None
        if self._settings.warning_cycle is not None:
            self._cycle_warning(now)
        self.control.apply(request.pcd1, request.pcd2, now)
        pke, ind, pwe, text = self._parameter_channel(request, now)
        if request.is_broadcast:
            return None
        reply = Telegram(
            address=request.address, address_format=request.address_format,
            pcd1=self.control.status_word, pcd2=self.control.main_actual_value,
            pke=pke, ind=ind, pwe=pwe, text=text,
        )  # fmt: skip
        return encode_telegram(reply)

    def _cycle_warning(self, now: float) -> None:
        """A recurring warning: active for ``for_s`` at the start of every ``every_s``."""
        assert self._settings.warning_cycle is not None
        number = self._settings.warning_cycle[0]
        if self._settings.warning_showing(now - self._born):
            self.control.raise_warning(number, now)
        else:
            self.control.clear_warning(number, now)

    def read(self, pnu: int, index: int, now: float) -> int:
        """The raw value of ``pnu`` at ``now``; raise :class:`Refused` if there is none."""
        self.advance(now)
        spec = _spec(pnu)
        _check_index(spec, index)
        if spec.is_text:
            raise Refused(ILLEGAL_PARAMETER, "a text parameter has no value")
        if pnu in SETTINGS:
            return self.parameters[pnu]
        return _fit(spec, spec.to_raw(READINGS[pnu](self, index)))

    def write(self, pnu: int, index: int, raw: int, now: float) -> None:
        """Set ``pnu`` to ``raw`` at ``now``, as a bus write would; raise :class:`Refused`."""
        self.advance(now)
        spec = _spec(pnu)
        _check_index(spec, index)
        if pnu not in SETTINGS:
            raise Refused(READ_ONLY, f"{spec.number} is read-only")
        if pnu in _MOTOR_DATA and self.motor.output_on:
            raise Refused(NOT_WHILE_RUNNING, "motor data cannot change while running")
        self.parameters.set(pnu, raw)
        if pnu in _MOTOR_DATA:
            self.motor.set_rating(self._rating(self.motor.rating), now)
        self.control.refresh(now)

    # -- internals ------------------------------------------------------------------------

    def _is_for_me(self, adr: int) -> bool:
        if adr in (0x80, 0x20):
            return True
        address = self.address
        return adr == 0x80 | address or (address <= 31 and adr == address)

    def _parameter_channel(
        self, request: Telegram, now: float
    ) -> tuple[int | None, int, int, bytes | None]:
        """PKE, IND, PWE and text of the reply's parameter channel."""
        if request.pke is None:
            return None, 0, 0, None
        ak, pnu, ind = request.ak, request.pnu, request.ind
        try:
            if ak == RequestAk.NONE:
                return make_pke(ResponseAk.NONE, pnu), ind, 0, None
            if ak == RequestAk.READ:
                raw = self.read(pnu, ind & 0xFF, now)
                return self._value_reply(pnu, ind, raw)
            if ak in _WRITES:
                raw = _raw_written(_spec(pnu), request.pwe, double_word=_WRITES[RequestAk(ak)])
                self.write(pnu, ind & 0xFF, raw, now)
                return self._value_reply(pnu, ind, raw)
            if ak == RequestAk.TEXT:
                return make_pke(ResponseAk.TEXT, pnu), ind, 0, self._text(pnu, ind)
            raise Refused(REQUEST_NOT_SUPPORTED, f"AK {ak:X}")
        except Refused as refusal:
            return make_pke(ResponseAk.ERROR, pnu), ind, refusal.code, None

    def _value_reply(self, pnu: int, ind: int, raw: int) -> tuple[int, int, int, None]:
        spec = _spec(pnu)
        ak = ResponseAk.VALUE_DWORD if spec.is_double_word else ResponseAk.VALUE_WORD
        return make_pke(ak, pnu), ind, spec.pwe_from_raw(raw), None

    def _text(self, pnu: int, ind: int) -> bytes:
        if not _spec(pnu).is_text:
            raise Refused(NO_TEXT, "not a text parameter")
        if ind & 0xFF00 == IND_TEXT_WRITE:
            raise Refused(READ_ONLY, "identification texts are read-only")
        return self.texts[pnu].encode("latin-1")

    def _rating(self, base: MotorRating) -> MotorRating:
        p = self.parameters
        return MotorRating(
            power_kw=p.value(120), voltage_v=p.value(122), frequency_hz=p.value(123),
            current_a=p.value(124), speed_rpm=p.value(125),
            mains_v=base.mains_v, ambient_c=base.ambient_c,
        )  # fmt: skip


def _spec(pnu: int) -> ParameterSpec:
    spec = MOTOR_SPECS.get(pnu) or PARAMETERS.get(pnu)
    if spec is None or (pnu not in SETTINGS and pnu not in READINGS and not spec.is_text):
        raise Refused(ILLEGAL_PARAMETER, f"no parameter {pnu}")
    return spec


def _check_index(spec: ParameterSpec, index: int) -> None:
    if spec.array_length:
        if index >= spec.array_length:
            raise Refused(BAD_INDEX, f"{spec.number} has {spec.array_length} entries")
    elif index:
        raise Refused(NOT_AN_ARRAY, f"{spec.number} is not an array")


def _raw_written(spec: ParameterSpec, pwe: int, *, double_word: bool) -> int:
    """The raw value a write carries; a word write cannot carry a 32-bit parameter."""
    if spec.is_double_word and not double_word:
        raise Refused(WRONG_DATA_TYPE, f"{spec.number} is 32 bits wide")
    if double_word and not spec.is_double_word:
        # All 32 bits count: a value beyond the parameter's width is out of range, not cut.
        return pwe - (1 << 32) if pwe >> 31 else pwe
    return spec.raw_from_pwe(pwe, double_word=double_word)


def _fit(spec: ParameterSpec, raw: int) -> int:
    """Clamp a reading into what its data type can carry (a counter past 65535, …)."""
    low, high = _BOUNDS.get(spec.data_type, (-(1 << 31), (1 << 32) - 1))
    return min(max(raw, low), high)
