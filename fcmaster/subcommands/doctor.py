"""`fcmaster doctor --port PORT`: find how a line is set up and what is wrong with it.

Theory of operation
-------------------
A line answers only when the master speaks the drives' protocol at their baud rate and
parity, so the doctor tries each setting (each protocol unless one is given; baud rates
fastest first; the factory parity first) with a few monitor-only polls — the protocol's
status request, which never commands a drive — to the first addresses (or the config's
drives). Once a drive answers, it scans every address at that setting only, and asks
again where anything came back, listening past the first reply so that a second drive at
the same address shows itself (two replies, or one garbled by the other).

Each request's bytes are read raw rather than through the daemon's Link, because the
doctor wants what the Link throws away: the request heard back before anything else (an
echoing adapter), bytes outside any frame (noise), a reply's worth of bytes that never
checks (a collision). What it concludes is :mod:`fcmaster.subcommands.diagnosis`'s business.

Exit codes: 0 when drives answer and there is nothing to fix; 1 when a finding needs
fixing or no drive answers (or the port cannot be opened); 2 for bad input.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Final

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.plan import LinePlan, with_protocol_options
from fcmaster.clock import Clock, MonotonicClock
from fcmaster.config import load
from fcmaster.errors import (
    MalformedReply,
    PortError,
    ProtocolError,
    ReplyTimeout,
    UnexpectedReply,
    UsageError,
)
from fcmaster.protocol.codec import DriveCodec, Exchange
from fcmaster.protocol.framing import Frame
from fcmaster.protocol.registry import NAMES, spec_for
from fcmaster.subcommands.diagnosis import (
    AddressReport,
    Expected,
    LineFormat,
    Survey,
    diagnose,
    to_json,
    to_text,
)
from fcmaster.transport.pipe import Transport
from fcmaster.transport.serial import SerialTransport

# The rates each protocol's drives offer (fastest first) and the parities (factory first)
# are its spec's baudrates and parities.
PROBES_PER_SETTING: Final = 4  # addresses asked at each setting before moving on
CONFIRM_ATTEMPTS: Final = 3  # attempts at an address where anything came back
# Beyond the wire time and the drives' delay, how long to wait for a reply: room for a 16 ms
# USB latency timer and a busy machine's scheduling, less than the daemon's 50 ms, since the
# doctor asks many silent addresses at many settings.
MARGIN_S: Final = 0.030

OpenTransport = Callable[[LinePlan], Transport]
Progress = Callable[[str], None]


@dataclass(slots=True)
class _Heard:
    """What came back from one request."""

    replies: int = 0  # frames that answer it
    stray: int = 0  # bytes outside those frames (the echo not counted)
    echo: bool = False
    turnaround_s: float | None = None


class _Prober:
    """Polls addresses at one line setting over an open transport."""

    def __init__(self, plan: LinePlan, transport: Transport, survey: Survey, clock: Clock) -> None:
        self.plan = plan
        self.codec: DriveCodec = codec_for(plan)
        self.transport = transport
        self.survey = survey
        self.clock = clock
        self._pause_s = self.codec.min_pause_s(plan.char_s)
        self.quiet_at = 0.0  # the protocol's pause after the last bytes heard ends here

    async def ask(self, address: int) -> _Heard:
        """Poll ``address`` once, listening until the reply deadline.

        Listening on after a reply costs only where a drive answers, and hears a second
        drive at the address that answers later than the first (a longer response delay);
        it also keeps that drive's reply from arriving in the next poll's window.
        """
        plan, codec, transport, clock = self.plan, self.codec, self.transport, self.clock
        exchange = codec.poll(address, None, None)
        request = exchange.request
        if self.quiet_at > clock.now():
            await clock.sleep_until(self.quiet_at)
        stale = transport.discard_input()  # bytes between requests: noise (or a late twin)
        self.survey.noise_bytes += len(stale)
        written = clock.now()
        await transport.write(request)
        self.survey.requests += 1
        sent_end = written + plan.wire_s(len(request))
        deadline = written + plan.reply_timeout(len(request), exchange.reply_length)
        heard = _Heard()
        framer = codec.new_framer()
        pending = b""  # bytes that may still turn out to be the echo
        echo_open = True
        while True:
            try:
                chunk = await transport.read(deadline)
            except ReplyTimeout:
                break
            arrived = transport.received_at
            self.quiet_at = arrived + self._pause_s
            if echo_open:
                pending += chunk
                if request.startswith(pending) and len(pending) < len(request):
                    continue  # an echo so far
                echo_open = False
                heard.echo = pending.startswith(request)
                chunk = pending[len(request) :] if heard.echo else pending
            framer.feed(chunk)
            while (piece := framer.next_frame()) is not None:
                if isinstance(piece, Frame) and self._answers(exchange, piece.data):
                    heard.replies += 1
                    if heard.replies == 1:
                        wire = plan.wire_s(len(piece.data))
                        heard.turnaround_s = max(0.0, arrived - sent_end - wire)
                else:
                    heard.stray += len(piece.data)
        framer.reset()
        while (piece := framer.next_frame()) is not None:
            heard.stray += len(piece.data)
        if echo_open and pending:
            heard.stray += len(pending)  # part of an echo and nothing else: noise all the same
        self.survey.listened_s += clock.now() - written
        self.survey.echoes += heard.echo
        return heard

    def _answers(self, exchange: Exchange, frame: bytes) -> bool:
        try:
            self.codec.parse(exchange, frame)
        except (UnexpectedReply, MalformedReply, ProtocolError):
            return False
        return True

    async def confirm(self, report: AddressReport, first: _Heard) -> None:
        """Count ``first`` and, where anything came back, listen to more attempts."""
        self._count(report, first)
        if first.replies or first.stray >= self.reply_length(report.address):
            for _ in range(CONFIRM_ATTEMPTS - 1):
                self._count(report, await self.ask(report.address))

    def _count(self, report: AddressReport, heard: _Heard) -> None:
        report.attempts += 1
        if heard.turnaround_s is not None:
            self.survey.turnarounds_s.append(heard.turnaround_s)
        if heard.replies > 1:
            report.doubled += 1
        elif heard.replies == 1:
            report.answered += 1
            self.survey.noise_bytes += heard.stray
        elif heard.stray >= self.reply_length(report.address):
            report.garbled += 1  # a reply's worth that never checked: two drives at once
        else:
            self.survey.noise_bytes += heard.stray

    def reply_length(self, address: int) -> int:
        """How long a status reply from ``address`` is: less than that is no collision."""
        return self.codec.poll(address, None, None).reply_length


def _serial(plan: LinePlan) -> Transport:
    return SerialTransport(plan.port, baudrate=plan.baudrate, parity=plan.parity,
                           stopbits=plan.stopbits)  # fmt: skip


def _plan(port: str, fmt: LineFormat, timeout_s: float | None) -> LinePlan:
    plan = LinePlan(
        name="doctor", port=port, protocol=fmt.protocol, baudrate=fmt.baudrate,
        parity=fmt.parity, stopbits=fmt.stopbits, timeout_s=timeout_s,
    )  # fmt: skip
    spec = spec_for(fmt.protocol)  # its defaults, then the probed options the format has
    plan = with_protocol_options(plan, spec.option_pairs(fmt))
    plan = with_protocol_delay(plan)
    if timeout_s is None:
        codec = codec_for(plan)
        exchange = codec.poll(codec.addresses[0], None, None)
        wire = plan.wire_s(len(exchange.request) + exchange.reply_length)
        plan = replace(plan, timeout_s=wire + plan.response_delay_s + MARGIN_S)
    return plan


def settings_to_try(
    protocols: tuple[str, ...], *, fixed: Expected | None = None, probe_format: bool = True
) -> Iterator[LineFormat]:
    """Each protocol's settings: baud rates fastest first, the factory parity first.

    Without ``probe_format`` (a ``socket://`` converter, whose serial side is set on the
    converter) each protocol is tried once, at the config's settings or its factory ones.
    """
    for protocol in protocols:
        spec = spec_for(protocol)
        baudrate, parity, stopbits = (spec.factory.baudrate, spec.factory.parity,
                                      spec.factory.stopbits)  # fmt: skip
        options = spec.probed_options()  # their defaults; the fallbacks are tried in examine
        if not probe_format:
            if fixed is not None and fixed.line.protocol == protocol:
                yield fixed.line
            else:
                yield LineFormat(protocol=protocol, baudrate=baudrate, parity=parity,
                                 stopbits=stopbits, protocol_options=options)  # fmt: skip
            continue
        for baudrate in spec.baudrates:
            for parity in spec.parities:
                yield LineFormat(protocol=protocol, baudrate=baudrate, parity=parity,
                                 stopbits=stopbits, protocol_options=options)  # fmt: skip


async def examine(
    port: str,
    *,
    protocols: tuple[str, ...],
    addresses: list[int] | None = None,
    expected: Expected | None = None,
    probe: list[int] | None = None,
    timeout_s: float | None = None,
    open_transport: OpenTransport = _serial,
    progress: Progress | None = None,
    clock: Clock | None = None,
) -> Survey:
    """Find the setting where drives answer, then scan and confirm the drives there.

    ``clock`` must be the transport's timebase (a serial port's is the monotonic clock).
    """
    survey = Survey(port=port, expected=expected)
    clock = clock or MonotonicClock()
    _check_addresses(addresses, protocols)
    note = progress or (lambda text: None)
    # A raw TCP converter (socket://) has its serial settings on the converter: the port
    # takes none, so every rate would seem to work. rfc2217:// does carry them.
    survey.settings_probed = not port.startswith("socket://")
    candidates = list(
        settings_to_try(protocols, fixed=expected, probe_format=survey.settings_probed)
    )
    opened = False
    first_error: PortError | None = None
    for number, fmt in enumerate(candidates, 1):
        survey.settings_tried = number
        note(f"setting {number}/{len(candidates)}: {fmt.text()}")
        plan = _plan(port, fmt, timeout_s)
        transport = open_transport(plan)
        try:
            await transport.open()
        except PortError as exc:  # a rate this port cannot take: the next one
            first_error = first_error or exc
            continue
        opened = True
        try:
            survey.adapter = survey.adapter or transport.adapter
            prober = _Prober(plan, transport, survey, clock)
            asked = _probe_list(prober.codec, probe, addresses)
            if await _anyone(prober, asked):
                survey.found = fmt
            else:  # drives that answer only to other options of their protocol's?
                prober = await _fallbacks(prober, fmt, asked, timeout_s)
            if survey.found is not None:
                await _scan(prober, addresses, survey, note)  # the prober that heard them
                return survey
        finally:
            await transport.close()
    if not opened and first_error is not None:
        raise first_error
    return survey


async def _fallbacks(
    prober: _Prober, fmt: LineFormat, asked: list[int], timeout_s: float | None
) -> _Prober:
    """Ask one address again with each of the protocol's fallback options, in order.

    Where drives answer, the survey records the format found and the options they needed;
    the prober returned is the one that heard them (or the last one asking).
    """
    survey = prober.survey
    for pairs in spec_for(fmt.protocol).fallback_options:
        if set(pairs) <= set(fmt.protocol_options):
            continue  # what was just asked
        other, heard_until = fmt.with_options(pairs), prober.quiet_at
        plan = _plan(prober.plan.port, other, timeout_s)
        prober = _Prober(plan, prober.transport, survey, prober.clock)
        prober.quiet_at = heard_until  # the same line: the pause still holds
        if await _anyone(prober, [a for a in asked if a in prober.codec.addresses][:1]):
            survey.found, survey.only_options = other, pairs
            break
    return prober


def _probe_list(
    codec: DriveCodec, probe: list[int] | None, addresses: list[int] | None
) -> list[int]:
    pool = probe or addresses or list(codec.addresses)
    return [a for a in pool if a in codec.addresses][:PROBES_PER_SETTING]


async def _anyone(prober: _Prober, addresses: list[int]) -> bool:
    """Whether a drive answers (or two collide) at one of ``addresses``."""
    for address in addresses:
        heard = await prober.ask(address)
        if heard.stray >= prober.reply_length(address) and not heard.replies:
            return True  # a reply's worth that never checks: two drives at once, likely
        prober.survey.noise_bytes += heard.stray
        if heard.replies:
            return True
    return False


async def _scan(
    prober: _Prober, addresses: list[int] | None, survey: Survey, note: Progress
) -> None:
    reach = prober.codec.addresses
    wanted = [a for a in addresses if a in reach] if addresses else list(reach)
    survey.scanned = wanted
    for done, address in enumerate(wanted, 1):
        note(f"scanning address {address} ({done}/{len(wanted)}), found {len(survey.drives)}")
        report = AddressReport(address=address)
        await prober.confirm(report, await prober.ask(address))
        if report.attempts > 1 or report.answered or report.garbled:
            survey.addresses.append(report)


def _check_addresses(addresses: list[int] | None, protocols: tuple[str, ...]) -> None:
    """UsageError for an address no protocol tried can reach (each scan keeps its own)."""
    reach = {p: codec_for(LinePlan(name="doctor", port="", protocol=p)).addresses
             for p in protocols}  # fmt: skip
    for address in addresses or ():
        if not any(address in span for span in reach.values()):
            spans = ", ".join(f"{p} {r.start}-{r.stop - 1}" for p, r in reach.items())
            raise UsageError(f"address {address} is outside every protocol's range ({spans})")


def expected_from_config(config: Path, port: str) -> Expected:
    """The bus of ``config`` at ``port`` (the same device, links followed); UsageError if none."""
    lines = load(config, buses_only=True).lines
    real = os.path.realpath(port)
    for plan in lines:
        if plan.port == port or ("://" not in plan.port and os.path.realpath(plan.port) == real):
            fmt = LineFormat(
                protocol=plan.protocol, baudrate=plan.baudrate, parity=plan.parity,
                stopbits=plan.stopbits,
                protocol_options=spec_for(plan.protocol).probed_options(plan),
            )  # fmt: skip
            return Expected(bus=plan.name, line=fmt, echo=plan.echo,
                            addresses=[d.address for d in plan.drives])  # fmt: skip
    ports = ", ".join(f"{p.name} at {p.port}" for p in lines) or "none"
    raise UsageError(f"no bus in {config} is at {port} (buses: {ports})")


async def run(
    port: str,
    *,
    protocol: str | None,
    config: Path | None,
    addresses: list[int] | None,
    timeout_s: float | None,
    as_json: bool,
) -> int:
    """The doctor as a command: examine, diagnose, print; 0 healthy, 1 something to fix."""
    expected = expected_from_config(config, port) if config is not None else None
    if protocol is not None:
        protocols: tuple[str, ...] = (protocol,)
    elif expected is not None:  # the config's protocol first, then the others
        first = expected.line.protocol
        protocols = (first, *(p for p in NAMES if p != first))
    else:
        protocols = NAMES
    show = sys.stderr.isatty()

    def progress(text: str) -> None:
        if show:
            sys.stderr.write(f"\r\033[K{text}")
            sys.stderr.flush()

    try:
        survey = await examine(
            port, protocols=protocols, addresses=addresses, timeout_s=timeout_s,
            expected=expected, probe=expected.addresses if expected else None,
            progress=progress,
        )  # fmt: skip
    finally:
        if show:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()
    findings = diagnose(survey)
    if as_json:
        print(json.dumps(to_json(survey, findings), indent=2))
    else:
        print("\n".join(to_text(survey, findings)))
    return 0 if survey.found is not None and not findings else 1
