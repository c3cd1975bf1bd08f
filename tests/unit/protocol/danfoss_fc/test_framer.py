"""The FC framer: exact pieces for hand-made streams, the coverage invariant, and resync.

The framer's contract (fcmaster/protocol/framing.py, STYLE.md §2 and §10): frames and
skipped pieces together cover every byte fed, in order, exactly once; it never raises;
noise before a telegram does not hide the telegram; and a candidate begun before an
inter-character gap (``reset()``) is never completed with bytes from after it.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.protocol.danfoss_fc import FcFramer, encode_telegram
from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from tests.unit.protocol import framer_laws as laws
from tests.unit.protocol.danfoss_fc.strategies import directed_telegrams, telegrams, xor_all
from tests.unit.protocol.framer_laws import covered, drain, frames

# 02^06=04 ^81=85 ^04=81 ^7C=FD ^20=DD ^00=DD
START_1 = bytes.fromhex("02 06 81 04 7C 20 00 DD")
# 02^06=04 ^16=12 ^04=16 ^3C=2A ^00=2A ^00=2A
STOP_22 = bytes.fromhex("02 06 16 04 3C 00 00 2A")
# 02^0E=0C ^81=8D ^11=9C ^55=C9, zeros: C9
READ_3_41 = bytes.fromhex("02 0E 81 11 55 00 00 00 00 00 00 00 00 00 00 C9")

# ---------------------------------------------------------------- hand-made streams


def test_empty_framer_needs_more_bytes() -> None:
    assert FcFramer().next_frame() is None


def test_whole_telegram_comes_out_as_one_frame() -> None:
    framer = FcFramer()
    framer.feed(READ_3_41)
    assert drain(framer) == [Frame(READ_3_41)]
    assert framer.buffered == 0


def test_telegram_fed_one_byte_at_a_time_comes_out_only_when_complete() -> None:
    framer = FcFramer()
    for byte in READ_3_41[:-1]:
        framer.feed(bytes((byte,)))
        assert framer.next_frame() is None
    assert framer.buffered == len(READ_3_41) - 1
    framer.feed(READ_3_41[-1:])
    assert drain(framer) == [Frame(READ_3_41)]


def test_back_to_back_telegrams_in_one_chunk() -> None:
    framer = FcFramer()
    framer.feed(START_1 + READ_3_41 + STOP_22)
    assert drain(framer) == [Frame(START_1), Frame(READ_3_41), Frame(STOP_22)]


def test_noise_before_and_after_is_skipped_as_noise() -> None:
    framer = FcFramer()
    framer.feed(b"\xff\x00\x55" + START_1 + b"\x81\x7e")
    assert drain(framer) == [
        Skipped(b"\xff\x00\x55", SkipReason.NOISE),
        Frame(START_1),
        Skipped(b"\x81\x7e", SkipReason.NOISE),
    ]


def test_wrong_bcc_gives_up_the_stx_then_the_rest_is_noise() -> None:
    broken = START_1[:-1] + b"\xdc"
    framer = FcFramer()
    framer.feed(broken)
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.CHECKSUM),
        Skipped(broken[1:], SkipReason.NOISE),
    ]


@pytest.mark.parametrize("lge", [0, 1, 5, 7, 8, 9], ids=lambda lge: f"lge-{lge}")
def test_impossible_length_gives_up_the_stx(lge: int) -> None:
    framer = FcFramer()
    framer.feed(bytes((0x02, lge)))
    assert drain(framer)[0] == Skipped(b"\x02", SkipReason.BAD_LENGTH)


def test_text_longer_than_the_limit_is_overflow() -> None:
    # LGE 10 + 6 = 16 > 10 + 4: refused at once, without waiting for 18 bytes.
    framer = FcFramer(max_text_length=4)
    framer.feed(b"\x02\x10")
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.OVERFLOW),
        Skipped(b"\x10", SkipReason.NOISE),
    ]


def test_default_limit_takes_a_64_character_text_and_refuses_65() -> None:
    framer = FcFramer()
    framer.feed(bytes((0x02, 10 + 64)))
    assert framer.next_frame() is None  # waits for the rest
    framer = FcFramer()
    framer.feed(bytes((0x02, 10 + 65)))
    assert framer.next_frame() == Skipped(b"\x02", SkipReason.OVERFLOW)


def test_telegram_inside_a_false_candidate_is_found() -> None:
    # 02 0E claims 16 bytes; the 16 bytes are 02 0E + START_1 + FF*6, whose XOR is
    # 02^0E = 0C (START_1 closes to 0, six FF cancel): a checksum error. Rescanning finds START_1.
    stream = b"\x02\x0e" + START_1 + b"\xff" * 6
    framer = FcFramer()
    framer.feed(stream)
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.CHECKSUM),
        Skipped(b"\x0e", SkipReason.NOISE),
        Frame(START_1),
        Skipped(b"\xff" * 6, SkipReason.NOISE),
    ]


def test_gap_releases_a_telegram_held_behind_a_false_candidate() -> None:
    framer = FcFramer()
    framer.feed(b"\x02\x0e" + START_1)  # the candidate waits for 16 bytes
    assert framer.next_frame() is None
    framer.reset()
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.GAP),
        Skipped(b"\x0e", SkipReason.NOISE),
        Frame(START_1),
    ]
    assert framer.buffered == 0


def test_candidate_cut_by_a_gap_is_not_completed_with_bytes_from_after_it() -> None:
    # Before the gap: a truncated telegram 02 06 81 04 7C F9 (6 of 8 bytes). After it: START_1.
    # Glued, the first 8 bytes 02 06 81 04 7C F9 02 06 close to zero
    # (02^06=04 ^81=85 ^04=81 ^7C=FD ^F9=04 ^02=06 ^06=00) and would pass as a frame with
    # reference 0xF902; START_1 would be lost. The bus feeds the bytes that ended the gap after
    # calling reset(), so this order is the one that matters.
    framer = FcFramer()
    framer.feed(bytes.fromhex("02 06 81 04 7C F9"))
    assert framer.next_frame() is None
    framer.reset()
    framer.feed(START_1)
    assert drain(framer) == [
        Skipped(b"\x02", SkipReason.GAP),
        Skipped(bytes.fromhex("06 81 04 7C F9"), SkipReason.NOISE),
        Frame(START_1),
    ]


def test_lone_stx_cut_by_a_gap_does_not_take_its_length_from_after_the_gap() -> None:
    framer = FcFramer()
    framer.feed(b"\x02")
    framer.reset()
    framer.feed(START_1)
    assert drain(framer) == [Skipped(b"\x02", SkipReason.GAP), Frame(START_1)]


def test_reset_on_an_empty_framer_changes_nothing() -> None:
    framer = FcFramer()
    framer.reset()
    framer.feed(START_1[:4])
    assert framer.next_frame() is None  # the candidate began after the gap: it may wait
    framer.feed(START_1[4:])
    assert drain(framer) == [Frame(START_1)]


def test_complete_frame_before_the_gap_is_kept() -> None:
    framer = FcFramer()
    framer.feed(START_1)
    framer.reset()
    framer.feed(STOP_22)
    assert drain(framer) == [Frame(START_1), Frame(STOP_22)]


# ---------------------------------------------------------------- invariant (hypothesis)

# Streams that are mostly interesting: fragments of real telegrams, STX-and-length pairs,
# and plain noise, so the framer visits every branch, not only "noise".
fragments = st.one_of(
    st.binary(max_size=24),
    telegrams(from_drive=True, max_text_length=80).map(encode_telegram),
    st.sampled_from([b"\x02", b"\x02\x06", b"\x02\x0e", b"\x02\x4a", b"\x02\x4b", b"\x02\xff"]),
)
streams = st.binary(max_size=400) | st.lists(fragments, max_size=20).map(b"".join)
wires = directed_telegrams(max_text_length=64).map(lambda case: encode_telegram(case[0]))
NO_STX = st.binary(max_size=40).map(lambda noise: noise.replace(b"\x02", b""))


def check_telegram(data: bytes) -> None:
    assert data[0] == 0x02
    assert len(data) == data[1] + 2
    assert xor_all(data) == 0


@given(st.data(), streams)
@settings(max_examples=300)
def test_any_chunking_covers_every_byte_once(data: st.DataObject, stream: bytes) -> None:
    laws.any_chunking_covers_every_byte_once(
        FcFramer,
        stream,
        laws.some_cuts(data, stream),
        check_telegram,
        max_buffered=10 + 64 + 1,
        heads=b"\x02",
    )


@given(st.lists(st.one_of(streams, st.just(None)), max_size=12))
@settings(max_examples=300)
def test_resets_anywhere_keep_the_coverage(steps: list[bytes | None]) -> None:
    laws.resets_anywhere_keep_the_coverage(FcFramer, steps, check_telegram)


@given(streams, st.integers(0, 245))
@settings(max_examples=100)
def test_the_text_limit_bounds_what_stays_buffered(stream: bytes, max_text: int) -> None:
    framer = FcFramer(max_text_length=max_text)
    pieces = laws.feed_all(framer, [stream])
    assert laws.covered(pieces) == stream[: len(stream) - framer.buffered]
    assert framer.buffered <= min(10 + max_text, 255) + 1


# ---------------------------------------------------------------- resync (hypothesis)


@given(st.data(), st.lists(st.tuples(NO_STX, wires), min_size=1, max_size=8), NO_STX)
@settings(max_examples=200)
def test_every_telegram_comes_out_between_noise_without_stx(
    data: st.DataObject, segments: list[tuple[bytes, bytes]], tail: bytes
) -> None:
    stream = b"".join(noise + wire for noise, wire in segments) + tail
    cuts = laws.some_cuts(data, stream, most=10)
    laws.frames_between_clean_noise_all_come_out(FcFramer, segments, tail, cuts)


@given(
    st.data(),
    st.lists(
        st.tuples(st.binary(max_size=60), st.lists(wires, min_size=1, max_size=3)),
        min_size=1,
        max_size=5,
    ),
)
@settings(max_examples=300)
def test_after_a_gap_every_telegram_comes_out_whatever_the_noise_before_it(
    data: st.DataObject, rounds: list[tuple[bytes, list[bytes]]]
) -> None:
    laws.after_a_gap_every_frame_comes_out(FcFramer, data, rounds)


def test_resync_example_by_hand() -> None:
    # A read reply whose BCC was hit, two noise bytes, then the drive's next good telegram.
    framer = FcFramer()
    framer.feed(READ_3_41[:-1] + b"\x00" + b"\x55\xaa" + START_1)
    pieces = drain(framer)
    assert frames(pieces) == [START_1]
    assert covered(pieces) == READ_3_41[:-1] + b"\x00\x55\xaa" + START_1
