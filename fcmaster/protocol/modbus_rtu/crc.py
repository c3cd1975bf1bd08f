"""The CRC-16 of Modbus RTU frames (Modbus over Serial Line V1.02 §2.5.1.2 and Appendix B).

Polynomial 0xA001 (0x8005 reflected), register preset to 0xFFFF, no final XOR. The CRC goes
on the wire low byte first, the one field of a Modbus frame that is not big-endian. A frame
with its CRC appended checks to 0, which is how a received frame is judged.
"""

from __future__ import annotations

from typing import Final


def _table() -> tuple[int, ...]:
    # One step per byte instead of eight per bit: the framer checks every candidate it
    # considers while resynchronising, so this runs for every byte of noise too.
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_TABLE: Final = _table()


def crc16(data: bytes | bytearray | memoryview) -> int:
    """The Modbus CRC-16 of ``data`` as a number (sent as ``crc & 0xFF, crc >> 8``)."""
    crc = 0xFFFF
    table = _TABLE
    for byte in data:
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc


def with_crc(body: bytes) -> bytes:
    """``body`` with its CRC appended, low byte first."""
    crc = crc16(body)
    return body + bytes((crc & 0xFF, crc >> 8))


def crc_ok(frame: bytes | bytearray | memoryview) -> bool:
    """Whether ``frame``'s last two bytes are the CRC of the rest (a frame checks to 0)."""
    return len(frame) >= 3 and crc16(frame) == 0
