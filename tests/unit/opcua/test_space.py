"""The address space: a drive's Values/ exist from the start, waiting for their first reading."""

from __future__ import annotations

from typing import Any

import pytest
import structlog.testing
from asyncua import Server, ua

from fcmaster.adapters.opcua import value_names
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.opcua.space import Space

NAMES = ["Frequency", "Motor Current"]


async def _refused(drive: str, method: str, command: dict[str, Any]) -> ua.StatusCode:
    return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)


@pytest.fixture
async def space() -> Space:
    server = Server()
    await server.init()  # the address space only: nothing listens
    made = Space(server, _refused)
    drives = [{"name": "pump-1", "bus": "line1", "values": NAMES}]
    await made.build(drives, [{"name": "line1", "counters": []}])
    return made


async def _read(space: Space, path: str) -> tuple[Any, int]:
    """The value and status code of a variable (read inside: a Bad one is no error)."""
    node_id = ua.NodeId(f"Drives/pump-1/{path}", space.ns)
    shown = space.server.read_attribute_value(node_id)
    assert shown.Value is not None
    assert shown.StatusCode is not None
    return shown.Value.Value, shown.StatusCode.value


async def _names(space: Space) -> list[str]:
    folder = space.server.get_node(ua.NodeId("Drives/pump-1/Values", space.ns))
    return [(await child.read_browse_name()).Name for child in await folder.get_children()]


def test_value_names_are_the_manual_names_of_the_monitor_list() -> None:
    monitored = DrivePlan(name="pump-1", address=1, monitor=("16-13", "16-14", "16-13"))
    line = LinePlan(name="line1", port="sim://x", drives=(monitored,))
    assert value_names(line, monitored) == NAMES  # as the drive state names them, once each
    default = DrivePlan(name="pump-2", address=2)
    names = value_names(LinePlan(name="line1", port="sim://x", drives=(default,)), default)
    assert "Motor Current" in names
    assert all(names)


async def test_values_never_read_wait_for_their_first_reading(space: Space) -> None:
    assert await _names(space) == NAMES
    for name in NAMES:
        shown = await _read(space, f"Values/{name}")
        assert shown == (None, ua.StatusCodes.BadWaitingForInitialData)
    await space.update_line({"name": "line1", "up": True})
    entry = {"name": "pump-1", "online": True, "at": 1000.0,
             "values": {"Motor Current": [3.5, 1000.0], "Type": ["FC-302", 1000.0]}}  # fmt: skip
    await space.update_drive(entry)
    assert await _read(space, "Values/Motor Current") == (3.5, ua.StatusCodes.Good)
    frequency = await _read(space, "Values/Frequency")  # not read yet: still waiting
    assert frequency == (None, ua.StatusCodes.BadWaitingForInitialData)
    typed = await _read(space, "Values/Type")  # one not in the list comes as it is read
    assert typed == ("FC-302", ua.StatusCodes.Good)
    assert await _names(space) == [*NAMES, "Type"]


async def test_a_listed_value_that_reads_as_text_says_so_in_its_data_type(space: Space) -> None:
    await space.update_line({"name": "line1", "up": True})
    entry = {"name": "pump-1", "online": True, "at": 1000.0,
             "values": {"Frequency": ["n/a", 1000.0]}}  # fmt: skip
    await space.update_drive(entry)
    assert await _read(space, "Values/Frequency") == ("n/a", ua.StatusCodes.Good)
    node = space.server.get_node(ua.NodeId("Drives/pump-1/Values/Frequency", space.ns))
    assert await node.read_data_type() == ua.NodeId(ua.ObjectIds.String)
    made_so = space.server.get_node(ua.NodeId("Drives/pump-1/Values/Motor Current", space.ns))
    assert await made_so.read_data_type() == ua.NodeId(ua.ObjectIds.Double)


async def _call(space: Space, on: str, method: str, *args: ua.Variant) -> ua.StatusCode:
    """Call ``method`` of pump-1 on the object ``on``, as a client would: its status."""
    request = ua.CallMethodRequest(
        ObjectId=ua.NodeId(on, 2), MethodId=ua.NodeId(f"Drives/pump-1/{method}", 2),
        InputArguments=list(args),
    )  # fmt: skip
    (result,) = await space.server.iserver.isession.call([request])
    status: ua.StatusCode = result.StatusCode
    return status


@pytest.mark.parametrize(
    "value",
    [
        pytest.param(ua.Variant(float("nan"), ua.VariantType.Double), id="nan"),
        pytest.param(ua.Variant(float("inf"), ua.VariantType.Double), id="inf"),
        pytest.param(ua.Variant(float("-inf"), ua.VariantType.Double), id="-inf"),
        pytest.param(ua.Variant(True, ua.VariantType.Boolean), id="boolean"),
        pytest.param(ua.Variant("30", ua.VariantType.String), id="text"),
    ],
)
async def test_a_reference_that_is_no_finite_number_is_an_invalid_argument(
    space: Space, value: ua.Variant
) -> None:
    with structlog.testing.capture_logs() as logged:
        status = await _call(space, "Drives/pump-1", "SetReference", value)
    assert status.value == ua.StatusCodes.BadInvalidArgument
    # refused before the daemon's audit, so logged here, with who asked
    (event,) = [e for e in logged if e["event"] == "opcua.call_refused"]
    assert (event["drive"], event["method"]) == ("pump-1", "SetReference")
    assert event["actor"].startswith("opcua:")
    fine = ua.Variant(30.0, ua.VariantType.Double)  # reaches the daemon (here: refused)
    status = await _call(space, "Drives/pump-1", "SetReference", fine)
    assert status.value == ua.StatusCodes.BadUserAccessDenied


async def test_a_method_called_on_another_object_is_invalid(space: Space) -> None:
    status = await _call(space, "Drives", "Start")
    assert status.value == ua.StatusCodes.BadMethodInvalid
    assert (
        await _call(space, "Drives/pump-1", "Start")
    ).value == ua.StatusCodes.BadUserAccessDenied
