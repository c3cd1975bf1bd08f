"""Every subcommand with every kind of bad input, each as its own process: no traceback.

A user's mistake (a missing or unknown option, a bad number, a negative magnitude, a
missing file or directory, a bad port or URL) ends in exit 2 and one message saying what
is wrong; a line or daemon that cannot be reached ends in exit 1. Neither ever shows a
traceback, and nothing here opens a real line (the ports named do not exist).
"""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import pytest

NO_PORT = "/dev/fcmaster-test-no-such-tty"
LINE = ("--port", NO_PORT)
USAGE, FAILED = 2, 1

# (arguments, the exit code, words the message must hold); paths are inside the test's
# directory: good.yaml (a valid config), bad.yaml (not YAML), junk.pcapng (not a capture)
CASES: list[tuple[tuple[str, ...], int, str]] = [
    ((), USAGE, "required: COMMAND"),
    (("scna",), USAGE, "did you mean 'scan'?"),
    (("run", "--config", "missing.yaml"), USAGE, "cannot read"),
    (("run", "--config", "bad.yaml"), USAGE, "line 1, column 8: not valid YAML: a list"),
    (("run", "--config", "."), USAGE, "cannot read"),
    (("run", "--config", "good.yaml", "--http-listen", "127.0.0.1:99999"), USAGE, "65535"),
    (
        ("run", "--config", "good.yaml", "--http-listen", "no-such-host.invalid:80"),
        USAGE,
        "not an address of this machine",
    ),
    (("run", "--bogus"), USAGE, "unrecognized arguments"),
    (("check",), USAGE, "--config"),
    (("check", "--config", "missing.yaml"), USAGE, "cannot read"),
    (("check", "--config", "/"), USAGE, "cannot read"),
    (("check", "--config", "junk.pcapng"), USAGE, "must be a mapping"),
    (("modbus-map", "--config", "missing.yaml"), USAGE, "cannot read"),
    (("modbus-map", "--config", "bad.yaml"), USAGE, "not valid YAML"),
    (("scan",), USAGE, "--port"),
    (("scan", *LINE), FAILED, "cannot open"),
    (("scan", *LINE, "--baudrate", "abc"), USAGE, "invalid int value"),
    (("scan", *LINE, "--baudrate", "-5"), USAGE, "--baudrate -5 is not a baud rate"),
    (("scan", *LINE, "--baudrate", "19000"), USAGE, "--baudrate 19000 is not a baud rate"),
    (("scan", *LINE, "--addresses", "0-500"), USAGE, "address 0 is outside 1-126"),
    (("scan", *LINE, "--addresses", "x"), USAGE, "is not like 1-126"),
    (("scan", *LINE, "--addresses", "-5"), USAGE, "is not like 1-126"),
    (("scan", *LINE, "--timeout", "-1"), USAGE, "not a positive number of seconds"),
    (("scan", *LINE, "--protocol", "enk"), USAGE, "did you mean 'enc'?"),
    (("scan", *LINE, "--adress", "3"), USAGE, "did you mean '--addresses'?"),
    (("scan", "--port", "socket:/10.0.0.5:4001"), USAGE, "write socket://host:port"),
    (("scan", "--port", "socket://"), USAGE, "use socket://host:port"),
    (("scan", "--port", "socket://host:99999"), USAGE, "use socket://host:port"),
    (("scan", "--port", "bogus://x"), USAGE, "is not a port this master can open"),
    (("scan", "--port", ""), USAGE, "--port is empty"),
    (("scan", "--port", ".", "--addresses", "1"), FAILED, "cannot open"),
    (("status", *LINE), USAGE, "--address"),
    (("status", *LINE, "--address", "x"), USAGE, "invalid int value"),
    (("status", *LINE, "--address", "-1"), USAGE, "--address -1 is outside 1-126"),
    (("status", *LINE, "--address", "999"), USAGE, "--address 999 is outside 1-126"),
    (("status", *LINE, "--address", "0", "--protocol", "enc"), USAGE, "--address 0"),
    (("read", *LINE, "--address", "1", "bogus"), USAGE, "bogus"),
    (("read", *LINE, "--address", "1", "-5"), USAGE, "-5"),
    (("write", *LINE, "--address", "1", "3-41"), USAGE, "VALUE"),
    (("write", *LINE, "--address", "1", "3-41", "abc"), USAGE, "'abc' is not a number"),
    (("control", *LINE, "--address", "1", "fly"), USAGE, "unknown action 'fly'"),
    (("control", *LINE, "--address", "1", "start", "--frequency", "-5"), USAGE, "magnitude"),
    (("control", *LINE, "--address", "1", "reverse", "--reference", "-20"), USAGE, "magnitude"),
    (("control", *LINE, "--address", "1", "start", "--frequency", "nan"), USAGE, "not a number"),
    (("control", *LINE, "--address", "1", "start", "--frequency", "x"), USAGE, "invalid float"),
    (
        ("control", *LINE, "--address", "1", "start", "--nominal-frequency", "-50"),
        USAGE,
        "--nominal-frequency -50 is not a positive number",
    ),
    (
        ("control", *LINE, "--address", "1", "start", "--max-frequency", "inf"),
        USAGE,
        "--max-frequency inf is not a positive number",
    ),
    (("control", *LINE, "--address", "1", "stop", "--frequency", "5"), USAGE, "takes no"),
    (("control", *LINE, "--address", "1", "set-reference"), USAGE, "needs --frequency"),
    (("decode",), USAGE, "FRAME"),
    (("decode", "zz"), USAGE, "not a hex digit"),
    (("decode", "--protocol", "enc", "<BOGUS>"), USAGE, "not a control character name"),
    (("decode", "--as", "response", "02 0E"), USAGE, "2 were given"),
    (("sim", "--baudrate", "-5"), USAGE, "--baudrate -5 is not a baud rate"),
    (("sim", "--addresses", "0-500"), USAGE, "not 0, 127, 128, 129, 130 and 370 more"),
    (("sim", "--faults", "bogus"), USAGE, "unknown fault 'bogus'"),
    (("sim", "--faults", "drp=0.1"), USAGE, "did you mean 'drop'?"),
    (("sim", "--faults", "drop=2"), USAGE, "outside 0…1"),
    (("sim", "--faults", "drop=x"), USAGE, "is not a number"),
    (("sim", "--config", "missing.yaml"), USAGE, "cannot read"),
    (("sim", "--config", "bad.yaml"), USAGE, "not valid YAML"),
    (("sim", "--config", "good.yaml", "--bus", "nope"), USAGE, "no bus called nope"),
    (("sim", "--replay", "missing.pcapng"), USAGE, "cannot read"),
    (("sim", "--replay", "junk.pcapng"), USAGE, "not a pcapng file"),
    (("sim", "--replay", "."), USAGE, "cannot read"),
    (("sim", "--link", "missing-dir/tty"), USAGE, "missing-dir is no directory"),
    (("sim", "--response-delay-ms", "-5"), USAGE, "-5"),
    (("sim", "--adapter-latency-ms", "-1"), USAGE, "1-255 ms"),
    (("monitor", "--url", "http://", "--once"), USAGE, "is not like http://"),
    (("monitor", "--url", "ftp://x", "--once"), USAGE, "is not like http://"),
    (("monitor", "--url", "http://[::1", "--once"), USAGE, "is not like http://"),
    (("monitor", "--url", "http://host:99999", "--once"), USAGE, "is not like http://"),
    (("monitor", "--interval", "-1", "--once"), USAGE, "not a positive number of seconds"),
    (("monitor", "--url", "http://127.0.0.1:1", "--once"), FAILED, "cannot reach"),
    (
        ("capture", "--bus", "a", "--seconds", "1", "-o", "missing-dir/x.pcapng"),
        USAGE,
        "the directory missing-dir does not exist",
    ),
    (("capture", "--bus", "a", "--seconds", "1", "-o", "."), USAGE, "is a directory"),
    (("capture", "--bus", "a", "--seconds", "-1", "-o", "x.pcapng"), USAGE, "positive"),
    (
        ("capture", "--url", "http://[::1", "--bus", "a", "--seconds", "1", "-o", "x.pcapng"),
        USAGE,
        "is not like http://",
    ),
    (
        (
            "capture",
            "--url",
            "http://127.0.0.1:1",
            "--bus",
            "a",
            "--seconds",
            "1",
            "-o",
            "x.pcapng",
        ),
        FAILED,
        "cannot reach",
    ),
    (("ports", "--config", "missing.yaml"), USAGE, "cannot read"),
    (("ports", "--config", "bad.yaml"), USAGE, "not valid YAML"),
    (("doctor", "--port", NO_PORT), FAILED, "cannot open"),
    (("doctor", "--port", NO_PORT, "--config", "missing.yaml"), USAGE, "cannot read"),
    (("doctor", "--port", NO_PORT, "--addresses", "x"), USAGE, "is not like 1-126"),
    (("doctor", "--port", "socket:/x:1"), USAGE, "write socket://host:port"),
    (("params",), USAGE, "VERB"),
    (
        ("params", "backup", *LINE, "--address", "1", "-o", "missing-dir/x.yaml"),
        USAGE,
        "the directory missing-dir does not exist",
    ),
    (("params", "backup", *LINE, "--address", "1", "-o", "."), USAGE, "is a directory"),
    (("params", "backup", *LINE, "--address", "200"), USAGE, "--address 200 is outside"),
    (("params", "diff", "missing.yaml", "good.yaml"), USAGE, "cannot read"),
    (("params", "diff", "good.yaml"), USAGE, "two files"),
    (("params", "restore", *LINE, "--address", "1", "missing.yaml"), USAGE, "cannot read"),
]
if os.geteuid() != 0:  # root reads a file of mode 000 all the same
    CASES += [
        (("check", "--config", "unreadable.yaml"), USAGE, "cannot read"),
        (("params", "diff", "unreadable.yaml", "good.yaml"), USAGE, "cannot read"),
    ]

GOOD = """
buses:
  - name: a
    port: sim://a
    drives: [{name: x, address: 1}]
"""


async def _run(cwd: Path, args: tuple[str, ...], gate: asyncio.Semaphore) -> tuple[int, str]:
    async with gate:
        process = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "fcmaster", *args, cwd=cwd,
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        _, err = await asyncio.wait_for(process.communicate(), 60)
    assert process.returncode is not None
    return process.returncode, err.decode()


async def test_every_subcommand_refuses_bad_input_in_words(tmp_path: Path) -> None:
    (tmp_path / "good.yaml").write_text(GOOD)
    (tmp_path / "bad.yaml").write_text("buses: [a")
    (tmp_path / "junk.pcapng").write_text("not a capture")
    unreadable = tmp_path / "unreadable.yaml"
    unreadable.write_text(GOOD)
    unreadable.chmod(0)
    gate = asyncio.Semaphore(4)  # a few at once: each is a cold interpreter
    results = await asyncio.gather(*(_run(tmp_path, args, gate) for args, _, _ in CASES))
    wrong = []
    for (args, code, words), (got, err) in zip(CASES, results, strict=True):
        if (
            got != code
            or "Traceback" in err
            or words not in err
            or not err.startswith(("fcmaster", "usage: fcmaster"))
        ):
            wrong.append(f"fcmaster {' '.join(args)} → exit {got} (want {code}, {words!r}):\n{err}")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("protocol", ["danfoss-fc", "mitsubishi", "enc"])
async def test_port_commands_refuse_a_baud_rate_the_protocol_does_not_offer(
    tmp_path: Path, protocol: str
) -> None:
    code, err = await _run(
        tmp_path,
        ("read", *LINE, "--protocol", protocol, "--address", "1", "--baudrate", "1", "x"),
        asyncio.Semaphore(1),
    )
    assert code == USAGE, err
    assert f"--baudrate 1 is not a baud rate {protocol} drives offer" in err
