"""What the rest of the house knows about the ENC free protocol (see protocol/spec.py)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.enc import parameters
from fcmaster.protocol.enc.codec import EncCodec
from fcmaster.protocol.enc.describe import describe_frame
from fcmaster.protocol.enc.frame import BROADCAST
from fcmaster.protocol.enc.parameters import StateWord
from fcmaster.protocol.enc.watchdog import WATCHDOG
from fcmaster.protocol.mitsubishi.notation import parse_ascii_frame
from fcmaster.protocol.spec import (
    DiagnosisParameters,
    LineKey,
    ParameterTables,
    ProtocolSpec,
    SerialSettings,
)


@dataclass(slots=True, frozen=True)
class EncOptions:
    """How an ENC line's drives write addresses ≥ 10, response codes and fault codes.

    protocols/enc.md §10 questions 1, 2 and 7; replies are read in either encoding.
    """

    address_encoding: str = "hex"  # hex | decimal
    response_encoding: str = "hex"
    fault_encoding: str = "hex"


def _codec(options: EncOptions, nominal_hz: Mapping[int, float]) -> DriveCodec:
    return EncCodec(
        address_encoding=options.address_encoding,
        response_encoding=options.response_encoding,
        fault_encoding=options.fault_encoding,
        # ENC frames carry frequencies in Hz: the drive's nominal says what 100 % is.
        nominal_hz=dict(nominal_hz),
    )


def _address_hint(options: EncOptions, address: int) -> str:
    if address in (0, BROADCAST):
        # F2.15 allows 0-127, but fcmaster sends its broadcasts to 127 and means broadcast
        # by address 0 between its layers, so neither can name one drive.
        return "set the drive's F2.15 to another address (0 and 127 are broadcast)"
    if options.address_encoding == "decimal":
        return "with address_encoding decimal an address has two decimal digits"
    return ""


def _encoding(what: str) -> LineKey:
    return LineKey(
        name=f"{what}_encoding",
        default="hex",
        choices=("hex", "decimal"),
        help=f"how the drives write {what} numbers (default hex)",
        simulated=True,
    )


SPEC: Final[ProtocolSpec[EncOptions]] = ProtocolSpec(
    name="enc",
    manufacturer="ENC",
    options=EncOptions,
    line_keys=(_encoding("address"), _encoding("response"), _encoding("fault")),
    new_codec=_codec,
    factory=SerialSettings(9600, "N", 1),  # F2.14 = 03
    baudrates=(38400, 19200, 9600, 4800, 2400, 1200),  # F2.14
    parities=("N", "E", "O"),  # F2.14
    address_hint=_address_hint,
    status_bits=StateWord,
    parameters=ParameterTables.of(
        parameters,
        lambda key: parameters.lookup(key.code).unit,
        lambda key: parameters.lookup(key.code).name,
    ),
    describe=describe_frame,
    checksum_key="checksum_ok",
    parse_text=parse_ascii_frame,
    ramp_parameters=("F0.08", "F0.09"),
    diagnosis=DiagnosisParameters(
        address="F2.15", baudrate="F2.14", parity="F2.14", delay="F2.17", factory_delay_s=0.005
    ),
    link_type=149,  # pcapng USER2
    simulator="fcmaster.sim.enc.simulator:SIMULATOR",
    watchdog=WATCHDOG,
)
