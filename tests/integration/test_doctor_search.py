"""The doctor's search in-process, against a simulated line that judges parity.

A pty carries no parity (Linux drops PARENB from a pty's settings), so a drive set to odd
parity can only be rehearsed here: the transport tells the simulated line the master's baud
rate and parity, and the line misframes every character sent at another.
"""

from __future__ import annotations

from fcmaster.bus.plan import LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.sim import DriveSettings, LineSettings, build_line
from fcmaster.sim.transport import SimTransport
from fcmaster.subcommands.diagnosis import Expected, LineFormat, diagnose
from fcmaster.subcommands.doctor import examine
from fcmaster.transport.pipe import Transport


async def test_drives_at_odd_parity_are_found_after_even_and_the_config_told() -> None:
    clock = MonotonicClock()
    line = build_line(
        LineSettings(protocol="danfoss-fc", baudrate=115200, parity="O"),
        [(1, DriveSettings()), (2, DriveSettings())],
        clock=clock,
    )
    heard_at: list[tuple[int, str]] = []

    def open_transport(plan: LinePlan) -> Transport:
        heard_at.append((plan.baudrate, plan.parity))
        line.hear_master_at(plan.baudrate, plan.parity)
        return SimTransport(line, clock)

    config = Expected(
        bus="north",
        line=LineFormat(
            protocol="danfoss-fc",
            baudrate=115200,
            parity="E",
            stopbits=1,
            protocol_options=(("address_format", 126),),
        ),
        echo=False,
    )
    survey = await examine(
        "sim://north", protocols=("danfoss-fc",), addresses=[1, 2, 3], expected=config,
        open_transport=open_transport,
    )  # fmt: skip
    assert heard_at == [(115200, "E"), (115200, "O")]  # the factory parity first, then odd
    assert line.counters.misframed_bytes > 0  # the even-parity polls reached no drive
    assert survey.found is not None
    assert (survey.found.baudrate, survey.found.parity) == (115200, "O")
    assert survey.drives == [1, 2]
    [finding] = diagnose(survey)
    assert finding.code == "settings"
    assert finding.fix == "set parity: O on bus north"
