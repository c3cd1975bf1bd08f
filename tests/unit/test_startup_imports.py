"""What starting loads: a module below a lazy face comes without the rest of the face, and
a command that opens no port starts without asyncio or the protocol specs.

Which modules an import loads is checked in a fresh interpreter, since this one has
imported nearly everything already.
"""

from __future__ import annotations

import subprocess
import sys
import types

import pytest

import fcmaster.adapters
import fcmaster.bus
from fcmaster.cli_arguments import build_parser
from fcmaster.lazy_face import lazy_face

HEAVY = ("fcmaster.bus.master", "fcmaster.transport.serial", "structlog", "serial", "asyncio")


def loaded_after(statement: str, modules: tuple[str, ...]) -> list[str]:
    """Which of ``modules`` a fresh interpreter has loaded after running ``statement``."""
    probe = f"import sys\n{statement}\nprint(' '.join(m for m in {modules!r} if m in sys.modules))"
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=60
    )
    return done.stdout.split()


def test_the_bus_plan_loads_without_the_master_logging_or_pyserial() -> None:
    assert loaded_after("import fcmaster.bus.plan", HEAVY) == []


def test_the_config_loads_without_the_master_or_the_adapters() -> None:
    others = (*HEAVY, "fcmaster.adapters.gateway", "fcmaster.hub", "fcmaster.state", "pydantic")
    assert loaded_after("import fcmaster.config", others) == ["pydantic"]


def test_the_cli_starts_without_asyncio_or_the_bus() -> None:
    assert loaded_after("import fcmaster.cli", (*HEAVY, "fcmaster.bus")) == []


def test_a_face_lists_every_public_name_before_any_is_used() -> None:
    statement = "import fcmaster.bus as face\nnames = dir(face)"
    listed = loaded_after(statement + "\nprint(*names)", ())
    assert set(fcmaster.bus.__all__) <= set(listed)
    assert loaded_after(statement, HEAVY) == []  # listing them loads nothing


def test_a_face_hands_out_the_defining_modules_object() -> None:
    from fcmaster.adapters.gateway import Gateway
    from fcmaster.bus.master import BusMaster

    assert fcmaster.bus.BusMaster is BusMaster
    assert fcmaster.adapters.Gateway is Gateway
    assert "BusMaster" in vars(fcmaster.bus)  # kept: the next use is a plain attribute


def test_a_name_that_is_not_public_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match=r"'fcmaster\.bus' has no attribute 'Planner'"):
        getattr(fcmaster.bus, "Planner".strip())  # mypy refuses the attribute: so does Python


def test_a_face_whose_modules_do_not_match_its_all_fails_on_import() -> None:
    package = types.ModuleType("fcmaster_test_face")
    sys.modules[package.__name__] = package
    try:
        with pytest.raises(ImportError, match=r"no module given for \['Gone'\]"):
            lazy_face(package.__name__, ["Gone", "Kept"], {"fcmaster.bus.plan": ("Kept",)})
        with pytest.raises(ImportError, match=r"not in __all__: \['LinePlan'\]"):
            lazy_face(
                package.__name__, ["DrivePlan"], {"fcmaster.bus.plan": ("DrivePlan", "LinePlan")}
            )
    finally:
        del sys.modules[package.__name__]


SPECS = tuple(f"fcmaster.protocol.{v}.spec" for v in ("danfoss_fc", "mitsubishi", "enc"))


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["decode", "--protocol", "enc", "--help"],
        ["check", "--help"],
    ],
)
def test_a_command_that_opens_no_port_starts_without_the_protocol_specs(argv: list[str]) -> None:
    statement = (
        "import contextlib, io\nfrom fcmaster.cli import main\n"
        f"with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
        f"    main({argv!r})"
    )
    assert loaded_after(statement, (*SPECS, "fcmaster.protocol.codec", "asyncio")) == []


def test_decoding_a_frame_loads_the_spec_of_its_protocol_only() -> None:
    frame = "020e01047f000000000000047f00000d"  # an FC telegram with a good BCC
    statement = (
        "import contextlib, io\nfrom fcmaster.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main(['decode', {frame!r}]) == 0"
    )
    assert loaded_after(statement, SPECS) == ["fcmaster.protocol.danfoss_fc.spec"]


@pytest.mark.parametrize(
    "argv",
    [
        ["scan", "--port", "p", "--protocol", "enc", "--address-encoding", "decimal"],
        ["status", "--port", "p", "--address", "3", "--address-format", "31"],
        ["params", "backup", "--port", "p", "--address", "1", "--output", "x.json"],
        ["sim", "--protocol", "enc", "--addresses", "1-3", "--address-encoding", "decimal"],
    ],
)
def test_a_parser_built_for_one_command_parses_it_as_the_whole_parser_does(
    argv: list[str],
) -> None:
    assert build_parser(argv[0]).parse_args(argv) == build_parser().parse_args(argv)


def test_the_daemon_without_an_opcua_section_never_loads_asyncua() -> None:
    # The OPC UA server lives in a process of its own; the daemon's side needs only the pipe.
    statement = (
        "import fcmaster.service, fcmaster.adapters.opcua, fcmaster.config\n"
        "fcmaster.config.parse('buses: [{name: l, port: sim://l}]\\n'\n"
        "                      'opcua: {pki: /tmp}\\n')"
    )
    assert loaded_after(statement, ("asyncua", "cryptography")) == []
