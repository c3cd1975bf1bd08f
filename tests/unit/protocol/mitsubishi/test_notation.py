"""Frames written with control-character names: ``<ENQ>01E1107ADF4<CR>``."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.mitsubishi import format_ascii_frame, parse_ascii_frame


@pytest.mark.parametrize(
    ("text", "wire"),
    [
        ("<ENQ>01E1107ADF4<CR>", b"\x0501E1107ADF4\r"),
        ("<enq>01E1107ADF4<cr><Lf>", b"\x0501E1107ADF4\r\n"),
        ("<STX>011770<ETX>30", b"\x02011770\x0330"),
        ("<ACK>01", b"\x0601"),
        ("<NAK>01A<CR>", b"\x1501A\r"),
        ("<STX>01FR-E720-0.4K        <ETX>", b"\x0201FR-E720-0.4K        \x03"),
        ("<0x1b>a<b", b"\x1ba<b"),  # an escape, and a lone "<" that opens no token
    ],
)
def test_names_become_control_characters(text: str, wire: bytes) -> None:
    assert parse_ascii_frame(text) == wire


@pytest.mark.parametrize("text", ["<EOT>01", "<ENQ>01\t", "<ENQ>é", ""])
def test_unknown_names_and_unprintable_characters_are_refused(text: str) -> None:
    with pytest.raises(UsageError):
        parse_ascii_frame(text)


def test_format_writes_the_names() -> None:
    assert format_ascii_frame(b"\x0501E1107ADF4\r\n") == "<ENQ>01E1107ADF4<CR><LF>"
    assert format_ascii_frame(b"<A>\x00") == "<0x3C>A><0x00>"


@given(st.binary(min_size=1, max_size=40))
def test_format_then_parse_gives_the_bytes_back(wire: bytes) -> None:
    assert parse_ascii_frame(format_ascii_frame(wire)) == wire
