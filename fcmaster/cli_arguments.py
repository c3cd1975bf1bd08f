"""The `fcmaster` argument parser: every subcommand and its options.

The options of a protocol's own line keys (``--address-format``, ``--terminator``, …) come
from the protocol specs (:mod:`fcmaster.protocol.registry`), so they match the config keys
of the same names and a new protocol brings its options along.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from fcmaster import __version__
from fcmaster.protocol.registry import DEFAULT, NAMES, PROTOCOLS
from fcmaster.suggest import did_you_mean

if TYPE_CHECKING:  # the specs load only for a command that opens a port
    from fcmaster.protocol.spec import LineKey

DEMO_CONFIG = Path(__file__).resolve().parent / "demo.yaml"  # config/demo.yaml links here


class _Parser(argparse.ArgumentParser):
    """argparse's parser, naming the nearest known word when one was misspelled."""

    _words: tuple[str, ...] = ()  # the command line being parsed

    def parse_known_args(  # type: ignore[override]
        self, args: list[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """As argparse's, keeping the words for :meth:`error`."""
        self._words = tuple(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        """Exit 2 with ``message`` and, for an unknown choice or option, a 'did you mean'."""
        choice = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if choice:
            message += did_you_mean(choice[1], re.findall(r"'([^']*)'", choice[2]))
        unknown = re.match(r"unrecognized arguments: (.*)", message)
        for word in unknown[1].split() if unknown else ():
            hint = did_you_mean(word.partition("=")[0], self._options()) if word[:2] == "--" else ""
            if hint:
                message += hint
                break
        super().error(message)

    def _options(self) -> list[str]:
        """The long options of this parser and of the subcommands named on the line."""
        found = [o for a in self._actions for o in a.option_strings if o.startswith("--")]
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    if name in self._words:
                        sub._words = self._words
                        found += sub._options()
        return found


def _addresses(text: str) -> list[int]:
    """``1-8,12`` → [1, …, 8, 12]."""
    out: list[int] = []
    try:
        for part in text.split(","):
            first, _, last = part.strip().partition("-")
            low, high = int(first), int(last or first)
            if high < low:
                raise argparse.ArgumentTypeError(
                    f"{part.strip()!r} runs backwards; write {high}-{low}"
                )
            out.extend(range(low, high + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not like 1-126 or 1,4,7") from None
    return out


def _seconds(text: str) -> float:
    """A positive, finite number of seconds (``--timeout``)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return value


def _line_options(parser: argparse.ArgumentParser, protocols: bool) -> None:
    """The options of every command that opens a port (``protocols``: with their own)."""
    parser.add_argument("--port", required=True, help="/dev/ttyUSB0, COM3, socket://host:port")
    parser.add_argument("--protocol", choices=NAMES, default=DEFAULT)
    parser.add_argument("--baudrate", type=int, help="default: the protocol's factory setting")
    parser.add_argument("--parity", choices=("N", "E", "O"))
    parser.add_argument("--stopbits", type=int, choices=(1, 2))
    parser.add_argument("--timeout", type=_seconds, help="reply deadline in seconds")
    if protocols:
        protocol_options(parser)


def protocol_options(
    parser: argparse.ArgumentParser, only: Callable[[LineKey], bool] = lambda _: True
) -> None:
    """Each protocol's own line keys (``only`` those it accepts) as options, in one group each.

    The option is the config key with dashes (``address_format`` → ``--address-format``),
    its value the parsed key, its default the key's default.
    """
    for spec in PROTOCOLS.values():
        keys = [key for key in spec.line_keys if only(key)]
        if not keys:
            continue
        group = parser.add_argument_group(f"options of {spec.name} lines")
        for key in keys:
            flag = "--" + key.name.replace("_", "-")
            if key.choices:
                group.add_argument(
                    flag, type=type(key.choices[0]), choices=key.choices, default=key.default,
                    help=key.help,
                )  # fmt: skip
            else:
                group.add_argument(
                    flag, type=_stepped(key), default=key.default, help=key.help,
                    metavar=key.metavar or ("N|none" if key.nullable else "N"),
                )  # fmt: skip


def _stepped(key: LineKey) -> Callable[[str], int | None]:
    """A whole number from the key's minimum to maximum in its steps, or ``none``."""
    span = f"{key.minimum}-{key.maximum} in steps of {key.step}"

    def parse(text: str) -> int | None:
        if key.nullable and text.lower() in ("none", "null"):
            return None
        try:
            value = int(text)
        except ValueError:
            value = key.minimum - 1
        if not key.minimum <= value <= key.maximum or (value - key.minimum) % key.step:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {span}{', or none' if key.nullable else ''}"
            )
        return value

    return parse


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser for every subcommand.

    With ``command`` (the one about to be parsed; "" for none), only that subcommand gets
    each protocol's own options: the protocol specs they come from are then loaded only for
    a command that opens a port, and ``--help`` or ``decode`` start without them.
    """

    def full(name: str) -> bool:
        return command is None or command == name

    parser = _Parser(
        prog="fcmaster", description="RS-485 master for fleets of variable frequency drives."
    )
    parser.add_argument("--version", action="version", version=f"fcmaster {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="run the daemon (the simulated demo fleet by default)")
    run.add_argument("--config", type=Path, help=f"default: {DEMO_CONFIG.name}, a simulated fleet")
    run.add_argument(
        "--http-listen",
        metavar="HOST:PORT",
        help="serve the HTTP API here instead of at the config's http.listen "
        "(the demo's is 127.0.0.1:8080)",
    )

    check = commands.add_parser("check", help="validate a config file")
    check.add_argument("--config", type=Path, required=True)

    events = commands.add_parser(
        "events", help="the journal: commands, alarms, starts, newest last"
    )
    events.add_argument("--config", type=Path, required=True)
    events.add_argument("--since", help="a time (2026-11-27T08:00:00Z) or an age (30m, 2h, 7d)")
    events.add_argument("--drive", help="one drive's records only")
    events.add_argument("--kind", help="command, alarm, warning, online, offline, watchdog, …")
    events.add_argument("--limit", type=int, default=1000, help="the newest this many (1-1000)")
    events.add_argument("--json", action="store_true", help="print JSON")

    modbus_map = commands.add_parser(
        "modbus-map", help="the Modbus TCP register map of a config, for PLC programmers"
    )
    modbus_map.add_argument("--config", type=Path, required=True)
    modbus_map.add_argument("--json", action="store_true", help="print JSON")

    opcua = commands.add_parser("opcua", help="the OPC UA server's certificates")
    opcua_commands = opcua.add_subparsers(dest="opcua_command", required=True)
    certs = opcua_commands.add_parser("certs", help="own, trusted and rejected certificates")
    certs.add_argument("--config", type=Path, required=True)
    certs.add_argument("--json", action="store_true", help="print JSON")
    trust = opcua_commands.add_parser("trust", help="trust a rejected client certificate")
    trust.add_argument("--config", type=Path, required=True)
    trust.add_argument("thumbprint", help="its SHA-1 thumbprint, as `opcua certs` shows it")

    scan = commands.add_parser("scan", help="find which addresses answer")
    _line_options(scan, full("scan"))
    scan.add_argument(
        "--addresses", type=_addresses, help="default: every address the protocol can reach"
    )
    scan.add_argument("--json", action="store_true", help="print JSON")

    status = commands.add_parser("status", help="one drive's decoded status now")
    _line_options(status, full("status"))
    status.add_argument("--address", type=int, required=True)
    status.add_argument("--json", action="store_true", help="print JSON")

    read = commands.add_parser("read", help="read a parameter, scaled to its unit")
    _line_options(read, full("read"))
    read.add_argument("--address", type=int, required=True)
    read.add_argument("--index", type=int, default=0)
    read.add_argument("--json", action="store_true", help="print JSON")
    read.add_argument("parameter", metavar="PARAM", help="as the manual writes it, e.g. 16-13")

    write = commands.add_parser("write", help="write a parameter")
    _line_options(write, full("write"))
    write.add_argument("--address", type=int, required=True)
    write.add_argument("--index", type=int, default=0)
    write.add_argument("--persist", action="store_true", help="to non-volatile memory too")
    write.add_argument("parameter", metavar="PARAM")
    write.add_argument("value", metavar="VALUE")

    control = commands.add_parser("control", help="start, stop, coast, quick-stop, reset, …")
    _line_options(control, full("control"))
    control.add_argument("--address", type=int, required=True)
    control.add_argument(
        "action",
        metavar="ACTION",
        help="start, stop, coast, quick-stop, reset, forward, reverse, jog, set-reference",
    )
    reference = control.add_mutually_exclusive_group()
    reference.add_argument("--frequency", type=float, help="Hz")
    reference.add_argument("--reference", type=float, help="%% of the nominal frequency")
    control.add_argument("--nominal-frequency", type=float, default=50.0, help="Hz at 100 %%")
    control.add_argument("--max-frequency", type=float, help="refuse more (default: nominal)")

    sim = commands.add_parser(
        "sim", help="serve simulated drives on a pseudo-terminal",
        description="Serve simulated drives on a pty; prints 'BUS PATH', runs until SIGINT/TERM.",
    )  # fmt: skip
    sim.add_argument(
        "--config",
        type=Path,
        help="simulate the drives of this config's buses; link each bus's port path to its pty",
    )
    sim.add_argument(
        "--bus",
        action="append",
        metavar="NAME",
        help="with --config: only this bus (repeat for more; default: every device-path bus)",
    )
    sim.add_argument("--protocol", choices=NAMES, default=DEFAULT)
    sim.add_argument("--addresses", type=_addresses, default=[1], help="e.g. 1-8 (default 1)")
    sim.add_argument("--baudrate", type=int, help="default: the protocol's factory setting")
    sim.add_argument("--parity", choices=("N", "E", "O"))
    sim.add_argument("--stopbits", type=int, choices=(1, 2))
    sim.add_argument("--name", default="line1", help="the bus name printed before the path")
    sim.add_argument("--link", help="also make this path a symbolic link to the pty")
    sim.add_argument(
        "--replay", type=Path, metavar="FILE",
        help="answer as the drives did in this capture (from fcmaster capture)",
    )  # fmt: skip
    sim.add_argument("--faults", default="", help="e.g. drop=0.05,corrupt=0.01,late=0.01,echo")
    sim.add_argument("--response-delay-ms", type=float, help="every drive's 8-35 (default 10)")
    sim.add_argument(
        "--adapter-latency-ms", type=float, metavar="MS",
        help="hold replies like a USB adapter's latency timer (FTDI's default is 16)",
    )  # fmt: skip
    sim.add_argument(
        "--duplicate-addresses", action="store_true",
        help="serve a repeated address (--addresses 1,1) as two drives that both answer",
    )  # fmt: skip
    if full("sim"):
        protocol_options(sim, lambda key: key.simulated)  # what the simulated drives take

    ports = commands.add_parser(
        "ports", help="this machine's serial adapters: stable names, driver, latency timer"
    )
    ports.add_argument("--config", type=Path, help="also say which bus uses each adapter")
    ports.add_argument("--json", action="store_true", help="print JSON")

    doctor = commands.add_parser(
        "doctor",
        help="find a line's settings and drives, and what to fix",
        description="Find the line's protocol, baud rate, parity and (FC) address format, the "
        "drives on it, an echoing adapter, two drives on one address, noise and the adapter's "
        "latency; say what to fix. Exit 0: drives answer and nothing needs fixing; 1: a "
        "finding needs fixing, no drive answers, or the port cannot be opened; 2: bad input.",
    )
    doctor.add_argument("--port", required=True, help="/dev/ttyUSB0, COM3, socket://host:port")
    doctor.add_argument("--protocol", choices=NAMES, help="default: try each")
    doctor.add_argument(
        "--config", type=Path, help="compare with the bus at this port in this config"
    )
    doctor.add_argument(
        "--addresses", type=_addresses,
        help="where to look (default: every address; the first few are probed per setting)",
    )  # fmt: skip
    doctor.add_argument("--timeout", type=_seconds, help="reply deadline in seconds")
    doctor.add_argument("--json", action="store_true", help="print JSON")

    capture = commands.add_parser(
        "capture", help="record a running line's frames to a pcapng file",
        description="Follow a running daemon's line for some seconds and write its frames, "
        "with their directions and times, to a pcapng file (Wireshark reads it).",
    )  # fmt: skip
    capture.add_argument("--url", default="http://127.0.0.1:8080", help="the daemon's HTTP API")
    capture.add_argument("--bus", required=True, metavar="NAME", help="the line to record")
    capture.add_argument("--seconds", type=_seconds, required=True, metavar="S", help="how long")
    capture.add_argument("-o", "--output", type=Path, required=True, metavar="FILE.pcapng")
    capture.add_argument("--token", help="a viewer token (default: $FCM_TOKEN)")

    monitor = commands.add_parser("monitor", help="a running daemon's fleet as a live table")
    monitor.add_argument("--url", default="http://127.0.0.1:8080", help="the daemon's HTTP API")
    monitor.add_argument("--token", help="a viewer token (default: $FCM_TOKEN)")
    monitor.add_argument("--once", action="store_true", help="print one table and exit")
    monitor.add_argument("--interval", type=_seconds, default=0.5, help="seconds between redraws")

    _params_parser(commands, full("params"))

    decode = commands.add_parser(
        "decode",
        help="explain a captured frame field by field",
        description="Decode a captured frame. FRAME is hex bytes (spaces optional), or for the "
        "ASCII protocols the characters with control codes written <ENQ>, <STX>, <CR>, ….",
    )
    decode.add_argument("--protocol", choices=NAMES, default=DEFAULT)
    decode.add_argument(
        "--as",
        dest="direction",
        choices=("request", "response"),
        default="request",
        help="whether the frame went to the drive (request, default) or came from it",
    )
    decode.add_argument("--json", action="store_true", help="print JSON")
    decode.add_argument("frame", nargs="+", metavar="FRAME")
    return parser


def _params_parser(commands: Any, protocols: bool) -> None:
    """`params backup | diff | restore`: a drive's parameter set to a file and back."""
    params = commands.add_parser("params", help="back up, compare and restore parameter sets")
    verbs = params.add_subparsers(dest="params_command", required=True, metavar="VERB")
    backup = verbs.add_parser(
        "backup", help="every writable parameter of a drive, with its identity, to YAML"
    )
    _line_options(backup, protocols)
    backup.add_argument("--address", type=int, required=True)
    backup.add_argument("-o", "--output", type=Path, metavar="FILE", help="default: stdout")
    diff = verbs.add_parser(
        "diff",
        help="a drive against a file, or two files",
        description="Compare a drive with a saved set (--port, --address, FILE) or two saved "
        "sets (FILE FILE). Exit codes: 0 the settings are equal, 1 they differ (or the drive "
        "could not be read), 2 bad input. Identity (serial numbers) is shown, not compared.",
    )
    _line_options(diff, protocols)
    for action in diff._actions:
        if action.dest == "port":
            action.required = False  # two files need no port
    diff.add_argument("--address", type=int)
    diff.add_argument("files", nargs="+", type=Path, metavar="FILE")
    restore = verbs.add_parser(
        "restore",
        help="write a saved set back, verifying each value",
        description="Judge the whole FILE first, then write the parameters that differ, each "
        "read back to verify. Nothing is written (exit 2) when FILE holds a parameter outside "
        "the protocol's set or a value its parameter cannot take, or a frequency ceiling (FC "
        "4-14, Mitsubishi Pr.1/Pr.18) above the drive's max_frequency_hz in --config. While "
        "the drive runs, only parameters known to be changeable in operation are written; "
        "line settings (address, baud, parity, protocol, operation mode) are left alone. Exit "
        "0 when every other difference was written and verified, 1 otherwise.",
    )
    _line_options(restore, protocols)
    restore.add_argument("--address", type=int, required=True)
    restore.add_argument(
        "--config", type=Path,
        help="judge the frequency ceilings against this drive's configured max_frequency_hz "
        "(the drive at --address on the bus at --port)",
    )  # fmt: skip
    restore.add_argument(
        "--force", action="store_true",
        help="restore a set saved from another drive type, and ceilings above the configured "
        "max_frequency_hz; never anything outside the set (a factory reset, the operation "
        "mode), a value its parameter cannot take, or a line setting",
    )  # fmt: skip
    restore.add_argument(
        "--ram-only", action="store_true", help="not to non-volatile memory (lost at power-off)"
    )
    restore.add_argument("file", type=Path, metavar="FILE")
