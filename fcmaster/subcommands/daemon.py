"""`fcmaster run` and `fcmaster check`: the daemon and its config check."""

from __future__ import annotations

import dataclasses
import errno
import os
import socket
from pathlib import Path

import structlog

from fcmaster import config as config_module
from fcmaster import logsetup
from fcmaster.bus.codecs import codec_for
from fcmaster.bus.plan import LinePlan
from fcmaster.bus.poll_round import poll_round_s, stranded_s
from fcmaster.bus.rotation import probe_period_s
from fcmaster.errors import ConfigError, UsageError
from fcmaster.subcommands.ports import unstable_ports
from fcmaster.transport.usb import Machine

log = structlog.get_logger("fcmaster.cli")

# `fcmaster run`: a shutdown stop did not reach its drive (the motor may still turn), so
# that systemd and docker can flag it
EXIT_STOP_FAILED = 3


def longest_probe_wait_s(plan: LinePlan) -> float:
    """The longest an absent drive waits for its probe, with every other drive but one absent.

    Probes keep to ``probe_share`` of the line's time while some drive answers, so the
    wait grows with the number of absent drives.
    """
    if not plan.drives:
        return 0.0
    codec = codec_for(plan)
    probe = codec.poll(plan.drives[0].address, None, None)
    cost = plan.miss_s(len(probe.request), probe.reply_length)
    return probe_period_s(plan, max(0, len(plan.drives) - 1), cost)


def check(path: Path, *, machine: Machine | None = None) -> int:
    """Validate ``path``; print a summary. ConfigError (exit 2) lists every problem.

    Warnings (exit 0): a bus at ``/dev/ttyUSBn`` whose adapter has a stable name.
    """
    config = config_module.load(path)
    print(f"{path}: valid")
    for plan in config.lines:
        controlled = sum(1 for d in plan.drives if d.control)
        one_round, refresh = poll_round_s(plan)
        print(
            f"  {plan.name}: {plan.port}, {plan.protocol}, {plan.baudrate} baud "
            f"{plan.databits}{plan.parity}{plan.stopbits}, {len(plan.drives)} drive(s) "
            f"({controlled} under bus control)"
        )
        print(
            f"    every drive polled within {one_round * 1000:.1f} ms; "
            f"every monitored value refreshed within {refresh:.2f} s"
        )

    model = config.model
    adapters = [
        name
        for name in ("http", "mqtt", "modbus", "opcua", "metrics")
        if getattr(model, name) is not None
    ]
    print(f"  adapters: {', '.join(adapters) or 'none'}; on_shutdown: {model.on_shutdown}")
    for plan in config.lines:
        if len(plan.drives) > 1:
            print(
                f"  {plan.name}: an absent drive is probed within "
                f"{longest_probe_wait_s(plan):.1f} s even with all others but one absent "
                f"(probes take at most {plan.probe_share:.0%} of the line while drives answer)"
            )
    for plan in config.lines:
        if len(plan.drives) > 1:
            print(
                f"  {plan.name}: should all other drives stop answering at once (a cabinet's "
                f"supply cut), a drive may wait up to {stranded_s(plan):.1f} s for its poll, "
                "once, while each of them is tried"
            )
    for unstable in unstable_ports(config.lines, machine):
        print(f"  warning: {unstable.message()}")
    for b, plan in enumerate(config.lines):
        # Not an error: a USB adapter may be plugged in later, and `run` waits for it.
        if "://" not in plan.port and not os.path.exists(plan.port):
            print(
                f"  warning: buses[{b}].port: {plan.port} does not exist (yet); {plan.name} "
                "stays down until it appears (see `fcmaster ports` for this machine's adapters)"
            )
    return 0


def with_http_listen(config: config_module.Config, listen: str) -> config_module.Config:
    """``config`` with the HTTP API at ``listen`` (switched on if the file has no ``http``).

    Everything else about the section (tokens, anonymous reads) stays as the file says, so
    the safety rules still apply: with no tokens the address must be a loopback one.
    """
    from fcmaster.adapters.http import parse_listen

    try:
        parse_listen(listen)
    except ConfigError as exc:
        raise UsageError(f"--http-listen: {exc.problems[0][1]}") from None
    http = config.model.http or config_module.HttpModel()
    model = config.model.model_copy(update={"http": http.model_copy(update={"listen": listen})})
    return dataclasses.replace(config, model=model)


def check_listen(listen: str, *, overridden: bool) -> None:
    """UsageError now, before any line is opened, if the HTTP address cannot be had.

    A trial bind with the options the HTTP adapter's own bind uses; it is closed at once.
    The adapter still reports a port taken in between, as the config's problem.
    """
    from fcmaster.adapters.http import parse_listen

    host, port = parse_listen(listen)
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        socket.create_server((host, port), family=family).close()
    except OSError as exc:
        where = "--http-listen" if overridden else "http.listen"
        if exc.errno == errno.EADDRINUSE:
            other = port + 1 if 0 < port < 65535 else 8081
            advice = f"it is taken (another fcmaster?); pass --http-listen {host}:{other}"
            raise UsageError(f"cannot serve HTTP at {host}:{port} ({where}): {advice}") from exc
        if isinstance(exc, socket.gaierror) or (exc.errno or 0) < 0:  # getaddrinfo: EAI_*
            advice = f"{host!r} is not an address of this machine nor a name that resolves"
        elif exc.errno == errno.EADDRNOTAVAIL:
            advice = (
                f"this machine has no address {host}; use one of its own, 127.0.0.1 for "
                "this machine only, or 0.0.0.0 for every interface"
            )
        else:
            advice = os.strerror(exc.errno) if exc.errno else str(exc)
        raise UsageError(f"cannot serve HTTP at {host}:{port} ({where}): {advice}") from exc


async def run(path: Path, *, demo: bool, http_listen: str | None = None) -> int:
    """Run the daemon until SIGTERM/SIGINT (``http_listen`` overrides ``http.listen``).

    Exit status 0, or :data:`EXIT_STOP_FAILED` when a shutdown stop did not reach its drive.
    """
    from fcmaster.service import Service

    config = config_module.load(path)
    if http_listen is not None:
        config = with_http_listen(config, http_listen)
    if config.model.http is not None:
        check_listen(config.model.http.listen, overridden=http_listen is not None)
    logsetup.configure(config.model.logging.level, config.model.logging.format)
    log.info("config.loaded", path=str(path), demo=demo, http_listen=http_listen)

    def load_again(_: config_module.Config) -> config_module.Config:
        # SIGHUP: the same file, with the same command-line override
        again = config_module.load(path)
        return again if http_listen is None else with_http_listen(again, http_listen)

    service = Service(config, demo=demo, load=load_again)
    await service.run()
    if service.stops_failed:
        log.error("service.exit_stop_failed", drives=service.stops_failed, exit_status=3)
        return EXIT_STOP_FAILED
    return 0
