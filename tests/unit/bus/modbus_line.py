"""A Modbus RTU line of simulated drives behind a scripted wire, in virtual time.

The drives are the simulator's (each enforcing its profile's state machine); a line outlives
the masters that poll it, so a test can restart the gateway and find the drives as a former
master left them.
"""

from __future__ import annotations

import random

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.sim.modbus_rtu.drive import ModbusSimDrive
from fcmaster.sim.settings import DriveSettings, LineSettings
from tests.fakes import ScriptedTransport, Timed, VirtualClock


class SimLine:
    """The simulated drives of a line, answering on a scripted wire."""

    def __init__(self, clock: VirtualClock, char_s: float, *drives: ModbusSimDrive) -> None:
        self.clock = clock
        self.char_s = char_s
        self.drives = {d.address: d for d in drives}

    def __call__(self, request: bytes) -> bytes | Timed | None:
        drive = self.drives.get(request[0])
        if drive is None:
            return None
        char_s = self.char_s
        ended = self.clock.now() + len(request) * char_s
        reply = drive.handle(request, ended)
        if reply is None:
            return None
        return Timed(
            ((len(request) * char_s + drive.response_delay_s + len(reply) * char_s, reply),)
        )

    @property
    def unheard(self) -> int:
        """Requests a drive did not hear, busy after a parameter write."""
        return sum(d.unheard for d in self.drives.values())


def sim_line(
    clock: VirtualClock,
    baudrate: int,
    *drives: DrivePlan,
    settings: dict[int, DriveSettings] | None = None,
) -> SimLine:
    """A simulated drive for each of ``drives``, by its profile (``settings`` by address)."""
    line = LineSettings(protocol="modbus-rtu", baudrate=baudrate)
    sims = [
        ModbusSimDrive(
            d.address,
            (settings or {}).get(d.address, DriveSettings(profile=d.profile)),
            now=clock.now(),
            line=line,
        )
        for d in drives
    ]
    return SimLine(clock, line.char_bits / baudrate, *sims)


def master_on(
    line: SimLine, baudrate: int, *drives: DrivePlan
) -> tuple[ScriptedTransport, BusMaster]:
    """A master polling ``drives`` on ``line``, over a scripted wire."""
    plan = LinePlan(
        name="line1", port="scripted", protocol="modbus-rtu", baudrate=baudrate, drives=drives
    )
    transport = ScriptedTransport(line.clock, line, char_s=line.char_s)
    master = BusMaster(
        plan, codec=codec_for(plan), transport=transport, clock=line.clock, rng=random.Random(1)
    )
    return transport, master


__all__ = ["SimLine", "master_on", "sim_line"]
