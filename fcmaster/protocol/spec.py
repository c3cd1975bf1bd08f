"""What the rest of the house may know about one protocol: its :class:`ProtocolSpec`.

Every vendor package under ``fcmaster/protocol/`` has a ``spec.py`` holding one
``ProtocolSpec``, and :mod:`fcmaster.protocol.registry` lists them, one line each. Config,
CLI, commissioning, decode, the doctor, confirmation deadlines, the simulator and the bus
read what they need from the spec of a line's ``protocol``; none of them branches on a
vendor's name. Adding a protocol is one new package plus one registry line.

The spec is plain data and pure functions, so it lives in the sans-I/O layer. Two things
belong to higher layers and are named here, never imported:

- the simulator: ``simulator`` is ``"module:attribute"`` of the sim layer's description of
  the vendor's simulated drives (a ``fcmaster.sim.simulator.SimProtocol``), resolved by
  ``fcmaster.sim.build`` when it builds a line. The protocol layer may not import the
  simulator (the import contract puts ``sim`` above it), and a dotted name keeps it so
  while the vendor still adds its simulator in its own package.
- the config models and CLI options: a protocol's own line settings are described once as
  :class:`LineKey` values (name, allowed values, default, help); ``fcmaster.config`` turns
  them into validated keys and ``fcmaster.cli_arguments`` into options, so the YAML key, the
  CLI option and the codec's argument cannot drift apart.

A protocol's *options* are the values of its line keys for one line, as a frozen
dataclass of its own (FC: the address format). :meth:`ProtocolSpec.options_of` reads them
from anything that carries the keys as attributes (a ``LinePlan``, a commissioning command's
options, the simulator's line settings) or as ``protocol_options`` pairs (a ``LinePlan``
keeps there the keys it has no field for, so a new protocol needs no new plan field); what
a source lacks takes its default.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Generic, TypeVar

from fcmaster.protocol.codec import DriveCodec, ParameterKey
from fcmaster.protocol.drive import Motion
from fcmaster.protocol.watchdog import WatchdogFacts

OptionsT = TypeVar("OptionsT")

# The value a line key may take: a choice (31, "crlf") or a number; None where null is allowed.
KeyValue = int | str | None
# Some of a protocol's options as (line key, value) pairs, the way a plan carries them.
OptionPairs = tuple[tuple[str, KeyValue], ...]


@dataclass(slots=True, frozen=True, kw_only=True)
class LineKey:
    """A line setting only this protocol has: one config key and one CLI option.

    The config key is ``name`` (``address_format``), the CLI option ``--`` with dashes
    (``--address-format``), and the options dataclass has a field of the same name.
    """

    name: str
    default: KeyValue
    help: str
    # The values it may take; empty: a whole number from ``minimum`` to ``maximum`` in
    # steps of ``step`` (Mitsubishi's waiting time).
    choices: tuple[int, ...] | tuple[str, ...] = ()
    minimum: int = 0
    maximum: int = 0
    step: int = 1
    nullable: bool = False  # null in the config, ``none`` on the command line
    metavar: str | None = None  # the CLI's name for a number's value ("MS|none")
    # The simulated drives take it from the line too (`fcmaster sim --KEY`).
    simulated: bool = False

    def problem(self, value: object) -> str:
        """Why ``value`` cannot be this key's ("" when it can)."""
        if value is None:
            return "" if self.nullable else "must be given (null is not allowed)"
        if self.choices:
            if value in self.choices and type(value) is type(self.choices[0]):
                return ""
            *first, last = (str(c) for c in self.choices)
            return f"{value!r} is not {', '.join(first)} or {last}"
        if (
            isinstance(value, int)
            and not isinstance(value, bool)
            and self.minimum <= value <= self.maximum
            and (value - self.minimum) % self.step == 0
        ):
            return ""
        return f"{value!r} is not {self.minimum}-{self.maximum} in steps of {self.step}"


@dataclass(slots=True, frozen=True)
class SerialSettings:
    """A drive's factory serial settings."""

    baudrate: int
    parity: str  # N | E | O
    stopbits: int


@dataclass(slots=True, frozen=True, kw_only=True)
class DiagnosisParameters:
    """The drive parameters the doctor names when it says what to set, and a drive's delay."""

    address: str
    baudrate: str
    parity: str
    delay: str  # the drive's response delay setting
    # that delay as the drives leave the factory; None where the protocol's drives have no
    # one such delay (Modbus RTU: each make answers in its own time), so none is judged slow
    factory_delay_s: float | None


@dataclass(slots=True, frozen=True, kw_only=True)
class ParameterTables:
    """The facts of a vendor's parameter tables that vendor-neutral code combines.

    What makes up a backup of a drive's settings, and the unit of a parameter's values.
    Parameters are written as the codec writes them (``"3-41"``, ``"Pr.7"``, ``"F0.08"``).
    """

    set_members: tuple[tuple[str, str], ...]  # (parameter, name) in the order to read/write
    identity: tuple[tuple[str, str], ...]  # (parameter, name): who the drive is
    identity_match: frozenset[str]  # identity entries a restore insists on (type, model)
    changeable_while_running: frozenset[str]  # known from the manuals; all others: stopped
    link_settings: frozenset[str]  # address, baud, parity, protocol: never restored
    unit_of: Callable[[ParameterKey], str]  # the unit its values come in, as read
    # the manual's name of a parameter ("Motor Current"; "" where the tables do not name it),
    # as its values carry it once read: surfaces show a value under it before the first read
    title_of: Callable[[ParameterKey], str]
    # Hz settings that cap the output frequency: a restore keeps them within the drive's
    # configured max_frequency_hz unless forced.
    frequency_ceilings: frozenset[str] = frozenset()
    # (low, high) in the parameter's unit, from the manuals, where a restore should know a
    # drive's range before it writes (the drive would refuse the value mid-restore).
    ranges: tuple[tuple[str, float, float], ...] = ()

    @classmethod
    def of(
        cls,
        tables: ModuleType,
        unit_of: Callable[[ParameterKey], str],
        title_of: Callable[[ParameterKey], str],
    ) -> ParameterTables:
        """The tables of a vendor's ``parameters`` module, where every vendor names them alike."""
        return cls(
            set_members=tables.SET_MEMBERS,
            identity=tables.IDENTITY,
            identity_match=tables.IDENTITY_MATCH,
            changeable_while_running=tables.CHANGEABLE_WHILE_RUNNING,
            link_settings=tables.LINK_SETTINGS,
            unit_of=unit_of,
            title_of=title_of,
            frequency_ceilings=tables.FREQUENCY_CEILINGS,
            ranges=tables.SET_RANGES,
        )


@dataclass(slots=True, frozen=True)
class ExecutedControl:
    """Where a drive tells the command it executes, so adoption can take over a stop.

    A drive ramping down after a stop still reports itself running until its output
    reaches 0 Hz; only what it executes says it is stopping, not running at a new speed.
    """

    parameter: str  # read by a poll (FC: 16-00 Control Word)
    stopping: Callable[[int], Motion | None]  # its raw value → the stop it executes, or None


# A frame → its fields, JSON-ready; ``from_drive``: a reply rather than a request.
Describe = Callable[..., dict[str, Any]]


@dataclass(slots=True, frozen=True, kw_only=True)
class ProtocolSpec(Generic[OptionsT]):
    """Everything outside a vendor's package needs to know about its protocol."""

    name: str  # the config and CLI id: "danfoss-fc"
    manufacturer: str  # as a device registry shows it (Home Assistant discovery)
    # The options dataclass: one field per line key, each with the key's default.
    options: Callable[..., OptionsT]
    line_keys: tuple[LineKey, ...] = ()
    # A codec for a line with these options; per address, what 100 % reference means in Hz.
    new_codec: Callable[[OptionsT, Mapping[int, float]], DriveCodec]
    # Where each drive follows a profile of its own (modbus-rtu): a codec also given each
    # address's profile (a DrivePlan's ``profile``); None: ``new_codec`` serves every line.
    new_profiled_codec: (
        Callable[[OptionsT, Mapping[int, float], Mapping[int, object]], DriveCodec] | None
    ) = None
    factory: SerialSettings
    baudrates: tuple[int, ...]  # the rates the drives offer, fastest first
    parities: tuple[str, ...]  # the parities the drives offer, the factory one first
    # The response delay the protocol fixes for these options (Mitsubishi: the waiting
    # time plus the data check), or None where it is each drive's own setting (FC 8-35).
    fixed_response_delay_s: Callable[[OptionsT], float | None] = lambda _: None
    # Why an address outside the range cannot be used, beyond "outside 1-126" ("": no more
    # to say): ENC's broadcast addresses, its decimal addresses' two digits.
    address_hint: Callable[[OptionsT, int], str] = lambda _options, _address: ""
    status_bits: type[enum.IntFlag]  # the status word, bit by bit, as the manual names them
    parameters: ParameterTables
    describe: Describe  # `fcmaster decode`
    checksum_key: str  # the key of ``describe``'s result that says whether the check held
    # Frames written the manuals' way (``<ENQ>01…<CR>``) → bytes; None: hex only.
    parse_text: Callable[[str], bytes] | None = None
    # Acceleration and deceleration times a poll can read (confirmation deadlines of stops);
    # None where reading them needs more than a poll.
    ramp_parameters: tuple[str, str] | None = None
    # What a drive found running but not at its reference executes (a stop it ramps down
    # on, or motion); None where a poll cannot read it.
    executed_control: ExecutedControl | None = None
    diagnosis: DiagnosisParameters
    simulator: str  # "module:attribute" of its SimProtocol in the sim layer (see above)
    link_type: int  # its pcapng link type in captures (a private USER type, 147-162, or one
    # a dissector knows: see fcmaster.protocol.pcapng)
    # The drive's communication watchdog: its parameters, their values, what counts as off
    watchdog: WatchdogFacts
    # Option sets the doctor tries, in order, at a character format where the options'
    # defaults found no drive: drives that answer only to one of them must be set that way
    # on the line (FC: drives that know only the 1-31 address format). The keys named here
    # are the ones the doctor shows and compares with the config.
    fallback_options: tuple[OptionPairs, ...] = ()
    # The watchdog facts of a line with these options where they depend on them (Mitsubishi:
    # the port the drives are wired to); None: ``watchdog`` on every line.
    watchdog_for: Callable[[OptionsT], WatchdogFacts] | None = None
    # The watchdog facts of a drive with this profile (a DrivePlan's ``profile``) where its
    # protocol's drives each follow one (modbus-rtu); None: the line's.
    watchdog_of_profile: Callable[[object], WatchdogFacts | None] | None = None
    # The parameter tables of a drive on a line with these options and, where its protocol's
    # drives follow profiles, this profile (a DrivePlan's, or None: the line's); None:
    # ``parameters`` for every drive.
    parameters_for: Callable[[OptionsT, object], ParameterTables] | None = None

    def options_of(self, source: object = None) -> OptionsT:
        """This protocol's options as ``source`` has them.

        A key is read from ``source``'s attribute of the same name, else from its
        ``protocol_options`` pairs (where a ``LinePlan`` keeps the keys of protocols it has
        no field for); a key that ``source`` lacks (or every key, with no source) takes its
        default.
        """
        extra = dict(getattr(source, "protocol_options", ()))
        given = {
            k.name: getattr(source, k.name) if hasattr(source, k.name) else extra[k.name]
            for k in self.line_keys
            if hasattr(source, k.name) or k.name in extra
        }
        return self.options(**given)

    def codec(
        self,
        source: object = None,
        nominal_hz: Mapping[int, float] | None = None,
        profiles: Mapping[int, object] | None = None,
    ) -> DriveCodec:
        """A codec for a line whose options ``source`` carries (see :meth:`options_of`).

        ``profiles``: each address's drive profile, for a protocol that has them.
        """
        if self.new_profiled_codec is not None:
            return self.new_profiled_codec(
                self.options_of(source), nominal_hz or {}, profiles or {}
            )
        return self.new_codec(self.options_of(source), nominal_hz or {})

    def addresses(self, source: object = None) -> range:
        """The addresses a drive may have on a line with ``source``'s options."""
        return self.codec(source).addresses

    def response_delay_s(self, source: object = None) -> float | None:
        """The response delay the protocol fixes for ``source``'s options (None: none)."""
        return self.fixed_response_delay_s(self.options_of(source))

    def bad_address(self, source: object, address: int) -> str:
        """Why ``address`` cannot name a drive on this line ("" when it can)."""
        addresses = self.addresses(source)
        if address in addresses:
            return ""
        reason = f"{address} is outside {addresses.start}-{addresses.stop - 1}"
        hint = self.address_hint(self.options_of(source), address)
        return f"{reason}: {hint}" if hint else reason

    def parameters_of(self, source: object = None, profile: object = None) -> ParameterTables:
        """The parameter tables of a drive with ``profile`` on a line with ``source``'s options."""
        if self.parameters_for is None:
            return self.parameters
        return self.parameters_for(self.options_of(source), profile)

    def option_pairs(self, source: object = None) -> OptionPairs:
        """This protocol's options as ``source`` has them, as (line key, value) pairs."""
        options = self.options_of(source)
        return tuple((k.name, getattr(options, k.name)) for k in self.line_keys)

    def option_problems(self, pairs: OptionPairs, *, simulated: bool = False) -> list[str]:
        """What is wrong with ``pairs`` as this protocol's options, every problem at once.

        A key must be one of this protocol's line keys (with ``simulated``: one the
        simulated drives take) and its value one the key allows.
        """
        keys = {k.name: k for k in self.line_keys if k.simulated or not simulated}
        problems = []
        for name, value in pairs:
            key = keys.get(name)
            if key is None:
                what = "simulated " if simulated else ""
                problems.append(f"{self.name} {what}lines have no {name}")
            elif problem := key.problem(value):
                problems.append(f"{name} {problem}")
        return problems

    def probed_options(self, source: object = None) -> OptionPairs:
        """``source``'s values of the keys the doctor probes (those ``fallback_options`` name)."""
        probed = {name for pairs in self.fallback_options for name, _ in pairs}
        return tuple(pair for pair in self.option_pairs(source) if pair[0] in probed)

    def watchdog_of(self, source: object = None) -> WatchdogFacts:
        """The drives' watchdog facts on a line with ``source``'s options."""
        if self.watchdog_for is None:
            return self.watchdog
        return self.watchdog_for(self.options_of(source))

    def drive_watchdog(self, source: object, profile: object) -> WatchdogFacts:
        """The watchdog facts of a drive with ``profile`` on a line with ``source``'s options."""
        if self.watchdog_of_profile is not None:
            facts = self.watchdog_of_profile(profile)
            if facts is not None:
                return facts
        return self.watchdog_of(source)
