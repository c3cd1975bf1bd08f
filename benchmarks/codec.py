"""Wall-clock cost of the FC codec per parameter telegram: encode, frame, decode, scale.

Run: ``python benchmarks/codec.py [--iterations N] [--repeats R]``. One round trip is what
the bus does for every parameter reply, plus the encode the simulator does to produce it:

    encode_telegram → FcFramer.feed → FcFramer.next_frame → decode_telegram →
    lookup + raw_from_pwe + to_value

The figure printed is the median over ``repeats`` runs of ``iterations`` round trips, in
microseconds per telegram. At 115200 baud a 16-byte telegram takes ~1530 µs on the wire,
so the codec's share of a transaction is what this measures against.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from fcmaster.protocol.danfoss_fc import (
    FcFramer,
    ResponseAk,
    Telegram,
    decode_telegram,
    encode_telegram,
    lookup,
)
from fcmaster.protocol.framing import Frame

# A drive's reply to a read of 16-14 Motor Current: AK 2, PNU 0x64E, 524 = 5.24 A.
REPLY = Telegram(address=1, pke=0x264E, pwe=524, pcd1=0x0F03, pcd2=0x2000)


def round_trip(framer: FcFramer, telegram: Telegram) -> float:
    """One telegram through the whole codec; returns the scaled value."""
    framer.feed(encode_telegram(telegram))
    frame = framer.next_frame()
    if not isinstance(frame, Frame):
        raise AssertionError(f"expected a frame, got {frame!r}")
    decoded = decode_telegram(frame.data, from_drive=True)
    spec = lookup(decoded.pnu)
    raw = spec.raw_from_pwe(decoded.pwe, double_word=decoded.ak == ResponseAk.VALUE_DWORD)
    return spec.to_value(raw)


def time_once(iterations: int) -> float:
    """Seconds for ``iterations`` round trips."""
    framer = FcFramer()
    telegram = REPLY
    start = time.perf_counter()
    for _ in range(iterations):
        round_trip(framer, telegram)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    """Print the median microseconds per telegram."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--iterations", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)

    value = round_trip(FcFramer(), REPLY)
    if abs(value - 5.24) > 1e-9:
        raise AssertionError(f"the codec decoded {value}, not 5.24 A")
    time_once(args.iterations // 10)  # warm up
    runs_us = [time_once(args.iterations) / args.iterations * 1e6 for _ in range(args.repeats)]
    median = statistics.median(runs_us)
    print(
        f"FC parameter telegram (encode + frame + decode + scale): {median:.2f} µs median "
        f"over {args.repeats} × {args.iterations:,} "
        f"(min {min(runs_us):.2f}, max {max(runs_us):.2f}; Python {sys.version.split()[0]})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
