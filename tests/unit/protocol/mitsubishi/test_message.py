"""Computer-link frames: golden frames worked out by hand, round trips, and refusals.

Every expected frame below is spelled out with its sum check added up in the comment
(protocols/mitsubishi.md §4: the low byte of the sum of the ASCII codes after ENQ/STX up
to the last data character). ASCII: "0"=30 "1"=31 "2"=32 "3"=33 "6"=36 "7"=37 "8"=38
"9"=39 "A"=41 "D"=44 "E"=45 "F"=46.
"""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.mitsubishi import (
    Ack,
    DataReply,
    Message,
    Nak,
    Request,
    Terminator,
    decode_frame,
    encode_frame,
    frame_length,
    split_terminator,
    sum_check,
    wait_digit,
)
from tests.unit.protocol.mitsubishi.strategies import ascii_sum, messages, terminators

GOLDEN: list[tuple[str, Message, Terminator, bytes]] = [
    (
        # §4 manual example 1: 30+31+45+31+31+30+37+41+44 = 0x1F4 -> "F4"
        "manual-request-E1-wait-10ms",
        Request(station=1, instruction=0xE1, data=0x07AD, width=4, wait_ms=10),
        Terminator.NONE,
        b"\x0501E1107ADF4",
    ),
    (
        # §4 manual example 2: 30+31+31+37+37+30 = 0x130 -> "30"
        "manual-reply-1770",
        DataReply(station=1, data=0x1770, width=4),
        Terminator.NONE,
        b"\x02011770\x0330",
    ),
    (
        # status read, station 1, wait "0": 30+31+37+41+30 = 0x109 -> "09"; CR
        "status-read-cr",
        Request(station=1, instruction=0x7A, wait_ms=0),
        Terminator.CR,
        b"\x05017A009\r",
    ),
    (
        # run forward, station 3: 30+33+46+41+30+30+32 = 0x17C -> "7C"
        "run-forward-station-3",
        Request(station=3, instruction=0xFA, data=0x02, width=2, wait_ms=0),
        Terminator.CR,
        b"\x0503FA0027C\r",
    ),
    (
        # 50.00 Hz = 5000 = 0x1388 to RAM: 30+33+45+44+30+31+33+38+38 = 0x1F0 -> "F0"
        "frequency-50hz-station-3",
        Request(station=3, instruction=0xED, data=0x1388, width=4, wait_ms=0),
        Terminator.CR,
        b"\x0503ED01388F0\r",
    ),
    (
        # reset without the waiting-time digit: 30+31+46+44+39+36+39+36 = 0x1C9 -> "C9"
        "reset-no-wait-crlf",
        Request(station=1, instruction=0xFD, data=0x9696, width=4),
        Terminator.CRLF,
        b"\x0501FD9696C9\r\n",
    ),
    (
        # station 10 is "0A", not "10": 30+41+37+41+30 = 0x119 -> "19"
        "station-10-is-0A",
        Request(station=10, instruction=0x7A, wait_ms=0),
        Terminator.NONE,
        b"\x050A7A019",
    ),
    (
        # status reply "02" (forward running): 30+31+30+32 = 0xC3 -> "C3"
        "status-reply-02",
        DataReply(station=1, data=0x02, width=2),
        Terminator.CR,
        b"\x020102\x03C3\r",
    ),
    (
        # 6-digit reply 0x0186A0: 30+31+30+31+38+36+41+30 = 0x1A1 -> "A1"
        "six-digit-reply",
        DataReply(station=1, data=0x0186A0, width=6),
        Terminator.CR,
        b"\x02010186A0\x03A1\r",
    ),
    ("ack-station-31", Ack(31), Terminator.CR, b"\x061F\r"),
    ("nak-mode-error", Nak(1, 0xA), Terminator.CRLF, b"\x1501A\r\n"),
    ("master-nak-no-code", Nak(2), Terminator.NONE, b"\x1502"),
]


@pytest.mark.parametrize(
    ("message", "terminator", "wire"),
    [case[1:] for case in GOLDEN],
    ids=[case[0] for case in GOLDEN],
)
def test_golden_frames_encode_and_decode(
    message: Message, terminator: Terminator, wire: bytes
) -> None:
    assert encode_frame(message, terminator) == wire
    assert decode_frame(wire) == message
    assert frame_length(message, terminator) == len(wire)
    assert split_terminator(wire)[1] is terminator


def test_model_name_reply_carries_text() -> None:
    text = "FR-E720-0.4K        "
    body = b"01" + text.encode()
    wire = b"\x02" + body + b"\x03" + ascii_sum(body).encode() + b"\r"
    reply = DataReply(station=1, data=None, width=20, text=text)
    assert encode_frame(reply) == wire
    assert decode_frame(wire) == reply


def test_sum_check_is_the_low_byte() -> None:
    assert sum_check(b"01E1107AD") == 0xF4
    assert sum_check(b"") == 0


@pytest.mark.parametrize(("wait_ms", "digit"), [(0, 0), (10, 1), (150, 15)])
def test_waiting_time_digit(wait_ms: int, digit: int) -> None:
    assert wait_digit(wait_ms) == digit


@pytest.mark.parametrize("wait_ms", [-10, 5, 160])
def test_waiting_time_outside_the_steps_is_refused(wait_ms: int) -> None:
    with pytest.raises(UsageError):
        wait_digit(wait_ms)


@given(messages, terminators)
def test_every_message_round_trips(message: Message, terminator: Terminator) -> None:
    wire = encode_frame(message, terminator)
    assert decode_frame(wire) == message
    assert len(wire) == frame_length(message, terminator)
    assert wire.endswith(terminator.suffix)


@given(messages, terminators)
def test_encoded_sum_matches_the_oracle(message: Message, terminator: Terminator) -> None:
    wire = split_terminator(encode_frame(message, terminator))[0]
    if isinstance(message, Request):
        assert wire[-2:].decode() == ascii_sum(wire[1:-2])
    elif isinstance(message, DataReply):
        assert wire[-3] == 0x03
        assert wire[-2:].decode() == ascii_sum(wire[1:-3])


@pytest.mark.parametrize(
    "request_",
    [
        Request(station=32, instruction=0x7A),
        Request(station=1, instruction=0xFA),  # a write code without data
        Request(station=1, instruction=0x7A, data=1, width=2),  # a read code with data
        Request(station=1, instruction=0xFA, data=0x100, width=2),  # too wide
        Request(station=1, instruction=0xFA, data=1, width=3),
        Request(station=1, instruction=0x100),
        Request(station=1, instruction=0x7A, wait_ms=5),
    ],
)
def test_impossible_requests_are_refused(request_: Request) -> None:
    with pytest.raises(UsageError):
        encode_frame(request_)


@pytest.mark.parametrize(
    "message",
    [
        DataReply(station=1, data=0x100, width=2),
        DataReply(station=1, data=1, width=8),
        DataReply(station=1, data=None, width=20, text="short"),
        Nak(1, 16),
        Ack(-1),
    ],
)
def test_impossible_replies_are_refused(message: Message) -> None:
    with pytest.raises(UsageError):
        encode_frame(message)


@pytest.mark.parametrize(
    "wire",
    [
        b"",
        b"\x0501e1107adf4",  # lowercase hex is a character error (§3)
        b"\x0501E1107ADF5",  # sum check off by one
        b"\x02011770\x0331",
        b"\x02011770\x03",  # no sum check
        b"\x0201177\x0330",  # 3 data digits
        b"\x0520E1107AD00",  # station H20
        b"\x06011",
        b"\x1501AB",
        b"\x41",
        b"\x0501E107ADF4",  # 8 characters after ENQ: no format has that many
    ],
)
def test_malformed_frames_are_refused(wire: bytes) -> None:
    with pytest.raises(MalformedReply):
        decode_frame(wire)


def test_wrong_sum_decodes_when_asked_not_to_check() -> None:
    assert decode_frame(b"\x02011770\x0331", check_sum=False) == DataReply(
        station=1, data=0x1770, width=4
    )


@given(st.binary(max_size=40))
def test_decode_raises_only_malformed_reply(data: bytes) -> None:
    with contextlib.suppress(MalformedReply):
        decode_frame(data)
