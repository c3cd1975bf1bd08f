"""What the rest of the house knows about the Mitsubishi computer link (see protocol/spec.py)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.mitsubishi import parameters
from fcmaster.protocol.mitsubishi.codec import MitsubishiCodec, answer_delay_s
from fcmaster.protocol.mitsubishi.describe import describe_frame
from fcmaster.protocol.mitsubishi.notation import parse_ascii_frame
from fcmaster.protocol.mitsubishi.profile import StatusBits
from fcmaster.protocol.mitsubishi.watchdog import DRIVE_PORTS, WATCHDOG, watchdog_for
from fcmaster.protocol.spec import (
    DiagnosisParameters,
    LineKey,
    ParameterTables,
    ProtocolSpec,
    SerialSettings,
)


@dataclass(slots=True, frozen=True)
class MitsubishiOptions:
    """A computer-link line's own settings, as its drives' Pr.124 and Pr.123 have them."""

    terminator: str = "cr"  # none | cr | crlf (Pr.124)
    # The waiting time each request carries, for drives at Pr.123 = 9999 (the factory
    # setting); None: requests leave it out because the drives' Pr.123 sets it.
    wait_time_ms: int | None = 0
    # The drives' port the line is wired to: the PU connector or the RS-485 terminals. Each
    # has its own communication settings and check (Pr.122 or Pr.336).
    drive_port: str = "pu"


def _codec(options: MitsubishiOptions, nominal_hz: Mapping[int, float]) -> DriveCodec:
    return MitsubishiCodec(
        terminator=options.terminator,
        wait_time_ms=options.wait_time_ms,
        # Frequencies travel in 0.01 Hz: the drive's nominal says what 100 % is.
        nominal_hz=dict(nominal_hz),
    )


def _response_delay_s(options: MitsubishiOptions) -> float:
    # The drives wait the waiting time, then check the data (up to 30 ms for a parameter),
    # so the reply deadline must allow for both.
    return answer_delay_s(options.wait_time_ms)


SPEC: Final[ProtocolSpec[MitsubishiOptions]] = ProtocolSpec(
    name="mitsubishi",
    manufacturer="Mitsubishi Electric",
    options=MitsubishiOptions,
    line_keys=(
        LineKey(
            name="terminator",
            default="cr",
            choices=("none", "cr", "crlf"),
            help="as the drives' Pr.124 (default cr)",
        ),
        LineKey(
            name="wait_time_ms",
            default=0,
            minimum=0,
            maximum=150,
            step=10,
            nullable=True,
            metavar="MS|none",
            help="the waiting time each request carries, 0-150 in steps of 10 "
            "(default 0); none when the drives' Pr.123 sets it",
        ),
        LineKey(
            name="drive_port",
            default="pu",
            choices=DRIVE_PORTS,
            help="the drives' port the line is wired to: pu (the PU connector, every model; "
            "its check is Pr.122) or terminals (the RS-485 terminals of A700/F700/800-series "
            "models; Pr.336) (default pu)",
            simulated=True,  # the simulated drives supervise that port's check
        ),
    ),
    new_codec=_codec,
    factory=SerialSettings(19200, "E", 2),  # Pr.118 / Pr.119 / Pr.120 defaults
    baudrates=(115200, 76800, 57600, 38400, 19200, 9600, 4800),  # Pr.118, 800 series
    parities=("E", "O", "N"),  # Pr.120
    fixed_response_delay_s=_response_delay_s,
    status_bits=StatusBits,
    parameters=ParameterTables.of(
        parameters,
        lambda key: parameters.resolve(key).unit,
        lambda key: parameters.resolve(key).name,
    ),
    describe=describe_frame,
    checksum_key="sum_ok",
    parse_text=parse_ascii_frame,
    # Pr.7/Pr.8 need a page selected first, which a poll cannot do: those drives use the
    # default confirmation deadline or confirm_s.
    ramp_parameters=None,
    diagnosis=DiagnosisParameters(
        address="Pr.117",
        baudrate="Pr.118",
        parity="Pr.120",
        delay="Pr.123",
        factory_delay_s=0.012,
    ),
    link_type=148,  # pcapng USER1
    simulator="fcmaster.sim.mitsubishi.simulator:SIMULATOR",
    watchdog=WATCHDOG,
    watchdog_for=lambda options: watchdog_for(options.drive_port),
)
