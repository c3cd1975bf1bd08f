"""Fleet state: an immutable snapshot per drive, and the typed events its changes make.

Theory of operation
-------------------
:class:`FleetState` is a :class:`~fcmaster.bus.master.BusObserver`: every BusMaster reports
replies, availability changes and command results to it, and it turns them into a new
:class:`DriveState` (a frozen snapshot — readers can keep a reference without copying or
locking) plus events, which it hands to ``emit`` (the hub's ``publish`` in the daemon).
Vendor words stay visible (``status_word``, raw parameter values) beside the normalised
fields, which mean the same for every protocol.

Alarms and warnings arrive per source word (FC: 16-90 and 16-91 are both alarms); the
snapshot shows their union, and a change makes one ``ConditionChanged`` per code raised or
cleared, so consumers never diff lists themselves.

Every reading keeps the time it was taken: ``updated_at`` (the last good reply),
``output_frequency_updated_at`` and each value's ``updated_at`` — Mitsubishi and ENC read
the frequency in an exchange of its own, so it may be older than the status beside it.

Only a change a subscriber can see is *published* as a ``DriveUpdated``: a status bit, the
status word, alarms, warnings, online, the commanded reference, the set of values, or the
output frequency or a value moving beyond its deadband since the state last published — so
slow drifts add up and go out once they cross it. A drive that keeps answering unchanged is
published again every ``heartbeat_s``, with its fresh times.

On a steady fleet most replies change nothing but times. Such a reply builds no snapshot:
its times wait in a small mutable record (``_Fresh``) and are folded into a new snapshot
when someone reads the drive (``get``, ``find``, ``snapshot``) or the heartbeat is due, so
readers still see the time of the last reply.
"""

from __future__ import annotations

import dataclasses
import operator
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fcmaster.bus.codecs import codec_for, monitor_keys
from fcmaster.bus.commands import Command, CommandResult
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.watchdog import WatchdogReport
from fcmaster.clock import Clock
from fcmaster.drive_state import DriveState, Measured, rfc3339
from fcmaster.errors import FcmasterError
from fcmaster.history import History, Series
from fcmaster.protocol.codec import Condition, Reply
from fcmaster.protocol.drive import ControlIntent

__all__ = [  # the snapshot's names are re-exported: readers import them from here
    "DEADBAND_PCT",
    "HEARTBEAT_S",
    "AvailabilityChanged",
    "CommandCompleted",
    "ConditionChanged",
    "DriveState",
    "DriveUpdated",
    "Event",
    "FleetState",
    "LineChanged",
    "Measured",
    "rfc3339",
]

_FREQUENCY = Series("output_frequency_hz", "Output frequency", "Hz")
HEARTBEAT_S = 5.0  # an unchanged drive that keeps answering is published this often
DEADBAND_PCT = 0.1  # of the nominal frequency for the output, of the reading for values
# Fields whose every change is published (the analog ones go by the deadband).
_DISCRETE = (
    "online", "running", "fault", "warning", "direction", "at_reference", "status_word",
    "reference_pct", "alarms", "warnings", "watchdog",
)  # fmt: skip


_FIELDS = tuple(f.name for f in dataclasses.fields(DriveState))
_fields_of = operator.attrgetter(*_FIELDS)
_discrete = operator.attrgetter(*_DISCRETE)


def _replace(state: DriveState, changes: dict[str, Any]) -> DriveState:
    """``dataclasses.replace`` for a drive state, at a third of its cost (every reply pays it)."""
    fields = dict(zip(_FIELDS, _fields_of(state), strict=True))
    fields.update(changes)
    return DriveState(**fields)


class _Fresh:
    """The reading times of replies that changed nothing, kept until the snapshot is read."""

    __slots__ = ("frequency_at", "updated_at", "values_at")

    def __init__(self, updated_at: float) -> None:
        self.updated_at = updated_at
        self.frequency_at: float | None = None
        self.values_at: dict[str, float] = {}


def _same_reading(old: Measured | None, new: Measured) -> bool:
    """Whether ``new`` reads exactly what ``old`` did (its time aside)."""
    return (
        old is not None
        and old.value == new.value
        and old.unit == new.unit
        and old.texts == new.texts
        and old.name == new.name
    )


def _monitored(line: LinePlan, drive: DrivePlan) -> frozenset[str] | None:
    """The parameter names ``drive``'s values show (None: any, when the codec cannot say)."""
    try:
        codec = codec_for(line)
        keys = monitor_keys(codec, drive)
        words = codec.condition_parameters(alarms=True, warnings=True)
    except FcmasterError:  # a plan the config would refuse; show what comes
        return None
    return frozenset(k.name for k in keys + words)


# -- events --------------------------------------------------------------------------------


@dataclass(slots=True, frozen=True)
class DriveUpdated:
    """A drive's snapshot changed (conflated for slow subscribers: latest wins).

    ``changed`` names the public fields that changed since the drive was last published
    (``values`` for any value); it is empty for a heartbeat.
    """

    state: DriveState
    changed: tuple[str, ...] = ()

    def after(self, earlier: DriveUpdated) -> DriveUpdated:
        """This update standing in for ``earlier`` too (conflation): the changes of both."""
        if not earlier.changed:
            return self
        return DriveUpdated(self.state, tuple(dict.fromkeys(earlier.changed + self.changed)))

    @property
    def bus(self) -> str:
        """The drive's line."""
        return self.state.bus

    @property
    def drive(self) -> str:
        """The drive's name."""
        return self.state.name


@dataclass(slots=True, frozen=True, kw_only=True)
class ConditionChanged:
    """An alarm or warning was raised or cleared."""

    bus: str
    drive: str
    kind: str  # "alarm" | "warning"
    code: int
    text: str
    active: bool


@dataclass(slots=True, frozen=True, kw_only=True)
class AvailabilityChanged:
    """A drive came online or went offline."""

    bus: str
    drive: str
    online: bool


@dataclass(slots=True, frozen=True, kw_only=True)
class CommandCompleted:
    """A command ended, with its one result."""

    bus: str
    drive: str
    command: Command
    result: CommandResult


@dataclass(slots=True, frozen=True, kw_only=True)
class LineChanged:
    """A line's port opened or was lost, or its statistics were sampled."""

    bus: str
    up: bool
    reason: str = ""
    stats: dict[str, Any] | None = None

    @property
    def drive(self) -> None:
        """Line events belong to no drive."""
        return None


Event = DriveUpdated | ConditionChanged | AvailabilityChanged | CommandCompleted | LineChanged


class FleetState:
    """The latest snapshot of every drive; a BusObserver for every line."""

    def __init__(
        self,
        lines: tuple[LinePlan, ...],
        *,
        emit: Callable[[Event], None],
        clock: Clock,
        heartbeat_s: float = HEARTBEAT_S,
        deadband_pct: float = DEADBAND_PCT,
    ) -> None:
        self._publish_event = emit
        self._clock = clock
        self._wall = clock.wall  # looked up once: every reply is stamped with it
        self._heartbeat_s = heartbeat_s
        self._band = deadband_pct / 100.0
        self.history = History()  # what was published, for charts opened later
        self._states: dict[str, DriveState] = {}
        self._fresh: dict[str, _Fresh] = {}  # times of unchanged replies not yet in _states
        self._charted: dict[str, dict[str, Series]] = {}  # what each drive's history holds
        # what each drive's subscribers last saw, and when (monotonic)
        self._published: dict[str, tuple[DriveState, float]] = {}
        self._sources: dict[str, dict[tuple[str, str], tuple[Condition, ...]]] = {}
        # the parameters each drive's values show: its monitor list and condition words
        self._monitored: dict[str, frozenset[str] | None] = {}
        self._nominal_hz: dict[str, float] = {}  # for a publication that no reply made
        for line in lines:
            self.replan(line)

    def replan(self, line: LinePlan) -> None:
        """Know the drives of ``line`` as it now says (at start, and at a reload).

        A drive new here, or at another address or under other control, starts as a new
        snapshot (offline until it answers); any other keeps its snapshot and takes its new
        monitor list and nominal frequency. Drives the line no longer has stay until
        :meth:`forget`: their last replies may still be on their way.
        """
        for drive in line.drives:
            key = f"{line.name}/{drive.name}"
            control = "bus" if drive.control else "monitor"
            old = self._states.get(key)
            if old is None or (old.address, old.control) != (drive.address, control):
                state = DriveState(
                    name=drive.name,
                    bus=line.name,
                    address=drive.address,
                    protocol=line.protocol,
                    control=control,
                )
                self._states[key] = state
                self._fresh.pop(key, None)
                self._published[key] = (state, float("-inf"))
                self._charted[key] = {_FREQUENCY.key: _FREQUENCY}
                self._sources[key] = {}
            self._monitored[key] = _monitored(line, drive)
            self._nominal_hz[key] = drive.nominal_frequency_hz

    def forget(self, bus: str, names: set[str]) -> None:
        """Drives ``names`` of line ``bus`` left the configuration: no snapshot, no events."""
        for name in names:
            key = f"{bus}/{name}"
            for table in (
                self._states, self._fresh, self._published, self._charted, self._sources,
                self._monitored, self._nominal_hz,
            ):  # fmt: skip
                table.pop(key, None)

    def _emit(self, event: Event) -> None:
        """Publish ``event``; a drive's discrete events are also kept in its history."""
        if isinstance(event, ConditionChanged | AvailabilityChanged | CommandCompleted):
            self.history.record_event(f"{event.bus}/{event.drive}", self._wall(), event)
        self._publish_event(event)

    def snapshot(self) -> list[DriveState]:
        """Every drive, in configuration order."""
        return [self._current(key) for key in self._states]

    def get(self, bus: str, name: str) -> DriveState | None:
        """One drive's snapshot."""
        key = f"{bus}/{name}"
        return self._current(key) if key in self._states else None

    def find(self, name: str) -> DriveState | None:
        """A drive by name alone (names are unique across the fleet)."""
        for key, state in self._states.items():
            if state.name == name:
                return self._current(key)
        return None

    def _current(self, key: str) -> DriveState:
        """The drive's snapshot with the times of the unchanged replies since it was built."""
        fresh = self._fresh.pop(key, None)
        state = self._states[key]
        if fresh is None:
            return state
        changes: dict[str, Any] = {"updated_at": fresh.updated_at}
        if fresh.frequency_at is not None:
            changes["output_frequency_updated_at"] = fresh.frequency_at
        if fresh.values_at:
            values = dict(state.values)
            for name, read_at in fresh.values_at.items():
                values[name] = dataclasses.replace(values[name], updated_at=read_at)
            changes["values"] = values
        state = self._states[key] = _replace(state, changes)
        return state

    # -- BusObserver ---------------------------------------------------------------------

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        """Fold one reply into the drive's snapshot."""
        key = f"{bus}/{drive.name}"
        read_at = self._wall() - (self._clock.now() - at)
        old = self._states.get(key)
        if old is None:  # removed by a reload while its reply was on its way
            return  # its times may lag (see _current): only its content is used
        changes: dict[str, Any] = {
            "online": True,
            "reference_pct": None if commanded is None else commanded.reference_pct,
        }
        status = reply.status
        if status is not None:
            changes.update(
                running=status.running,
                fault=status.fault,
                warning=status.warning,
                at_reference=status.at_reference,
                status_word=status.word,
            )
        hz = reply.output_frequency_hz
        if status is not None and status.reverse is not None:
            changes["direction"] = "reverse" if status.reverse else "forward"
        elif commanded is not None:
            if status is not None:
                changes["direction"] = "reverse" if commanded.reverse else "forward"
        elif hz and reply.output_signed:
            # A status word without a reverse bit, nothing commanded: a signed frequency's
            # sign is the direction (a magnitude, or 0 Hz, says nothing of it).
            changes["direction"] = "reverse" if hz < 0 else "forward"
        if hz is not None:
            changes["output_frequency_hz"] = abs(hz)
        value, report, read, measured = reply.value, reply.conditions, None, None
        monitored = self._monitored[key]
        if value is not None and (monitored is None or value.parameter.name in monitored):
            # A one-off read of anything else is its caller's answer, not a monitored value.
            read = value.parameter.name
            if value.index:
                read = f"{read}[{value.index}]"
            texts = None
            if report is not None and report.source == value.parameter.name:
                texts = tuple(c.text for c in report.active)  # an alarm or warning word
            measured = Measured(value.value, value.unit, value.raw, value.title, read_at, texts)
        if (
            all(getattr(old, field) == given for field, given in changes.items())
            and (measured is None or _same_reading(old.values.get(read or ""), measured))
            and (
                report is None
                or self._sources[key].get((report.kind, report.source)) == report.active
            )
        ):
            # Nothing but the times: no new snapshot, no event, until someone reads it or the
            # heartbeat is due.
            self._refresh(key, read_at, "output_frequency_hz" in changes, read)
            if at - self._published[key][1] >= self._heartbeat_s:
                self._publish(key, self._current(key), drive.nominal_frequency_hz, at=at)
            return
        old = self._current(key)
        changes["updated_at"] = read_at
        if "output_frequency_hz" in changes:
            changes["output_frequency_updated_at"] = read_at
        if measured is not None and read is not None:
            changes["values"] = {**old.values, read: measured}
        if report is not None:
            self._conditions(key, old, reply, changes)
        new = _replace(old, changes)
        self._states[key] = new
        if not old.online:
            self._emit(AvailabilityChanged(bus=new.bus, drive=new.name, online=True))
        self._publish(key, new, drive.nominal_frequency_hz, read, at=at)

    def _refresh(self, key: str, read_at: float, frequency: bool, value: str | None) -> None:
        fresh = self._fresh.get(key)
        if fresh is None:
            fresh = self._fresh[key] = _Fresh(read_at)
        fresh.updated_at = read_at
        if frequency:
            fresh.frequency_at = read_at
        if value is not None:
            fresh.values_at[value] = read_at

    def _publish(
        self,
        key: str,
        new: DriveState,
        nominal_frequency_hz: float,
        read: str | None = None,
        *,
        at: float | None = None,
    ) -> None:
        """Emit ``new`` if a subscriber could see a change, or the heartbeat is due.

        ``at``: when the reading in ``new`` was taken (a reply's arrival), else now. The
        heartbeat runs on those times, the ones ``updated_at`` shows, so no repeat of an
        unchanged state carries a time less than a heartbeat after the last one's.
        """
        sent, sent_at = self._published[key]
        changed = self._changes(sent, new, nominal_frequency_hz, read)
        now = self._clock.now() if at is None else at
        if changed or now - sent_at >= self._heartbeat_s:
            self._published[key] = (new, now)
            self._emit(DriveUpdated(new, changed))
            self._record(key, new)

    def _record(self, key: str, state: DriveState) -> None:
        online = state.online
        values: dict[str, float | None] = {
            _FREQUENCY.key: state.output_frequency_hz if online else None
        }
        charted = self._charted[key]
        for name, measured in state.values.items():
            if measured.texts is None and not isinstance(measured.value, str):
                values[name] = measured.value if online else None
                if name not in charted:
                    charted[name] = Series(name, measured.name or name, measured.unit)
        at = state.updated_at if online and state.updated_at is not None else self._wall()
        self.history.record_drive(key, at, values, charted)

    def _changes(
        self, sent: DriveState, new: DriveState, nominal_frequency_hz: float, read: str | None
    ) -> tuple[str, ...]:
        """The public fields in which ``new`` differs visibly from the state last ``sent``.

        ``read`` is the value the reply that made ``new`` carried, if any.
        """
        changed: list[str] = []
        if _discrete(sent) != _discrete(new):  # one C call each: the common case is equal
            changed = [name for name in _DISCRETE if getattr(sent, name) != getattr(new, name)]
        band = self._band
        old_hz, new_hz = sent.output_frequency_hz, new.output_frequency_hz
        if (old_hz is None) != (new_hz is None) or (
            old_hz is not None
            and new_hz is not None
            and abs(new_hz - old_hz) > band * abs(nominal_frequency_hz)
        ):
            changed.append("output_frequency_hz")
        if sent.values.keys() != new.values.keys():
            changed.append("values")
        elif read is not None:
            # Only the value this reply read can have moved since the last publication: any
            # other was within the band when it was read, or it would have been published.
            old, value = sent.values[read].value, new.values[read].value
            if isinstance(old, str) or isinstance(value, str):
                moved = old != value
            else:
                moved = abs(value - old) > band * max(abs(value), abs(old))
            if moved:
                changed.append("values")
        return tuple(changed)

    def _conditions(self, key: str, old: DriveState, reply: Reply, changes: dict[str, Any]) -> None:
        report = reply.conditions
        assert report is not None
        sources = self._sources[key]
        sources[(report.kind, report.source)] = report.active
        union = tuple(
            dict.fromkeys(
                condition
                for (kind, _), active in sources.items()
                if kind == report.kind
                for condition in active
            )
        )
        before = old.alarms if report.kind == "alarm" else old.warnings
        changes["alarms" if report.kind == "alarm" else "warnings"] = union
        for condition in union:
            if condition not in before:
                self._emit(self._condition_event(old, report.kind, condition, active=True))
        for condition in before:
            if condition not in union:
                self._emit(self._condition_event(old, report.kind, condition, active=False))

    @staticmethod
    def _condition_event(
        state: DriveState, kind: str, condition: Condition, *, active: bool
    ) -> ConditionChanged:
        return ConditionChanged(
            bus=state.bus,
            drive=state.name,
            kind=kind,
            code=condition.code,
            text=condition.text,
            active=active,
        )

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        """Mark a drive online or offline; its last values stay, with their time."""
        key = f"{bus}/{drive.name}"
        if key not in self._states:  # removed by a reload
            return
        old = self._current(key)
        if old.online == online:
            return
        new = dataclasses.replace(old, online=online)
        self._states[key] = new
        self._emit(AvailabilityChanged(bus=new.bus, drive=new.name, online=online))
        self._publish(key, new, drive.nominal_frequency_hz)

    def drive_watchdog(self, bus: str, name: str, report: WatchdogReport) -> None:
        """A drive's communication watchdog was read and judged (the watchdog audit).

        A verdict that differs from the one the drive shows is published at once (listed in
        its ``changed``), so the dashboard and MQTT show it with the log's warning; the same
        verdict again (an audit repeated when the drive comes back) publishes nothing. This
        is called once per audit, never per reply.
        """
        key = f"{bus}/{name}"
        if key not in self._states:  # removed by a reload
            return
        old = self._current(key)
        if old.watchdog != report:
            new = self._states[key] = dataclasses.replace(old, watchdog=report)
            self._publish(key, new, self._nominal_hz[key])

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        """A line opened or was lost."""
        self._emit(LineChanged(bus=bus, up=up, reason=reason))

    def line_sampled(self, bus: str, up: bool, stats: dict[str, Any]) -> None:
        """A line's statistics were sampled: kept in its history and published."""
        self.history.record_line(bus, self._wall(), stats)
        self._emit(LineChanged(bus=bus, up=up, stats=stats))

    def command_completed(
        self, bus: str, drive: str, command: Command, result: CommandResult
    ) -> None:
        """A command ended; its result becomes an event."""
        self._emit(CommandCompleted(bus=bus, drive=drive, command=command, result=result))
