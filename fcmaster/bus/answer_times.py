"""How long a line's drives take to answer, and so how long to wait for a reply.

Until a line has timed a few replies, the deadline for one is the plan's conservative one
(wire time, response delay and a 50 ms margin). Then it is the wire time, the drive's
response delay (or the answer time measured, if longer) and a margin of four times the
measured spread of answer times (rising fast, falling slowly, and counting replies that
came after their deadline), as TCP sets its retransmission timeout, but at least the
answer time once more, so a lost reply costs about two transactions instead of a fixed
margin. ``timeout_s`` in the config overrides both.
"""

from __future__ import annotations

from fcmaster.bus.plan import LinePlan

ANSWER_SAMPLES = 8  # replies timed before deadlines follow the line


class AnswerTimes:
    """A line's answer times (latency beyond the wire time): smoothed mean and spread."""

    def __init__(self, plan: LinePlan) -> None:
        self.plan = plan
        self.mean_s = 0.0
        self.spread_s = 0.0
        self.count = 0

    def deadline_s(self, request_length: int, reply_length: int) -> float:
        """Seconds from writing a request to giving up on its reply."""
        plan = self.plan
        fixed = plan.reply_timeout(request_length, reply_length)
        if plan.timeout_s is not None or self.count < ANSWER_SAMPLES:
            return fixed
        wire = plan.wire_s(request_length + reply_length)
        answer = max(plan.response_delay_s, self.mean_s)
        # The margin is at least the answer time itself: a host's scheduling hiccup or an
        # adapter's latency timer can delay a reply by that much without the spread having
        # shown it yet.
        margin = max(4.0 * self.spread_s, self.mean_s, plan.gap_s)
        return min(fixed, wire + answer + margin)

    def timed(self, answer_s: float) -> None:
        """Fold one reply's answer time into the estimate."""
        if self.count == 0:
            self.mean_s, self.spread_s = answer_s, answer_s / 2
        else:
            # The spread rises fast and falls slowly: one slow answer (a loaded host, a USB
            # adapter's latency timer) keeps the margin wide for a while.
            error = abs(answer_s - self.mean_s)
            self.spread_s += (error - self.spread_s) / (4 if error > self.spread_s else 16)
            self.mean_s += (answer_s - self.mean_s) / 8
        self.count += 1
