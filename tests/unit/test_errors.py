"""Every exception class fcmaster defines stands under the one root (errors.py's tree)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from types import ModuleType

import fcmaster
from fcmaster.errors import FcmasterError

# Importing __main__ runs the command line.
NOT_IMPORTED = {"fcmaster.__main__"}


def every_module() -> list[ModuleType]:
    """Every module of the package, imported (each subpackage's own modules too)."""
    names = [
        info.name
        for info in pkgutil.walk_packages(fcmaster.__path__, prefix="fcmaster.")
        if info.name not in NOT_IMPORTED
    ]
    return [fcmaster, *(importlib.import_module(name) for name in names)]


def defined_exceptions() -> dict[str, type[BaseException]]:
    """Every exception class defined (not imported) in a module of fcmaster, by full name."""
    found: dict[str, type[BaseException]] = {}
    for module in every_module():
        for name, value in vars(module).items():
            if (
                inspect.isclass(value)
                and issubclass(value, BaseException)
                and value.__module__ == module.__name__
            ):
                found[f"{module.__name__}.{name}"] = value
    return found


def test_the_walk_reaches_every_layer() -> None:
    modules = {module.__name__ for module in every_module()}
    # A walk that stopped at the top would find nothing wrong: show it went everywhere.
    for name in (
        "fcmaster.adapters.auth",
        "fcmaster.bus.master",
        "fcmaster.subcommands.commission",
        "fcmaster.protocol.mitsubishi.codec",
        "fcmaster.sim.enc.parameters",
        "fcmaster.state",
    ):
        assert name in modules


def test_every_exception_of_the_package_derives_from_the_root() -> None:
    found = defined_exceptions()
    # The ones that once stood outside the tree are among those checked.
    assert {
        "fcmaster.adapters.auth.AuthError",
        "fcmaster.adapters.readlimit.ReadsBusy",
        "fcmaster.adapters.parameter_sets.ReadFailed",
        "fcmaster.protocol.pcapng.PcapngError",
        "fcmaster.sim.danfoss_fc.parameters.Refused",
        "fcmaster.sim.enc.parameters.Refused",
    } <= set(found)
    outside = sorted(name for name, cls in found.items() if not issubclass(cls, FcmasterError))
    assert outside == []


def test_every_exception_the_tree_names_is_drawn_in_its_docstring() -> None:
    import fcmaster.errors

    drawn = fcmaster.errors.__doc__ or ""
    public = {name.rpartition(".")[2] for name in defined_exceptions() if "._" not in name}
    assert sorted(name for name in public if not re.search(rf"\b{name}\b", drawn)) == []
