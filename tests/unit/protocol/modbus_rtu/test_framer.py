"""The RTU framer: exact pieces for hand-made streams, and the laws every framer keeps.

RTU frames are told by length (the function code gives it) and by the silence before them,
which the bus measures and reports with ``reset()``. Noise is skipped and counted, never
decoded; a frame after noise is found again by rescanning from the next byte.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from fcmaster.protocol.modbus_rtu import (
    Direction,
    RtuFramer,
    crc_ok,
    decode_request,
    decode_response,
)
from tests.unit.protocol import framer_laws as laws
from tests.unit.protocol.framer_laws import drain, frames
from tests.unit.protocol.modbus_rtu.strategies import bitwise_crc, request_wires, response_wires


def crc(body: bytes) -> bytes:
    value = bitwise_crc(body)
    return body + bytes((value & 0xFF, value >> 8))


READ = crc(bytes.fromhex("110306022B00000064"))  # §6.3's answer from server 0x11
ECHO = crc(bytes.fromhex("110600010003"))  # §6.6
WRITTEN = crc(bytes.fromhex("111000010002"))  # §6.12
EXCEPTION = crc(bytes.fromhex("118102"))  # §7
READ_REQUEST = crc(bytes.fromhex("1103006B0003"))
WRITE_REQUEST = crc(bytes.fromhex("11100001000204000A0102"))


def responses() -> RtuFramer:
    return RtuFramer(Direction.RESPONSES)


def requests() -> RtuFramer:
    return RtuFramer(Direction.REQUESTS)


def check_response(frame: bytes) -> None:
    assert crc_ok(frame)
    decode_response(frame)


def check_request(frame: bytes) -> None:
    assert crc_ok(frame)
    decode_request(frame)


# ---------------------------------------------------------------- hand-made streams


def test_empty_framer_needs_more_bytes() -> None:
    assert responses().next_frame() is None


@pytest.mark.parametrize("wire", [READ, ECHO, WRITTEN, EXCEPTION], ids=["03", "06", "16", "exc"])
def test_each_answer_comes_out_whole(wire: bytes) -> None:
    framer = responses()
    framer.feed(wire)
    assert drain(framer) == [Frame(wire)]
    assert framer.buffered == 0


@pytest.mark.parametrize("wire", [READ_REQUEST, ECHO, WRITE_REQUEST], ids=["03", "06", "16"])
def test_each_request_comes_out_whole(wire: bytes) -> None:
    framer = requests()
    framer.feed(wire)
    assert drain(framer) == [Frame(wire)]


def test_a_frame_fed_byte_by_byte_comes_out_only_when_complete() -> None:
    framer = responses()
    for byte in READ[:-1]:
        framer.feed(bytes((byte,)))
        assert framer.next_frame() is None
    framer.feed(READ[-1:])
    assert drain(framer) == [Frame(READ)]


def test_the_exception_frame_is_five_bytes() -> None:
    framer = responses()
    framer.feed(EXCEPTION + ECHO)
    assert drain(framer) == [Frame(EXCEPTION), Frame(ECHO)]
    assert len(EXCEPTION) == 5


def test_bytes_that_cannot_begin_an_answer_are_noise() -> None:
    # 00 and F8-FF are no server's address; 11 42 is an address with no register function.
    framer = responses()
    framer.feed(b"\x00\xff\xf8\x11\x42" + ECHO)
    assert drain(framer) == [Skipped(b"\x00\xff\xf8\x11\x42", SkipReason.NOISE), Frame(ECHO)]


def test_noise_that_looks_like_a_start_is_skipped_by_its_crc_and_the_frame_found() -> None:
    # "01 06" begins an 8-byte candidate that takes six bytes of the real frame: its CRC
    # fails, it gives up one byte, and the rescan finds the frame.
    framer = responses()
    framer.feed(b"\x01\x06" + ECHO)
    pieces = drain(framer)
    assert frames(pieces) == [ECHO]
    assert pieces[0] == Skipped(b"\x01", SkipReason.CHECKSUM)
    assert laws.covered(pieces) == b"\x01\x06" + ECHO


def test_an_impossible_byte_count_is_bad_length() -> None:
    framer = responses()
    framer.feed(b"\x11\x03\x03" + ECHO)  # an odd byte count
    pieces = drain(framer)
    assert pieces[0] == Skipped(b"\x11", SkipReason.BAD_LENGTH)
    assert frames(pieces) == [ECHO]


def test_a_bad_crc_is_counted_and_the_frame_not_handed_out() -> None:
    broken = ECHO[:-1] + bytes((ECHO[-1] ^ 1,))
    framer = responses()
    framer.feed(broken)
    framer.reset()
    pieces = drain(framer)
    assert frames(pieces) == []
    assert pieces[0] == Skipped(broken[:1], SkipReason.CHECKSUM)
    assert laws.covered(pieces) == broken


def test_a_gap_gives_up_an_unfinished_frame() -> None:
    framer = responses()
    framer.feed(READ[:6])
    assert framer.next_frame() is None
    framer.reset()
    framer.feed(ECHO)
    pieces = drain(framer)
    assert frames(pieces) == [ECHO]
    assert pieces[0] == Skipped(READ[:1], SkipReason.GAP)
    assert laws.covered(pieces) == READ[:6] + ECHO


def test_a_frame_cut_by_a_gap_is_not_completed_with_bytes_from_after_it() -> None:
    framer = responses()
    framer.feed(ECHO[:3])
    framer.reset()
    framer.feed(ECHO[3:])
    assert frames(drain(framer)) == []


def test_a_drained_framer_holds_less_than_the_longest_frame() -> None:
    framer = responses()
    longest = crc(bytes((1, 3, 250)) + bytes(250))
    assert len(longest) == 255
    framer.feed(longest[:-1])
    assert framer.next_frame() is None
    assert framer.buffered == 254
    framer.feed(longest[-1:])
    assert drain(framer) == [Frame(longest)]


# ---------------------------------------------------------------- the laws

noise = st.binary(max_size=24)
# Bytes no answer can begin with: 0 and 248-255 are no server's address.
clean_noise = st.lists(st.sampled_from([0, *range(248, 256)]), max_size=8).map(bytes)


@given(st.lists(noise | response_wires, max_size=6), st.data())
def test_any_chunking_covers_every_byte_once(parts: list[bytes], data: st.DataObject) -> None:
    stream = b"".join(parts)
    laws.any_chunking_covers_every_byte_once(
        responses, stream, laws.some_cuts(data, stream), check_response, max_buffered=254
    )


@given(st.lists(noise | request_wires, max_size=6), st.data())
def test_any_chunking_of_requests_covers_every_byte_once(
    parts: list[bytes], data: st.DataObject
) -> None:
    stream = b"".join(parts)
    laws.any_chunking_covers_every_byte_once(
        requests, stream, laws.some_cuts(data, stream), check_request, max_buffered=254
    )


@given(st.lists(st.none() | noise | response_wires, max_size=10))
def test_resets_anywhere_keep_the_coverage(steps: list[bytes | None]) -> None:
    laws.resets_anywhere_keep_the_coverage(responses, steps, check_response)


@given(st.lists(st.tuples(clean_noise, response_wires), max_size=5), clean_noise, st.data())
def test_frames_between_clean_noise_all_come_out(
    segments: list[tuple[bytes, bytes]], tail: bytes, data: st.DataObject
) -> None:
    stream = b"".join(a + b for a, b in segments) + tail
    laws.frames_between_clean_noise_all_come_out(
        responses, segments, tail, laws.some_cuts(data, stream)
    )


@given(st.lists(st.tuples(noise, st.lists(response_wires, max_size=3)), max_size=4), st.data())
def test_after_a_gap_every_frame_comes_out(
    rounds: list[tuple[bytes, list[bytes]]], data: st.DataObject
) -> None:
    laws.after_a_gap_every_frame_comes_out(responses, data, rounds)


@given(st.lists(st.tuples(noise, st.lists(request_wires, max_size=3)), max_size=4), st.data())
def test_after_a_gap_every_request_comes_out(
    rounds: list[tuple[bytes, list[bytes]]], data: st.DataObject
) -> None:
    laws.after_a_gap_every_frame_comes_out(requests, data, rounds)


@given(noise, response_wires)
def test_noise_then_silence_then_a_frame_the_noise_is_skipped_never_decoded(
    junk: bytes, wire: bytes
) -> None:
    framer = responses()
    framer.feed(junk)
    pieces = drain(framer)
    framer.reset()  # the line fell silent after the noise
    framer.feed(wire)
    pieces += drain(framer)
    found = frames(pieces)
    # Noise may by chance hold a whole frame with a right CRC; the frame sent is the last.
    assert found[-1:] == [wire]
    skipped = [p for p in pieces if isinstance(p, Skipped)]
    assert len(laws.covered(skipped)) + sum(map(len, found)) == len(junk) + len(wire)
    assert all(len(f) >= 5 for f in found)
