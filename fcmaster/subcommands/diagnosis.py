"""What `fcmaster doctor` concludes from what it heard on a line: findings and their fixes.

Pure: a :class:`Survey` (what the probes observed) goes in, :class:`Finding` objects come
out, each with the sentence that names the problem and the one that says what to change.
The probing itself lives in :mod:`fcmaster.subcommands.doctor`.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field, replace
from typing import Any, Final

from fcmaster.protocol.registry import PROTOCOLS, spec_for
from fcmaster.protocol.spec import OptionPairs
from fcmaster.transport.usb import LOW_LATENCY_MS, UDEV_FILE, UDEV_RULE, Adapter
from fcmaster.transport.usb import max_transactions_per_s as adapter_limit

NOISE_MIN_BYTES: Final = 3  # fewer stray bytes than this are a glitch (a port opening), not noise
# Answers later than the drives' factory delay by this much (median) are held somewhere: a
# 16 ms USB latency timer holds a reply 8 ms on average, a pty or a 1 ms timer about 1 ms.
SLOW_BY_S: Final = 0.005

# Where a drive keeps the settings a finding asks to change, and how long it takes to
# answer a status request at its factory settings: ProtocolSpec.diagnosis.


@dataclass(slots=True, frozen=True, kw_only=True)
class LineFormat:
    """A protocol, the character format it is spoken in and the options the doctor probes."""

    protocol: str
    baudrate: int
    parity: str
    stopbits: int
    # The protocol's own line keys the doctor probes (ProtocolSpec.probed_options), as
    # (key, value) pairs: FC's address format; none for most protocols.
    protocol_options: OptionPairs = ()

    @property
    def character_format(self) -> str:
        """``19200 8E1``."""
        return f"{self.baudrate} 8{self.parity}{self.stopbits}"

    def value(self, key: str) -> object:
        """The value of the config key ``key`` (``baudrate``, ``address_format``)."""
        options = dict(self.protocol_options)
        return options[key] if key in options else getattr(self, key)

    def with_options(self, pairs: OptionPairs) -> LineFormat:
        """The same format with ``pairs`` in place of the options of the same names."""
        names = {name for name, _ in pairs}
        return replace(
            self,
            protocol_options=(*(p for p in self.protocol_options if p[0] not in names), *pairs),
        )

    def text(self) -> str:
        """``<protocol> 19200 8E1`` (and the probed options: ``, address format 126``)."""
        fmt = f"{self.protocol} {self.baudrate} 8{self.parity}{self.stopbits}"
        return fmt + "".join(f", {name.replace('_', ' ')} {v}" for name, v in self.protocol_options)

    def to_json(self) -> dict[str, Any]:
        """As the config's bus keys name them."""
        out: dict[str, Any] = {
            "protocol": self.protocol,
            "baudrate": self.baudrate,
            "parity": self.parity,
            "stopbits": self.stopbits,
        }
        out.update(self.protocol_options)
        return out


@dataclass(slots=True, kw_only=True)
class AddressReport:
    """What came back from one address over its attempts."""

    address: int
    attempts: int = 0
    answered: int = 0  # attempts with exactly one reply that checked
    doubled: int = 0  # attempts with two or more replies that checked
    garbled: int = 0  # attempts with a reply's worth of bytes and no reply that checked

    @property
    def collides(self) -> bool:
        """Whether two drives seem to answer here: doubled, or garbled more than not."""
        return self.doubled > 0 or (self.garbled >= 2 and self.garbled > self.answered)

    @property
    def present(self) -> bool:
        """Whether at least one drive is here."""
        return self.answered > 0 or self.collides

    def to_json(self) -> dict[str, Any]:
        """The counts, and whether two drives seem to share the address."""
        return {
            "address": self.address,
            "attempts": self.attempts,
            "answered": self.answered,
            "doubled": self.doubled,
            "garbled": self.garbled,
            "collides": self.collides,
        }


@dataclass(slots=True, kw_only=True)
class Expected:
    """What the config says about the line (the bus at the doctored port)."""

    bus: str
    line: LineFormat
    echo: bool
    addresses: list[int] = field(default_factory=list)  # its drives'


@dataclass(slots=True, kw_only=True)
class Survey:
    """Everything the probes observed on one port."""

    port: str
    found: LineFormat | None = None  # where drives answered; None: nowhere
    settings_tried: int = 0
    addresses: list[AddressReport] = field(default_factory=list)  # at ``found``
    scanned: list[int] = field(default_factory=list)  # every address asked at ``found``
    requests: int = 0  # every request written, at every setting
    echoes: int = 0  # of those, how many came back byte for byte before anything else
    noise_bytes: int = 0  # bytes outside frames (collision garbage not counted)
    listened_s: float = 0.0  # time spent waiting for replies
    turnarounds_s: list[float] = field(default_factory=list)  # request end → reply end, less wire
    adapter: Adapter | None = None
    expected: Expected | None = None
    # The drives answered only with these options (one of the spec's fallback_options),
    # not with their defaults: () when they answered at the defaults
    only_options: OptionPairs = ()
    settings_probed: bool = True  # False: a socket:// converter, whose own settings apply

    @property
    def drives(self) -> list[int]:
        """The addresses where a drive answered (or two collided)."""
        return [report.address for report in self.addresses if report.present]

    @property
    def turnaround_ms(self) -> float | None:
        """The median time a drive took to answer, wire time excluded (its delay + the adapter)."""
        if not self.turnarounds_s:
            return None
        return statistics.median(self.turnarounds_s) * 1000.0


@dataclass(slots=True, frozen=True)
class Finding:
    """One thing to fix: a code for scripts, what is wrong, and what to do."""

    # no_answer, settings, echo, no_echo, duplicate_address, …, or the line key a drive
    # answers only to a fallback value of (address_format)
    code: str
    message: str
    fix: str
    data: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """``{"code", "message", "fix", …data}``."""
        return {"code": self.code, "message": self.message, "fix": self.fix, **self.data}


def diagnose(survey: Survey) -> list[Finding]:
    """The findings, most fundamental first (nothing else matters until drives answer)."""
    findings: list[Finding] = []
    if survey.found is None:
        findings.append(_no_answer(survey))
    else:
        findings.extend(_settings(survey, survey.found))
        findings.extend(_duplicates(survey, survey.found))
    findings.extend(_echo(survey))
    findings.extend(_noise(survey))
    latency = _latency(survey)
    findings.extend(latency or _slow(survey))
    return findings


def _no_answer(survey: Survey) -> Finding:
    converter = "" if survey.settings_probed else "set the converter's serial side to the drives'; "
    return Finding(
        "no_answer",
        f"no drive answered on {survey.port} at any of {survey.settings_tried} line settings",
        f"{converter}check that the drives are powered and set to the protocol; swap the A "
        "and B wires if they may be crossed; terminate both ends of the line with 120 ohm; "
        "if the drives are at other addresses than those probed, pass --addresses",
    )


def _settings(survey: Survey, found: LineFormat) -> list[Finding]:
    expected = survey.expected
    if not survey.settings_probed:
        return []  # the converter's settings, not the port's: nothing was compared
    findings: list[Finding] = []
    if expected is not None:
        want = expected.line
        keys = ("protocol", "baudrate", "parity")
        differ = [k for k in keys if found.value(k) != want.value(k)]
        # the probed options, when the config's protocol is the one found
        mine = dict(want.protocol_options) if want.protocol == found.protocol else {}
        differ += [k for k, v in found.protocol_options if k in mine and mine[k] != v]
        if differ:
            said = ", ".join(f"{k} {want.value(k)}" for k in differ)
            sets = ", ".join(f"{k}: {found.value(k)}" for k in differ)
            findings.append(
                Finding(
                    "settings",
                    f"drives answer at {found.character_format} ({found.protocol}) "
                    f"but the config (bus {expected.bus}) says {said}",
                    f"set {sets} on bus {expected.bus}",
                    {"found": found.to_json(), "config": want.to_json()},
                )
            )
            return findings
    only = survey.only_options
    if only and (expected is None or not set(only) <= set(expected.line.protocol_options)):
        named = ", ".join(f"{k} {v}" for k, v in only)
        sets = ", ".join(f"{k}: {v}" for k, v in only)
        flags = " ".join(f"--{k.replace('_', '-')} {v}" for k, v in only)
        findings.append(
            Finding(
                "_".join(k for k, _ in only),
                f"the drives answer only with {named}, not with the default",
                f"set {sets} (or {flags})",
            )
        )
    return findings


def _duplicates(survey: Survey, found: LineFormat) -> list[Finding]:
    spec = PROTOCOLS.get(found.protocol)
    parameter = spec.diagnosis.address if spec else "its address parameter"
    taken = set(survey.drives)
    findings = []
    for report in survey.addresses:
        if not report.collides:
            continue
        how = "doubled replies" if report.doubled else "garbled replies"
        free = next((a for a in survey.scanned if a not in taken), None)
        suggestion = f" (e.g. {free}, where nothing answered)" if free is not None else ""
        taken.add(free if free is not None else -1)
        findings.append(
            Finding(
                "duplicate_address",
                f"two drives answer at address {report.address} ({how} in "
                f"{report.doubled + report.garbled} of {report.attempts} attempts)",
                f"give one of them another address with {parameter}{suggestion}",
                {"address": report.address},
            )
        )
    return findings


def _echo(survey: Survey) -> list[Finding]:
    heard = survey.requests > 0 and survey.echoes * 2 >= survey.requests
    configured = survey.expected.echo if survey.expected is not None else False
    if heard and not configured:
        return [
            Finding(
                "echo",
                f"the adapter echoes: {survey.echoes} of {survey.requests} requests came back "
                "before any reply",
                "set echo: true on the bus (or switch the adapter's echo off, if it can)",
                {"echoes": survey.echoes, "requests": survey.requests},
            )
        ]
    if configured and survey.requests >= 4 and survey.echoes == 0 and survey.found is not None:
        return [
            Finding(
                "no_echo",
                "the config expects an echo but the adapter does not echo",
                "set echo: false on the bus",
            )
        ]
    return []


def _noise(survey: Survey) -> list[Finding]:
    if survey.noise_bytes < NOISE_MIN_BYTES:
        return []
    per_100 = 100.0 * survey.noise_bytes / max(survey.requests, 1)
    per_s = survey.noise_bytes / survey.listened_s if survey.listened_s > 0 else 0.0
    return [
        Finding(
            "noise",
            f"{survey.noise_bytes} bytes of noise outside frames ({per_100:.0f} per 100 "
            f"requests, {per_s:.1f} per second of listening)",
            "terminate both ends of the line with 120 ohm (and nowhere else), bias it once, "
            "ground the shield at one end, and keep the cable away from motor leads",
            {
                "noise_bytes": survey.noise_bytes,
                "per_100_requests": round(per_100, 1),
                "per_second": round(per_s, 2),
            },
        )
    ]


def _latency(survey: Survey) -> list[Finding]:
    adapter = survey.adapter
    if adapter is None or adapter.latency_ms is None or adapter.latency_ms <= LOW_LATENCY_MS:
        return []
    limit = adapter_limit(adapter.latency_ms)
    return [
        Finding(
            "adapter_latency",
            f"{adapter.latency_ms} ms latency timer on {adapter.device} "
            f"({adapter.driver or 'unknown driver'}): at most about {limit} transactions/s",
            f"as root: echo '{UDEV_RULE}' > {UDEV_FILE}; then replug the adapter",
            {"latency_ms": adapter.latency_ms, "max_transactions_per_s": limit},
        )
    ]


def _slow(survey: Survey) -> list[Finding]:
    turnaround_ms, found = survey.turnaround_ms, survey.found
    if turnaround_ms is None or found is None or "://" in survey.port:
        return []  # over a network the round trip is in it too: no measure of the line
    diagnosis = spec_for(found.protocol).diagnosis
    if diagnosis.factory_delay_s is None:
        return []  # no delay to compare with; a USB latency timer is judged on its own
    factory_ms = diagnosis.factory_delay_s * 1000.0
    if turnaround_ms - factory_ms < SLOW_BY_S * 1000.0:
        return []
    parameter = diagnosis.delay
    return [
        Finding(
            "slow_replies",
            f"the drives answer {turnaround_ms:.1f} ms after a request ends, "
            f"{turnaround_ms - factory_ms:.1f} ms later than at their factory delay: an "
            "adapter that holds replies (a USB latency timer) or a longer response delay",
            "on a USB adapter, lower its latency timer (fcmaster ports shows it; as root: "
            f"echo '{UDEV_RULE}' > {UDEV_FILE}, then replug it); otherwise check the drives' "
            f"{parameter}",
            {"turnaround_ms": round(turnaround_ms, 2), "factory_delay_ms": factory_ms},
        )
    ]


def to_json(survey: Survey, findings: list[Finding]) -> dict[str, Any]:
    """The doctor's ``--json`` document."""
    turnaround = survey.turnaround_ms
    return {
        "port": survey.port,
        "healthy": survey.found is not None and not findings,
        "line": survey.found.to_json() if survey.found is not None else None,
        "drives": survey.drives,
        "addresses": [r.to_json() for r in survey.addresses if r.present],
        "settings_tried": survey.settings_tried,
        "settings_probed": survey.settings_probed,
        "requests": survey.requests,
        "echoes": survey.echoes,
        "noise_bytes": survey.noise_bytes,
        "turnaround_ms": round(turnaround, 2) if turnaround is not None else None,
        "adapter": survey.adapter.to_json() if survey.adapter is not None else None,
        "config_bus": survey.expected.bus if survey.expected is not None else None,
        "findings": [finding.to_json() for finding in findings],
    }


def to_text(survey: Survey, findings: list[Finding]) -> list[str]:
    """The doctor's report for a person: the line, the drives, then each finding and its fix."""
    lines = [f"port      {survey.port}"]
    if survey.adapter is not None:
        adapter = survey.adapter
        latency = "no latency timer" if adapter.latency_ms is None else f"{adapter.latency_ms} ms"
        lines.append(f"adapter   {adapter.driver or 'unknown driver'}, latency timer {latency}")
    if survey.found is not None and not survey.settings_probed:
        lines.append(f"line      {survey.found.protocol} (the converter's own serial settings)")
    elif survey.found is not None:
        lines.append(f"line      {survey.found.text()}")
        drives = ", ".join(str(a) for a in survey.drives) or "none"
        lines.append(f"drives    {drives}")
    if survey.turnaround_ms is not None:
        lines.append(
            f"answers   {survey.turnaround_ms:.1f} ms after the request (wire time excluded)"
        )
    if not findings:
        lines.append("healthy: nothing to fix")
    for finding in findings:
        lines.append(f"problem   {finding.message}")
        lines.append(f"  fix     {finding.fix}")
    return lines
