"""Registers as parameters: how a user writes a register, and its :class:`ParameterKey`.

A register is written ``hr106`` (holding register, PDU address 106), ``ir3204`` (input
register), or a bare ``106`` (holding); ``x2`` after it reads two registers as one 32-bit
value, high word first (``hr16139x2``). The key's code packs the same facts: the address in
bits 0-15, bit 16 for an input register, bit 17 for two words.

Three keys stand for a profile's own registers rather than an address, because the line's
drives may follow different profiles: :data:`OUTPUT_FREQUENCY`, :data:`FAULT_CODE` and
:data:`CONTROL_FEED` (the steady control word written to keep the drive's watchdog fed).
"""

from __future__ import annotations

import re
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import ParameterKey
from fcmaster.protocol.modbus_rtu.profile import Register

_INPUT: Final = 1 << 16
_TWO_WORDS: Final = 1 << 17
_PROFILE: Final = 1 << 20  # the keys below: no address of their own

OUTPUT_FREQUENCY: Final = ParameterKey("output_frequency", _PROFILE | 1)
FAULT_CODE: Final = ParameterKey("fault_code", _PROFILE | 2)
CONTROL_FEED: Final = ParameterKey("control_word", _PROFILE | 3)
PROFILE_KEYS: Final = frozenset((OUTPUT_FREQUENCY, FAULT_CODE, CONTROL_FEED))

_TEXT: Final = re.compile(r"(?P<table>hr|ir)?(?P<address>\d{1,5})(?P<two>x2)?", re.IGNORECASE)


def register_key(register: Register) -> ParameterKey:
    """The key that reads ``register``."""
    table = "ir" if register.input else "hr"
    name = f"{table}{register.address}" + ("x2" if register.words == 2 else "")
    code = register.address | (_INPUT if register.input else 0)
    return ParameterKey(name, code | (_TWO_WORDS if register.words == 2 else 0))


def parse_register(text: str) -> ParameterKey:
    """``hr106``, ``ir3204``, ``106``, ``hr16139x2`` → its key; UsageError otherwise."""
    match = _TEXT.fullmatch(text.strip())
    address = int(match["address"]) if match else -1
    if match is None or address > 0xFFFF or (match["two"] and address == 0xFFFF):
        raise UsageError(
            f"{text!r} is not a register: write hr<address> (holding), ir<address> (input), "
            "a PDU address 0-65535, with x2 for a 32-bit value (hr16139x2)"
        )
    table = (match["table"] or "hr").lower()
    return register_key(
        Register(address=address, input=table == "ir", words=2 if match["two"] else 1)
    )


def key_register(key: ParameterKey) -> Register:
    """The register a key reads, unscaled (UsageError for a profile key)."""
    if key.code & _PROFILE:
        raise UsageError(f"{key.name} is the drive profile's, not a register")
    return Register(
        address=key.code & 0xFFFF,
        input=bool(key.code & _INPUT),
        words=2 if key.code & _TWO_WORDS else 1,
    )


def same_register(a: Register, b: Register) -> bool:
    """Whether two registers are the same place in the drive (their scaling aside)."""
    return (a.address, a.input, a.words) == (b.address, b.input, b.words)
