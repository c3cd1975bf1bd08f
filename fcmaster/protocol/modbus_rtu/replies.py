"""What a Modbus drive's answer to a read says, through its profile (the codec's reply side).

A read answers registers from a start address; which of them are the drive's status word,
output frequency, fault register or a monitored value, and in what scaling, is its
profile's. A drive without a profile gives values only, unscaled.
"""

from __future__ import annotations

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import (
    Condition,
    ConditionReport,
    DriveStatus,
    Exchange,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import pct_to_hz
from fcmaster.protocol.modbus_rtu.frame import Function, ReadRequest
from fcmaster.protocol.modbus_rtu.keys import (
    FAULT_CODE,
    OUTPUT_FREQUENCY,
    PROFILE_KEYS,
    key_register,
    same_register,
)
from fcmaster.protocol.modbus_rtu.profile import DriveProfile, Register


def read_reply(
    exchange: Exchange,
    request: ReadRequest,
    values: tuple[int, ...],
    profile: DriveProfile | None,
    nominal_hz: float,
) -> Reply:
    """The reply of a drive with ``profile`` whose registers from ``request`` are ``values``."""
    key = exchange.parameter
    wanted = key is not None and key not in PROFILE_KEYS
    if profile is None:
        value = value_of(None, key, values) if wanted and key is not None else None
        return Reply(address=exchange.address, value=value)
    words = dict(enumerate(values, request.start))
    table_input = request.function is Function.READ_INPUT

    def held(register: Register) -> tuple[int, ...] | None:
        span = range(register.address, register.address + register.words)
        if register.input != table_input or not all(a in words for a in span):
            return None
        return tuple(words[a] for a in span)

    status = frequency = conditions = value = None
    if (word := held(profile.status)) is not None and key is None:
        status = status_of(profile, word[0])
        conditions = STATUS_READ  # it takes its profile's status read: no warning of it
    freq_words = held(profile.output_frequency)
    if freq_words is not None and key in (None, OUTPUT_FREQUENCY):
        frequency = hz_of(profile.output_frequency, freq_words, nominal_hz)
    if key is FAULT_CODE and profile.fault_code is not None:
        raw = held(profile.fault_code)
        if raw is not None:
            code = round(profile.fault_code.value(raw) / profile.fault_code.scale)
            active = tuple(Condition(c, t) for c, t in profile.fault_texts(code))
            conditions = ConditionReport(kind="alarm", source="fault_code", active=active)
    elif wanted and key is not None:
        value = value_of(profile, key, values)
    return Reply(
        address=exchange.address,
        status=status,
        output_frequency_hz=frequency,
        output_signed=profile.output_frequency.signed,
        conditions=conditions,
        value=value,
    )


# A drive that refuses its profile's status read is of another family than its profile says
# (or set up otherwise): its state cannot be read, which it shows as a warning of its own.
STATUS_SOURCE = "status read"
STATUS_READ = ConditionReport(kind="warning", source=STATUS_SOURCE, active=())


def status_refused(profile: DriveProfile, code: int, text: str) -> ConditionReport:
    """The warning of a drive that refused its profile's status read with ``code``."""
    said = f"refuses the status read of profile {profile.name} ({text}): is it that profile's?"
    return ConditionReport(kind="warning", source=STATUS_SOURCE, active=(Condition(code, said),))


def status_of(profile: DriveProfile, word: int) -> DriveStatus:
    """The status word in vendor-neutral terms, by the profile's bits."""
    remote = profile.bit(word, "remote")
    return DriveStatus(
        word=word,
        running=bool(profile.bit(word, "running")),
        fault=bool(profile.bit(word, "fault")),
        warning=bool(profile.bit(word, "warning")),
        at_reference=bool(profile.bit(word, "at_reference")),
        reverse=profile.bit(word, "reverse"),
        accepts_bus_control=True if remote is None else remote,
    )


def hz_of(register: Register, words: tuple[int, ...], nominal_hz: float) -> float:
    """A frequency register's value in Hz (a share of ``nominal_hz`` where it is in %)."""
    value = register.value(words)
    return pct_to_hz(value, nominal_hz) if register.unit == "%" else value


def _title(profile: DriveProfile | None, register: Register) -> str:
    """The name the profile gives ``register`` ("" where it lists it nowhere)."""
    listed = (*profile.values, *profile.parameters) if profile is not None else ()
    return next((v.name for v in listed if same_register(v.register, register)), "")


def title_of(profile: DriveProfile | None, key: ParameterKey) -> str:
    """The name the profile gives the register ``key`` names ("" for none, or no register)."""
    try:
        return _title(profile, scaled(profile, key_register(key)))
    except UsageError:  # a profile's own key (output frequency, fault)
        return ""


def value_of(
    profile: DriveProfile | None, key: ParameterKey, words: tuple[int, ...]
) -> ParameterValue:
    """The value of the register ``key`` names, in the profile's scaling and by its name."""
    register = scaled(profile, key_register(key))
    title = _title(profile, register)
    raw = 0
    for word in words:
        raw = raw << 16 | word
    return ParameterValue(
        parameter=key,
        index=0,
        raw=raw,
        value=register.value(words),
        unit=register.unit,
        title=title,
    )


def scaled(profile: DriveProfile | None, register: Register) -> Register:
    """``register`` with the scaling the profile gives it, if the profile lists it."""
    if profile is None:
        return register
    listed = [v.register for v in (*profile.values, *profile.parameters)]
    listed += profile.watchdog.registers
    listed += [profile.reference, profile.output_frequency]
    return next((r for r in listed if same_register(r, register)), register)
