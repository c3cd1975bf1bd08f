"""`fcmaster ports`: the machine's serial adapters, their stable names, and who uses them.

``ttyUSB0`` and ``ttyUSB1`` can swap at boot; ``/dev/serial/by-id/…`` names stay with the
adapter and ``/dev/serial/by-path/…`` names with the USB socket (for two identical
adapters, whose by-id names may clash). With ``--config``, each adapter says which bus uses
it, and a bus whose port is on no adapter is named. :func:`unstable_ports` is what ``check``
warns about: a bus at a kernel name that has a stable one.
"""

from __future__ import annotations

import json
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from fcmaster.bus.plan import LinePlan
from fcmaster.config import load
from fcmaster.transport.usb import LOW_LATENCY_MS, Adapter, Machine, list_adapters

_KERNEL_NAME = re.compile(r"/dev/tty(USB|ACM)\d+")  # names the kernel hands out in plug order


@dataclass(slots=True, frozen=True)
class UnstablePort:
    """A bus configured at a kernel name while a stable name for the same adapter exists."""

    bus: str
    port: str
    stable: str

    def message(self) -> str:
        """What ``check`` prints."""
        return (
            f"{self.bus}: {self.port} may name another adapter after a reboot or replug; "
            f"use {self.stable}"
        )


def run(
    config: Path | None,
    *,
    as_json: bool,
    machine: Machine | None = None,
    out: TextIO | None = None,
) -> int:
    """List the adapters (and, with ``config``, who uses them); always 0."""
    out = out or sys.stdout
    machine = machine or Machine()
    adapters = list_adapters(machine)
    lines = load(config, buses_only=True).lines if config is not None else ()
    users = {a.device: [p.name for p in lines if _same(p.port, a)] for a in adapters}
    missing = [
        {"bus": p.name, "port": p.port}
        for p in lines
        if "://" not in p.port and not any(_same(p.port, a) for a in adapters)
    ]
    if as_json:
        listed = [{**a.to_json(), "used_by": users[a.device]} for a in adapters]
        body: dict[str, Any] = {"adapters": listed}
        if config is not None:
            body["missing"] = missing
        print(json.dumps(body, indent=2), file=out)
        return 0
    if not adapters:
        print("no serial adapters found", file=out)
    for adapter in adapters:
        _print_adapter(adapter, users[adapter.device] if config is not None else None, out)
    for entry in missing:
        print(f"bus {entry['bus']}: {entry['port']} is on no adapter of this machine", file=out)
    return 0


def _print_adapter(adapter: Adapter, used_by: list[str] | None, out: TextIO) -> None:
    """One adapter; ``used_by``: the buses of the config at it (None: no config given)."""
    latency = (
        "no latency timer" if adapter.latency_ms is None else f"latency {adapter.latency_ms} ms"
    )
    if adapter.latency_ms is not None and adapter.latency_ms > LOW_LATENCY_MS:
        latency += " (fcmaster asks for 1 ms when it opens the port)"
    used = f"used by {', '.join(used_by)}" if used_by else "not in the config"
    print(f"{adapter.device}  {adapter.driver or 'unknown driver'}  {latency}", file=out)
    for kind, name in (("by-id", adapter.by_id), ("by-path", adapter.by_path)):
        if name is not None:
            print(f"  {kind:<8}{name}", file=out)
    if used_by is not None:
        print(f"  {used}", file=out)


def unstable_ports(
    lines: tuple[LinePlan, ...], machine: Machine | None = None
) -> list[UnstablePort]:
    """Buses at ``/dev/ttyUSBn`` or ``/dev/ttyACMn`` whose adapter has a stable name."""
    machine = machine or Machine()
    if not any(_KERNEL_NAME.fullmatch(_in_dev(p.port, machine)) for p in lines):
        return []  # nothing to look up
    found = []
    for adapter in list_adapters(machine):
        for plan in lines:
            name = _in_dev(plan.port, machine)
            if adapter.stable_name and _KERNEL_NAME.fullmatch(name) and _same(plan.port, adapter):
                found.append(UnstablePort(plan.name, plan.port, adapter.stable_name))
    return found


def _in_dev(port: str, machine: Machine) -> str:
    """``port`` as it would read under the real /dev (the machine's dev root may be a fake)."""
    prefix = str(machine.dev) + "/"
    return "/dev/" + port[len(prefix) :] if port.startswith(prefix) else port


def _same(port: str, adapter: Adapter) -> bool:
    """Whether ``port`` (a kernel name or any link to it) is ``adapter``'s device."""
    return "://" not in port and os.path.realpath(port) == os.path.realpath(adapter.device)
