"""What the rest of the house knows about the Danfoss FC protocol (see protocol/spec.py)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.danfoss_fc import parameters
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.describe import describe_telegram
from fcmaster.protocol.danfoss_fc.profile import StatusWord, executed_motion
from fcmaster.protocol.danfoss_fc.telegram import AddressFormat
from fcmaster.protocol.danfoss_fc.watchdog import WATCHDOG
from fcmaster.protocol.spec import (
    DiagnosisParameters,
    ExecutedControl,
    LineKey,
    ParameterTables,
    ProtocolSpec,
    SerialSettings,
)


@dataclass(slots=True, frozen=True)
class FcOptions:
    """An FC line's own setting: how telegrams write the address (§5.2)."""

    address_format: int = 126  # 31 | 126


def _codec(options: FcOptions, nominal_hz: Mapping[int, float]) -> DriveCodec:
    # The main actual value is in % of each drive's nominal; replies carry Hz.
    return FcCodec(AddressFormat(options.address_format), nominal_hz=dict(nominal_hz))


SPEC: Final[ProtocolSpec[FcOptions]] = ProtocolSpec(
    name="danfoss-fc",
    manufacturer="Danfoss",
    options=FcOptions,
    line_keys=(
        LineKey(
            name="address_format",
            default=126,
            choices=(31, 126),
            help="how telegrams write the address, 1-31 or 1-126 (default 126)",
        ),
    ),
    new_codec=_codec,
    factory=SerialSettings(9600, "E", 1),  # 8-32 / 8-33 defaults
    baudrates=(115200, 76800, 57600, 38400, 19200, 9600, 4800, 2400),  # 8-32
    parities=("E", "O", "N"),  # 8-33
    # The response delay is each drive's own 8-35: the line's response_delay_ms says it.
    status_bits=StatusWord,
    parameters=ParameterTables.of(
        parameters,
        lambda key: parameters.lookup(key.code).unit,
        lambda key: parameters.lookup(key.code).name,
    ),
    describe=describe_telegram,
    checksum_key="bcc_ok",
    ramp_parameters=("3-41", "3-42"),
    executed_control=ExecutedControl("16-00", executed_motion),
    diagnosis=DiagnosisParameters(
        address="8-31", baudrate="8-32", parity="8-33", delay="8-35", factory_delay_s=0.010
    ),
    link_type=147,  # pcapng USER0
    simulator="fcmaster.sim.danfoss_fc.simulator:SIMULATOR",
    watchdog=WATCHDOG,
    # Older drives (and some gateways) know only the 1-31 address format and ignore 126's.
    fallback_options=((("address_format", 31),),),
)
