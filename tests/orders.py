"""Commands for one drive of a BusMaster, written as a test reads them best.

The daemon has one way to command a drive: a :class:`~fcmaster.bus.commands.Command` handed
to ``BusMaster.execute`` (the adapters reach it through ``Gateway.execute``). These helpers
build the same commands, so ``await orders(master, "d1").start(frequency_hz=25.0)`` is
``await master.execute("d1", Command(action=Action.START, reference_pct=50.0))`` on a
drive whose nominal frequency is 50 Hz.
"""

from __future__ import annotations

from fcmaster.bus.commands import Action, Command, CommandResult
from fcmaster.bus.master import BusMaster


class Orders:
    """The commands of one drive of a running BusMaster; each returns its one result."""

    __slots__ = ("_master", "name", "nominal_frequency_hz")

    def __init__(self, master: BusMaster, name: str) -> None:
        self._master = master
        self.name = name
        self.nominal_frequency_hz = master.planner.slot(name).plan.nominal_frequency_hz

    async def execute(self, command: Command) -> CommandResult:
        """Carry out any command."""
        return await self._master.execute(self.name, command)

    def _pct(self, frequency_hz: float | None, reference_pct: float | None) -> float | None:
        if frequency_hz is not None:
            return frequency_hz / self.nominal_frequency_hz * 100.0
        return reference_pct

    async def start(
        self, *, frequency_hz: float | None = None, reference_pct: float | None = None
    ) -> CommandResult:
        """Run, optionally at a new reference."""
        pct = self._pct(frequency_hz, reference_pct)
        return await self.execute(Command(action=Action.START, reference_pct=pct))

    async def set_reference(
        self, *, frequency_hz: float | None = None, reference_pct: float | None = None
    ) -> CommandResult:
        """Change the reference without changing the motion."""
        pct = self._pct(frequency_hz, reference_pct)
        return await self.execute(Command(action=Action.SET_REFERENCE, reference_pct=pct))

    async def stop(self) -> CommandResult:
        """Ramp down and stay ready."""
        return await self.execute(Command(action=Action.STOP))

    async def coast(self) -> CommandResult:
        """Switch the output off."""
        return await self.execute(Command(action=Action.COAST))

    async def quick_stop(self) -> CommandResult:
        """Ramp down on the quick-stop ramp."""
        return await self.execute(Command(action=Action.QUICK_STOP))

    async def reset(self) -> CommandResult:
        """Acknowledge a trip."""
        return await self.execute(Command(action=Action.RESET))

    async def forward(self) -> CommandResult:
        """Turn forward."""
        return await self.execute(Command(action=Action.FORWARD))

    async def reverse(self) -> CommandResult:
        """Turn in reverse."""
        return await self.execute(Command(action=Action.REVERSE))

    async def jog(self) -> CommandResult:
        """Run at the jog speed."""
        return await self.execute(Command(action=Action.JOG))

    async def read(self, parameter: str, *, index: int = 0) -> CommandResult:
        """Read a parameter; the value is in ``result.value``."""
        return await self.execute(Command(action=Action.READ, parameter=parameter, index=index))

    async def write(
        self, parameter: str, value: float, *, index: int = 0, persist: bool = False
    ) -> CommandResult:
        """Write a parameter (``persist``: to non-volatile memory too)."""
        return await self.execute(
            Command(
                action=Action.WRITE, parameter=parameter, index=index, value=value, persist=persist
            )
        )


def orders(master: BusMaster, name: str) -> Orders:
    """The commands of drive ``name`` of ``master``; KeyError if the line has none."""
    return Orders(master, name)
