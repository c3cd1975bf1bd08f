"""ENC frames: golden vectors from protocols/enc.md, round trips, and what is refused.

Every golden checksum below is the sum of the ASCII codes between ``~`` and the checksum
(§3.1), added up by hand in the comment beside it ("0"=30, "1"=31, …, "9"=39, "A"=41 …
"F"=46, all hex).
"""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.enc import (
    Command,
    Request,
    Response,
    RunControl,
    checksum,
    decode_request,
    decode_response,
    encode_request,
    encode_response,
)
from tests.unit.protocol.enc.strategies import (
    ascii_sum,
    checked_frames,
    close,
    requests,
    responses,
)

RC = Command.RUN_CONTROL

GOLDEN_REQUESTS = [
    # §3.1: 30+31+30+41+30+30+30+30 = 192
    pytest.param(Request(address=1, command=Command.LOOK_UP_STATE), b"~010A00000192\r", id="10"),
    # §8: 30+31+30+42 = D3, +30+30+30 = 163, +46 = 1A9
    pytest.param(
        Request(address=1, command=Command.READ_VALUE, cmd_index=0x0F),
        b"~010B000F01A9\r",
        id="11-000F",
    ),
    # §4.1: 163 + 31 = 194
    pytest.param(
        Request(address=1, command=Command.READ_VALUE, cmd_index=0x01),
        b"~010B00010194\r",
        id="11-0001",
    ),
    # §3.1: 30+31+30+43+30+30+30+35+30+46+41+30 = 280
    pytest.param(
        Request(address=1, command=RC, cmd_index=RunControl.FORWARD_WITH_FREQUENCY, data=4000),
        b"~010C00050FA00280\r",
        id="12-0005-40Hz",
    ),
    # §4.2: as above with 36 for 35: 281
    pytest.param(
        Request(address=1, command=RC, cmd_index=RunControl.REVERSE_WITH_FREQUENCY, data=4000),
        b"~010C00060FA00281\r",
        id="12-0006-40Hz",
    ),
    # EDS300 table: 30+31+30+43 = D4, +30+30+30 = 164, +31 = 195, +30+46+41+30 = 27C
    pytest.param(
        Request(address=1, command=RC, cmd_index=RunControl.SET_FREQUENCY, data=4000),
        b"~010C00010FA0027C\r",
        id="12-0001-40Hz",
    ),
    # §4.2: 164 + 37 = 19B
    pytest.param(
        Request(address=1, command=RC, cmd_index=RunControl.STOP), b"~010C0007019B\r", id="stop"
    ),
    # §4.2: 164 + 43 = 1A7
    pytest.param(
        Request(address=1, command=RC, cmd_index=RunControl.FAULT_RESET),
        b"~010C000C01A7\r",
        id="reset",
    ),
    # §4.2: 164 + 44 = 1A8 (the manual prints index 000E with this checksum)
    pytest.param(
        Request(address=1, command=RC, cmd_index=RunControl.EMERGENCY_STOP),
        b"~010C000D01A8\r",
        id="emergency-stop",
    ),
    # §4.3: 30+31+30+44 = D5, +30+30+30 = 165, +31 = 196
    pytest.param(
        Request(address=1, command=Command.READ_PARAMETER, cmd_index=0x01),
        b"~010D00010196\r",
        id="13-F0.01",
    ),
    # §4.3: 30+31+30+45 = D6, +30+30+30 = 166, +31 = 197, +31+33+38+38 = 26B
    pytest.param(
        Request(address=1, command=Command.WRITE_PARAMETER, cmd_index=0x01, data=5000),
        b"~010E00011388026B\r",
        id="14-F0.01-50Hz",
    ),
    # §4.3: D6, +30+30+30+33 = 199, +30+30+30+31 = 25A
    pytest.param(
        Request(address=1, command=Command.WRITE_PARAMETER, cmd_index=0x03, data=1),
        b"~010E00030001025A\r",
        id="14-F0.03-1",
    ),
    # §4: 30+31+30+46 = D7, +30+30+30+30 = 197
    pytest.param(Request(address=1, command=Command.SOFTWARE_VERSION), b"~010F00000197\r", id="15"),
    # F2.15 (index 020F) read at address 0x7F: 37+46+30+44 = F1, +30+32 = 153, +30+46 = 1C9
    pytest.param(
        Request(address=0x7F, command=Command.READ_PARAMETER, aux_index=0x02, cmd_index=0x0F),
        b"~7F0D020F01C9\r",
        id="13-F2.15-at-7F",
    ),
]

# No source prints a reply (§8, §10); these follow the §3 layout, checksums by hand.
GOLDEN_RESPONSES = [
    # state word 0005 from address 01, no fault: 30×9 = 1B0, +31 = 1E1, +46 = 227, +35 = 25C
    pytest.param(
        Response(address=1, response=0, failure_index=0, cmd_index=0x0F, data=5),
        b"~0100000F0005025C\r",
        id="state-word",
    ),
    # 40.00 Hz = 0FA0: eight "0" = 180, two "1" = +62 = 1E2, "F" +46 = 228, "A" +41 = 269
    pytest.param(
        Response(address=1, response=0, failure_index=0, cmd_index=0x01, data=4000),
        b"~010000010FA00269\r",
        id="running-frequency",
    ),
    # frame error, hex, index area left out: 30+31+31+34 = C6
    pytest.param(Response(address=1, response=0x14), b"~011400C6\r", id="frame-error-short"),
    # command-10 answer without data area: 30×5 = F0, +31×3 = 183
    pytest.param(
        Response(address=1, response=0x11, failure_index=0, cmd_index=0),
        b"~011100000183\r",
        id="state-answer-14-bytes",
    ),
]


@pytest.mark.parametrize(("request_", "wire"), GOLDEN_REQUESTS)
def test_request_golden_frames(request_: Request, wire: bytes) -> None:
    assert encode_request(request_) == wire
    assert decode_request(wire) == request_


@pytest.mark.parametrize(("response", "wire"), GOLDEN_RESPONSES)
def test_response_golden_frames(response: Response, wire: bytes) -> None:
    assert encode_response(response) == wire
    assert decode_response(wire) == response


def test_checksum_of_the_manual_example() -> None:
    assert checksum(b"010A0000") == 0x192


def test_index_joins_auxiliary_and_command_index() -> None:
    assert Request(address=1, command=13, aux_index=2, cmd_index=0x0B).index == 0x020B


@given(requests)
def test_request_round_trip(request_: Request) -> None:
    assert decode_request(encode_request(request_)) == request_


@given(responses())
def test_response_round_trip(response: Response) -> None:
    assert decode_response(encode_response(response)) == response


@given(checked_frames)
def test_any_checked_frame_round_trips_as_a_response(frame: bytes) -> None:
    assert encode_response(decode_response(frame)) == frame


@given(checked_frames.filter(lambda frame: len(frame) != 10))
def test_any_checked_frame_of_request_length_round_trips_as_a_request(frame: bytes) -> None:
    assert encode_request(decode_request(frame)) == frame


@given(requests)
def test_encoded_checksum_follows_the_hand_rule(request_: Request) -> None:
    wire = encode_request(request_)
    body = wire[1:-5].decode("ascii")
    assert wire[-5:-1] == format(ascii_sum(body), "04X").encode()


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        pytest.param(b"~010A00000193\r", "checksum", id="wrong-checksum"),
        pytest.param(b"~010a00000192\r", "lowercase", id="lowercase"),
        pytest.param(b"010A00000192\r", "starts with ~", id="no-head"),
        pytest.param(b"~010A00000192", "ends with CR", id="no-cr"),
        pytest.param(close("010A000"), "7 characters", id="odd-body"),
        pytest.param(close("010A0000000000"), "longer", id="too-long"),
    ],
)
def test_broken_requests_are_malformed(frame: bytes, reason: str) -> None:
    with pytest.raises(MalformedReply, match=reason) as caught:
        decode_request(frame)
    assert caught.value.raw == frame


def test_a_bare_four_character_body_is_a_response_but_not_a_request() -> None:
    assert decode_response(close("0114")) == Response(address=1, response=0x14)
    with pytest.raises(MalformedReply, match="4 characters"):
        decode_request(close("0114"))


@given(st.binary(max_size=24))
def test_decoders_raise_only_malformed_reply(data: bytes) -> None:
    for decode in (decode_request, decode_response):
        with contextlib.suppress(MalformedReply):
            decode(data)


@pytest.mark.parametrize(
    "request_",
    [
        Request(address=256, command=10),
        Request(address=1, command=-1),
        Request(address=1, command=12, cmd_index=0x100),
        Request(address=1, command=12, data=0x10000),
    ],
    ids=["address", "command", "index", "data"],
)
def test_fields_that_do_not_fit_are_usage_errors(request_: Request) -> None:
    with pytest.raises(UsageError):
        encode_request(request_)


def test_response_needs_both_index_halves_and_an_index_for_data() -> None:
    with pytest.raises(UsageError, match="both halves"):
        encode_response(Response(address=1, response=0, failure_index=0))
    with pytest.raises(UsageError, match="index area too"):
        encode_response(Response(address=1, response=0, data=1))
