"""Request data widths by instruction code (§6, §9), the rule framer, receiver and drive share."""

from __future__ import annotations

import pytest

from fcmaster.protocol.mitsubishi.instructions import request_widths

_TWO_DIGIT_WRITES = (0xEC, 0xF3, 0xFA, 0xFF)  # A1: HEC, HF3, HFA, HFF
_MULTI_COMMAND = 0xF0


@pytest.mark.parametrize("code", range(0x100))
def test_request_widths_follow_the_manual(code: int) -> None:
    if code < 0x80:
        expected: tuple[int, ...] = (0,)  # a read carries no data
    elif code == _MULTI_COMMAND:
        expected = (10,)
    elif code in _TWO_DIGIT_WRITES:
        expected = (2,)
    else:
        expected = (4, 6)  # A or A2, told apart by the sum check
    assert request_widths(code) == expected
