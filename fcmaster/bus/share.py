"""How long commands may keep the line from the round's polls.

Commands go before polls (DESIGN's order of service), so clients sending one command after
another (a slider dragged, a script in a loop, two SCADA screens) would hold the line for as
long as they keep on: no other drive is polled, their values grow old while still shown as
read, and their control-word watchdogs trip. So once commands have followed each other for
:data:`BURST_S` (no pause as long between two of them), a command that would follow a
command waits for one poll of the round: they take turns, one exchange each, until the
commands stop. A stop still goes first, and a command whose exchanges have begun
finishes them (a poll between the steps of an enable sequence would write the drive's old
control word). A plant's commands, a few exchanges each, never meet the rule; a flood of
them costs each other drive at most twice its round.
"""

from __future__ import annotations

from typing import Final

from fcmaster.bus.steps import Pending

BURST_S: Final = 0.25  # about 20 exchanges at 19200 baud: any one command's whole sequence


class CommandShare:
    """When the round's next poll goes before the next command."""

    __slots__ = ("after_command", "burst_at", "last_at")

    def __init__(self) -> None:
        # Kept by the planner as each step goes out (Planner.commit).
        self.burst_at = 0.0  # since when commands have followed each other
        self.last_at = float("-inf")  # when the last command's exchange went out
        self.after_command = False  # the last step sent was a command's

    def command_sent(self, now: float) -> None:
        """A command's exchange went out."""
        if now - self.last_at >= BURST_S:
            self.burst_at = now  # the line had a pause: a new run of commands
        self.last_at = now
        self.after_command = True

    def poll_first(self, pending: Pending, now: float) -> bool:
        """Whether a poll goes before ``pending``, the command the queue would send next."""
        return (
            self.after_command
            and now - self.burst_at >= BURST_S
            and now - self.last_at < BURST_S
            and not pending.command.action.is_urgent
            and pending.part == 0
            and pending.attempts == 0
        )
