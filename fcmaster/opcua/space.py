"""The address space: ``Objects/fcmaster/Drives/<drive>`` and ``Objects/fcmaster/Lines/<bus>``.

Node ids are strings in the fcmaster namespace that follow the browse path
(``ns=2;s=Drives/pump-1/OutputFrequency``), so a SCADA tag list can be written by hand. The
values come from the daemon's compact drive states (:mod:`.wire`); their quality and source
time from :mod:`.quality`. Every variable is read-only (the access rules refuse writes).
A drive's ``Values/`` are made with it from the names its monitor list gives them (the
hello's ``values``), waiting for their first reading; a value the drive reports under
another name is added the first time it is read. A variable is written when its value or
quality changes, with the time of the reading that showed it.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Awaitable, Callable, Iterable, Mapping
from typing import Any, Final

import structlog
from asyncua import Node, Server, ua

from fcmaster.opcua.access import CALLER
from fcmaster.opcua.quality import Quality, Reading, readings

__all__ = ["METHODS", "NAMESPACE", "Space"]

log = structlog.get_logger("fcmaster.opcua")

NAMESPACE: Final = "urn:fcmaster"
V = ua.VariantType
_TYPES: Final = {
    "Online": V.Boolean, "Running": V.Boolean, "Fault": V.Boolean, "Warning": V.Boolean,
    "AtReference": V.Boolean, "Direction": V.String, "StatusWord": V.UInt32,
    "OutputFrequency": V.Double, "ReferencePercent": V.Double, "Alarms": V.String,
    "Warnings": V.String, "WatchdogVerdict": V.String,
}  # fmt: skip
_ARRAYS: Final = ("Alarms", "Warnings")
_ZERO: Final[dict[ua.VariantType, Any]] = {
    V.Boolean: False, V.String: "", V.UInt32: 0, V.UInt64: 0, V.Double: 0.0,
}  # fmt: skip
# method → the command it sends (SetReference adds its FrequencyHz)
METHODS: Final = {
    "Start": "start", "Stop": "stop", "Coast": "coast", "QuickStop": "quick_stop",
    "Reset": "reset", "Forward": "forward", "Reverse": "reverse", "Jog": "jog",
    "SetReference": "set_reference",
}  # fmt: skip
_CODES: Final = {q: getattr(ua.StatusCodes, q.value) for q in Quality}
# UNECE code "HTZ" (hertz) as OPC UA's EUInformation numbers it
_HERTZ = ua.EUInformation(
    NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact",
    UnitId=(ord("H") << 16) | (ord("T") << 8) | ord("Z"),
    DisplayName=ua.LocalizedText("Hz"),
    Description=ua.LocalizedText("hertz"),
)

Call = Callable[[str, str, dict[str, Any]], Awaitable[list[ua.Variant] | ua.StatusCode]]


def _time(wall: float | None) -> datetime.datetime | None:
    return None if wall is None else datetime.datetime.fromtimestamp(wall, datetime.UTC)


class Space:
    """The fcmaster objects of one server, and the values they show."""

    def __init__(self, server: Server, call: Call) -> None:
        self.server = server
        self._call = call  # (drive, method, command) → outputs or a refusal
        self.ns = 0
        self._nodes: dict[str, ua.NodeId] = {}  # "Drives/pump-1/Running" → its node id
        self._drives: dict[str, Node] = {}
        self._values: dict[str, Node] = {}  # each drive's Values folder
        self._texts: set[str] = set()  # the Values variables whose DataType says String
        self._entries: dict[str, Mapping[str, Any]] = {}  # each drive's last compact entry
        self._line_of: dict[str, str] = {}
        self._lines_up: dict[str, bool] = {}

    def _id(self, path: str) -> ua.NodeId:
        return ua.NodeId(path, self.ns)

    async def build(self, drives: list[dict[str, Any]], lines: list[dict[str, Any]]) -> None:
        """Make the objects for ``drives`` (name, bus, values) and ``lines`` (name, counters)."""
        self.ns = await self.server.register_namespace(NAMESPACE)
        root = await self.server.nodes.objects.add_folder(self._id("fcmaster"), "fcmaster")
        folder = await root.add_folder(self._id("Drives"), "Drives")
        for drive in drives:
            await self._drive(folder, drive["name"], drive.get("values", ()))
            self._line_of[drive["name"]] = drive["bus"]
        folder = await root.add_folder(self._id("Lines"), "Lines")
        for line in lines:
            name = line["name"]
            node = await folder.add_object(self._id(f"Lines/{name}"), name)
            await self._variable(node, f"Lines/{name}/Up", "Up", V.Boolean)
            for counter in line.get("counters", ()):
                await self._variable(node, f"Lines/{name}/{counter}", counter, V.UInt64)
            self._lines_up[name] = False

    async def _drive(self, folder: Node, name: str, values: Iterable[str]) -> None:
        node = await folder.add_object(self._id(f"Drives/{name}"), name)
        self._drives[name] = node
        for variable, kind in _TYPES.items():
            created = await self._variable(node, f"Drives/{name}/{variable}", variable, kind)
            if variable == "OutputFrequency":
                prop = await created.add_property(
                    self._id(f"Drives/{name}/OutputFrequency/EngineeringUnits"),
                    "EngineeringUnits",
                    _HERTZ,
                )
                await prop.write_value_rank(ua.ValueRank.Scalar)
        self._values[name] = await node.add_folder(self._id(f"Drives/{name}/Values"), "Values")
        for value in values:  # a number until its first reading says it is text
            await self._variable(
                self._values[name], f"Drives/{name}/Values/{value}", value, V.Double
            )
        outputs = [_argument("Outcome"), _argument("Reason")]
        for method, action in METHODS.items():
            inputs = [_argument("FrequencyHz", V.Double)] if method == "SetReference" else []
            await node.add_method(
                self._id(f"Drives/{name}/{method}"),
                method,
                self._method(name, method, action),
                inputs,
                outputs,
            )

    def _method(
        self, drive: str, method: str, action: str
    ) -> Callable[..., Awaitable[list[ua.Variant] | ua.StatusCode]]:
        def refused(code: int, reason: str) -> ua.StatusCode:
            # Refused here, the call never reaches the daemon's audit: it is logged with who
            # made it instead, as a refused request is.
            user = CALLER.get()
            log.warning("opcua.call_refused", actor=f"opcua:{(user and user.name) or 'anonymous'}",
                        drive=drive, method=method, reason=reason)  # fmt: skip
            return ua.StatusCode(code)

        async def called(parent: ua.NodeId, *args: ua.Variant) -> list[ua.Variant] | ua.StatusCode:
            # asyncua runs a method on whatever object the call names: only its own drive's
            if parent != self._id(f"Drives/{drive}"):
                return refused(ua.StatusCodes.BadMethodInvalid, f"called on {parent.to_string()}")
            command: dict[str, Any] = {"action": action}
            if method == "SetReference":
                given = args[0].Value if len(args) == 1 else None
                # a Boolean is an int to Python, and NaN or infinity no frequency at all
                if isinstance(given, bool) or not isinstance(given, int | float):
                    return refused(ua.StatusCodes.BadInvalidArgument, f"not a number: {given!r}")
                if not math.isfinite(given):
                    return refused(ua.StatusCodes.BadInvalidArgument, f"not finite: {given!r}")
                command["frequency_hz"] = float(given)
            elif args:
                return refused(ua.StatusCodes.BadTooManyArguments, f"{len(args)} arguments")
            return await self._call(drive, method, command)

        return called

    async def _variable(self, parent: Node, path: str, name: str, kind: V) -> Node:
        rank_array = name in _ARRAYS and path.startswith("Drives/")
        initial = [] if rank_array else _ZERO[kind]  # replaced by a null value at once
        node = await parent.add_variable(
            self._id(path), name, ua.Variant(initial, kind), kind, ua.NodeId(kind.value)
        )
        if rank_array:
            await node.write_value_rank(ua.ValueRank.OneDimension)
        self._nodes[path] = node.nodeid
        await self._write(path, kind, None, Quality.WAITING, None)
        return node

    async def _write(
        self, path: str, kind: V, value: Any, quality: Quality, source_at: float | None
    ) -> None:
        now = datetime.datetime.now(datetime.UTC)
        variant = ua.Variant(value, kind) if value is not None else ua.Variant()
        data = ua.DataValue(
            Value=variant,
            StatusCode=ua.StatusCode(_CODES[quality]),
            SourceTimestamp=_time(source_at) or now,
            ServerTimestamp=now,
        )
        await self.server.write_attribute_value(self._nodes[path], data)

    async def update_drive(self, entry: Mapping[str, Any]) -> None:
        """Show a drive's new compact entry."""
        name = entry["name"]
        if name not in self._drives:
            return  # not in the hello: a reload restarts the server with the new drives
        old = self._entries.get(name)
        self._entries[name] = entry
        up = self._lines_up.get(self._line_of.get(name, ""), False)
        previous = {} if old is None else {r.path: r for r in readings(old, line_up=up)}
        for reading in readings(entry, line_up=up):
            before = previous.get(reading.path)
            # A value the drive reports again unchanged keeps the time it was first read with
            # that value and quality: writing it again would only cost every subscriber.
            if before is None or (before.value, before.quality) != (reading.value, reading.quality):
                await self._show(name, reading)

    async def update_line(self, line: Mapping[str, Any]) -> None:
        """Show a line's state and counters; its drives' quality follows ``up``."""
        name = line["name"]
        if name not in self._lines_up:
            return
        was, up = self._lines_up[name], bool(line["up"])
        self._lines_up[name] = up
        await self._write(f"Lines/{name}/Up", V.Boolean, up, Quality.GOOD, None)
        for counter, value in line.get("counters", {}).items():
            if f"Lines/{name}/{counter}" in self._nodes:
                path = f"Lines/{name}/{counter}"
                await self._write(path, V.UInt64, int(value), Quality.GOOD, None)
        if was != up:  # every value of its drives changes quality
            for drive, bus in self._line_of.items():
                entry = self._entries.get(drive)
                if bus == name and entry is not None:
                    for reading in readings(entry, line_up=up):
                        await self._show(drive, reading)

    async def _show(self, drive: str, reading: Reading) -> None:
        path = f"Drives/{drive}/{reading.path}"
        if path not in self._nodes:
            if not reading.path.startswith("Values/"):
                return
            kind = V.String if isinstance(reading.value, str) else V.Double
            await self._variable(self._values[drive], path, reading.path[len("Values/") :], kind)
        kind = _TYPES.get(reading.path, V.Double)
        value = reading.value
        if reading.path.startswith("Values/") and isinstance(value, str):
            kind = V.String
            if path not in self._texts:  # made as a number before its first reading
                self._texts.add(path)
                await self.server.get_node(self._nodes[path]).write_attribute(
                    ua.AttributeIds.DataType,
                    ua.DataValue(ua.Variant(ua.NodeId(kind.value), V.NodeId)),
                )
        elif kind is V.Double and value is not None:
            value = float(value)
        await self._write(path, kind, value, reading.quality, reading.source_at)


def _argument(name: str, kind: V = V.String) -> ua.Argument:
    argument = ua.Argument()
    argument.Name = name
    argument.DataType = ua.NodeId(kind.value)
    argument.ValueRank = ua.ValueRank.Scalar
    argument.Description = ua.LocalizedText(name)
    return argument
