"""A user's drive profile from YAML (DESIGN "Drive profiles"), with every problem named.

The file has the shape of :class:`~.profile.DriveProfile`::

    name: my-vfd
    state_machine: bits            # cia402 | profidrive | bits (default bits)
    registers:                     # zero-based PDU addresses; holding unless input: true
      control: {address: 256}
      reference: {address: 257, scale: 0.01, unit: Hz}
      status: {address: 512}
      output_frequency: {address: 513, scale: 0.01, unit: Hz}
      fault_code: {address: 514}
    commands: {start: [6, 7], stop: [1]}
    status_bits: {running: 8, fault: 9}
    faults: {770: "Overcurrent"}
    watchdog: {timeout: {address: 600, scale: 0.1}, action: {address: 601},
               actions: {0: {action: "off", stops: false}, 1: {action: "trip", stops: true}}}
    values: [{name: "Motor Current", address: 515, scale: 0.1, unit: A}]
    parameters: [{name: "Acceleration time", address: 600, scale: 0.1, unit: s}]
    pacing: {after_write_s: 0.01}

Nothing here reads a file: the caller hands the text over and names where it came from, so
each problem reads ``<where>registers.status.address: …`` whatever the source.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Final, TypeVar

import yaml

from fcmaster.errors import ConfigError
from fcmaster.protocol.modbus_rtu.profile import (
    DriveProfile,
    Pacing,
    Register,
    StateMachine,
    Value,
    WatchdogProfile,
    checked,
    profile_problems,
)

_TOP: Final = frozenset(
    {
        "name", "title", "state_machine", "registers", "commands", "status_bits", "faults",
        "fault_bits", "watchdog", "values", "parameters", "pacing", "sources", "unverified",
    }
)  # fmt: skip
_REGISTER_KEYS: Final = frozenset({"address", "scale", "unit", "input", "signed", "words"})
_REGISTERS: Final = ("control", "reference", "status", "output_frequency", "fault_code")
_REQUIRED_REGISTERS: Final = ("control", "reference", "status", "output_frequency")
T = TypeVar("T")

Problems = list[tuple[str, str]]


def parse_profile_text(text: str, where: str = "") -> DriveProfile:
    """The profile in YAML ``text``; ConfigError naming every problem, each after ``where``."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "YAML"
        raise ConfigError(
            [(f"{where}{at}", f"not valid YAML: {getattr(exc, 'problem', exc)}")]
        ) from None
    return parse_profile(data, where)


def parse_profile(data: object, where: str = "") -> DriveProfile:
    """The profile in a mapping read from YAML; ConfigError naming every problem."""
    problems: Problems = []
    if not isinstance(data, dict):
        raise ConfigError([(f"{where}(top)", "a profile is a mapping with name, registers, …")])
    for key in data:
        if key not in _TOP:
            problems.append((str(key), f"unknown key (have: {', '.join(sorted(_TOP))})"))
    name = _get(data, "name", str, problems, "")
    if "name" not in data:
        problems.append(("name", "missing: a profile is named"))
    machine = _get(data, "state_machine", str, problems, StateMachine.BITS.value)
    if machine not in tuple(StateMachine):
        problems.append(("state_machine", f"{machine!r} is not cia402, profidrive or bits"))
        machine = StateMachine.BITS.value
    registers = _mapping(data, "registers", problems)
    for key in registers:
        if key not in _REGISTERS:
            problems.append(
                (f"registers.{key}", f"unknown register (have: {', '.join(_REGISTERS)})")
            )
    for key in _REQUIRED_REGISTERS:
        if key not in registers:
            problems.append((f"registers.{key}", "missing"))
    parsed = {
        key: _register(registers[key], f"registers.{key}", problems)
        for key in _REGISTERS
        if key in registers
    }
    commands = {
        str(k): _words(v, f"commands.{k}", problems)
        for k, v in _mapping(data, "commands", problems).items()
    }
    status_bits = {
        str(k): _int(v, f"status_bits.{k}", problems)
        for k, v in _mapping(data, "status_bits", problems).items()
    }
    faults = {
        _int(k, f"faults.{k}", problems): _text(v, f"faults.{k}", problems)
        for k, v in _mapping(data, "faults", problems).items()
    }
    values = _values(data.get("values", []), problems)
    parameters = _values(data.get("parameters", []), problems, "parameters")
    watchdog = _watchdog(_mapping(data, "watchdog", problems), problems)
    pacing_data = _mapping(data, "pacing", problems)
    pacing = Pacing(
        after_write_s=_number(
            pacing_data.get("after_write_s", 0.0), "pacing.after_write_s", problems
        ),
        between_steps_s=_number(
            pacing_data.get("between_steps_s", 0.0), "pacing.between_steps_s", problems
        ),
    )
    for key in pacing_data:
        if key not in ("after_write_s", "between_steps_s"):
            problems.append((f"pacing.{key}", "unknown key (have: after_write_s, between_steps_s)"))
    fault_bits = _get(data, "fault_bits", bool, problems, False)
    placeholder = Register(address=0)
    profile = DriveProfile(
        name=name,
        title=_get(data, "title", str, problems, ""),
        state_machine=StateMachine(machine),
        control=parsed.get("control", placeholder),
        reference=parsed.get("reference", Register(address=0, unit="Hz")),
        status=parsed.get("status", placeholder),
        output_frequency=parsed.get("output_frequency", Register(address=0, unit="Hz")),
        fault_code=parsed.get("fault_code"),
        fault_bits=fault_bits,
        commands=commands,
        status_bits=status_bits,
        faults=faults,
        watchdog=watchdog,
        values=values,
        parameters=parameters,
        pacing=pacing,
        sources=tuple(_texts(data.get("sources", []), "sources", problems)),
        unverified=tuple(_texts(data.get("unverified", []), "unverified", problems)),
    )
    if problems:  # the model's own rules on top, for what was well-formed
        raise ConfigError([(f"{where}{p}", r) for p, r in _merge(problems, profile)])
    return checked(profile, where)


def _merge(problems: Problems, profile: DriveProfile) -> Problems:
    said = {path for path, _ in problems}
    more = [(p, r) for p, r in profile_problems(profile) if not any(p.startswith(s) for s in said)]
    return problems + more


# ------------------------------------------------------------------ pieces


def _get(data: Mapping[str, Any], key: str, kind: type[T], problems: Problems, default: T) -> T:
    value = data.get(key, default)
    if (kind is not bool and isinstance(value, bool)) or not isinstance(value, kind):
        problems.append((key, f"must be {_KIND_NAMES.get(kind, kind.__name__)}, not {value!r}"))
        return default
    return value


_KIND_NAMES: Final[dict[type, str]] = {str: "text", bool: "true or false", int: "a whole number"}


def _mapping(data: Mapping[str, Any], key: str, problems: Problems) -> dict[Any, Any]:
    value = data.get(key, {})
    if value is None:
        return {}
    if not isinstance(value, dict):
        problems.append((key, f"must be a mapping, not {value!r}"))
        return {}
    return value


def _int(value: object, path: str, problems: Problems) -> int:
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    problems.append((path, f"must be a whole number, not {value!r}"))
    return 0


def _number(value: object, path: str, problems: Problems) -> float:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    problems.append((path, f"must be a number, not {value!r}"))
    return 0.0


def _text(value: object, path: str, problems: Problems) -> str:
    if isinstance(value, str) and value:
        return value
    problems.append((path, f"must be a text, not {value!r}"))
    return ""


def _texts(value: object, path: str, problems: Problems) -> list[str]:
    if not isinstance(value, list):
        problems.append((path, "must be a list of texts"))
        return []
    return [_text(v, f"{path}[{i}]", problems) for i, v in enumerate(value)]


def _flag(value: object, path: str, problems: Problems) -> bool:
    if isinstance(value, bool):
        return value
    problems.append((path, f"must be true or false, not {value!r}"))
    return False


def _words(value: object, path: str, problems: Problems) -> tuple[int, ...]:
    if isinstance(value, int) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list):
        problems.append((path, f"must be a list of control words, not {value!r}"))
        return ()
    return tuple(_int(v, f"{path}[{i}]", problems) for i, v in enumerate(value))


def _register(value: object, path: str, problems: Problems) -> Register:
    if not isinstance(value, dict):
        problems.append((path, f"must be a mapping with an address, not {value!r}"))
        return Register(address=0)
    for key in value:
        if key not in _REGISTER_KEYS:
            allowed = ", ".join(sorted(_REGISTER_KEYS))
            problems.append((f"{path}.{key}", f"unknown key (have: {allowed})"))
    if "address" not in value:
        problems.append((f"{path}.address", "missing"))
    fields: dict[str, Callable[[object, str, Problems], Any]] = {
        "address": _int, "scale": _number, "unit": _unit, "input": _flag, "signed": _flag,
        "words": _int,
    }  # fmt: skip
    given = {
        k: parse(value[k], f"{path}.{k}", problems) for k, parse in fields.items() if k in value
    }
    return Register(**{"address": 0, **given})


def _unit(value: object, path: str, problems: Problems) -> str:
    if isinstance(value, str):
        return value
    problems.append((path, f"must be a text, not {value!r}"))
    return ""


def _values(value: object, problems: Problems, key: str = "values") -> tuple[Value, ...]:
    if not isinstance(value, list):
        problems.append((key, "must be a list of {name, address, …}"))
        return ()
    values = []
    for i, item in enumerate(value):
        path = f"{key}[{i}]"
        if not isinstance(item, dict):
            problems.append((path, f"must be a mapping with name and address, not {item!r}"))
            continue
        register = _register({k: v for k, v in item.items() if k != "name"}, path, problems)
        values.append(
            Value(name=_text(item.get("name"), f"{path}.name", problems), register=register)
        )
    return tuple(values)


def _watchdog(data: Mapping[str, Any], problems: Problems) -> WatchdogProfile:
    for key in data:
        if key not in ("timeout", "action", "enable", "actions", "fixed_action"):
            problems.append(
                (
                    f"watchdog.{key}",
                    "unknown key (have: action, actions, enable, fixed_action, timeout)",
                )
            )
    registers = {
        key: _register(data[key], f"watchdog.{key}", problems)
        for key in ("timeout", "action", "enable")
        if key in data
    }
    actions: dict[int, tuple[str, bool | None]] = {}
    for key, entry in _mapping(data, "actions", problems).items():
        path = f"watchdog.actions.{key}"
        if not isinstance(entry, dict) or set(entry) - {"action", "stops"}:
            problems.append((path, "must be {action: text, stops: true|false}"))
            continue
        stops = entry.get("stops")
        actions[_int(key, path, problems)] = (
            _text(entry.get("action"), f"{path}.action", problems),
            None if stops is None else _flag(stops, f"{path}.stops", problems),
        )
    # Without ``actions`` the action register is read but its values mean nothing known:
    # the verdict stays unknown until the file says which values stop the motor.
    fixed = data.get("fixed_action", "trip")
    return WatchdogProfile(
        timeout=registers.get("timeout"),
        action=registers.get("action"),
        enable=registers.get("enable"),
        actions=actions,
        fixed_action=_text(fixed, "watchdog.fixed_action", problems),
    )
