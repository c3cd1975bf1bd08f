"""How long a line takes to poll every drive once, at worst: the figure watchdogs are held to.

``fcmaster check`` prints it, and each drive's communication watchdog is judged against
it (:mod:`fcmaster.bus.watchdog`): a drive whose timeout is shorter trips in normal polling.
"""

from __future__ import annotations

from fcmaster.bus.codecs import codec_for, monitor_keys
from fcmaster.bus.plan import LinePlan

__all__ = ["poll_round_s"]


def poll_round_s(plan: LinePlan) -> tuple[float, float]:
    """Worst-case seconds for one poll of every drive, and for a full monitor refresh.

    Every drive is assumed to answer, each after the line's response delay.
    """
    codec = codec_for(plan)
    pause = plan.pause_s if plan.pause_s is not None else codec.min_pause_s(plan.char_s)
    one_round = full_refresh = 0.0
    for drive in plan.drives:
        monitor = monitor_keys(codec, drive)
        times = []
        for read in codec.poll_sequence(monitor):
            exchange = codec.poll(drive.address, None, read)
            wire = plan.wire_s(len(exchange.request) + exchange.reply_length)
            times.append(wire + plan.response_delay_s + pause)
        one_round += max(times)
        full_refresh += sum(times)
    return one_round, full_refresh
