"""Error codes a drive returns in PWElow with AK 7 (protocols/danfoss-fc.md §6.6).

Older design guides print some of these in hexadecimal (11, 82, 83 for 17, 130, 131); the
value on the wire is the binary integer, which is what this table is keyed by.
"""

from __future__ import annotations

from typing import Final

ERROR_CODES: Final[dict[int, str]] = {
    0: "Illegal parameter number",
    1: "Parameter cannot be changed",
    2: "Upper or lower limit exceeded",
    3: "Sub-index corrupted or does not exist",
    4: "Parameter is not an array",
    5: "Wrong data type for this parameter",
    6: "Not used",
    7: "Not used",
    9: "Description element not available",
    11: "No parameter write access",
    15: "No text available",
    17: "Not possible while running or in the present mode",
    18: "Other error",
    23: "Parameter database busy",
    100: "Error 100",
    130: "No bus access for this parameter",
    131: "Write to factory set-up not possible",
    132: "No LCP access",
    252: "Unknown viewer",
    253: "Request not supported",
    254: "Unknown attribute",
    255: "No error",
}

ILLEGAL_PARAMETER: Final = 0
READ_ONLY: Final = 1
LIMIT_EXCEEDED: Final = 2
BAD_INDEX: Final = 3
NOT_AN_ARRAY: Final = 4
WRONG_DATA_TYPE: Final = 5
NO_TEXT: Final = 15
NOT_WHILE_RUNNING: Final = 17
REQUEST_NOT_SUPPORTED: Final = 253


def error_text(code: int) -> str:
    """Text of a drive error code; codes the manuals list without text get a generic one."""
    return ERROR_CODES.get(code, f"Drive error {code}")
