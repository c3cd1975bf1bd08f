"""The `fcmaster` command line: parses arguments and maps the error tree to exit codes.

Exit codes: 0 success; 1 the drive or the line failed the request; 2 bad input from the
user (arguments, config, a malformed frame); 3 (``run`` only) a shutdown stop did not reach
its drive. Each subcommand's work lives in
``fcmaster.subcommands`` and its options in :mod:`fcmaster.cli_arguments`; this module only
dispatches and maps errors.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Callable, Coroutine
from typing import Any

from fcmaster.cli_arguments import DEMO_CONFIG, build_parser
from fcmaster.errors import BusError, CommandError, ConfigError, FcmasterError, UsageError
from fcmaster.protocol.registry import spec_for

__all__ = [
    "COMMANDS",
    "DEMO_CONFIG",
    "EXIT_FAILED",
    "EXIT_OK",
    "EXIT_PIPE_CLOSED",
    "EXIT_USAGE",
    "build_parser",
    "main",
]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
# The reader of our output left (``fcmaster check | head -1``): the code a shell gives a
# command that SIGPIPE ended, as for any other tool in a pipeline.
EXIT_PIPE_CLOSED = 128 + signal.SIGPIPE


def _run_async(coro: Coroutine[Any, Any, int]) -> int:
    # Imported here: --help, decode and the other synchronous commands start without asyncio.
    import asyncio

    from fcmaster.clock import new_event_loop

    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        return runner.run(coro)


def _options(args: argparse.Namespace) -> Any:
    """The line options of a port-opening command; UsageError for a bad one or address."""
    from fcmaster.subcommands.commission import LineOptions

    options = LineOptions(
        port=args.port,
        protocol=args.protocol,
        baudrate=args.baudrate,
        parity=args.parity,
        stopbits=args.stopbits,
        timeout_s=args.timeout,
        # the protocol's own keys, as the options of the same names parsed them
        protocol_options=tuple(
            (key.name, getattr(args, key.name)) for key in spec_for(args.protocol).line_keys
        ),
    )
    address = getattr(args, "address", None)
    if address is not None:  # before the port opens: a wrong address is no line's failure
        problem = spec_for(args.protocol).bad_address(options, address)
        if problem:
            raise UsageError(f"--address {problem}")
    return options


def _cmd_run(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import daemon

    config = args.config or DEMO_CONFIG
    demo = config.resolve() == DEMO_CONFIG  # also when named as config/demo.yaml
    return _run_async(daemon.run(config, demo=demo, http_listen=args.http_listen))


def _cmd_check(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import daemon

    return daemon.check(args.config)


def _cmd_events(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import events

    return events.run(
        args.config, since=args.since, drive=args.drive, kind=args.kind, limit=args.limit,
        as_json=args.json,
    )  # fmt: skip


def _cmd_modbus_map(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import modbus_map

    return modbus_map.run(args.config, as_json=args.json)


def _cmd_opcua(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import opcua

    if args.opcua_command == "trust":
        return opcua.trust(args.config, args.thumbprint)
    return opcua.certs(args.config, as_json=args.json)


def _cmd_scan(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import commission

    return _run_async(commission.scan(_options(args), args.addresses, as_json=args.json))


def _cmd_status(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import commission

    return _run_async(commission.status(_options(args), args.address, as_json=args.json))


def _cmd_read(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import commission

    return _run_async(
        commission.access(
            _options(args), args.address, args.parameter, index=args.index, value=None,
            as_json=args.json,
        )
    )  # fmt: skip


def _cmd_write(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import commission

    return _run_async(
        commission.access(
            _options(args), args.address, args.parameter, index=args.index, value=args.value,
            persist=args.persist,
        )
    )  # fmt: skip


def _cmd_control(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import commission

    return _run_async(
        commission.control(
            _options(args),
            args.address,
            args.action,
            frequency_hz=args.frequency,
            reference_pct=args.reference,
            nominal_frequency_hz=args.nominal_frequency,
            max_frequency_hz=args.max_frequency,
        )
    )


def _cmd_sim(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import sim

    return _run_async(sim.run(args))


def _cmd_decode(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import decode

    return decode.run(
        args.protocol,
        " ".join(args.frame),
        as_response=args.direction == "response",
        as_json=args.json,
    )


def _cmd_ports(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import ports

    return ports.run(args.config, as_json=args.json)


def _cmd_doctor(args: argparse.Namespace) -> int:
    from fcmaster.config_values import port_url_problem
    from fcmaster.subcommands import doctor

    if problem := port_url_problem(args.port):
        raise UsageError(f"--port {problem}")

    return _run_async(
        doctor.run(
            args.port, protocol=args.protocol, config=args.config, addresses=args.addresses,
            timeout_s=args.timeout, as_json=args.json,
        )
    )  # fmt: skip


def _cmd_capture(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import capture
    from fcmaster.subcommands.paths import check_output

    check_output(args.output, "-o")

    return _run_async(capture.capture(args.url, args.bus, args.seconds, args.output, args.token))


def _cmd_monitor(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import monitor

    return _run_async(monitor.run(args.url, args.token, once=args.once, interval_s=args.interval))


def _cmd_params(args: argparse.Namespace) -> int:
    from fcmaster.subcommands import params

    if args.params_command == "backup":
        if args.output is not None:
            from fcmaster.subcommands.paths import check_output

            check_output(args.output, "-o")
        return _run_async(params.backup(_options(args), args.address, args.output))
    if args.params_command == "diff":
        options = _options(args) if args.port else None
        return _run_async(params.diff(options, args.address, args.files))
    return _run_async(
        params.restore(
            _options(args),
            args.address,
            args.file,
            force=args.force,
            persist=not args.ram_only,
            config=args.config,
        )
    )


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "run": _cmd_run,
    "check": _cmd_check,
    "events": _cmd_events,
    "modbus-map": _cmd_modbus_map,
    "opcua": _cmd_opcua,
    "scan": _cmd_scan,
    "status": _cmd_status,
    "read": _cmd_read,
    "write": _cmd_write,
    "control": _cmd_control,
    "decode": _cmd_decode,
    "sim": _cmd_sim,
    "monitor": _cmd_monitor,
    "capture": _cmd_capture,
    "ports": _cmd_ports,
    "doctor": _cmd_doctor,
    "params": _cmd_params,
}


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    # Only the subcommand named gets its protocols' options (see build_parser).
    command = next((arg for arg in argv if not arg.startswith("-")), "")
    args = build_parser(command).parse_args(argv)
    if args.command not in ("run", "decode", "check", "events", "modbus-map", "opcua", "ports"):
        from fcmaster import logsetup

        # commissioning tools: only what needs attention, in words even into a pipe or file;
        # `status` says itself that its one drive is silent (no log line for the same)
        logsetup.configure("error" if args.command == "status" else "warning", "console")
    try:
        code = COMMANDS[args.command](args)
        sys.stdout.flush()  # a reader that left shows here, not in the interpreter's exit
        return code
    except BrokenPipeError:
        _stdout_closed()
        return EXIT_PIPE_CLOSED
    except ConfigError as exc:
        print(f"fcmaster {args.command}: invalid configuration", file=sys.stderr)
        for path, reason in exc.problems:
            print(f"  {path}: {reason}", file=sys.stderr)
        return EXIT_USAGE
    except UsageError as exc:
        print(f"fcmaster {args.command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (BusError, CommandError, FcmasterError) as exc:
        print(f"fcmaster {args.command}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except OSError as exc:  # a file or device that failed after its checks: said, not traced
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"fcmaster {args.command}: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        return 130


def _stdout_closed() -> None:
    """Quietly drop what is left for a stdout nobody reads.

    What is still buffered would fail again when the interpreter flushes at exit and print
    a traceback there; stdout now writes to the null device instead.
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    finally:
        os.close(devnull)
