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
from tests.unit.protocol.danfoss_fc.strategies import directed_telegrams, telegrams, xor_all

# 02^06=04 ^81=85 ^04=81 ^7C=FD ^20=DD ^00=DD
START_1 = bytes.fromhex("02 06 81 04 7C 20 00 DD")
# 02^06=04 ^16=12 ^04=16 ^3C=2A ^00=2A ^00=2A
STOP_22 = bytes.fromhex("02 06 16 04 3C 00 00 2A")
# 02^0E=0C ^81=8D ^11=9C ^55=C9, zeros: C9
READ_3_41 = bytes.fromhex("02 0E 81 11 55 00 00 00 00 00 00 00 00 00 00 C9")

Piece = Frame | Skipped


def drain(framer: FcFramer) -> list[Piece]:
    pieces: list[Piece] = []
    while (piece := framer.next_frame()) is not None:
        pieces.append(piece)
    return pieces


def feed_all(framer: FcFramer, chunks: list[bytes]) -> list[Piece]:
    pieces: list[Piece] = []
    for chunk in chunks:
        framer.feed(chunk)
        pieces += drain(framer)
    return pieces


def frames(pieces: list[Piece]) -> list[bytes]:
    return [piece.data for piece in pieces if isinstance(piece, Frame)]


def covered(pieces: list[Piece]) -> bytes:
    return b"".join(piece.data for piece in pieces)


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


def check_pieces(pieces: list[Piece]) -> None:
    for piece in pieces:
        assert piece.data, "an empty piece"
        if isinstance(piece, Frame):
            assert piece.data[0] == 0x02
            assert len(piece.data) == piece.data[1] + 2
            assert xor_all(piece.data) == 0


def assert_covers(framer: FcFramer, pieces: list[Piece], fed: bytes) -> None:
    check_pieces(pieces)
    assert covered(pieces) == fed[: len(fed) - framer.buffered]
    # A drained framer holds at most one unfinished candidate, which starts with STX.
    assert framer.buffered <= 10 + 64 + 1
    if framer.buffered:
        assert fed[len(fed) - framer.buffered] == 0x02


def assert_reset_hands_out_the_rest(framer: FcFramer, pieces: list[Piece], fed: bytes) -> None:
    framer.reset()
    pieces = pieces + drain(framer)
    check_pieces(pieces)
    assert covered(pieces) == fed
    assert framer.buffered == 0


@given(streams)
@settings(max_examples=300)
def test_any_bytes_fed_whole_are_covered_exactly_once(stream: bytes) -> None:
    framer = FcFramer()
    pieces = feed_all(framer, [stream])
    assert_covers(framer, pieces, stream)
    assert_reset_hands_out_the_rest(framer, pieces, stream)


@given(streams)
@settings(max_examples=150, deadline=None)
def test_any_bytes_fed_one_at_a_time_are_covered_exactly_once(stream: bytes) -> None:
    framer = FcFramer()
    pieces = feed_all(framer, [stream[i : i + 1] for i in range(len(stream))])
    assert_covers(framer, pieces, stream)
    assert_reset_hands_out_the_rest(framer, pieces, stream)


@given(st.data(), streams)
@settings(max_examples=300)
def test_any_chunking_gives_the_same_pieces_as_feeding_whole(
    data: st.DataObject, stream: bytes
) -> None:
    cuts = sorted(data.draw(st.sets(st.integers(0, len(stream)), max_size=12)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    whole, chunked = FcFramer(), FcFramer()
    whole_pieces = feed_all(whole, [stream])
    chunked_pieces = feed_all(chunked, chunks)
    assert_covers(chunked, chunked_pieces, stream)
    # Without gaps, how the bytes arrived makes no difference to the frames found.
    assert frames(chunked_pieces) == frames(whole_pieces)
    assert_reset_hands_out_the_rest(chunked, chunked_pieces, stream)


@given(st.lists(st.one_of(streams, st.just(None)), max_size=12))
@settings(max_examples=300)
def test_resets_anywhere_keep_the_coverage(steps: list[bytes | None]) -> None:
    # None = the bus saw a gap: reset(); bytes = a read, fed then drained (or not).
    framer = FcFramer()
    pieces: list[Piece] = []
    fed = b""
    for step in steps:
        if step is None:
            framer.reset()
        else:
            framer.feed(step)
            fed += step
        pieces += drain(framer)
        check_pieces(pieces)
        assert covered(pieces) == fed[: len(fed) - framer.buffered]
    assert_reset_hands_out_the_rest(framer, pieces, fed)


@given(streams, st.integers(0, 245))
@settings(max_examples=100)
def test_the_text_limit_bounds_what_stays_buffered(stream: bytes, max_text: int) -> None:
    framer = FcFramer(max_text_length=max_text)
    pieces = feed_all(framer, [stream])
    assert covered(pieces) == stream[: len(stream) - framer.buffered]
    assert framer.buffered <= min(10 + max_text, 255) + 1


# ---------------------------------------------------------------- resync (hypothesis)

NO_STX = st.binary(max_size=40).map(lambda noise: noise.replace(b"\x02", b""))
wires = directed_telegrams(max_text_length=64).map(lambda case: encode_telegram(case[0]))


@given(st.data(), st.lists(st.tuples(NO_STX, wires), min_size=1, max_size=8), NO_STX)
@settings(max_examples=200)
def test_every_telegram_comes_out_between_noise_without_stx(
    data: st.DataObject, segments: list[tuple[bytes, bytes]], tail: bytes
) -> None:
    # Noise with no STX byte cannot start a candidate, so nothing it holds can hide a telegram.
    stream = b"".join(noise + wire for noise, wire in segments) + tail
    cuts = sorted(data.draw(st.sets(st.integers(0, len(stream)), max_size=10)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    framer = FcFramer()
    pieces = feed_all(framer, chunks)
    assert frames(pieces) == [wire for _, wire in segments]
    skipped = [piece for piece in pieces if isinstance(piece, Skipped)]
    assert {piece.reason for piece in skipped} <= {SkipReason.NOISE}
    assert b"".join(piece.data for piece in skipped) == b"".join(n for n, _ in segments) + tail
    assert framer.buffered == 0


@given(
    st.data(),
    st.lists(
        st.tuples(st.binary(max_size=60), st.lists(wires, min_size=1, max_size=3)),
        min_size=1,
        max_size=5,
    ),
)
@settings(max_examples=300, deadline=None)
def test_after_a_gap_every_telegram_comes_out_whatever_the_noise_before_it(
    data: st.DataObject, rounds: list[tuple[bytes, list[bytes]]]
) -> None:
    # Each round: noise (STX and all), then a gap the bus measured (reset()), then telegrams.
    # Noise may by chance hold a frame of its own, so the honest claim is about positions: no
    # frame spans a gap, and from each gap on, the frames are exactly the telegrams sent.
    framer = FcFramer()
    pieces: list[Piece] = []
    fed = b""
    gaps: list[int] = []
    expected: dict[int, bytes] = {}  # offset in the stream → telegram starting there
    regions: list[range] = []  # offsets from each gap to the end of that round's telegrams
    for noise, round_wires in rounds:
        for part in (noise, None, *round_wires):
            if part is None:
                framer.reset()
                gaps.append(len(fed))
                continue
            if part is not noise:
                expected[len(fed)] = part
            cut = data.draw(st.integers(0, len(part)))
            for chunk in (part[:cut], part[cut:]):
                framer.feed(chunk)
                fed += chunk
                if data.draw(st.booleans()):
                    pieces += drain(framer)
        regions.append(range(gaps[-1], len(fed)))
    pieces += drain(framer)
    assert covered(pieces) == fed
    assert framer.buffered == 0

    found: dict[int, bytes] = {}
    offset = 0
    for piece in pieces:
        start, end = offset, offset + len(piece.data)
        offset = end
        if isinstance(piece, Frame):
            assert not any(start < gap < end for gap in gaps), f"frame spans a gap: {piece}"
            found[start] = piece.data
    for start, wire in expected.items():
        assert found.get(start) == wire, f"telegram at offset {start} lost"
    for start, wire in found.items():
        if any(start in region for region in regions):
            assert start in expected, f"invented frame {wire.hex(' ')} at offset {start}"


def test_resync_example_by_hand() -> None:
    # A read reply whose BCC was hit, two noise bytes, then the drive's next good telegram.
    framer = FcFramer()
    framer.feed(READ_3_41[:-1] + b"\x00" + b"\x55\xaa" + START_1)
    pieces = drain(framer)
    assert frames(pieces) == [START_1]
    assert covered(pieces) == READ_3_41[:-1] + b"\x00\x55\xaa" + START_1
