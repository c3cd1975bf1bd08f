from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.codec import (
    Condition,
    ConditionReport,
    DriveStatus,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.state import (
    AvailabilityChanged,
    ConditionChanged,
    DriveState,
    DriveUpdated,
    Event,
    FleetState,
)
from tests.fakes import FakeClock

PUMP = DrivePlan(name="pump-1", address=1, control=True, nominal_frequency_hz=60.0)
FAN = DrivePlan(name="fan-1", address=2)
LINE = LinePlan(name="line1", port="sim://line1", drives=(PUMP, FAN))
WALL_AT_START = 1_790_000_000.0


def _fleet() -> tuple[FleetState, list[Event], FakeClock]:
    events: list[Event] = []
    clock = FakeClock(start=500.0, epoch=WALL_AT_START - 500.0)
    fleet = FleetState((LINE,), emit=events.append, clock=clock)
    return fleet, events, clock


def _get(fleet: FleetState, name: str) -> DriveState:
    state = fleet.get("line1", name)
    assert state is not None
    return state


def _status(**flags: bool) -> DriveStatus:
    return DriveStatus(
        word=0x0F07,
        running=flags.get("running", False),
        fault=flags.get("fault", False),
        warning=flags.get("warning", False),
        at_reference=flags.get("at_reference", False),
        reverse=flags.get("reverse"),
    )


def _alarms(source: str, *codes: int) -> Reply:
    return Reply(
        address=1,
        status=_status(fault=bool(codes)),
        conditions=ConditionReport(
            kind="alarm", source=source, active=tuple(Condition(c, f"A{c}") for c in codes)
        ),
    )


def test_every_drive_starts_offline_with_the_public_json_keys() -> None:
    fleet, _, _ = _fleet()
    state = fleet.get("line1", "pump-1")
    assert state is not None
    assert set(state.to_json()) == {
        "name", "bus", "address", "protocol", "online", "control", "running", "fault",
        "warning", "direction", "at_reference", "output_frequency_hz",
        "output_frequency_updated_at", "reference_pct", "status_word", "status_bits", "values",
        "alarms",
        "warnings", "updated_at",
    }  # fmt: skip
    assert state.online is False
    assert state.control == "bus"
    assert fleet.get("line1", "fan-1") is not None
    assert _get(fleet, "fan-1").control == "monitor"


def test_a_reply_sets_status_frequency_and_the_time_it_arrived() -> None:
    fleet, events, clock = _fleet()
    # 50 % of a 60 Hz nominal, in the unit every codec reports it in
    reply = Reply(
        address=1, status=_status(running=True, at_reference=True), output_frequency_hz=30.0
    )
    clock.time = 510.0
    fleet.drive_replied("line1", PUMP, reply, 509.75, ControlIntent(Motion.RUN, False, 50.0))
    state = fleet.get("line1", "pump-1")
    assert state is not None
    assert state.online
    assert state.running
    assert state.at_reference
    assert state.output_frequency_hz == 30.0  # 50 % of a 60 Hz nominal
    assert state.reference_pct == 50.0
    assert state.status_word == 0x0F07
    # arrived 0.25 s before "now": wall 1_790_000_009.75 (`date -u -d @1790000009.75`)
    assert state.to_json()["updated_at"] == "2026-09-21T14:13:29.750Z"
    assert events[0] == AvailabilityChanged(bus="line1", drive="pump-1", online=True)
    assert isinstance(events[1], DriveUpdated)


def test_direction_comes_from_the_reply_or_else_from_the_command() -> None:
    fleet, _, _ = _fleet()
    fleet.drive_replied("line1", PUMP, Reply(address=1, status=_status(reverse=True)), 500.0, None)
    assert _get(fleet, "pump-1").direction == "reverse"
    intent = ControlIntent(Motion.STOP, reverse=False)
    fleet.drive_replied("line1", PUMP, Reply(address=1, status=_status()), 500.0, intent)
    assert _get(fleet, "pump-1").direction == "forward"


def test_a_signed_frequency_tells_the_direction_where_the_status_and_command_do_not() -> None:
    fleet, _, _ = _fleet()

    def frequency(hz: float, *, signed: bool, status: DriveStatus | None = None) -> str:
        reply = Reply(address=1, status=status, output_frequency_hz=hz, output_signed=signed)
        fleet.drive_replied("line1", PUMP, reply, 500.0, None)
        return _get(fleet, "pump-1").direction

    assert frequency(-20.0, signed=True) == "reverse"  # a V20's r0024, read on its own
    assert _get(fleet, "pump-1").output_frequency_hz == 20.0
    assert frequency(0.0, signed=True) == "reverse"  # at rest: no sign, nothing learned
    assert frequency(20.0, signed=True, status=_status()) == "forward"  # read with the status
    assert frequency(-20.0, signed=True, status=_status()) == "reverse"
    # a magnitude says nothing of the direction; a reverse bit or a command still wins
    assert frequency(20.0, signed=False) == "reverse"
    assert frequency(-20.0, signed=True, status=_status(reverse=False)) == "forward"
    intent = ControlIntent(Motion.RUN, reverse=True)
    reply = Reply(address=1, status=_status(), output_frequency_hz=5.0, output_signed=True)
    fleet.drive_replied("line1", PUMP, reply, 500.0, intent)
    assert _get(fleet, "pump-1").direction == "reverse"


def test_parameter_values_accumulate_by_name_and_index_each_with_its_own_time() -> None:
    fleet, _, _ = _fleet()
    key = ParameterKey("16-14", 1614)
    for index, value, at in ((0, 5.24, 500.5), (3, 1.5, 501.0)):
        value_read = ParameterValue(
            parameter=key, index=index, raw=None, value=value, unit="A", title="Motor Current"
        )
        fleet.drive_replied("line1", PUMP, Reply(address=1, value=value_read), at, None)
    values = _get(fleet, "pump-1").to_json()["values"]
    assert values == {
        "16-14": {
            "value": 5.24,
            "unit": "A",
            "name": "Motor Current",
            "updated_at": "2026-09-21T14:13:20.500Z",
        },
        "16-14[3]": {
            "value": 1.5,
            "unit": "A",
            "name": "Motor Current",
            "updated_at": "2026-09-21T14:13:21.000Z",
        },
    }


def test_a_frequency_read_apart_from_the_status_keeps_the_time_it_was_read() -> None:
    fleet, _, clock = _fleet()
    clock.time = 502.0
    fleet.drive_replied("line1", PUMP, Reply(address=1, output_frequency_hz=42.0), 501.0, None)
    fleet.drive_replied("line1", PUMP, Reply(address=1, status=_status()), 502.0, None)
    state = _get(fleet, "pump-1").to_json()
    assert (state["output_frequency_hz"], state["running"]) == (42.0, False)
    assert state["output_frequency_updated_at"] == "2026-09-21T14:13:21.000Z"
    assert state["updated_at"] == "2026-09-21T14:13:22.000Z"


def test_alarms_from_several_words_are_united_and_each_change_is_one_event() -> None:
    fleet, events, _ = _fleet()
    fleet.drive_replied("line1", PUMP, _alarms("16-90", 13, 14), 500.0, None)
    fleet.drive_replied("line1", PUMP, _alarms("16-91", 940), 500.0, None)
    state = fleet.get("line1", "pump-1")
    assert state is not None
    assert [c.code for c in state.alarms] == [13, 14, 940]
    raised = [e for e in events if isinstance(e, ConditionChanged)]
    assert [(e.code, e.active) for e in raised] == [(13, True), (14, True), (940, True)]
    events.clear()
    fleet.drive_replied("line1", PUMP, _alarms("16-90", 14), 500.0, None)
    changes = [(e.code, e.active) for e in events if isinstance(e, ConditionChanged)]
    assert changes == [(13, False)]
    assert [c.code for c in _get(fleet, "pump-1").alarms] == [14, 940]


def test_going_offline_keeps_the_last_values_and_emits_once() -> None:
    fleet, events, _ = _fleet()
    fleet.drive_replied("line1", FAN, Reply(address=2, status=_status(running=True)), 500.0, None)
    events.clear()
    fleet.drive_availability("line1", FAN, False, 501.0)
    fleet.drive_availability("line1", FAN, False, 502.0)
    state = fleet.get("line1", "fan-1")
    assert state is not None
    assert not state.online
    assert state.running  # last known, with its time
    assert events[0] == AvailabilityChanged(bus="line1", drive="fan-1", online=False)
    assert len([e for e in events if isinstance(e, AvailabilityChanged)]) == 1


def _updates(events: list[Event]) -> list[DriveUpdated]:
    return [e for e in events if isinstance(e, DriveUpdated)]


def test_an_unchanged_reply_is_not_published_until_the_heartbeat() -> None:
    fleet, events, clock = _fleet()
    steady = Reply(address=1, status=_status(running=True), output_frequency_hz=42.0)
    fleet.drive_replied("line1", PUMP, steady, 500.0, None)
    (first,) = _updates(events)
    assert set(first.changed) >= {"online", "running", "status_word", "output_frequency_hz"}
    events.clear()
    for n in range(1, 50):  # 4.9 s of polls every 0.1 s, nothing changes
        clock.time = 500.0 + n * 0.1
        fleet.drive_replied("line1", PUMP, steady, clock.time, None)
    assert events == []
    assert _get(fleet, "pump-1").updated_at == WALL_AT_START + 4.9  # the snapshot is fresh
    clock.time = 505.0
    fleet.drive_replied("line1", PUMP, steady, 505.0, None)
    (heartbeat,) = _updates(events)
    assert heartbeat.changed == ()
    assert heartbeat.state.updated_at == WALL_AT_START + 5.0


def test_a_drift_is_published_once_it_crosses_the_deadband_since_the_last_publication() -> None:
    fleet, events, clock = _fleet()  # PUMP: 60 Hz nominal, deadband 0.1 %: 0.06 Hz
    fleet.drive_replied("line1", PUMP, Reply(address=1, output_frequency_hz=30.0), 500.0, None)
    events.clear()
    published = []
    for n, hz in enumerate((30.02, 30.04, 30.06, 30.08, 30.1, 30.12), 1):
        clock.time = 500.0 + n * 0.1
        fleet.drive_replied("line1", PUMP, Reply(address=1, output_frequency_hz=hz), 500.0, None)
        published += [(hz, u.changed) for u in _updates(events)]
        events.clear()
    assert published == [(30.08, ("output_frequency_hz",))]


def test_a_status_bit_or_a_value_beyond_its_deadband_is_published_at_once() -> None:
    fleet, events, _ = _fleet()
    key = ParameterKey("16-14", 1614)

    def current(amps: float) -> Reply:
        value = ParameterValue(parameter=key, index=0, raw=None, value=amps, unit="A")
        return Reply(address=1, status=_status(), value=value)

    fleet.drive_replied("line1", PUMP, current(8.0), 500.0, None)
    events.clear()
    fleet.drive_replied("line1", PUMP, current(8.005), 500.0, None)  # 0.06 %: within
    assert events == []
    fleet.drive_replied("line1", PUMP, current(8.02), 500.0, None)  # 0.25 %: beyond
    assert [u.changed for u in _updates(events)] == [("values",)]
    events.clear()
    reply = Reply(address=1, status=_status(warning=True), value=current(8.02).value)
    fleet.drive_replied("line1", PUMP, reply, 500.0, None)
    assert [u.changed for u in _updates(events)] == [("warning",)]


def test_a_one_off_read_is_not_mixed_into_the_monitored_values() -> None:
    fleet, _, _ = _fleet()  # PUMP monitors the FC defaults: 16-13, 16-14, … 16-92
    ramp = ParameterValue(
        parameter=ParameterKey("3-41", 341), index=0, raw=500, value=5.0, unit="s"
    )
    current = ParameterValue(
        parameter=ParameterKey("16-14", 1614), index=0, raw=882, value=8.82, unit="A"
    )
    fleet.drive_replied("line1", PUMP, Reply(address=1, value=ramp), 500.0, None)
    fleet.drive_replied("line1", PUMP, Reply(address=1, value=current), 500.0, None)
    assert list(_get(fleet, "pump-1").values) == ["16-14"]


def test_an_alarm_word_shows_the_texts_of_its_conditions() -> None:
    fleet, _, _ = _fleet()
    word = ParameterValue(
        parameter=ParameterKey("16-92", 1692), index=0, raw=1 << 25, value=33554432.0, unit=""
    )
    report = ConditionReport(
        kind="warning", source="16-92", active=(Condition(25, "Current limit"),)
    )
    fleet.drive_replied("line1", PUMP, Reply(address=1, value=word, conditions=report), 500.0, None)
    assert _get(fleet, "pump-1").to_json()["values"]["16-92"]["texts"] == ["Current limit"]
    cleared = ConditionReport(kind="warning", source="16-92", active=())
    fleet.drive_replied(
        "line1", PUMP, Reply(address=1, value=word, conditions=cleared), 500.0, None
    )
    assert _get(fleet, "pump-1").to_json()["values"]["16-92"]["texts"] == []


def test_status_bits_are_named_as_each_protocol_s_manual_names_them() -> None:
    def bits(protocol: str, word: int) -> list[str]:
        state = DriveState(
            name="d", bus="l", address=1, protocol=protocol, control="monitor", status_word=word
        )
        return list(state.to_json()["status_bits"])

    assert bits("danfoss-fc", 0x0808) == ["trip", "running"]  # bits 3 and 11
    assert bits("mitsubishi", 0x4B) == ["run", "forward", "su", "fu"]
    assert bits("enc", 0x11) == ["running", "normal_run"]
    assert DriveState(name="d", bus="l", address=1, protocol="enc", control="bus").status_bits == []


def test_an_unchanged_reading_still_refreshes_the_times_the_snapshot_shows() -> None:
    fleet, events, clock = _fleet()
    current = ParameterValue(
        parameter=ParameterKey("16-14", 1614), index=0, raw=882, value=8.82, unit="A"
    )
    steady = Reply(address=1, status=_status(running=True), output_frequency_hz=30.0, value=current)
    fleet.drive_replied("line1", PUMP, steady, 500.0, None)
    events.clear()
    clock.time = 501.5
    fleet.drive_replied("line1", PUMP, Reply(address=1, status=_status(running=True)), 501.0, None)
    fleet.drive_replied("line1", PUMP, steady, 501.5, None)
    assert events == []  # nothing a subscriber could see changed
    state = _get(fleet, "pump-1")
    assert (state.updated_at, state.output_frequency_updated_at) == (
        WALL_AT_START + 1.5,
        WALL_AT_START + 1.5,
    )
    assert state.values["16-14"].updated_at == WALL_AT_START + 1.5
    assert fleet.snapshot()[0] is state  # built once, then kept until the next reply


def test_the_json_shows_an_fc_output_step_to_the_thousandth_of_a_hz() -> None:
    # 8191 of 16384 steps of a 50 Hz nominal is 24.99694824... Hz: shown as people read it.
    def shown(hz: float | None) -> object:
        state = DriveState(
            name="p", bus="l", address=1, protocol="danfoss-fc", control="bus",
            output_frequency_hz=hz,
        )  # fmt: skip
        return state.to_json()["output_frequency_hz"]

    assert shown(8191 / 16384 * 50) == 24.997
    assert shown(None) is None
