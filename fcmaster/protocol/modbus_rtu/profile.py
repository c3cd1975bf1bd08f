"""A drive profile: how one family of drives is run over Modbus registers (plain data).

Modbus says how registers travel, not what they mean. A :class:`DriveProfile` says it for
one family: which registers hold the control word, the reference, the status word, the
output frequency and the fault; which control words, written in order, start, stop, coast,
quick-stop or reset the drive (a state machine's sequence where the family has one: CiA 402
0x06 → 0x07 → 0x0F); which status bits mean running, fault, warning, at reference; the
fault texts; the drive's own communication watchdog; values worth watching; settings a
backup keeps; and pacing rules. Built-in profiles live in
:mod:`fcmaster.protocol.modbus_rtu.profiles`; a user's own is read from YAML by
:mod:`fcmaster.protocol.modbus_rtu.profile_file`.

Addresses are zero-based PDU addresses (holding register 40001 is 0). A register's value is
``raw * scale`` in its unit; a reference or output frequency in ``%`` is a share of the
drive's nominal frequency (the config's ``nominal_frequency_hz``), one in ``Hz`` is Hz.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from fcmaster.errors import ConfigError, UsageError
from fcmaster.protocol.watchdog import WatchdogSetting

# The commands a profile may offer, as the command surfaces name them.
COMMANDS: Final = ("start", "stop", "coast", "quick_stop", "reset", "start_reverse", "jog")
REQUIRED_COMMANDS: Final = ("start", "stop")
# The status bits a profile may name; running and fault are needed for confirmation.
STATUS_BITS: Final = (
    "running", "fault", "warning", "at_reference", "remote", "reverse", "ready",
)  # fmt: skip
REQUIRED_STATUS_BITS: Final = ("running", "fault")
UNITS: Final = ("Hz", "%")  # what a reference or output frequency may be in


class StateMachine(enum.StrEnum):
    """How a family's control word moves the drive.

    The two state machines need their enable sequence in ``start`` (checked when a profile
    is built): a drive that is not walked through its states ignores a run word.
    """

    CIA402 = "cia402"  # CiA 402 / IEC 61800-7: 0x06 shutdown, 0x07 switch on, 0x0F enable
    PROFIDRIVE = "profidrive"  # PROFIdrive / ABB Drives: OFF1 off (…6/…E), then on (…7/…F)
    BITS = "bits"  # a bit per command (Yaskawa, Delta, Danfoss FC profile): no sequence


@dataclass(slots=True, frozen=True, kw_only=True)
class Register:
    """One value in the drive's register map."""

    address: int  # zero-based PDU address
    scale: float = 1.0  # value = raw × scale
    unit: str = ""
    input: bool = False  # an input register (FC 4) instead of a holding register (FC 3)
    signed: bool = False  # two's complement
    words: int = 1  # 2: a 32-bit value, high word first

    def value(self, words: Sequence[int]) -> float:
        """The value of the register's raw ``words`` (as many as :attr:`words`)."""
        raw = 0
        for word in words:
            raw = raw << 16 | word
        bits = 16 * self.words
        if self.signed and raw >> (bits - 1):
            raw -= 1 << bits
        return raw * self.scale

    def raw(self, value: float) -> tuple[int, ...]:
        """The words that hold ``value``; UsageError if it cannot be written as it is."""
        bits = 16 * self.words
        low, high = (
            (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if self.signed else (0, (1 << bits) - 1)
        )
        if not math.isfinite(value):
            raise UsageError(f"{value} cannot be written to register {self.address}")
        raw = round(value / self.scale)
        if not low <= raw <= high:
            lowest, highest = low * self.scale, high * self.scale
            raise UsageError(
                f"{value:g} {self.unit} is outside {lowest:g}-{highest:g} {self.unit} "
                f"that register {self.address} holds".replace("  ", " ")
            )
        raw &= (1 << bits) - 1
        return tuple((raw >> (16 * i)) & 0xFFFF for i in reversed(range(self.words)))


@dataclass(slots=True, frozen=True, kw_only=True)
class Value:
    """A monitored value: its manual name and register."""

    name: str
    register: Register


@dataclass(slots=True, frozen=True, kw_only=True)
class WatchdogProfile:
    """The drive's communication watchdog: the registers that set it and their meaning.

    The timeout register (0 = off), the action register (value → words and whether the
    motor stops), an enable register where the family has one (0 = off). ``decode``
    replaces the generic reading where a family's rules need their own (Danfoss 8-04).
    """

    timeout: Register | None = None
    action: Register | None = None
    enable: Register | None = None
    actions: Mapping[int, tuple[str, bool | None]] = field(default_factory=dict)
    fixed_action: str = "trip"  # the action where no register chooses one
    decode: Callable[[Sequence[float]], WatchdogSetting] | None = None

    @property
    def registers(self) -> tuple[Register, ...]:
        """The registers to read, in the order :meth:`setting` takes their values."""
        return tuple(r for r in (self.timeout, self.action, self.enable) if r is not None)

    def setting(self, values: Sequence[float]) -> WatchdogSetting:
        """What the values read from :attr:`registers` say."""
        if self.decode is not None:
            return self.decode(values)
        named = [n for n in ("timeout", "action", "enable") if getattr(self, n) is not None]
        given = dict(zip(named, values, strict=True))
        timeout = given.get("timeout")
        if given.get("enable") == 0 or timeout == 0:
            return WatchdogSetting(timeout_s=None, action="off", stops=False)
        if "action" in given:
            option = int(given["action"])
            words, stops = self.actions.get(option, (f"option {option}", None))
        else:
            words, stops = self.fixed_action, True
        # stops False: supervised, but the motor keeps turning (judged as off by the bus)
        return WatchdogSetting(timeout_s=timeout, action=words, stops=stops)


@dataclass(slots=True, frozen=True, kw_only=True)
class Pacing:
    """Waits a family asks for beyond the 3.5-character silence.

    The codec puts them on the exchanges they follow (``Exchange.settle_s``) and the bus
    keeps them for that drive alone: the line's other drives are served meanwhile.
    """

    after_write_s: float = 0.0  # after a parameter write, before the next request
    between_steps_s: float = 0.0  # between the steps of a command sequence


@dataclass(slots=True, frozen=True, kw_only=True)
class DriveProfile:
    """How one family of drives is run over Modbus RTU (see the module docstring)."""

    name: str
    title: str = ""  # the family in words ("ABB drives, ABB Drives profile")
    state_machine: StateMachine = StateMachine.BITS
    control: Register
    reference: Register
    status: Register
    output_frequency: Register
    fault_code: Register | None = None
    fault_bits: bool = False  # the fault register is a bit field: ``faults`` keys are bits
    commands: Mapping[str, tuple[int, ...]]
    status_bits: Mapping[str, int]
    faults: Mapping[int, str] = field(default_factory=dict)
    watchdog: WatchdogProfile = field(default_factory=WatchdogProfile)
    values: tuple[Value, ...] = ()
    # Settings a backup keeps (``fcmaster params``): writable registers, by manual name. The
    # watchdog's registers are kept too, after these.
    parameters: tuple[Value, ...] = ()
    pacing: Pacing = field(default_factory=Pacing)
    sources: tuple[str, ...] = ()  # the manuals and pages each fact came from
    unverified: tuple[str, ...] = ()  # facts not checked against a manual page

    def fault_texts(self, raw: int) -> list[tuple[int, str]]:
        """The faults a fault register's ``raw`` value shows, as (code, text)."""
        if self.fault_bits:
            return [
                (bit, self.faults.get(bit, f"Fault bit {bit}"))
                for bit in range(16 * (self.fault_code.words if self.fault_code else 1))
                if raw >> bit & 1
            ]
        if raw == 0:
            return []
        return [(raw, self.faults.get(raw, f"Fault {raw}"))]

    def bit(self, word: int, name: str) -> bool | None:
        """Whether status bit ``name`` is set in ``word`` (None: the profile has no such bit)."""
        position = self.status_bits.get(name)
        return None if position is None else bool(word >> position & 1)


def checked(profile: DriveProfile, where: str = "") -> DriveProfile:
    """``profile`` if it has no problem; ConfigError naming every problem otherwise.

    ``where`` goes before each key path (the file a user profile came from).
    """
    problems = profile_problems(profile)
    if problems:
        raise ConfigError([(f"{where}{path}", reason) for path, reason in problems])
    return profile


def profile_problems(profile: DriveProfile) -> list[tuple[str, str]]:
    """Every problem with ``profile``, as (key path, reason), the way a config names them."""
    problems: list[tuple[str, str]] = []
    if not profile.name:
        problems.append(("name", "must not be empty"))
    registers = {
        "control": profile.control,
        "reference": profile.reference,
        "status": profile.status,
        "output_frequency": profile.output_frequency,
    }
    if profile.fault_code is not None:
        registers["fault_code"] = profile.fault_code
    for name, register in registers.items():
        problems += [(f"registers.{name}.{k}", r) for k, r in register_problems(register)]
    for name in ("reference", "output_frequency"):
        if registers[name].unit not in UNITS:
            problems.append(
                (f"registers.{name}.unit", f"must be Hz or %, not {registers[name].unit!r}")
            )
    for name, register in (("control", profile.control), ("status", profile.status)):
        if register.words != 1 or register.scale != 1:
            problems.append(
                (f"registers.{name}", "a control or status word is one unscaled register")
            )
    if profile.control.input:
        problems.append(("registers.control.input", "the control word must be a holding register"))
    if profile.reference.input:
        problems.append(("registers.reference.input", "the reference must be a holding register"))
    for name in REQUIRED_COMMANDS:
        if name not in profile.commands:
            problems.append((f"commands.{name}", "missing: every profile must start and stop"))
    for name, words in profile.commands.items():
        if name not in COMMANDS:
            problems.append((f"commands.{name}", f"unknown command (have: {', '.join(COMMANDS)})"))
        elif not words:
            problems.append((f"commands.{name}", "an empty sequence"))
        for i, word in enumerate(words):
            if not 0 <= word <= 0xFFFF:
                problems.append((f"commands.{name}[{i}]", f"{word} is not a 16-bit word"))
    problems += _state_machine_problems(profile)
    for name in REQUIRED_STATUS_BITS:
        if name not in profile.status_bits:
            problems.append((f"status_bits.{name}", "missing: confirmation needs it"))
    reverses = "start_reverse" in profile.commands or profile.reference.signed
    if reverses and "reverse" not in profile.status_bits and not profile.output_frequency.signed:
        # A gateway restarted under a drive running in reverse would take it for forward,
        # and its next command would turn the motor round.
        problems.append(
            (
                "status_bits.reverse",
                "missing: a drive that can run in reverse must tell it, by this bit or a "
                "signed registers.output_frequency",
            )
        )
    for name, bit in profile.status_bits.items():
        if name not in STATUS_BITS:
            problems.append(
                (f"status_bits.{name}", f"unknown bit (have: {', '.join(STATUS_BITS)})")
            )
        if not 0 <= bit <= 15:
            problems.append((f"status_bits.{name}", f"{bit} is not a bit of a 16-bit word (0-15)"))
    for key, listed in (("values", profile.values), ("parameters", profile.parameters)):
        for i, value in enumerate(listed):
            path = f"{key}[{i}]"
            problems += [(f"{path}.{k}", r) for k, r in register_problems(value.register)]
            if not value.name:
                problems.append((f"{path}.name", "must not be empty"))
    for i, value in enumerate(profile.parameters):
        if value.register.input:
            problems.append((f"parameters[{i}].input", "a setting is a holding register"))
    for name in ("timeout", "action", "enable"):
        register = getattr(profile.watchdog, name)
        if register is not None:
            problems += [(f"watchdog.{name}.{k}", r) for k, r in register_problems(register)]
    for name in ("after_write_s", "between_steps_s"):
        wait = getattr(profile.pacing, name)
        if not 0 <= wait <= 10:
            problems.append((f"pacing.{name}", f"{wait} is outside 0-10 s"))
    return problems


def register_problems(register: Register) -> list[tuple[str, str]]:
    """What is wrong with one register, as (key, reason)."""
    problems = []
    if not 0 <= register.address <= 0xFFFF - (register.words - 1):
        problems.append(("address", f"{register.address} is outside 0-65535"))
    if register.words not in (1, 2):
        problems.append(("words", f"{register.words}: a value takes 1 or 2 registers"))
    if not (math.isfinite(register.scale) and register.scale > 0):
        problems.append(("scale", f"{register.scale} is not a positive number"))
    return problems


def _state_machine_problems(profile: DriveProfile) -> list[tuple[str, str]]:
    """A state machine's start must walk the drive through its states, or it never runs."""
    problems = []
    for name in ("start", "start_reverse"):
        words = profile.commands.get(name)
        if words and not _walks(profile.state_machine, words):
            problems.append((f"commands.{name}", _SEQUENCES[profile.state_machine]))
    return problems


_SEQUENCES: Final = {
    StateMachine.CIA402: (
        "a CiA 402 drive runs only after its enable sequence: shutdown (0x06), switch on "
        "(0x07), enable operation (0x0F), in that order"
    ),
    StateMachine.PROFIDRIVE: (
        "a PROFIdrive / ABB Drives drive runs only after OFF1 is cleared: a word ending in "
        "binary 110 (ready to switch on), then one ending in 1111 (operation enabled)"
    ),
}


def _walks(machine: StateMachine, words: tuple[int, ...]) -> bool:
    if machine is StateMachine.CIA402:
        # bits 0-3 and 7 (fault reset) of the last three: 0110, 0111, 1111
        return [w & 0x8F for w in words[-3:]] == [0x06, 0x07, 0x0F]
    if machine is StateMachine.PROFIDRIVE:
        return len(words) >= 2 and words[-2] & 0x07 == 0x06 and words[-1] & 0x0F == 0x0F
    return True
