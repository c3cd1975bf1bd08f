"""What an adapter may use of the daemon: the seam between adapters and the service."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from fcmaster.bus.commands import Command, CommandResult
from fcmaster.bus.frame_log import FramesSince
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import Clock
from fcmaster.hub import Hub
from fcmaster.state import FleetState


@dataclass(slots=True, frozen=True, kw_only=True)
class LineInfo:
    """One line as the adapters show it."""

    name: str
    port: str
    protocol: str
    baudrate: int
    up: bool
    drives: tuple[str, ...]
    stats: dict[str, Any]
    adapter: dict[str, Any] | None = None  # the USB adapter behind a local port, once open

    def to_json(self) -> dict[str, Any]:
        """The public JSON shape of a line."""
        return {
            "name": self.name,
            "port": self.port,
            "protocol": self.protocol,
            "baudrate": self.baudrate,
            "up": self.up,
            "drives": list(self.drives),
            "stats": self.stats,
            "adapter": self.adapter,
        }


class Gateway(Protocol):
    """The daemon as adapters see it (the Service meets this)."""

    @property
    def clock(self) -> Clock:
        """The daemon's clock: what adapters wait on and stamp their messages with."""

    @property
    def hub(self) -> Hub:
        """Where fleet events are published."""

    @property
    def fleet(self) -> FleetState:
        """The latest snapshot of every drive."""

    def drive_plan(self, name: str) -> DrivePlan | None:
        """A drive's configuration (limits, nominal frequency, control), or None."""

    def lines(self) -> list[LineInfo]:
        """Every line with its statistics."""

    def line_frames(self, name: str, since: int) -> tuple[LinePlan, FramesSince] | None:
        """Line ``name``'s plan and its frames numbered ``since`` and after; None: no line."""

    async def execute(self, drive: str, command: Command) -> CommandResult:
        """Carry out ``command`` on drive ``drive``; one result, always."""

    def config_status(self) -> dict[str, Any]:
        """The running config: ``hash``, ``loaded_at``, ``last_reload``, ``reloads``."""

    def opcua_status(self) -> dict[str, Any] | None:
        """The OPC UA server: ``listen``, ``up``, ``restarts``, ``sessions``; None: no opcua:."""

    async def events(
        self,
        *,
        since: float | None = None,
        kind: str | None = None,
        drive: str | None = None,
        limit: int = 100,
    ) -> list[dict[str, Any]]:
        """The journal's newest ``limit`` records matching the filters, oldest first."""
