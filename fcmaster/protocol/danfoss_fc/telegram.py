"""FC telegrams: the bytes on the wire and back (protocols/danfoss-fc.md §5-§6).

::

    STX | LGE | ADR | PKE IND PWEhigh PWElow | PCD1 PCD2 | BCC
     02   06/0E/10+n      (parameter channel)   (process data)

* LGE counts ADR through BCC, so a telegram is LGE + 2 bytes long (§5.1).
* BCC is the XOR of every byte from STX through the last data byte (§5.3).
* All words are big-endian (§5.4).
* The same layout travels both ways; only the meaning of AK and of PCD1/PCD2 differs
  (master → drive: command AK, control word, reference; drive → master: response AK,
  status word, main actual value).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from fcmaster.errors import MalformedReply, UsageError

STX = 0x02
LGE_PROCESS = 6  # ADR + PCD1 + PCD2 + BCC
LGE_PARAMETER = 14  # ADR + PKE + IND + PWE + PCD1 + PCD2 + BCC
LGE_TEXT_BASE = 10  # ADR + PKE + IND + PCD1 + PCD2 + BCC, plus n text bytes
MAX_LGE = 0xFF

PROCESS_LENGTH = LGE_PROCESS + 2
PARAMETER_LENGTH = LGE_PARAMETER + 2

IND_TEXT_READ = 0x0400  # IND high byte for AK F (§6.4)
IND_TEXT_WRITE = 0x0500

_PROCESS = struct.Struct(">BBBHHB")
_PARAMETER = struct.Struct(">BBBHHIHHB")


class AddressFormat(enum.IntEnum):
    """The two ADR encodings (§5.2)."""

    FORMAT_31 = 31  # bit 7 = 0; bits 0-4 address; bit 5 = broadcast
    FORMAT_126 = 126  # bit 7 = 1; bits 0-6 address; 0 = broadcast


class RequestAk(enum.IntEnum):
    """AK of a master → drive telegram (§6.2)."""

    NONE = 0x0
    READ = 0x1
    WRITE_WORD = 0x2
    WRITE_DWORD = 0x3
    READ_DESCRIPTION = 0x4  # legacy, optional
    WRITE_DWORD_EEPROM = 0xD
    WRITE_WORD_EEPROM = 0xE
    TEXT = 0xF


class ResponseAk(enum.IntEnum):
    """AK of a drive → master telegram (§6.3)."""

    NONE = 0x0
    VALUE_WORD = 0x1
    VALUE_DWORD = 0x2
    DESCRIPTION = 0x3  # legacy, answer to READ_DESCRIPTION
    ERROR = 0x7
    TEXT = 0xF


def bcc(data: bytes | bytearray | memoryview) -> int:
    """Return the XOR of all bytes given (STX through the last data byte)."""
    value = 0
    for byte in data:
        value ^= byte
    return value


def encode_address(address: int, address_format: AddressFormat = AddressFormat.FORMAT_126) -> int:
    """Return the ADR byte for ``address`` (0 = broadcast) in the given format."""
    if address_format is AddressFormat.FORMAT_126:
        if not 0 <= address <= 126:
            raise UsageError(f"address {address} is outside 1-126 (0 = broadcast)")
        return 0x80 | address
    if not 0 <= address <= 31:
        raise UsageError(f"address {address} is outside 1-31 (0 = broadcast) in the 31 format")
    return 0x20 if address == 0 else address


def decode_address(adr: int) -> tuple[int, AddressFormat]:
    """Return ``(address, format)`` of an ADR byte; address 0 means broadcast."""
    if adr & 0x80:
        address = adr & 0x7F
        if address == 127:
            raise MalformedReply(f"ADR 0x{adr:02X}: address 127 does not exist")
        return address, AddressFormat.FORMAT_126
    if adr & 0x40:
        raise MalformedReply(f"ADR 0x{adr:02X}: bit 6 is set in the 31 format")
    if adr & 0x20:
        return 0, AddressFormat.FORMAT_31
    if adr == 0:
        raise MalformedReply("ADR 0x00: address 0 without the broadcast bit")
    return adr, AddressFormat.FORMAT_31


@dataclass(slots=True, frozen=True, kw_only=True)
class Telegram:
    """One FC telegram in either direction.

    ``pke`` is None for a process block. ``text`` is set for a text block, whose text
    bytes take the place of PWE. ``pwe`` is the 32-bit PWEhigh:PWElow as an unsigned
    integer; its meaning follows the parameter's data type (see ``parameters``).
    """

    address: int
    address_format: AddressFormat = AddressFormat.FORMAT_126
    pcd1: int = 0
    pcd2: int = 0
    pke: int | None = None
    ind: int = 0
    pwe: int = 0
    text: bytes | None = None

    @property
    def ak(self) -> int:
        """AK, the top four bits of PKE (0 for a process block)."""
        return 0 if self.pke is None else self.pke >> 12

    @property
    def pnu(self) -> int:
        """PNU, the low twelve bits of PKE (0 for a process block)."""
        return 0 if self.pke is None else self.pke & 0x0FFF

    @property
    def is_broadcast(self) -> bool:
        """Whether the telegram is addressed to every drive."""
        return self.address == 0

    @property
    def wire_length(self) -> int:
        """Bytes this telegram takes on the wire."""
        if self.pke is None:
            return PROCESS_LENGTH
        if self.text is not None:
            return LGE_TEXT_BASE + len(self.text) + 2
        return PARAMETER_LENGTH


def make_pke(ak: int, pnu: int) -> int:
    """Combine AK (4 bits) and PNU (12 bits) into PKE (§6.1)."""
    if not 0 <= ak <= 0xF:
        raise UsageError(f"AK {ak} does not fit in 4 bits")
    if not 0 <= pnu <= 0xFFF:
        raise UsageError(f"parameter number {pnu} does not fit in 12 bits (0-4095)")
    return (ak << 12) | pnu


def encode_telegram(telegram: Telegram) -> bytes:
    """Return the bytes of ``telegram`` on the wire, BCC included."""
    adr = encode_address(telegram.address, telegram.address_format)
    _check_word("PCD1", telegram.pcd1)
    _check_word("PCD2", telegram.pcd2)
    if telegram.pke is None:
        body = _PROCESS.pack(STX, LGE_PROCESS, adr, telegram.pcd1, telegram.pcd2, 0)
    else:
        _check_word("PKE", telegram.pke)
        _check_word("IND", telegram.ind)
        if telegram.text is None:
            if not 0 <= telegram.pwe <= 0xFFFF_FFFF:
                raise UsageError(f"PWE {telegram.pwe} does not fit in 32 bits")
            body = _PARAMETER.pack(
                STX, LGE_PARAMETER, adr, telegram.pke, telegram.ind, telegram.pwe,
                telegram.pcd1, telegram.pcd2, 0,
            )  # fmt: skip
        else:
            lge = LGE_TEXT_BASE + len(telegram.text)
            if lge > MAX_LGE:
                raise UsageError(f"text of {len(telegram.text)} bytes is longer than 245")
            body = (
                struct.pack(">BBBHH", STX, lge, adr, telegram.pke, telegram.ind)
                + telegram.text
                + struct.pack(">HHB", telegram.pcd1, telegram.pcd2, 0)
            )
    return body[:-1] + bytes((bcc(body[:-1]),))


def decode_telegram(frame: bytes, *, from_drive: bool) -> Telegram:
    """Decode a whole frame into a :class:`Telegram`; raise MalformedReply if it is not one.

    ``from_drive`` settles the one ambiguity of the format: a text block of four characters
    has the same length as a parameter block. A drive's AK F reply is always text; a
    master's AK F request is text only when it writes one (IND high byte 0x05).
    """
    length = len(frame)
    if length < PROCESS_LENGTH or frame[0] != STX:
        raise MalformedReply("not an FC telegram: no STX or too short", raw=frame)
    lge = frame[1]
    if lge + 2 != length:
        raise MalformedReply(f"LGE {lge} does not match {length} bytes", raw=frame)
    if bcc(frame) != 0:
        raise MalformedReply("BCC does not match", raw=frame)
    try:
        address, address_format = decode_address(frame[2])
    except MalformedReply as exc:  # keep the frame for the caller's logs, like every error here
        raise MalformedReply(str(exc), raw=frame) from None
    if lge == LGE_PROCESS:
        _, _, _, pcd1, pcd2, _ = _PROCESS.unpack(frame)
        return Telegram(address=address, address_format=address_format, pcd1=pcd1, pcd2=pcd2)
    if lge < LGE_TEXT_BASE:
        raise MalformedReply(f"LGE {lge} is neither 6, 14 nor 10 + text length", raw=frame)
    pke, ind = struct.unpack_from(">HH", frame, 3)
    pcd1, pcd2 = struct.unpack_from(">HH", frame, length - 5)
    is_text = pke >> 12 == 0xF and (from_drive or ind & 0xFF00 == IND_TEXT_WRITE)
    if lge == LGE_PARAMETER and not is_text:
        (pwe,) = struct.unpack_from(">I", frame, 7)
        return Telegram(
            address=address, address_format=address_format, pcd1=pcd1, pcd2=pcd2,
            pke=pke, ind=ind, pwe=pwe,
        )  # fmt: skip
    if pke >> 12 != 0xF:
        raise MalformedReply(f"LGE {lge} is a text block, but AK is not F", raw=frame)
    return Telegram(
        address=address, address_format=address_format, pcd1=pcd1, pcd2=pcd2,
        pke=pke, ind=ind, text=bytes(frame[7 : length - 5]),
    )  # fmt: skip


def _check_word(name: str, value: int) -> None:
    if not 0 <= value <= 0xFFFF:
        raise UsageError(f"{name} {value} does not fit in 16 bits")
