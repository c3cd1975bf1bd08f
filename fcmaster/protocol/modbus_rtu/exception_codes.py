"""Modbus exception codes and what each means (Modbus Application Protocol V1.1b3 §7).

A server that cannot carry out a request answers its function code with the high bit set
and one of these codes; the texts here are fcmaster's words for them.
"""

from __future__ import annotations

import enum
from typing import Final


class ExceptionCode(enum.IntEnum):
    """The exception codes of the Modbus specification."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SERVER_DEVICE_FAILURE = 0x04
    ACKNOWLEDGE = 0x05
    SERVER_DEVICE_BUSY = 0x06
    MEMORY_PARITY_ERROR = 0x08
    GATEWAY_PATH_UNAVAILABLE = 0x0A
    GATEWAY_TARGET_FAILED = 0x0B


EXCEPTION_TEXTS: Final[dict[int, str]] = {
    ExceptionCode.ILLEGAL_FUNCTION: "Illegal function: the drive does not offer this function",
    ExceptionCode.ILLEGAL_DATA_ADDRESS: "Illegal data address: no such register in the drive",
    ExceptionCode.ILLEGAL_DATA_VALUE: "Illegal data value: the drive does not accept the value",
    ExceptionCode.SERVER_DEVICE_FAILURE: "Device failure: the drive could not carry it out",
    ExceptionCode.ACKNOWLEDGE: "Acknowledge: accepted, the drive needs longer to finish it",
    ExceptionCode.SERVER_DEVICE_BUSY: "Device busy: the drive is busy, try again later",
    ExceptionCode.MEMORY_PARITY_ERROR: "Memory parity error in the drive",
    ExceptionCode.GATEWAY_PATH_UNAVAILABLE: "Gateway path unavailable",
    ExceptionCode.GATEWAY_TARGET_FAILED: "Gateway target device failed to respond",
}


def exception_text(code: int) -> str:
    """The text of exception ``code``; unknown codes are named by their number."""
    return EXCEPTION_TEXTS.get(code, f"Exception code {code} (not in the Modbus specification)")
