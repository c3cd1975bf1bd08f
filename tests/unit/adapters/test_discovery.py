from fcmaster.adapters.discovery import Discovery
from fcmaster.adapters.mqtt_topics import Topics
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.state import FleetState

PUMP = DrivePlan(name="pump-1", address=1, control=True)


def _components(controls: bool) -> set[str]:
    fleet = FleetState(
        (LinePlan(name="line1", port="sim://line1", drives=(PUMP,)),),
        emit=lambda _: None,
        clock=MonotonicClock(),
    )
    state = fleet.get("line1", "pump-1")
    assert state is not None
    configs = Discovery(Topics("fcmaster", None), "homeassistant", controls=controls).drive(
        state, PUMP
    )
    return {topic.split("/")[1] for topic, _ in configs}


def test_buttons_only_where_commands_need_no_token() -> None:
    assert {"button", "number"} <= _components(controls=True)
    assert _components(controls=False) == {"sensor", "binary_sensor"}
