"""The ENC framer: exact pieces for hand-made streams, the coverage invariant, and resync.

The framer's contract (fcmaster/protocol/framing.py, STYLE.md §2 and §10): frames and
skipped pieces together cover every byte fed, in order, exactly once; it never raises;
noise before a frame does not hide the frame; and a candidate begun before an
inter-character gap (``reset()``) is never completed with bytes from after it.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.protocol.enc import EncFramer, encode_request, encode_response
from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from tests.unit.protocol import framer_laws as laws
from tests.unit.protocol.enc.strategies import ascii_sum, close, requests, responses
from tests.unit.protocol.framer_laws import covered, drain, frames

STOP = b"~010C0007019B\r"  # §4.2, checksum worked out in test_frame.py
READ_FREQUENCY = b"~010B00010194\r"  # §4.1
FORWARD_40 = b"~010C00050FA00280\r"  # §3.1
FRAME_ERROR = b"~011400C6\r"  # 30+31+31+34 = C6

# ---------------------------------------------------------------- hand-made streams


def test_empty_framer_needs_more_bytes() -> None:
    assert EncFramer().next_frame() is None


@pytest.mark.parametrize("wire", [STOP, FORWARD_40, FRAME_ERROR], ids=["14", "18", "10"])
def test_whole_frame_of_each_length_comes_out_as_one_frame(wire: bytes) -> None:
    framer = EncFramer()
    framer.feed(wire)
    assert drain(framer) == [Frame(wire)]
    assert framer.buffered == 0


def test_frame_fed_one_byte_at_a_time_comes_out_only_when_complete() -> None:
    framer = EncFramer()
    for byte in FORWARD_40[:-1]:
        framer.feed(bytes((byte,)))
        assert framer.next_frame() is None
    assert framer.buffered == len(FORWARD_40) - 1
    framer.feed(FORWARD_40[-1:])
    assert drain(framer) == [Frame(FORWARD_40)]


def test_back_to_back_frames_in_one_chunk() -> None:
    framer = EncFramer()
    framer.feed(STOP + FORWARD_40 + FRAME_ERROR + READ_FREQUENCY)
    assert frames(drain(framer)) == [STOP, FORWARD_40, FRAME_ERROR, READ_FREQUENCY]


def test_noise_before_and_after_is_skipped_as_noise() -> None:
    framer = EncFramer()
    framer.feed(b"\xff\r01" + STOP + b"AB\r")
    assert drain(framer) == [
        Skipped(b"\xff\r01", SkipReason.NOISE),
        Frame(STOP),
        Skipped(b"AB\r", SkipReason.NOISE),
    ]


def test_wrong_checksum_skips_the_whole_candidate() -> None:
    broken = STOP[:-2] + b"C\r"
    framer = EncFramer()
    framer.feed(broken + READ_FREQUENCY)
    assert drain(framer) == [Skipped(broken, SkipReason.CHECKSUM), Frame(READ_FREQUENCY)]


def test_too_short_candidate_is_bad_length() -> None:
    # 9 bytes: a body of 3 characters cannot be a frame, whatever its sum.
    short = close("011")
    assert len(short) == 9
    framer = EncFramer()
    framer.feed(short)
    assert drain(framer) == [Skipped(short, SkipReason.BAD_LENGTH)]


def test_a_new_head_cuts_a_truncated_candidate() -> None:
    framer = EncFramer()
    framer.feed(STOP[:6] + STOP)
    assert drain(framer) == [Skipped(STOP[:6], SkipReason.BAD_LENGTH), Frame(STOP)]


@pytest.mark.parametrize("bad", [b"a", b"\x00", b"G", b"\xfe"], ids=["lower", "nul", "G", "fe"])
def test_an_illegal_character_breaks_the_candidate(bad: bytes) -> None:
    wire = STOP[:5] + bad + STOP[6:]
    framer = EncFramer()
    framer.feed(wire + STOP)
    assert drain(framer) == [
        Skipped(STOP[:5], SkipReason.NOISE),
        Skipped(bad + STOP[6:], SkipReason.NOISE),
        Frame(STOP),
    ]


def test_candidate_without_cr_overflows_at_18_bytes() -> None:
    framer = EncFramer()
    framer.feed(b"~" + b"0" * 16)
    assert framer.next_frame() is None  # 17 bytes: an 18-byte frame may still end
    framer.feed(b"0" + STOP)
    assert drain(framer) == [
        Skipped(b"~" + b"0" * 17, SkipReason.OVERFLOW),
        Frame(STOP),
    ]


def test_gap_gives_up_a_candidate_and_keeps_the_next_frame() -> None:
    # Before the gap: the first 9 bytes of a stop frame. Glued to what comes after, no
    # frame could come of it, but its bytes must not wait for one either.
    framer = EncFramer()
    framer.feed(STOP[:9])
    assert framer.next_frame() is None
    framer.reset()
    framer.feed(READ_FREQUENCY)
    assert drain(framer) == [Skipped(STOP[:9], SkipReason.GAP), Frame(READ_FREQUENCY)]


def test_candidate_cut_by_a_gap_is_not_completed_with_bytes_from_after_it() -> None:
    # "~01" before the gap, "1400C6\r" after it: glued, they are FRAME_ERROR and would pass
    # as a frame. The bus feeds the bytes that ended the gap after calling reset(), so this
    # order is the one that matters.
    framer = EncFramer()
    framer.feed(FRAME_ERROR[:3])
    framer.reset()
    framer.feed(FRAME_ERROR[3:])
    assert drain(framer) == [
        Skipped(FRAME_ERROR[:3], SkipReason.GAP),
        Skipped(FRAME_ERROR[3:], SkipReason.NOISE),
    ]


def test_reset_on_an_empty_framer_changes_nothing() -> None:
    framer = EncFramer()
    framer.reset()
    framer.feed(STOP[:4])
    assert framer.next_frame() is None  # the candidate began after the gap: it may wait
    framer.feed(STOP[4:])
    assert drain(framer) == [Frame(STOP)]


def test_complete_frame_before_the_gap_is_kept() -> None:
    framer = EncFramer()
    framer.feed(STOP)
    framer.reset()
    framer.feed(READ_FREQUENCY)
    assert drain(framer) == [Frame(STOP), Frame(READ_FREQUENCY)]


# ---------------------------------------------------------------- invariant (hypothesis)

# Streams that are mostly interesting: real frames, their fragments, heads, CRs and hex
# digits, plus plain noise, so the framer visits every branch, not only "noise".
wires = st.one_of(requests.map(encode_request), responses().map(encode_response))
fragments = st.one_of(
    st.binary(max_size=24),
    wires,
    wires.flatmap(lambda wire: st.integers(0, len(wire)).map(lambda cut: wire[:cut])),
    st.text(alphabet="0123456789ABCDEF~\r", max_size=20).map(str.encode),
)
streams = st.binary(max_size=400) | st.lists(fragments, max_size=20).map(b"".join)
NO_HEAD = st.binary(max_size=40).map(lambda noise: noise.replace(b"~", b""))


def check_frame(data: bytes) -> None:
    assert data[0] == ord("~")
    assert data[-1] == ord("\r")
    assert 10 <= len(data) <= 18
    body = data[1:-5].decode("ascii")
    assert data[-5:-1] == format(ascii_sum(body), "04X").encode()


@given(st.data(), streams)
@settings(max_examples=300)
def test_any_chunking_covers_every_byte_once(data: st.DataObject, stream: bytes) -> None:
    cuts = laws.some_cuts(data, stream)
    laws.any_chunking_covers_every_byte_once(
        EncFramer, stream, cuts, check_frame, max_buffered=17, heads=b"~"
    )


@given(st.lists(st.one_of(streams, st.just(None)), max_size=12))
@settings(max_examples=300)
def test_resets_anywhere_keep_the_coverage(steps: list[bytes | None]) -> None:
    laws.resets_anywhere_keep_the_coverage(EncFramer, steps, check_frame)


# ---------------------------------------------------------------- resync (hypothesis)


@given(st.data(), st.lists(st.tuples(NO_HEAD, wires), min_size=1, max_size=8), NO_HEAD)
@settings(max_examples=200)
def test_every_frame_comes_out_between_noise_without_a_head(
    data: st.DataObject, segments: list[tuple[bytes, bytes]], tail: bytes
) -> None:
    stream = b"".join(noise + wire for noise, wire in segments) + tail
    cuts = laws.some_cuts(data, stream, most=10)
    laws.frames_between_clean_noise_all_come_out(EncFramer, segments, tail, cuts)


@given(
    st.data(),
    st.lists(
        st.tuples(st.binary(max_size=60), st.lists(wires, min_size=1, max_size=3)),
        min_size=1,
        max_size=5,
    ),
)
@settings(max_examples=300)
def test_after_a_gap_every_frame_comes_out_whatever_the_noise_before_it(
    data: st.DataObject, rounds: list[tuple[bytes, list[bytes]]]
) -> None:
    laws.after_a_gap_every_frame_comes_out(EncFramer, data, rounds)


def test_resync_example_by_hand() -> None:
    # A reply whose checksum was hit, two noise bytes, then the drive's next good frame.
    framer = EncFramer()
    framer.feed(FORWARD_40[:-2] + b"1\r" + b"\x55\xaa" + STOP)
    pieces = drain(framer)
    assert frames(pieces) == [STOP]
    assert covered(pieces) == FORWARD_40[:-2] + b"1\r\x55\xaa" + STOP
