"""The codec's writes and the simulated drives' state machines agree, whatever the order.

For every built-in profile, any sequence of commands — runs at any reference and in either
direction, stops, coasts, quick stops, resets — leaves the simulated drive running exactly
when the last command was a run, with the steady word fed between commands as the polls
feed it. A start that skipped a state, or a feed that broke one, would show here.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.modbus_rtu.codec import ModbusCodec
from fcmaster.protocol.modbus_rtu.keys import CONTROL_FEED
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.sim.modbus_rtu import ModbusSimDrive
from fcmaster.sim.motor import Mode
from fcmaster.sim.settings import DriveSettings

intents = st.builds(
    ControlIntent,
    motion=st.sampled_from([Motion.RUN, Motion.RUN, Motion.STOP, Motion.COAST, Motion.QUICK_STOP]),
    reverse=st.booleans(),
    reference_pct=st.integers(0, 100).map(float),
    reset=st.booleans(),
)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(tuple(BUILT_IN)), st.lists(intents, min_size=1, max_size=8))
def test_the_drive_runs_exactly_when_last_told_to(
    profile: str, sequence: list[ControlIntent]
) -> None:
    codec = ModbusCodec({1: BUILT_IN[profile]}, {1: 50.0})
    sim = ModbusSimDrive(1, DriveSettings(profile=profile), now=0.0)
    now = 0.0

    def send(request: bytes) -> None:
        nonlocal now
        now += 0.01
        answer = sim.handle(request, now)
        assert answer is not None

    for intent in sequence:
        try:
            exchanges = codec.control(1, intent)
        except UsageError:
            continue  # a command the profile does not offer is refused before the wire
        for exchange in exchanges:
            send(exchange.request)
        steady = ControlIntent(intent.motion, intent.reverse, intent.reference_pct)
        for _ in range(2):  # the polls that follow feed the steady word
            send(codec.poll(1, steady, CONTROL_FEED).request)
        wanted_run = intent.motion is Motion.RUN
        assert (sim.machine.mode is Mode.RUN) == wanted_run, (profile, intent, sim.machine.state)
