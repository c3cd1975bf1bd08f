"""Simulated lines for the daemon's ``sim://NAME`` ports, built from a bus's config.

A bus whose port is ``sim://NAME`` gets a simulated line in the bus's character format with
one simulated drive per configured drive, at its address. Each drive's motor is rated at the
drive's ``nominal_frequency_hz``, which is also what 100 % reference means to it, so a
``start`` at 50 % turns it at half its nominal frequency. A bus with ``echo: true`` gets a
line that echoes, so the daemon's echo suppression is exercised too.

The bus's optional ``simulation:`` section says what the drives do::

    simulation:
      seed: 7                              # the faults' random sequence
      faults: "drop=0.01,corrupt=0.005"    # the --faults form, or a mapping {drop: 0.01}
      response_delay_ms: 10                # every drive's (default: the bus's response_delay)
      load: 0.7                            # load torque at rated speed, fraction of rated
      adapter_latency_ms: 16               # replies held as by a USB adapter's latency timer
      drives:                              # by address; overrides the keys above
        3: {load: 0.9, faults: "silent_at=60-70", local: false,
            interlocked: false,                      # true: acknowledges a start, never turns
            response_delay_ms: 20, parameters: {"3-41": 5.0},
            running_hz: 35,                          # found running, as a former master left it
            warning: {number: 59, every_s: 60, for_s: 15}}   # a warning that comes and goes

Mistakes raise ConfigError naming the key path.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, Final

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import Clock
from fcmaster.errors import ConfigError, FcmasterError
from fcmaster.sim.build import SIM_PROTOCOLS, build_line, simulated_keys
from fcmaster.sim.faults import FaultPlan, parse_faults
from fcmaster.sim.line import SimLine
from fcmaster.sim.motor import MotorRating
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.transport import SimTransport

_LINE_KEYS: Final = frozenset(
    {"seed", "faults", "response_delay_ms", "load", "drives", "adapter_latency_ms"}
)
_DRIVE_KEYS: Final = frozenset(
    {
        "faults",
        "response_delay_ms",
        "load",
        "local",
        "interlocked",
        "parameters",
        "running_hz",
        "warning",
    }
)
_RPM_PER_HZ: Final = 29.0  # a four-pole motor with 3 % slip: 1450 rpm at 50 Hz


def sim_transport(plan: LinePlan, simulation: Mapping[str, Any], *, clock: Clock) -> SimTransport:
    """A transport onto a new simulated line for ``plan`` (see the module docstring)."""
    return SimTransport(sim_line(plan, simulation, clock=clock), clock, port=plan.port)


def sim_line(plan: LinePlan, simulation: Mapping[str, Any], *, clock: Clock) -> SimLine:
    """The simulated line for ``plan``, powered up now; ConfigError for a bad section."""
    line, drives = sim_settings(plan, simulation)
    try:
        return build_line(line, drives, clock=clock)
    except FcmasterError as exc:
        raise ConfigError([(f"buses.{plan.name}.simulation", str(exc))]) from exc


def sim_settings(
    plan: LinePlan, simulation: Mapping[str, Any]
) -> tuple[LineSettings, list[tuple[int, DriveSettings]]]:
    """The simulator's settings for ``plan`` and its ``simulation:`` section."""
    where = f"buses.{plan.name}.simulation"
    _check_keys(simulation, _LINE_KEYS, where)
    faults = _faults(simulation.get("faults"), f"{where}.faults")
    faults = dataclasses.replace(faults, seed=simulation.get("seed", faults.seed),
                                 echo=faults.echo or plan.echo)  # fmt: skip
    per_drive = simulation.get("drives") or {}
    if not isinstance(per_drive, Mapping):
        raise ConfigError([(f"{where}.drives", "must map addresses to settings")])
    known = {drive.address for drive in plan.drives}
    unknown = sorted(str(a) for a in per_drive if _int(a) not in known)
    if unknown:
        raise ConfigError([(f"{where}.drives", f"no configured drive at {', '.join(unknown)}")])
    overrides = {_int(address): settings for address, settings in per_drive.items()}
    drives = [
        (drive.address, _drive(plan, drive, simulation, overrides.get(drive.address) or {}, where))
        for drive in plan.drives
    ]
    line = LineSettings(
        name=plan.name, protocol=plan.protocol, baudrate=plan.baudrate, parity=plan.parity,
        stopbits=plan.stopbits, databits=plan.databits, faults=faults,
        protocol_options=simulated_keys(plan.protocol, plan),
    )  # fmt: skip
    if "adapter_latency_ms" in simulation:
        try:
            latency = float(simulation["adapter_latency_ms"])
            line = dataclasses.replace(line, adapter_latency_ms=latency)
        except (FcmasterError, TypeError, ValueError) as exc:
            raise ConfigError([(f"{where}.adapter_latency_ms", str(exc))]) from exc
    return line, drives


def _drive(
    plan: LinePlan,
    drive: DrivePlan,
    common: Mapping[str, Any],
    own: Mapping[str, Any],
    where: str,
) -> DriveSettings:
    here = f"{where}.drives.{drive.address}"
    _check_keys(own, _DRIVE_KEYS, here)
    merged = {**common, **own}
    protocol = SIM_PROTOCOLS.get(plan.protocol)
    # A drive that times its own replies (Mitsubishi) keeps its factory timing unless the
    # simulation section gives one; the bus's response delay is only the master's allowance.
    own_timing = protocol is not None and protocol.own_timing
    delay_ms = merged.get("response_delay_ms", None if own_timing else plan.response_delay_s * 1e3)
    implied = protocol.line_parameters(plan) if protocol and protocol.line_parameters else {}
    nominal = drive.nominal_frequency_hz
    try:
        return DriveSettings(
            response_delay_s=None if delay_ms is None else float(delay_ms) / 1000.0,
            rating=MotorRating(frequency_hz=nominal, speed_rpm=_RPM_PER_HZ * nominal),
            load=float(merged.get("load", 0.7)),
            reference_100_hz=nominal,
            max_frequency_hz=max(drive.max_frequency_hz, 1.3 * nominal),
            parameters={
                **implied,
                **{str(k): float(v) for k, v in dict(own.get("parameters") or {}).items()},
            },
            faults=_faults(own.get("faults"), f"{here}.faults") if "faults" in own else None,
            local=bool(own.get("local", False)),
            interlocked=bool(own.get("interlocked", False)),
            running_hz=float(own["running_hz"]) if "running_hz" in own else None,
            warning_cycle=_warning_cycle(own.get("warning"), f"{here}.warning"),
            profile=drive.profile,  # modbus-rtu: the simulated drive follows the same profile
        )
    except (TypeError, ValueError) as exc:
        raise ConfigError([(here, str(exc))]) from exc


def _warning_cycle(value: object, where: str) -> tuple[int, float, float] | None:
    """``{number: 59, every_s: 60, for_s: 15}``: a warning that comes and goes."""
    if value is None:
        return None
    if not isinstance(value, Mapping) or set(value) != {"number", "every_s", "for_s"}:
        raise ConfigError([(where, "write it as {number: 59, every_s: 60, for_s: 15}")])
    number, every_s, for_s = int(value["number"]), float(value["every_s"]), float(value["for_s"])
    if not 0 < for_s < every_s:
        raise ConfigError([(where, "for_s must be above 0 and below every_s")])
    return number, every_s, for_s


def _faults(value: object, where: str) -> FaultPlan:
    try:
        if value is None:
            return FaultPlan()
        if isinstance(value, str):
            return parse_faults(value)
        if isinstance(value, Mapping):
            fields = dict(value)
            periods = fields.pop("silent_periods", ())
            return FaultPlan(silent_periods=tuple(tuple(p) for p in periods), **fields)
    except (FcmasterError, TypeError, ValueError) as exc:
        raise ConfigError([(where, str(exc))]) from exc
    raise ConfigError([(where, "write faults as 'drop=0.01,…' or as a mapping")])


def _check_keys(section: object, allowed: frozenset[str], where: str) -> None:
    if not isinstance(section, Mapping):
        raise ConfigError([(where, "must be a mapping")])
    extra = sorted(str(key) for key in section if key not in allowed)
    if extra:
        raise ConfigError([(f"{where}.{key}", "unknown key") for key in extra])


def _int(value: object) -> int:
    try:
        return int(str(value))
    except ValueError:
        return -1
