"""Commissioning commands that talk to a port directly, without a daemon.

`scan`, `read` and `write` open the port, carry a few exchanges over a
:class:`~fcmaster.bus.link.Link` — the same wire discipline the daemon uses — and close it.
`status` and `control` run the daemon's own :class:`~fcmaster.bus.master.BusMaster` on the
open port for one drive: `status` lets it poll one round of the drive's monitor list into a
:class:`~fcmaster.state.FleetState`, its observer, as the daemon's lines do; `control`
hands it the command and awaits its one result, so limits are checked and a running drive
is adopted, never jolted, exactly as in the daemon.

Why `read` and `write` stay on the Link: a BusMaster writes parameters only to a ``control:
bus`` drive (a write counts as commanding), and such a drive is adopted and its control
word fed, which stops when the command exits, so its watchdog could then trip a running
motor for the sake of a parameter. On a monitor-only plan the master refuses the write;
letting it through would weaken that rule for the daemon too. A read alone could go
through a monitor-only master, but it would add the master's idle polls (and demotion and
retries on a silent address) to what is today one exchange, and split `read` from `write`.
The Link carries the same wire discipline (pauses, stale input, echo, deadlines) and the
exchanges are the codec's own, built with no control intent, as a monitor-only master's.
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.link import Link
from fcmaster.bus.master import BusMaster, BusObserver
from fcmaster.bus.plan import DrivePlan, LinePlan, with_protocol_options
from fcmaster.bus.stats import DriveStats
from fcmaster.clock import MonotonicClock
from fcmaster.config_profiles import drive_profile
from fcmaster.config_values import baudrate_problem, port_url_problem
from fcmaster.errors import BusError, CommandError, UsageError
from fcmaster.protocol.codec import DriveCodec, DriveError, Reply
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ, ControlIntent, hz_to_pct, pct_to_hz
from fcmaster.protocol.registry import DEFAULT, spec_for
from fcmaster.protocol.spec import OptionPairs
from fcmaster.state import FleetState
from fcmaster.transport.serial import SerialTransport

# The actions a --frequency or --reference means something to.
_TAKES_REFERENCE = (Action.START, Action.SET_REFERENCE, Action.FORWARD, Action.REVERSE)


@dataclass(slots=True, frozen=True, kw_only=True)
class LineOptions:
    """The line options every port-opening command takes."""

    port: str
    protocol: str = DEFAULT
    baudrate: int | None = None
    parity: str | None = None
    stopbits: int | None = None
    timeout_s: float | None = None
    # The protocol's own line keys given (ProtocolSpec.line_keys), as (key, value) pairs;
    # a key left out takes the spec's default.
    protocol_options: OptionPairs = ()

    def __post_init__(self) -> None:
        spec = spec_for(self.protocol)
        problems = spec.option_problems(self.protocol_options)
        if port_problem := port_url_problem(self.port):
            problems.insert(0, f"--port {port_problem}")
        if self.baudrate is not None and self.baudrate not in spec.baudrates:
            problems.insert(0, f"--baudrate {baudrate_problem(spec, self.baudrate)}")
        if problems:
            raise UsageError("; ".join(problems))

    def plan(self, drives: tuple[DrivePlan, ...] = ()) -> LinePlan:
        """A line plan with the protocol's factory settings where nothing was given."""
        spec = spec_for(self.protocol)
        factory = spec.factory
        plan = LinePlan(
            name="cli",
            port=self.port,
            protocol=self.protocol,
            baudrate=self.baudrate or factory.baudrate,
            parity=self.parity or factory.parity,
            stopbits=self.stopbits or factory.stopbits,
            timeout_s=self.timeout_s,
            retries=1,
            drives=drives,
        )
        # every key of the protocol, so a plan field's default never stands in for the spec's
        plan = with_protocol_options(plan, spec.option_pairs(self))
        return with_protocol_delay(plan)  # Mitsubishi: waiting time and data check time


class _Session:
    """An open port with a Link on it, as an async context manager."""

    def __init__(self, plan: LinePlan) -> None:
        self.plan = plan
        self.codec: DriveCodec = codec_for(plan)
        self.clock = MonotonicClock()
        self.transport = SerialTransport(
            plan.port, baudrate=plan.baudrate, parity=plan.parity, stopbits=plan.stopbits
        )
        self.link = Link(plan, codec=self.codec, transport=self.transport, clock=self.clock)

    async def __aenter__(self) -> _Session:
        await self.transport.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.transport.close()

    async def poll(self, address: int, read: Any = None) -> Reply | None:
        """One monitor-only poll (the drive is never commanded)."""
        return await self.link.transact(self.codec.poll(address, None, read))

    def master(self, plan: LinePlan, observer: BusObserver | None = None) -> BusMaster:
        """The daemon's BusMaster for ``plan`` on this open port (it closes the port)."""
        return BusMaster(
            plan, codec=self.codec, transport=self.transport, clock=self.clock, observer=observer
        )


def _check_address(codec: DriveCodec, address: int) -> None:
    if address not in codec.addresses:
        span = f"{codec.addresses.start}-{codec.addresses.stop - 1}"
        raise UsageError(f"address {address} is outside {span} for this protocol")


async def scan(options: LineOptions, addresses: list[int] | None, *, as_json: bool) -> int:
    """Poll each address once (default: every one the codec can reach); list those that answer.

    Interrupted (Ctrl-C), it still lists the drives found so far, then re-raises.
    """
    found: list[dict[str, Any]] = []
    show_progress = sys.stderr.isatty()
    session = _Session(options.plan())
    addresses = list(session.codec.addresses) if addresses is None else addresses
    for address in addresses:  # before the port opens: a wrong address is the user's
        _check_address(session.codec, address)
    async with session:
        done = 0
        try:
            for done, address in enumerate(addresses, 1):
                reply = await session.poll(address)
                if reply is None:  # one retry: a single lost reply must not hide a drive
                    reply = await session.poll(address)
                if reply is not None:
                    found.append(_summary(address, reply))
                if show_progress:
                    _progress(done, len(addresses), address, len(found))
        except asyncio.CancelledError:  # Ctrl-C: what was found is still worth knowing
            if show_progress:
                print(file=sys.stderr)
            print(f"interrupted at {done} of {len(addresses)} addresses", file=sys.stderr)
            _print_found(found, options, done, as_json=as_json, interrupted=True)
            raise
        if show_progress:
            print(file=sys.stderr)
    _print_found(found, options, len(addresses), as_json=as_json)
    return 0 if found else 1


def _print_found(
    found: list[dict[str, Any]],
    options: LineOptions,
    tried: int,
    *,
    as_json: bool,
    interrupted: bool = False,
) -> None:
    if as_json:
        print(json.dumps(found, indent=2), flush=True)
    elif found:
        spec = spec_for(options.protocol)
        # Without a profile a Modbus drive is only asked whether it is there (a read of
        # register 0, which some refuse), never for its status.
        unprofiled = spec.new_profiled_codec is not None and not _line_profile(options)
        for entry in found:
            if entry["refused"] is not None and not unprofiled:  # another family's drive
                refused = entry["refused"]
                print(
                    f"{entry['address']:>4}  answers, but refused the status read "
                    f"({refused['text']}, code {refused['code']})"
                )
                continue
            if entry["status_word"] is None:  # it answers, but no status word was read
                print(f"{entry['address']:>4}  answers (no status read: it needs a profile)")
                continue
            flags = ", ".join(k for k in ("running", "fault", "warning") if entry[k]) or "stopped"
            print(f"{entry['address']:>4}  status 0x{entry['status_word']:04X}  {flags}")
    elif interrupted:
        print(f"no drive answered on {options.port} before the interrupt")
    else:
        print(f"no drive answered on {options.port} ({tried} addresses tried)")
        _print_hint(options)
    sys.stdout.flush()


def _line_profile(options: LineOptions) -> object:
    """The drive profile given for the line (``--profile``), None where none was."""
    return dict(spec_for(options.protocol).option_pairs(options)).get("profile")


def _print_hint(options: LineOptions) -> None:
    """What to try after a scan that found nothing: other settings, or the doctor."""
    plan = options.plan()
    spec = spec_for(options.protocol)
    others = [str(rate) for rate in spec.baudrates if rate != plan.baudrate]
    print(
        f"  tried {options.protocol} at {plan.baudrate} {plan.databits}{plan.parity}"
        f"{plan.stopbits}; the drives may be set otherwise: try --baudrate "
        f"{' / '.join(others)}, --parity {' / '.join(spec.parities)}, or let "
        f"`fcmaster doctor --port {options.port}` find the settings",
        file=sys.stderr,
    )


def _progress(done: int, total: int, address: int, found: int) -> None:
    width = 30
    filled = width * done // total
    bar = "#" * filled + "-" * (width - filled)
    sys.stderr.write(f"\r[{bar}] {done}/{total}  address {address:<3}  found {found}")
    sys.stderr.flush()


def _summary(address: int, reply: Reply) -> dict[str, Any]:
    status, hz = reply.status, reply.output_frequency_hz  # of a drive at the default nominal
    error = reply.error
    return {
        "address": address,
        "status_word": status.word if status else None,
        # not known without a status word (a drive that answers only to say no)
        "running": status.running if status else None,
        "fault": status.fault if status else None,
        "warning": status.warning if status else None,
        "output_pct": None if hz is None else hz_to_pct(hz, DEFAULT_NOMINAL_HZ),
        "output_frequency_hz": hz,
        "refused": None if error is None else {"code": error.code, "text": error.text},
    }


async def status(options: LineOptions, address: int, *, as_json: bool) -> int:
    """One drive's decoded state now: status, then every default monitor value."""
    drive = DrivePlan(name=f"drive-{address}", address=address)
    plan = options.plan((drive,))
    async with _Session(plan) as session:
        _check_address(session.codec, address)
        reads = len(session.codec.poll_sequence(session.codec.default_monitor()))
        # Demoted (and the round over) only when a whole round went unanswered.
        plan = replace(plan, offline_after=reads)
        fleet = FleetState((plan,), emit=lambda event: None, clock=session.clock)
        observer = _OneRound(fleet, reads)
        master = session.master(plan, observer)
        observer.stats = master.stats.drives[drive.name]
        async with master:
            await observer.over.wait()
        if not observer.replies:
            raise BusError(f"no reply from address {address} on {options.port}", address=address)
        refused = observer.refused
        if not observer.statuses and refused is not None:
            # Its state would read stopped and healthy: a drive of another family than its
            # profile says refuses the profile's status register.
            raise BusError(
                f"address {address} answers but refused the status read ({refused.text}, "
                f"code {refused.code}): does the drive's profile match it?",
                address=address,
            )
    state = fleet.get(plan.name, drive.name)
    assert state is not None
    out = state.to_json()
    if as_json:
        print(json.dumps(out, indent=2))
    else:
        _print_state(out)
    return 0


def _print_state(out: dict[str, Any]) -> None:
    """A drive state as a two-column table, every key apart from its value."""
    width = max(len(key) for key in out) + 2
    for key, value in out.items():
        if key == "values":
            print("values")
            for name, v in value.items():
                label = f"{name} {v['name']}" if v.get("name") else name
                print(f"  {label:<{width - 2}}{v['value']} {v['unit']}".rstrip())
        elif key in ("alarms", "warnings"):
            texts = ", ".join(f"{c['text']} ({c['code']})" for c in value) or "none"
            print(f"{key:<{width}}{texts}")
        else:
            print(f"{key:<{width}}{value}")


async def access(
    options: LineOptions,
    address: int,
    parameter: str,
    *,
    index: int,
    value: str | None,
    persist: bool = False,
    as_json: bool = False,
) -> int:
    """`read` (value None) or `write` one parameter."""
    session = _Session(options.plan())
    codec = session.codec
    _check_address(codec, address)  # the exchanges are built before the port opens: a
    key = codec.parameter(parameter)  # mistake in them is the user's, not the line's
    if value is None:
        exchanges = codec.read(address, key, index, None)
    else:
        exchanges = codec.write(address, key, index, _number(value), None, persist=persist)
    async with session:
        # Several exchanges (a Mitsubishi parameter: the page, then the access): the first
        # refusal or silence ends it; the last reply holds the value.
        reply: Reply | None = None
        for exchange in exchanges:
            reply = await session.link.transact(exchange)
            if reply is None or reply.error is not None:
                break
    if reply is None:
        raise BusError(f"no reply from address {address} on {options.port}", address=address)
    if reply.error is not None:
        result = CommandResult(
            outcome=Outcome.REFUSED,
            error=reply.error,
            reason=f"the drive refused: {reply.error.text} (error {reply.error.code})",
        )
        result.raise_for_outcome()
    got = reply.value
    if value is not None:
        print(f"{key.name} = {got.value if got else value} {got.unit if got else ''}".rstrip())
        return 0
    assert got is not None
    if as_json:
        print(
            json.dumps(
                {
                    "parameter": key.name,
                    "index": index,
                    "value": got.value,
                    "unit": got.unit,
                    "raw": got.raw,
                }
            )
        )
    else:
        print(f"{got.value} {got.unit}".rstrip())
    return 0


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"{text!r} is not a number") from None


async def control(
    options: LineOptions,
    address: int,
    action: str,
    *,
    frequency_hz: float | None,
    reference_pct: float | None,
    nominal_frequency_hz: float,
    max_frequency_hz: float | None,
) -> int:
    """Command one drive through the daemon's planner, so limits and adoption apply."""
    try:
        verb = Action(action.replace("-", "_"))
    except ValueError:
        raise UsageError(f"unknown action {action!r}") from None
    if not verb.is_control:
        raise UsageError(f"{action} is not a control action; use read or write")
    given = "--frequency" if frequency_hz is not None else "--reference"
    _check_magnitudes(frequency_hz, reference_pct, nominal_frequency_hz, max_frequency_hz)
    if (frequency_hz is not None or reference_pct is not None) and verb not in _TAKES_REFERENCE:
        takes = ", ".join(a.value.replace("_", "-") for a in _TAKES_REFERENCE)
        raise UsageError(f"{action} takes no {given} (only {takes} do)")
    drive = DrivePlan(
        name=f"drive-{address}",
        address=address,
        control=True,
        nominal_frequency_hz=nominal_frequency_hz,
        max_frequency_hz=max_frequency_hz or nominal_frequency_hz,
    )
    plan = replace(options.plan((drive,)), offline_after=1)
    pct = reference_pct
    if frequency_hz is not None:
        pct = hz_to_pct(frequency_hz, nominal_frequency_hz)
    if verb is Action.SET_REFERENCE and pct is None:
        raise UsageError("set_reference needs --frequency or --reference")
    if pct is not None and max_frequency_hz is None and abs(pct) > 100.0 + 1e-9:
        # The limit is the nominal frequency only because none was given: say how to give one.
        raise UsageError(
            f"{pct_to_hz(pct, nominal_frequency_hz):g} Hz is beyond the nominal "
            f"{nominal_frequency_hz:g} Hz; pass --max-frequency if the drive may run faster"
        )
    command = Command(action=verb, reference_pct=pct, actor="cli")
    async with _Session(plan) as session:
        _check_address(session.codec, address)
        async with session.master(plan) as master:
            result = await master.execute(drive.name, command)
    if result.outcome is Outcome.DONE:
        print(f"{action}: done")
        if verb in (Action.START, Action.JOG, Action.FORWARD, Action.REVERSE):
            print(
                "note: fcmaster no longer feeds this drive's control-word watchdog; the drive "
                f"does what {_watchdog_words(options, plan)} says",
                file=sys.stderr,
            )
        return 0
    try:
        result.raise_for_outcome()
    except CommandError as exc:
        exc.args = (f"{action}: {exc}",)  # the same error, its other fields kept
        raise
    return 1  # pragma: no cover - raise_for_outcome raises for every other outcome


def _watchdog_words(options: LineOptions, plan: LinePlan) -> str:
    """The drive's own watchdog settings on this line, named as its manual or profile does."""
    named = _line_profile(options)  # modbus-rtu: each family keeps it in its own registers
    profile = None
    if named is not None:
        profile = drive_profile(plan.protocol, str(named), Path.cwd(), "--profile", [])
    names = spec_for(plan.protocol).drive_watchdog(plan, profile).parameters
    if not names:
        return "its communication watchdog (set in registers its drive profile names)"
    if named is not None:
        return f"its communication watchdog ({named} registers {', '.join(names)})"
    return f"its timeout function ({'/'.join(names)})"


def _check_magnitudes(
    frequency_hz: float | None,
    reference_pct: float | None,
    nominal_frequency_hz: float,
    max_frequency_hz: float | None,
) -> None:
    """UsageError, before the port is opened, for a speed that is not a magnitude.

    Frequencies and references are magnitudes, as on every surface of the daemon: the
    direction changes only with forward or reverse, so ``--frequency -5`` must never run a
    drive backwards at 5 Hz.
    """
    for option, value in (("--nominal-frequency", nominal_frequency_hz),
                          ("--max-frequency", max_frequency_hz)):  # fmt: skip
        if value is not None and not (math.isfinite(value) and value > 0):
            raise UsageError(f"{option} {value:g} is not a positive number of Hz")
    for option, value, unit in (("--frequency", frequency_hz, "Hz"),
                                ("--reference", reference_pct, "%")):  # fmt: skip
        if value is None:
            continue
        if not math.isfinite(value):
            raise UsageError(f"{option} {value:g} is not a number of {unit}")
        if value < 0:
            hz = value if unit == "Hz" else pct_to_hz(value, nominal_frequency_hz)
            raise UsageError(
                f"{option} {value:g} ({hz:g} Hz) is a magnitude and must be 0 or more: "
                "change the direction with the forward or reverse action"
            )


class _OneRound:
    """A status's observer: fills the fleet state and tells when the poll round is over.

    The round is over when each item of the drive's poll round was asked once, when the
    drive was demoted for a whole round unanswered, or when the port was lost. Replies
    reach an observer just after the next request is written, so the round is over one
    transaction after its last poll: the state then holds every answer of the round.
    """

    def __init__(self, fleet: FleetState, reads: int) -> None:
        self.fleet = fleet
        self.reads = reads
        self.replies = 0
        self.statuses = 0  # replies that carried a status word
        self.refused: DriveError | None = None  # the drive's first refusal, if any
        self.stats = DriveStats()  # the master's own, once it runs
        self.over = asyncio.Event()

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        """Fill the state; the round is over once every poll of it was answered or lost."""
        self.fleet.drive_replied(bus, drive, reply, at, commanded)
        self.replies += 1
        self.statuses += reply.status is not None
        if reply.error is not None and self.refused is None:
            self.refused = reply.error
        if self.replies + self.stats.timeouts >= self.reads:
            self.over.set()

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        """A drive demoted after a whole round unanswered: the round is over."""
        self.fleet.drive_availability(bus, drive, online, at)
        if not online:
            self.over.set()

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        """A lost port ends the round with what it brought."""
        self.fleet.line_availability(bus, up, reason, at)
        if not up:
            self.over.set()

    def command_completed(
        self, bus: str, drive: str, command: Command, result: CommandResult
    ) -> None:
        """No command is given during a status."""
