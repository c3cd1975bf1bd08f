"""The computer-link framer: hand-made streams, the coverage invariant, and resync.

The framer's contract (fcmaster/protocol/framing.py, STYLE.md §2 and §10): frames and
skipped pieces together cover every byte fed, in order, exactly once; it never raises;
every frame it hands out decodes; noise before a frame does not hide the frame; and a
candidate begun before an inter-character gap (``reset()``) is never completed with bytes
from after it.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from fcmaster.protocol.mitsubishi import (
    Message,
    MitsubishiFramer,
    Terminator,
    decode_frame,
    encode_frame,
)
from tests.unit.protocol import framer_laws as laws
from tests.unit.protocol.framer_laws import covered, drain, frames
from tests.unit.protocol.mitsubishi.strategies import master_answers, replies, requests

# status reply "02": 30+31+30+32 = 0xC3
STATUS_02 = b"\x020102\x03C3\r"
# manual reply 1770: 30+31+31+37+37+30 = 0x130 -> "30"
REPLY_1770 = b"\x02011770\x0330\r"
ACK_01 = b"\x0601\r"
NAK_01_A = b"\x1501A\r"

# ---------------------------------------------------------------- hand-made streams


def test_empty_framer_needs_more_bytes() -> None:
    assert MitsubishiFramer().next_frame() is None


@pytest.mark.parametrize("wire", [STATUS_02, REPLY_1770, ACK_01, NAK_01_A])
def test_whole_reply_comes_out_as_one_frame(wire: bytes) -> None:
    framer = MitsubishiFramer()
    framer.feed(wire)
    assert drain(framer) == [Frame(wire)]
    assert framer.buffered == 0


def test_reply_fed_one_byte_at_a_time_comes_out_only_with_its_cr() -> None:
    framer = MitsubishiFramer()
    for byte in REPLY_1770[:-1]:
        framer.feed(bytes((byte,)))
        assert framer.next_frame() is None
    framer.feed(b"\r")
    assert drain(framer) == [Frame(REPLY_1770)]


def test_back_to_back_replies_and_noise() -> None:
    framer = MitsubishiFramer()
    framer.feed(b"\xff0" + STATUS_02 + ACK_01 + b"zz" + NAK_01_A + b"\x00")
    assert drain(framer) == [
        Skipped(b"\xff0", SkipReason.NOISE),
        Frame(STATUS_02),
        Frame(ACK_01),
        Skipped(b"zz", SkipReason.NOISE),
        Frame(NAK_01_A),
        Skipped(b"\x00", SkipReason.NOISE),
    ]


def test_wrong_sum_gives_up_the_stx_then_the_rest_is_noise() -> None:
    broken = b"\x02011770\x0331\r"
    framer = MitsubishiFramer()
    framer.feed(broken)
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.CHECKSUM),
        Skipped(broken[1:], SkipReason.NOISE),
    ]


def test_missing_cr_is_not_tolerated() -> None:
    # ACK frames have no sum check: the CR is what tells them from noise.
    framer = MitsubishiFramer(terminator=Terminator.CR)
    framer.feed(b"\x0601" + ACK_01)
    assert drain(framer) == [
        Skipped(b"\x06", SkipReason.BAD_LENGTH),
        Skipped(b"01", SkipReason.NOISE),
        Frame(ACK_01),
    ]


def test_missing_lf_is_tolerated_when_another_frame_follows() -> None:
    framer = MitsubishiFramer(terminator=Terminator.CRLF)
    framer.feed(b"\x0601\r" + b"\x0602\r\n")
    assert drain(framer) == [Frame(b"\x0601\r"), Frame(b"\x0602\r\n")]


def test_missing_lf_is_tolerated_at_a_gap() -> None:
    framer = MitsubishiFramer(terminator=Terminator.CRLF)
    framer.feed(STATUS_02)
    assert framer.next_frame() is None  # the LF may still come
    framer.reset()
    assert drain(framer) == [Frame(STATUS_02)]


def test_without_terminator_a_stray_cr_is_noise() -> None:
    framer = MitsubishiFramer(terminator=Terminator.NONE)
    framer.feed(STATUS_02)
    assert drain(framer) == [Frame(STATUS_02[:-1]), Skipped(b"\r", SkipReason.NOISE)]


@pytest.mark.parametrize(
    "start",
    [b"\x02\x41", b"\x0620", b"\x020112345\x03", b"\x0201" + b"x" * 21, b"\x02012\x03"],
    ids=["bad-station-digit", "station-20", "five-digits", "over-20", "one-digit"],
)
def test_impossible_candidates_give_up_the_start_byte(start: bytes) -> None:
    framer = MitsubishiFramer()
    framer.feed(start)
    assert drain(framer)[0] == Skipped(start[:1], SkipReason.BAD_LENGTH)


def test_candidate_cut_by_a_gap_is_not_completed_with_bytes_from_after_it() -> None:
    framer = MitsubishiFramer()
    framer.feed(b"\x020117")
    assert framer.next_frame() is None
    framer.reset()
    framer.feed(REPLY_1770)
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.GAP),
        Skipped(b"0117", SkipReason.NOISE),
        Frame(REPLY_1770),
    ]


def test_complete_frame_before_the_gap_is_kept() -> None:
    framer = MitsubishiFramer()
    framer.feed(STATUS_02)
    framer.reset()
    framer.feed(ACK_01)
    assert drain(framer) == [Frame(STATUS_02), Frame(ACK_01)]


# Requests, for a simulated drive. Pr.123 = 9999 (digit "0") unless said otherwise.
# Pr.7 write 100 = 0x64 (4 digits): 30+31+38+37+30+30+30+36+34 = 0x1CA -> "CA"
WRITE_4 = b"\x05018700064CA\r"
# the same with 6 digits 0x000064: + 30+30 = 0x22A -> "2A"
WRITE_6 = b"\x0501870000064" + b"2A\r"


def test_request_framer_settles_4_or_6_digits_by_sum_and_terminator() -> None:
    framer = MitsubishiFramer(from_drive=False)
    framer.feed(WRITE_4 + WRITE_6 + b"\x05017A009\r" + b"\x1501\r")
    assert frames(drain(framer)) == [WRITE_4, WRITE_6, b"\x05017A009\r", b"\x1501\r"]


def test_request_framer_without_waiting_digit() -> None:
    # reset, no digit: 30+31+46+44+39+36+39+36 = 0x1C9 -> "C9"
    framer = MitsubishiFramer(from_drive=False, wait_digit=False, terminator=Terminator.CRLF)
    framer.feed(b"\x0501FD9696C9\r\n")
    assert drain(framer) == [Frame(b"\x0501FD9696C9\r\n")]


# ---------------------------------------------------------------- invariant (hypothesis)

configs = st.sampled_from(
    [
        (t, from_drive, wait)
        for t in Terminator
        for from_drive in (True, False)
        for wait in (True, False)
    ]
)


@st.composite
def wires(draw: st.DrawFn, terminator: Terminator, from_drive: bool, wait: bool) -> bytes:
    sent = master_answers | requests(wait=wait, by_code=True)
    message: Message = draw(replies if from_drive else sent)
    return encode_frame(message, terminator)


fragments = st.one_of(
    st.binary(max_size=16),
    st.sampled_from([b"\x02", b"\x05", b"\x06", b"\x15", b"\x0201", b"\x03", b"\r", b"\n", b"0"]),
    st.text("0123456789ABCDEF\x02\x03\x05\x06\x15\r\n", max_size=12).map(str.encode),
)


@st.composite
def streams(draw: st.DrawFn, terminator: Terminator, from_drive: bool, wait: bool) -> bytes:
    parts = draw(st.lists(fragments | wires(terminator, from_drive, wait), max_size=16))
    return b"".join(parts)


def check_frame(data: bytes) -> None:
    decode_frame(data)  # every frame handed out decodes, sum check and all


def framer_for(config: tuple[Terminator, bool, bool]) -> Callable[[], MitsubishiFramer]:
    terminator, from_drive, wait = config
    return partial(MitsubishiFramer, terminator=terminator, from_drive=from_drive, wait_digit=wait)


@given(st.data(), configs)
@settings(max_examples=300)
def test_any_chunking_covers_every_byte_once(
    data: st.DataObject, config: tuple[Terminator, bool, bool]
) -> None:
    stream = data.draw(streams(*config))
    cuts = laws.some_cuts(data, stream)
    # 28 bytes: the longest frame, E3 with CR LF.
    laws.any_chunking_covers_every_byte_once(
        framer_for(config), stream, cuts, check_frame, max_buffered=28
    )


@given(st.binary(max_size=300))
def test_random_bytes_never_raise(stream: bytes) -> None:
    framer = MitsubishiFramer()
    pieces = laws.feed_all(framer, [stream])
    laws.assert_reset_hands_out_the_rest(framer, pieces, stream, check_frame)


@given(st.data(), st.lists(st.binary(max_size=20) | st.none(), max_size=12), configs)
@settings(max_examples=200)
def test_resets_anywhere_keep_the_coverage(
    data: st.DataObject, steps: list[bytes | None], config: tuple[Terminator, bool, bool]
) -> None:
    # Each read carries a real frame behind its noise, so frames come out along the way.
    reads = [step if step is None else step + data.draw(wires(*config)) for step in steps]
    laws.resets_anywhere_keep_the_coverage(framer_for(config), reads, check_frame)


# ---------------------------------------------------------------- resync (hypothesis)

START_BYTES = b"\x02\x05\x06\x15"
NO_START = st.binary(max_size=30).map(lambda noise: bytes(b for b in noise if b not in START_BYTES))


@given(st.data(), configs, NO_START)
@settings(max_examples=200)
def test_every_frame_comes_out_between_noise_without_start_bytes(
    data: st.DataObject, config: tuple[Terminator, bool, bool], tail: bytes
) -> None:
    terminator, from_drive, _ = config
    segments = data.draw(st.lists(st.tuples(NO_START, wires(*config)), min_size=1, max_size=6))
    stream = b"".join(noise + wire for noise, wire in segments) + tail
    cuts = laws.some_cuts(data, stream, most=10)
    if terminator is Terminator.NONE and not from_drive:
        # Without a terminator, a 6-digit write whose first 4 digits happen to close a sum
        # (1 in 256) is cut as a 4-digit one: only coverage is promised then.
        framer = framer_for(config)()
        pieces = laws.feed_all(framer, laws.cut(stream, cuts))
        laws.assert_reset_hands_out_the_rest(framer, pieces, stream, check_frame)
        return
    laws.frames_between_clean_noise_all_come_out(framer_for(config), segments, tail, cuts)


def test_resync_example_by_hand() -> None:
    # A reply whose sum was hit, two noise bytes, then the drive's next good reply.
    framer = MitsubishiFramer()
    framer.feed(REPLY_1770[:-2] + b"1\r" + b"\x55\xaa" + STATUS_02)
    pieces = drain(framer)
    assert frames(pieces) == [STATUS_02]
    assert covered(pieces) == REPLY_1770[:-2] + b"1\r\x55\xaa" + STATUS_02
