"""What a BusMaster tells the layers above it: the observer it reports to."""

from __future__ import annotations

from typing import Protocol

from fcmaster.bus.commands import Command, CommandResult
from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.drive import ControlIntent


class BusObserver(Protocol):
    """Where a BusMaster reports what it learns. Calls must be quick and never block."""

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        """A valid reply from ``drive`` on ``bus`` arrived at monotonic time ``at``.

        ``commanded`` is what the master now commands the drive (None: nothing).
        """

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        """``drive`` came online or was demoted."""

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        """The line's port opened or was lost."""

    def command_completed(
        self, bus: str, drive: str, command: Command, result: CommandResult
    ) -> None:
        """A command for ``drive`` ("*": the whole line) ended."""


class NullObserver:
    """Hears everything and does nothing (a line nobody listens to)."""

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        """Nothing to do."""

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        """Nothing to do."""

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        """Nothing to do."""

    def command_completed(
        self, bus: str, drive: str, command: Command, result: CommandResult
    ) -> None:
        """Nothing to do."""
