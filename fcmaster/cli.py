"""The `fcmaster` command line: parses arguments and maps the error tree to exit codes.

Exit codes: 0 success; 1 the drive or the line failed the request; 2 bad input from the
user (arguments, config, a malformed frame).
"""

from __future__ import annotations

import argparse
import sys

from fcmaster import __version__
from fcmaster.errors import BusError, CommandError, ConfigError, FcmasterError, UsageError

PROTOCOLS = ("danfoss-fc", "mitsubishi", "enc")

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


def build_parser() -> argparse.ArgumentParser:
    """The argument parser for every subcommand."""
    parser = argparse.ArgumentParser(
        prog="fcmaster", description="RS-485 master for fleets of variable frequency drives."
    )
    parser.add_argument("--version", action="version", version=f"fcmaster {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    decode = commands.add_parser(
        "decode", help="explain a captured frame field by field",
        description="Decode a captured frame. FRAME is hex bytes; spaces are optional.",
    )  # fmt: skip
    decode.add_argument("--protocol", choices=PROTOCOLS, default="danfoss-fc")
    decode.add_argument(
        "--as", dest="direction", choices=("request", "response"), default="request",
        help="whether the frame went to the drive (request, default) or came from it",
    )  # fmt: skip
    decode.add_argument("--json", action="store_true", help="print JSON")
    decode.add_argument("frame", nargs="+", metavar="FRAME")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "decode":
            from fcmaster.commands import decode

            return decode.run(
                args.protocol, " ".join(args.frame),
                as_response=args.direction == "response", as_json=args.json,
            )  # fmt: skip
    except (UsageError, ConfigError) as exc:
        print(f"fcmaster {args.command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (BusError, CommandError) as exc:
        print(f"fcmaster {args.command}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except FcmasterError as exc:
        print(f"fcmaster {args.command}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    raise AssertionError(f"unhandled command {args.command}")  # pragma: no cover
