"""Prometheus text exposition (format 0.0.4), rendered from the fleet state and line stats.

A scrape never asks a line for anything: drive gauges come from the latest snapshots, line
counters and histograms from each BusMaster's :class:`~fcmaster.bus.stats.LineStats`, both
already in memory. Names follow Prometheus conventions: ``fcmaster_`` prefix, base units
(``_seconds``, ``_hz``, ``_ratio``), ``_total`` on counters, labels ``bus`` and ``drive``.

Drive gauges (labels ``bus``, ``drive``):
``fcmaster_drive_info`` (1, with ``address``, ``protocol``, ``control``),
``fcmaster_drive_online``, ``_running``, ``_fault``, ``_warning``, ``_at_reference``
(0/1), ``fcmaster_drive_output_frequency_hz``, ``fcmaster_drive_reference_ratio``,
``fcmaster_drive_status_word``, ``fcmaster_drive_last_reply_timestamp_seconds``,
``fcmaster_drive_output_frequency_timestamp_seconds``,
``fcmaster_drive_value`` (every numeric measured value, labels ``param`` as the manual
writes it and ``unit``), ``fcmaster_drive_alarms`` and ``fcmaster_drive_warnings`` (how
many are active), ``fcmaster_drive_alarm_active`` and ``fcmaster_drive_warning_active``
(1 per active ``code``, with its ``text``); from the line statistics
``fcmaster_drive_requests_total``, ``_replies_total``, ``_timeouts_total``,
``_refused_total`` and ``fcmaster_drive_last_latency_seconds``. ``control: bus`` drives also
have ``fcmaster_drive_watchdog_verdict`` (one sample per ``verdict``: ok, off, too_short,
unknown; 1 for the drive's present verdict, 0 for the others, so an alert is
``fcmaster_drive_watchdog_verdict{verdict="off"} == 1``) and, when the drive's watchdog
has a timeout, ``fcmaster_drive_watchdog_timeout_seconds``.

Line metrics (label ``bus``): ``fcmaster_bus_info`` (``port``, ``protocol``,
``baudrate``), ``fcmaster_bus_up``, ``fcmaster_bus_utilisation_ratio``, counters
``fcmaster_bus_{requests,replies,timeouts,retries,broadcasts,checksum_errors,
malformed_frames,unexpected_replies,noise_bytes,late_bytes,reopens}_total``, and histograms
``fcmaster_bus_transaction_latency_seconds``, ``fcmaster_bus_turnaround_seconds`` and
``fcmaster_bus_wakeup_lateness_seconds``; the daemon adds ``fcmaster_gc_pause_seconds``.

Hub: ``fcmaster_hub_subscriptions``, ``fcmaster_hub_events_published_total`` and
``fcmaster_hub_events_dropped`` (dropped for subscribers now connected).
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Iterable, Mapping
from typing import Any, Final

from fcmaster.adapters.gateway import LineInfo
from fcmaster.bus.watchdog import Verdict
from fcmaster.hub import Hub
from fcmaster.state import DriveState

CONTENT_TYPE: Final = "text/plain; version=0.0.4; charset=utf-8"
YIELD_EVERY: Final = 8  # drives rendered between two turns of the event loop

# LineStats key → (metric suffix, help)
_LINE_COUNTERS: Final = (
    ("requests", "requests", "Requests written to the line."),
    ("replies", "replies", "Valid replies received."),
    ("timeouts", "timeouts", "Requests that got no valid reply before the deadline."),
    ("retries", "retries", "Commands sent again after a failed attempt."),
    ("broadcasts", "broadcasts", "Broadcast telegrams (no reply expected)."),
    ("checksum_errors", "checksum_errors", "Frames that failed their checksum."),
    ("malformed", "malformed_frames", "Checked frames whose content did not decode."),
    ("unexpected", "unexpected_replies", "Replies from another address or of the wrong kind."),
    ("noise_bytes", "noise_bytes", "Bytes skipped by the framer (checksum failures included)."),
    ("late_bytes", "late_bytes", "Stale bytes discarded before a request."),
    ("reopens", "reopens", "Times the port was reopened after it was lost."),
)
_LINE_HISTOGRAMS: Final = (
    ("latency_s", "transaction_latency_seconds", "From request written to reply decoded."),
    ("turnaround_s", "turnaround_seconds", "The master's own time between two transactions."),
    ("wakeup_lateness_s", "wakeup_lateness_seconds", "How late the line's timers fired."),
)
_DRIVE_COUNTERS: Final = (
    ("requests", "Requests addressed to the drive."),
    ("replies", "Valid replies from the drive."),
    ("timeouts", "Requests to the drive that timed out."),
    ("refused", "Requests the drive refused."),
)
_FLAGS: Final = (
    ("online", "Whether the drive answers (1) or is offline (0)."),
    ("running", "Whether the motor is running."),
    ("fault", "Whether the drive has tripped (an alarm is active)."),
    ("warning", "Whether a warning is active."),
    ("at_reference", "Whether the output has reached the reference."),
)


def format_value(value: float) -> str:
    """A sample value as the exposition format writes it (+Inf, -Inf, NaN, shortest repr)."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "+Inf" if value > 0 else "-Inf"
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def _escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def labels(pairs: Mapping[str, object], base: str = "") -> str:
    """Label text for a selector, ``bus="line1",drive="pump-1"``, appended to ``base``."""
    text = ",".join(f'{key}="{_escape(str(value))}"' for key, value in pairs.items())
    return f"{base},{text}" if base and text else base or text


class Exposition:
    """Collects samples by metric family and writes them out, HELP and TYPE once each.

    Labels come rendered (see :func:`labels`), so a drive's are escaped once per scrape,
    not once per sample.
    """

    def __init__(self) -> None:
        self._families: dict[str, tuple[str, str, list[str]]] = {}

    def add(
        self,
        name: str,
        kind: str,
        help_text: str,
        value: float,
        selector: str = "",
        *,
        suffix: str = "",
    ) -> None:
        """One sample of family ``name`` (``suffix``: ``_bucket``/``_sum``/``_count``)."""
        family = self._families.get(name)
        if family is None:
            family = self._families[name] = (kind, help_text, [])
        braces = f"{{{selector}}}" if selector else ""
        family[2].append(f"{name}{suffix}{braces} {format_value(value)}")

    def histogram(self, name: str, help_text: str, data: Mapping[str, Any], selector: str) -> None:
        """A histogram from ``Histogram.to_json`` (cumulative buckets, count, sum)."""
        for bucket in data.get("buckets", ()):
            le = bucket["le"]
            le_text = format_value(float(le)) if not isinstance(le, str) else le
            if "." not in le_text and "e" not in le_text and le_text[-3:] != "Inf":
                le_text += ".0"
            bucket_selector = f'{selector},le="{le_text}"' if selector else f'le="{le_text}"'
            self.add(
                name, "histogram", help_text, bucket["count"], bucket_selector, suffix="_bucket"
            )
        self.add(name, "histogram", help_text, data.get("sum", 0.0), selector, suffix="_sum")
        self.add(name, "histogram", help_text, data.get("count", 0), selector, suffix="_count")

    def render(self) -> str:
        """The exposition text, ending in a newline."""
        out: list[str] = []
        for name, (kind, help_text, samples) in self._families.items():
            out.append(f"# HELP {name} {help_text}")
            out.append(f"# TYPE {name} {kind}")
            out.extend(samples)
        return "\n".join(out) + "\n"


def _drive(x: Exposition, state: DriveState) -> None:
    base = labels({"bus": state.bus, "drive": state.name})
    info = labels(
        {"address": state.address, "protocol": state.protocol, "control": state.control}, base
    )
    x.add("fcmaster_drive_info", "gauge", "The drive's configuration (always 1).", 1, info)
    for flag, help_text in _FLAGS:
        x.add(f"fcmaster_drive_{flag}", "gauge", help_text, int(getattr(state, flag)), base)
    if state.output_frequency_hz is not None:
        x.add(
            "fcmaster_drive_output_frequency_hz",
            "gauge",
            "Output frequency.",
            state.output_frequency_hz,
            base,
        )
    if state.output_frequency_updated_at is not None:
        x.add(
            "fcmaster_drive_output_frequency_timestamp_seconds",
            "gauge",
            "Unix time the output frequency was read (older than the last reply when the "
            "protocol reads it in an exchange of its own).",
            state.output_frequency_updated_at,
            base,
        )
    if state.reference_pct is not None:
        x.add(
            "fcmaster_drive_reference_ratio",
            "gauge",
            "The reference the master commands, as a share of nominal frequency.",
            state.reference_pct / 100.0,
            base,
        )
    if state.status_word is not None:
        x.add(
            "fcmaster_drive_status_word",
            "gauge",
            "The raw vendor status word.",
            state.status_word,
            base,
        )
    if state.updated_at is not None:
        x.add(
            "fcmaster_drive_last_reply_timestamp_seconds",
            "gauge",
            "Unix time of the drive's last good reply.",
            state.updated_at,
            base,
        )
    for param, measured in state.values.items():
        if isinstance(measured.value, int | float) and not isinstance(measured.value, bool):
            x.add(
                "fcmaster_drive_value",
                "gauge",
                "A measured value, by parameter as the drive's manual writes it.",
                measured.value,
                labels({"param": param, "unit": measured.unit}, base),
            )
    for kind, conditions in (("alarm", state.alarms), ("warning", state.warnings)):
        x.add(f"fcmaster_drive_{kind}s", "gauge", f"Active {kind}s.", len(conditions), base)
        for condition in conditions:
            x.add(
                f"fcmaster_drive_{kind}_active",
                "gauge",
                f"An active {kind} (always 1).",
                1,
                labels({"code": condition.code, "text": condition.text}, base),
            )

    if state.watchdog is not None:
        _watchdog(x, state, base)


def _watchdog(x: Exposition, state: DriveState, base: str) -> None:
    watchdog = state.watchdog
    assert watchdog is not None
    for verdict in Verdict:
        x.add(
            "fcmaster_drive_watchdog_verdict",
            "gauge",
            "The verdict on the drive's own communication watchdog (1 for the present one): "
            "off = the motor keeps running if the gateway dies, too_short = polling trips it.",
            int(watchdog.verdict is verdict),
            labels({"verdict": verdict.value}, base),
        )
    if watchdog.timeout_s is not None:
        x.add(
            "fcmaster_drive_watchdog_timeout_seconds",
            "gauge",
            "The drive's communication watchdog timeout, as read from the drive.",
            watchdog.timeout_s,
            base,
        )


def _line(x: Exposition, line: LineInfo) -> None:
    base = labels({"bus": line.name})
    info = labels({"port": line.port, "protocol": line.protocol, "baudrate": line.baudrate}, base)
    x.add("fcmaster_bus_info", "gauge", "The line's configuration (always 1).", 1, info)
    x.add("fcmaster_bus_up", "gauge", "Whether the line's port is open.", int(line.up), base)
    _adapter(x, line.adapter, base)
    stats = line.stats
    if not stats:
        return
    if "utilisation" in stats:
        x.add(
            "fcmaster_bus_utilisation_ratio",
            "gauge",
            "Share of time since the line came up spent in transactions.",
            stats["utilisation"],
            base,
        )
    for key, suffix, help_text in _LINE_COUNTERS:
        if key in stats:
            x.add(f"fcmaster_bus_{suffix}_total", "counter", help_text, stats[key], base)
    for key, suffix, help_text in _LINE_HISTOGRAMS:
        if isinstance(stats.get(key), Mapping):
            x.histogram(f"fcmaster_bus_{suffix}", help_text, stats[key], base)
    for drive, counters in (stats.get("drives") or {}).items():
        drive_labels = labels({"drive": drive}, base)
        for key, help_text in _DRIVE_COUNTERS:
            if key in counters:
                x.add(
                    f"fcmaster_drive_{key}_total", "counter", help_text, counters[key], drive_labels
                )
        if counters.get("last_latency_s") is not None:
            x.add(
                "fcmaster_drive_last_latency_seconds",
                "gauge",
                "Latency of the drive's last transaction.",
                counters["last_latency_s"],
                drive_labels,
            )


def _adapter(x: Exposition, adapter: Mapping[str, Any] | None, base: str) -> None:
    if adapter is None:
        return
    names = {k: adapter[k] or "" for k in ("device", "driver", "by_id")}
    x.add("fcmaster_bus_adapter_info", "gauge", "The line's serial adapter (always 1).", 1,
          labels(names, base))  # fmt: skip
    if adapter["latency_ms"] is not None:
        x.add(
            "fcmaster_bus_adapter_latency_seconds",
            "gauge",
            "The adapter's latency timer: how long it may hold a reply back.",
            adapter["latency_ms"] / 1000.0,
            base,
        )


def _hub(x: Exposition, hub: Hub) -> None:
    x.add("fcmaster_hub_subscriptions", "gauge", "Open hub subscriptions.", hub.subscriptions)
    x.add(
        "fcmaster_hub_events_published_total",
        "counter",
        "Events published to the hub.",
        hub.published,
    )
    x.add(
        "fcmaster_hub_events_dropped",
        "gauge",
        "Discrete events dropped for subscribers now connected (they fell behind).",
        hub.dropped(),
    )


def render(drives: Iterable[DriveState], lines: Iterable[LineInfo], hub: Hub | None = None) -> str:
    """The whole exposition for one scrape."""
    x = Exposition()
    for state in drives:
        _drive(x, state)
    for line in lines:
        _line(x, line)
    if hub is not None:
        _hub(x, hub)
    return x.render()


async def render_async(
    drives: Iterable[DriveState],
    lines: Iterable[LineInfo],
    hub: Hub | None = None,
    *,
    slice_size: int = YIELD_EVERY,
    gc_pauses: Mapping[str, Any] | None = None,
) -> str:
    """:func:`render`, letting the event loop run (the lines) every ``slice_size`` drives.

    ``gc_pauses``: the collector's pauses (``fcmaster.health.gc_pauses``), if watched.
    """
    x = Exposition()
    for n, state in enumerate(drives, 1):
        _drive(x, state)
        if n % slice_size == 0:
            await asyncio.sleep(0)
    for line in lines:
        _line(x, line)
    if hub is not None:
        _hub(x, hub)
    if gc_pauses is not None:
        x.histogram("fcmaster_gc_pause_seconds", "The garbage collector's pauses.", gc_pauses, "")
    return x.render()
