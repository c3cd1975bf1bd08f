"""What the rest of the house knows about Modbus RTU lines (see protocol/spec.py).

Each drive on the line follows a drive profile (its config's ``profile:``), which the line's
codec is given by address (``ProtocolSpec.new_profiled_codec``).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.modbus_rtu.codec import ModbusCodec
from fcmaster.protocol.modbus_rtu.describe import describe_frame
from fcmaster.protocol.modbus_rtu.parameter_tables import tables_of
from fcmaster.protocol.modbus_rtu.profile import DriveProfile
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.protocol.modbus_rtu.watchdog import WATCHDOG, profile_facts
from fcmaster.protocol.spec import (
    DiagnosisParameters,
    LineKey,
    ParameterTables,
    ProtocolSpec,
    SerialSettings,
)


@dataclass(slots=True, frozen=True)
class ModbusOptions:
    """The profile of a line's drives that name none of their own (None: each names one)."""

    profile: str | None = None


class StatusBit(enum.IntFlag):
    """The status word's bits by number: what each means is the drive profile's."""

    BIT_0 = 1 << 0
    BIT_1 = 1 << 1
    BIT_2 = 1 << 2
    BIT_3 = 1 << 3
    BIT_4 = 1 << 4
    BIT_5 = 1 << 5
    BIT_6 = 1 << 6
    BIT_7 = 1 << 7
    BIT_8 = 1 << 8
    BIT_9 = 1 << 9
    BIT_10 = 1 << 10
    BIT_11 = 1 << 11
    BIT_12 = 1 << 12
    BIT_13 = 1 << 13
    BIT_14 = 1 << 14
    BIT_15 = 1 << 15


def _codec(options: ModbusOptions, nominal_hz: Mapping[int, float]) -> DriveCodec:
    return _profiled(options, nominal_hz, {})


def _profiled(
    options: ModbusOptions, nominal_hz: Mapping[int, float], profiles: Mapping[int, object]
) -> DriveCodec:
    chosen = {a: p for a, p in profiles.items() if isinstance(p, DriveProfile)}
    default = None if options.profile is None else BUILT_IN[options.profile]
    return ModbusCodec(chosen, nominal_hz, default)


def _tables(options: ModbusOptions, profile: object) -> ParameterTables:
    """The set of a drive with ``profile`` (a DrivePlan's), else the line's ``profile``."""
    if not isinstance(profile, DriveProfile):
        profile = None if options.profile is None else BUILT_IN[options.profile]
    return tables_of(profile)


SPEC: Final[ProtocolSpec[ModbusOptions]] = ProtocolSpec(
    name="modbus-rtu",
    manufacturer="Modbus RTU drive",
    options=ModbusOptions,
    line_keys=(
        LineKey(
            name="profile",
            default=None,
            choices=tuple(BUILT_IN),
            nullable=True,
            help="the built-in drive profile of the line's drives that name none of their own",
            simulated=True,
        ),
    ),
    new_codec=_codec,
    new_profiled_codec=_profiled,
    # Serial Line V1.02 §2.5.1: even parity is the default; 19200 and 9600 must be offered.
    factory=SerialSettings(19200, "E", 1),
    baudrates=(115200, 57600, 38400, 19200, 9600, 4800, 2400, 1200),
    parities=("E", "N", "O"),
    status_bits=StatusBit,
    parameters=tables_of(None),
    parameters_for=_tables,
    describe=describe_frame,
    checksum_key="crc_ok",
    diagnosis=DiagnosisParameters(
        address="the drive's Modbus address parameter",
        baudrate="its baud rate parameter",
        parity="its parity parameter",
        delay="its response delay parameter",
        factory_delay_s=None,  # each make answers in its own time: 2 to over 20 ms
    ),
    link_type=250,  # pcapng RTAC_SERIAL: Wireshark decodes its payload as Modbus RTU
    simulator="fcmaster.sim.modbus_rtu.simulator:SIMULATOR",
    watchdog=WATCHDOG,
    watchdog_of_profile=profile_facts,
)
