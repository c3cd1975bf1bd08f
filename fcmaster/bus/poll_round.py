"""How long a line takes to poll every drive once, at worst: the figure watchdogs are held to.

``fcmaster check`` prints it, and each drive's communication watchdog is judged against
it (:mod:`fcmaster.bus.watchdog`): a drive whose timeout is shorter trips in normal polling.
``check`` also prints what a round costs when every other drive has stopped answering
(:func:`stranded_s`), the case a round of answering drives does not cover.
"""

from __future__ import annotations

from collections.abc import Iterator

from fcmaster.bus.codecs import codec_for, monitor_keys
from fcmaster.bus.plan import LinePlan
from fcmaster.protocol.codec import Exchange

__all__ = ["poll_round_s", "stranded_s"]


def poll_round_s(plan: LinePlan) -> tuple[float, float]:
    """Worst-case seconds for one poll of every drive, and for a full monitor refresh.

    Every drive is assumed to answer, each after the line's response delay.
    """
    pause = plan.pause_s if plan.pause_s is not None else codec_for(plan).min_pause_s(plan.char_s)
    one_round = full_refresh = 0.0
    for polls in _polls(plan):
        times = [
            plan.wire_s(len(poll.request) + poll.reply_length) + plan.response_delay_s + pause
            for poll in polls
        ]
        one_round += max(times)
        full_refresh += sum(times)
    return one_round, full_refresh


def stranded_s(plan: LinePlan) -> float:
    """The longest a drive may wait for its poll once every other drive stopped answering.

    A cabinet's supply or a feeder switched off: each of the others is tried once before a
    drive still on is asked again (:mod:`~fcmaster.bus.misses`; after that it is polled
    between their misses), and each miss costs the line the reply's deadline and the wait
    for a late reply after it. Counted with the plan's fixed deadline (``timeout_s``, or the
    one a line starts with), so it is an upper bound: once the line has timed its drives'
    answers, the deadline follows them and is mostly shorter.
    """
    misses = [
        max(plan.miss_s(len(poll.request), poll.reply_length) for poll in polls)
        for polls in _polls(plan)
    ]
    return sum(misses) - min(misses) if misses else 0.0


def _polls(plan: LinePlan) -> Iterator[list[Exchange]]:
    """Each drive's polls, in the order of the plan's drives."""
    codec = codec_for(plan)
    for drive in plan.drives:
        monitor = monitor_keys(codec, drive)
        yield [codec.poll(drive.address, None, read) for read in codec.poll_sequence(monitor)]
