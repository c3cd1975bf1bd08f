"""Negative speeds on the command line: refused before the port opens, for every protocol.

A frequency or reference is a magnitude on every surface; the direction changes only with
``forward`` or ``reverse``. ``fcmaster control … start --frequency -5`` once ran an FC drive
backwards at 5 Hz. Each command here runs as its own process against simulated drives at
the protocol's factory settings on a pseudo-terminal, and the test watches the line: no
byte may reach it and no drive may hear a request.
"""

from __future__ import annotations

import pytest

from fcmaster.protocol.registry import NAMES, spec_for
from fcmaster.sim import DriveSettings, LineSettings
from tests.integration import commissioning

# (action, option, value, what the message says it means at the default nominal 50 Hz)
NEGATIVE = [
    ("start", "--frequency", "-5", "-5 Hz"),
    ("set-reference", "--frequency", "-5", "-5 Hz"),
    ("reverse", "--reference", "-20", "-10 Hz"),
    ("start", "--reference", "-20", "-10 Hz"),
]


@pytest.mark.parametrize("protocol", NAMES)
async def test_a_negative_frequency_or_reference_never_reaches_the_wire(protocol: str) -> None:
    factory = spec_for(protocol).factory
    line = LineSettings(
        protocol=protocol,
        baudrate=factory.baudrate,
        parity=factory.parity,
        stopbits=factory.stopbits,
    )
    address = spec_for(protocol).addresses().start + 1
    async with commissioning.served(line, [(address, DriveSettings())]) as server:
        written: list[bytes] = []
        write = server.line.write

        def recording(data: bytes) -> None:
            written.append(data)
            write(data)

        server.line.write = recording  # type: ignore[method-assign]
        for action, option, value, hz in NEGATIVE:
            code, out, err = await commissioning.fcmaster(
                server, protocol, "control", "--address", str(address), action, option, value
            )
            assert code == 2, (action, option, out, err)
            assert "Traceback" not in err
            assert f"{option} {value} ({hz}) is a magnitude" in err
            assert "forward or reverse" in err
            assert "done" not in out
        assert written == []
        assert server.line.counters.requests == 0
        assert not server.line.transactions
