"""The laws every framer keeps, written once for all protocols.

The contract (fcmaster/protocol/framing.py, STYLE.md §2 and §10): frames and skipped pieces
together cover every byte fed, in order, exactly once; how the bytes were chunked makes no
difference to the frames found; every frame handed out is a valid frame; noise that cannot
start a frame never hides one; and a candidate begun before an inter-character gap
(``reset()``) is never completed with bytes from after it.

A protocol's test module brings what only it knows — a framer factory, a check that a
handed-out frame is valid, and hypothesis strategies for its wires — and calls these laws
from its own ``@given`` tests.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from hypothesis import strategies as st

from fcmaster.protocol.framing import Frame, Framer, Skipped, SkipReason

Piece = Frame | Skipped
CheckFrame = Callable[[bytes], None]  # fails when a handed-out frame is not a valid frame
NewFramer = Callable[[], Framer]


def drain(framer: Framer) -> list[Piece]:
    pieces: list[Piece] = []
    while (piece := framer.next_frame()) is not None:
        pieces.append(piece)
    return pieces


def feed_all(framer: Framer, chunks: Sequence[bytes]) -> list[Piece]:
    pieces: list[Piece] = []
    for chunk in chunks:
        framer.feed(chunk)
        pieces += drain(framer)
    return pieces


def frames(pieces: Sequence[Piece]) -> list[bytes]:
    return [piece.data for piece in pieces if isinstance(piece, Frame)]


def covered(pieces: Sequence[Piece]) -> bytes:
    return b"".join(piece.data for piece in pieces)


def cut(stream: bytes, cuts: set[int]) -> list[bytes]:
    """``stream`` split at the offsets in ``cuts``."""
    edges = sorted(cuts)
    return [stream[a:b] for a, b in zip([0, *edges], [*edges, len(stream)], strict=True)]


def some_cuts(data: st.DataObject, stream: bytes, most: int = 12) -> set[int]:
    return data.draw(st.sets(st.integers(0, len(stream)), max_size=most))


def check_pieces(pieces: Sequence[Piece], check_frame: CheckFrame) -> None:
    for piece in pieces:
        assert piece.data, "an empty piece"
        if isinstance(piece, Frame):
            check_frame(piece.data)


def assert_reset_hands_out_the_rest(
    framer: Framer, pieces: Sequence[Piece], fed: bytes, check_frame: CheckFrame
) -> None:
    rest = [*pieces, *_flush(framer)]
    check_pieces(rest, check_frame)
    assert covered(rest) == fed
    assert framer.buffered == 0


def any_chunking_covers_every_byte_once(
    new_framer: NewFramer,
    stream: bytes,
    cuts: set[int],
    check_frame: CheckFrame,
    *,
    max_buffered: int,
    heads: bytes | None = None,
) -> None:
    """Whole, in chunks, byte by byte: the same frames, and every byte covered once.

    A drained framer holds at most one unfinished candidate: at most ``max_buffered``
    bytes, starting with one of ``heads`` when the protocol has distinct start bytes.
    """
    whole, chunked, bytewise = new_framer(), new_framer(), new_framer()
    found = {
        "whole": (whole, feed_all(whole, [stream])),
        "chunked": (chunked, feed_all(chunked, cut(stream, cuts))),
        "bytewise": (bytewise, feed_all(bytewise, cut(stream, set(range(len(stream)))))),
    }
    for framer, pieces in found.values():
        check_pieces(pieces, check_frame)
        assert covered(pieces) == stream[: len(stream) - framer.buffered]
        assert framer.buffered <= max_buffered
        if heads is not None and framer.buffered:
            assert stream[len(stream) - framer.buffered] in heads
    # Without gaps, how the bytes arrived makes no difference to the frames found.
    assert frames(found["chunked"][1]) == frames(found["whole"][1])
    assert frames(found["bytewise"][1]) == frames(found["whole"][1])
    for framer, pieces in found.values():
        assert_reset_hands_out_the_rest(framer, pieces, stream, check_frame)


def resets_anywhere_keep_the_coverage(
    new_framer: NewFramer, steps: Sequence[bytes | None], check_frame: CheckFrame
) -> None:
    """``None`` is a gap the bus saw (``reset()``); bytes are a read, fed then drained."""
    framer = new_framer()
    pieces: list[Piece] = []
    fed = b""
    for step in steps:
        if step is None:
            framer.reset()
        else:
            framer.feed(step)
            fed += step
        pieces += drain(framer)
        check_pieces(pieces, check_frame)
        assert covered(pieces) == fed[: len(fed) - framer.buffered]
    assert_reset_hands_out_the_rest(framer, pieces, fed, check_frame)


def frames_between_clean_noise_all_come_out(
    new_framer: NewFramer, segments: Sequence[tuple[bytes, bytes]], tail: bytes, cuts: set[int]
) -> None:
    """Noise that holds no start byte cannot begin a candidate, so it can hide no frame."""
    stream = b"".join(noise + wire for noise, wire in segments) + tail
    framer = new_framer()
    pieces = feed_all(framer, cut(stream, cuts)) + _flush(framer)
    assert covered(pieces) == stream
    assert frames(pieces) == [wire for _, wire in segments]
    skipped = [piece for piece in pieces if isinstance(piece, Skipped)]
    assert {piece.reason for piece in skipped} <= {SkipReason.NOISE}
    assert covered(skipped) == b"".join(noise for noise, _ in segments) + tail


def after_a_gap_every_frame_comes_out(
    new_framer: NewFramer, data: st.DataObject, rounds: Sequence[tuple[bytes, Sequence[bytes]]]
) -> None:
    """Rounds of noise (start bytes and all), a gap the bus measured, then good frames.

    Noise may by chance hold a frame of its own, so the honest claim is about positions:
    no frame spans a gap, and from each gap on, the frames are exactly the ones sent.
    """
    framer = new_framer()
    pieces: list[Piece] = []
    fed = b""
    gaps: list[int] = []
    expected: dict[int, bytes] = {}  # offset in the stream → the frame sent there
    regions: list[range] = []  # from each gap to the end of that round's frames
    for noise, wires in rounds:
        for part in (noise, None, *wires):
            if part is None:
                framer.reset()
                gaps.append(len(fed))
                continue
            if part is not noise:
                expected[len(fed)] = part
            split = data.draw(st.integers(0, len(part)))
            for chunk in (part[:split], part[split:]):
                framer.feed(chunk)
                fed += chunk
                if data.draw(st.booleans()):
                    pieces += drain(framer)
        regions.append(range(gaps[-1], len(fed)))
    pieces += _flush(framer)
    assert covered(pieces) == fed

    found: dict[int, bytes] = {}
    offset = 0
    for piece in pieces:
        start, end = offset, offset + len(piece.data)
        offset = end
        if isinstance(piece, Frame):
            assert not any(start < gap < end for gap in gaps), f"frame spans a gap: {piece}"
            found[start] = piece.data
    for start, wire in expected.items():
        assert found.get(start) == wire, f"frame at offset {start} lost"
    for start, wire in found.items():
        if any(start in region for region in regions):
            assert start in expected, f"invented frame {wire!r} at offset {start}"


def _flush(framer: Framer) -> list[Piece]:
    """What is left after the line falls quiet: drain, reset, drain."""
    pieces = drain(framer)
    framer.reset()
    return pieces + drain(framer)
