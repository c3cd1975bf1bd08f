"""`fcmaster params backup | diff | restore`: a drive's parameter set, to a file and back.

The set's members, identity and the rules of what may be written while the motor turns come
from :mod:`fcmaster.protocol.parameter_set`; this module opens the port (as the other
commissioning commands do), reads and writes one parameter at a time, and talks to the user.
A restore judges the whole file before it opens the port (only the set's own parameters,
values each parameter can take, frequency ceilings within the drive's configured limit), then
reads the drive, writes only what differs, reads each written value back, and never writes a
parameter that needs the motor stopped while the drive reports running.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import yaml

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.plan import DrivePlan
from fcmaster.config_yaml import read
from fcmaster.errors import BusError, ConfigError, UsageError
from fcmaster.protocol.codec import DriveError, Exchange, ParameterValue, Reply
from fcmaster.protocol.parameter_set import (
    Difference,
    Entry,
    ParameterSet,
    SetProfile,
    compare,
    identity_mismatches,
    judge,
    profile_for,
    read_set,
)
from fcmaster.subcommands.commission import LineOptions, _check_address, _Session

EXIT_EQUAL, EXIT_DIFFERENT = 0, 1


class _Drive:
    """One drive on an open session: parameter reads and writes, status."""

    def __init__(self, session: _Session, address: int) -> None:
        self.session, self.address = session, address
        _check_address(session.codec, address)

    async def _exchange(self, exchanges: Sequence[Exchange], what: str) -> Reply:
        """Carry ``exchanges`` out; the last reply (or the first refusal). BusError on silence."""
        for _ in range(2):  # one retry: a single lost reply must not end a long backup
            reply = None
            for exchange in exchanges:
                reply = await self.session.link.transact(exchange)
                if exchange.settle_s:  # the drive's pacing (a Yaskawa after a write), kept
                    await self.session.clock.sleep(exchange.settle_s)  # whatever the reply
                if reply is None or reply.error is not None:
                    break
            if reply is not None:
                return reply
        port = self.session.plan.port
        raise BusError(f"no reply from address {self.address} on {port} ({what})")

    async def read(self, name: str) -> ParameterValue | DriveError:
        """The value of ``name``, or the drive's refusal; BusError on silence."""
        codec = self.session.codec
        reply = await self._exchange(
            codec.read(self.address, codec.parameter(name), 0, None), f"reading {name}"
        )
        if reply.error is None and reply.value is None:
            raise BusError(f"address {self.address} answered a read of {name} without a value")
        return reply.error or reply.value  # type: ignore[return-value]

    async def write(self, name: str, value: float, *, persist: bool) -> DriveError | None:
        """Write ``value``; the drive's refusal, or None when it took it."""
        codec = self.session.codec
        exchanges = codec.write(
            self.address, codec.parameter(name), 0, value, None, persist=persist
        )
        return (await self._exchange(exchanges, f"writing {name}")).error

    async def running(self) -> bool:
        """Whether the drive says its motor runs (BusError if it does not answer)."""
        reply = await self.session.poll(self.address)
        if reply is None:
            reply = await self.session.poll(self.address)
        if reply is None:
            port = self.session.plan.port
            raise BusError(f"no reply from address {self.address} on {port}")
        return reply.status is None or reply.status.running  # no status: assume the worst


def _set_of(options: LineOptions) -> SetProfile:
    """The set of the line's drives; UsageError when none is known (a profile names it)."""
    found = profile_for(options.protocol, options)
    if not found.members:
        raise UsageError(
            f"no parameter set is known for {options.protocol} drives here: a drive "
            "profile lists it (--profile)"
        )
    return found


def _progress(done: int, total: int, what: str) -> None:
    width = 30
    bar = "#" * (width * done // total) + "-" * (width - width * done // total)
    sys.stderr.write(f"\r[{bar}] {done}/{total}  {what:<12}")
    sys.stderr.flush()


async def _read_drive(drive: _Drive, profile: SetProfile) -> ParameterSet:
    tty = sys.stderr.isatty()
    wall = drive.session.clock.wall()
    now = datetime.fromtimestamp(wall, UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    try:
        return await read_set(
            profile, drive.address, drive.read, saved_at=now, on_progress=_progress if tty else None
        )
    finally:
        if tty:
            sys.stderr.write("\n")


def load(path: Path) -> ParameterSet:
    """A set from a YAML file; UsageError if it cannot be read or is not a set."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise UsageError(f"{path} is not YAML: {exc}") from None
    twice: list[tuple[str, str]] = []  # a parameter given twice: which value was meant?
    try:
        data = read(text, twice)
    except ConfigError as exc:
        raise UsageError(f"{path} is not YAML: {_problems(exc.problems)}") from None
    if twice:
        raise UsageError(f"{path} is not a valid parameter set: {_problems(twice)}")
    return ParameterSet.from_dict(data, source=str(path))


def _problems(problems: list[tuple[str, str]]) -> str:
    return "; ".join(f"{where}: {reason}" for where, reason in problems)


def dump(found: ParameterSet) -> str:
    """The YAML text of a set."""
    text: str = yaml.safe_dump(found.to_dict(), sort_keys=False, allow_unicode=True)
    return text


async def backup(options: LineOptions, address: int, output: Path | None) -> int:
    """Read every member and the identity; write the YAML (stdout when no file)."""
    profile = _set_of(options)
    async with _Session(options.plan()) as session:
        found = await _read_drive(_Drive(session, address), profile)
    text = dump(found)
    if output is None:
        sys.stdout.write(text)
    else:
        partial = output.with_name(output.name + ".partial")
        partial.write_text(text, encoding="utf-8")
        partial.replace(output)  # a reader never sees half a file
    refused = [k for k, e in found.parameters.items() if e.refused is not None]
    where = f" to {output}" if output else ""
    also = f"; the drive refused to read {', '.join(refused)}" if refused else ""
    print(f"{len(found.parameters) - len(refused)} parameters saved{where}{also}", file=sys.stderr)
    return 0


def _table(differences: list[Difference], left: str, right: str) -> None:
    rows = [("parameter", "name", left, right)] + [
        (d.parameter, d.name, _side(d.left), _side(d.right)) for d in differences
    ]
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    for row in rows:
        cells = (cell.ljust(w) for cell, w in zip(row[:3], widths, strict=True))
        print("  ".join([*cells, row[3]]))


def _side(entry: Entry | None) -> str:
    return "(absent)" if entry is None else entry.shown()


async def diff(options: LineOptions | None, address: int | None, files: list[Path]) -> int:
    """A drive against a file, or two files: a table; 0 equal, 1 different."""
    if options is None:
        if len(files) != 2:
            raise UsageError("without --port, give two files to compare")
        left, right = load(files[0]), load(files[1])
        labels = (str(files[0]), str(files[1]))
    else:
        if len(files) != 1 or address is None:
            raise UsageError("with --port, give --address and one file to compare the drive with")
        left = load(files[0])
        if left.protocol != options.protocol:
            raise UsageError(
                f"{files[0]} is a {left.protocol} set; the line is {options.protocol} (--protocol)"
            )
        async with _Session(options.plan()) as session:
            right = await _read_drive(_Drive(session, address), _set_of(options))
        labels = (str(files[0]), f"drive {address}")
    differences = compare(left, right)
    # A parameter only one side has is a difference too: count both sides' parameters.
    compared = len(left.parameters.keys() | right.parameters.keys())
    if not differences:
        print(f"no differences in {compared} parameters")
        return EXIT_EQUAL
    _table(differences, *labels)
    print(f"{len(differences)} of {compared} parameters differ")
    return EXIT_DIFFERENT


async def restore(
    options: LineOptions,
    address: int,
    path: Path,
    *,
    force: bool,
    persist: bool,
    config: Path | None = None,
) -> int:
    """Judge the whole file, then write what differs, each verified by reading back.

    0 when all was written. Nothing reaches the line (the port is not even opened) when the
    file holds a parameter outside the set or a value its parameter cannot take, or, unless
    ``force``, a frequency ceiling above the drive's ``max_frequency_hz`` in ``config``.
    """
    saved = load(path)
    profile = _set_of(options)
    if saved.protocol != options.protocol:
        raise UsageError(
            f"{path} is a {saved.protocol} set; the line is {options.protocol} (--protocol)"
        )
    codec = codec_for(options.plan())
    _check_address(codec, address)
    configured = None if config is None else _configured(config, options, address)

    def encode(key: str, value: float) -> object:  # built, never sent: the judge's measure
        return codec.write(address, codec.parameter(key), 0, value, None, persist=persist)

    ceiling = None if configured is None else configured.max_frequency_hz
    verdict = judge(profile, saved, encode, max_frequency_hz=ceiling)
    if verdict.refused or (verdict.beyond_limits and not force):
        lines = [f"  {line} (--force does not change this)" for line in verdict.refused]
        lines += [f"  {line} (--force writes it anyway)" for line in verdict.beyond_limits]
        raise UsageError(f"{path} is refused; nothing was written:\n" + "\n".join(lines))
    for line in verdict.beyond_limits:
        print(f"{line}: allowed by --force", file=sys.stderr)
    async with _Session(options.plan()) as session:
        drive = _Drive(session, address)
        current = await _read_drive(drive, profile)
        mismatches = identity_mismatches(profile, saved, current)
        if mismatches and not force:
            raise UsageError(
                f"{path} was not saved from a drive like this one: "
                + "; ".join(mismatches)
                + " (--force writes it anyway)"
            )
        wanted = [d for d in compare(saved, current) if _restorable(d)]
        report = _Report()
        tty = sys.stderr.isatty()
        for done, change in enumerate(wanted, 1):
            await _restore_one(drive, profile, change, persist=persist, report=report)
            if tty:
                _progress(done, len(wanted), change.parameter)
        # A value the drive refused may have been bounded by another not yet written (FC:
        # 4-12 Motor Speed Low Limit ≤ 4-14 High Limit): once the others are in, try again.
        again = [d for d in wanted if d.parameter in report.refused_by_drive]
        if again and report.written:
            for change in again:
                await _restore_one(drive, profile, change, persist=persist, report=report)
        if wanted and tty:
            sys.stderr.write("\n")
    for line in [*report.lines, *report.left_alone]:
        print(line)
    for d in compare(saved, current):
        if not _restorable(d):
            print(f"{d.parameter:<8} {d.name}: not restored ({_why_not(d)})")
    print(
        f"{report.written} written and verified, {report.failed} not written, "
        f"{len(report.left_alone)} line settings left alone, "
        f"{len(saved.parameters) - len(wanted)} already equal or not restorable"
    )
    return 0 if report.failed == 0 else 1


def _configured(config: Path, options: LineOptions, address: int) -> DrivePlan:
    """The drive at ``address`` on ``config``'s bus at the port (links followed)."""
    from fcmaster.config import load as load_config  # pydantic: only when a config is named

    port = options.port
    real = os.path.realpath(port)
    for plan in load_config(config, buses_only=True).lines:
        if plan.port == port or ("://" not in plan.port and os.path.realpath(plan.port) == real):
            if plan.protocol != options.protocol:
                raise UsageError(
                    f"bus {plan.name} in {config} is {plan.protocol}; the line is "
                    f"{options.protocol} (--protocol)"
                )
            for drive in plan.drives:
                if drive.address == address:
                    return drive
            raise UsageError(f"bus {plan.name} in {config} has no drive at address {address}")
    raise UsageError(f"no bus in {config} is at {port}")


def _restorable(d: Difference) -> bool:
    return d.left is not None and d.left.refused is None and isinstance(d.left.value, float)


def _why_not(d: Difference) -> str:
    if d.left is None:
        return "not in the file"
    return "the file has no value: the drive it came from refused to read it"


class _Report:
    """Each difference's last outcome, in the order first tried."""

    def __init__(self) -> None:
        self.outcomes: dict[str, tuple[bool, str]] = {}
        self.refused_by_drive: set[str] = set()
        self.left_alone: list[str] = []  # line settings: deliberately not restored

    def add(self, d: Difference, ok: bool, text: str, *, drive_refused: bool = False) -> None:
        self.outcomes[d.parameter] = (ok, f"{d.parameter:<8} {d.name}: {text}")
        if drive_refused:
            self.refused_by_drive.add(d.parameter)
        else:
            self.refused_by_drive.discard(d.parameter)

    @property
    def lines(self) -> list[str]:
        return [line for _, line in self.outcomes.values()]

    @property
    def written(self) -> int:
        return sum(ok for ok, _ in self.outcomes.values())

    @property
    def failed(self) -> int:
        return len(self.outcomes) - self.written


async def _restore_one(
    drive: _Drive, profile: SetProfile, d: Difference, *, persist: bool, report: _Report,
) -> None:  # fmt: skip
    assert d.left is not None
    assert isinstance(d.left.value, float)
    change = f"{_side(d.right)} → {d.left.shown()}"
    if d.parameter in profile.link_settings:
        report.left_alone.append(
            f"{d.parameter:<8} {d.name}: {change} left alone: it sets how the drive talks on "
            "the line; change it with fcmaster write, then the line options"
        )
        return
    # Asked just before each write: a drive started during a long restore is seen.
    if d.parameter not in profile.changeable_while_running and await drive.running():
        report.add(d, False, f"{change} not written: needs the motor stopped, and the drive "
                   "is running (stop it, then restore again)")  # fmt: skip
        return
    refused = await drive.write(d.parameter, d.left.value, persist=persist)
    if refused is not None:
        report.add(d, False, f"{change} refused by the drive: {refused.text} "
                   f"(error {refused.code})", drive_refused=True)  # fmt: skip
        return
    back = await drive.read(d.parameter)
    entry = Entry.of(d.name, back)
    if entry.same_as(d.left):
        report.add(d, True, f"{change} written, read back {entry.shown()}")
    else:
        report.add(d, False, f"{change} written, but reads back {entry.shown()}")
