"""The simulated Mitsubishi drive's control: run command and frequency in, status out.

Theory of operation
-------------------
State: the operation mode (network, external, PU), the last run command (HFA/HF9 bits),
the set frequency in RAM and in EEPROM, a latched trip with the fault history, and the
communication check (Pr.122). What the motor does follows from that state through
:meth:`MitsubishiControl._command`, recomputed whenever an input changes; the
:class:`~fcmaster.sim.motor.Motor` integrates lazily in between.

Priority, highest first: a trip (output off); MRS (output stop: off, the motor coasts);
STF or STR alone: run forward or reverse at the set frequency, held between Pr.2 and Pr.1,
with no output below Pr.13 (starting frequency); anything else (neither, or both, as with
both terminals on): decelerate on Pr.8 and switch off at 0 Hz. Ramps are Pr.7/Pr.8 from 0
to Pr.20 (acceleration/deceleration reference frequency), as the manuals define them.

Status monitor (protocols/mitsubishi.md §10.1, factory terminal assignments): RUN while the
output is on; forward/reverse running by the output's direction; SU within Pr.41 (10 %) of
the set frequency; OL (stall prevention) while the motor is overloaded or an injected
warning is active; FU at or above Pr.42 (6 Hz); ABC1 and, in H79, bit 15 on a trip.

Communication check (Pr.122 on the PU connector, Pr.336 on the RS-485 terminals, §1.1): the
check of the port the drive is wired to (``port``), armed by the first request the drive
hears; when no request has come for the interval, the drive trips with E.PUE (PU connector)
or E.SER (terminals). The other port hears nothing, so its check never arms. 9999 switches
it off. 0 is
model dependent; here it is the E700 reading: the link works, but the drive trips as soon
as the link commands it (a run command), so 0 cannot protect a commanded motor.

Inverter reset (HFD): the trip clears, the output goes off, the run command and the link
parameter page are forgotten, the set frequency is the one stored in EEPROM again, and the
drive starts in the mode Pr.340 selects. The fault history survives.
"""

from __future__ import annotations

from typing import Final

from fcmaster.protocol.mitsubishi.parameters import SETTING_9999
from fcmaster.protocol.mitsubishi.profile import OperationMode, RunCommand, StatusBits
from fcmaster.sim.mitsubishi.parameters import ParameterStore
from fcmaster.sim.motor import Mode, Motor, MotorCommand

E_PUE: Final = 0xB1  # PU disconnection / communication errors / signal loss (§11)
E_SER: Final = 0xC6  # communication fault on the RS-485 terminals (§11)
# The port the link is wired to → its check time interval, its retry count and its trip.
PORT_CHECKS: Final = {"pu": (122, 121, E_PUE), "terminals": (336, 335, E_SER)}
HISTORY_LENGTH: Final = 8  # H74-H77: two faults per word
UP_TO_FREQUENCY: Final = 0.10  # Pr.41 factory setting: ±10 %
FREQUENCY_DETECTION_HZ: Final = 6.0  # Pr.42 factory setting
OVERLOAD_TORQUE: Final = 1.5  # fraction of rated torque where stall prevention acts


class MitsubishiControl:
    """Run command, set frequency, trips and the communication check of one drive."""

    def __init__(
        self,
        parameters: ParameterStore,
        motor: Motor,
        now: float,
        *,
        local: bool = False,
        port: str = "pu",
    ) -> None:
        """A drive powered up at ``now``; ``local`` keeps it out of network operation.

        ``port``: the port the link is wired to, ``pu`` or ``terminals`` (its check).
        """
        self.parameters = parameters
        self._check, self.retry_parameter, self.link_trip = PORT_CHECKS[port]
        self.motor = motor
        self.local = local
        self.run_bits = 0
        self.set_hz_eeprom = 0.0
        self.set_hz = 0.0  # RAM
        self.fault: int | None = None
        self.history: list[int] = []  # newest first
        self.warning = False  # an injected warning (stall prevention shown)
        self.mode = OperationMode.NETWORK
        self._heard_at: float | None = None  # the last request, once the check is armed
        self.power_up(now)

    # -- inputs ---------------------------------------------------------------------------

    def power_up(self, now: float) -> None:
        """The state after power-on or an inverter reset (see the module docstring)."""
        self.motor.set_command(MotorCommand(mode=Mode.OFF), now)
        self.run_bits = 0
        self.fault = None
        self.set_hz = self.set_hz_eeprom
        network = self.parameters[340] != 0 and not self.local
        self.mode = OperationMode.NETWORK if network else OperationMode.EXTERNAL
        self._heard_at = None

    def heard(self, now: float) -> None:
        """A request for this drive arrived: the communication check starts over."""
        self.advance(now)
        self._heard_at = now

    def advance(self, now: float) -> None:
        """Bring the motor and the communication check up to ``now``."""
        deadline = self._check_deadline()
        if deadline is not None and deadline <= now:
            self.trip(self.link_trip, deadline)
        self.motor.advance(now)

    def command(self, bits: int, now: float) -> None:
        """A run command (HFA/HF9 data)."""
        self.advance(now)
        self.run_bits = bits
        if self.parameters[self._check] == 0 and bits & (RunCommand.STF | RunCommand.STR):
            self.trip(self.link_trip, now)  # 0: no check allowed while the link commands
            return
        self._apply(now)

    def set_frequency(self, hz: float, now: float, *, eeprom: bool) -> None:
        """A running-frequency write (HED; HEE also keeps it through a reset)."""
        self.advance(now)
        self.set_hz = hz
        if eeprom:
            self.set_hz_eeprom = hz
        self._apply(now)

    def trip(self, code: int, now: float) -> None:
        """Trip with fault ``code``: output off, fault output on, the code in the history.

        A tripped drive does not trip again (one entry in the history per trip).
        """
        if self.fault is not None:
            return
        self.motor.set_command(MotorCommand(mode=Mode.OFF), now)
        self.fault = code
        self.history.insert(0, code)
        del self.history[HISTORY_LENGTH:]

    def refresh(self, now: float) -> None:
        """Ramp times or limits changed: follow them."""
        self.advance(now)
        self._apply(now)

    # -- outputs --------------------------------------------------------------------------

    def status(self, *, extended: bool) -> int:
        """H7A (8 bits) or H79 (16 bits) data."""
        motor = self.motor
        bits = StatusBits(0)
        if motor.output_on:
            bits |= StatusBits.RUN
            reverse = motor.frequency_hz < 0 or (
                not motor.frequency_hz and self._direction() == RunCommand.STR
            )
            bits |= StatusBits.REVERSE if reverse else StatusBits.FORWARD
            target = self._target_hz()
            if target and abs(abs(motor.frequency_hz) - target) <= UP_TO_FREQUENCY * target:
                bits |= StatusBits.SU
            if abs(motor.frequency_hz) >= FREQUENCY_DETECTION_HZ:
                bits |= StatusBits.FU
        if self.warning or motor.torque_fraction > OVERLOAD_TORQUE:
            bits |= StatusBits.OL
        if self.fault is not None:
            bits |= StatusBits.ABC1
            if extended:
                bits |= StatusBits.FAULT
        return int(bits) & (0xFFFF if extended else 0xFF)

    def fault_word(self, first: int) -> int:
        """H74-H77 data: faults ``first`` (bits 7-0) and ``first + 1`` (bits 15-8)."""
        newer = self.history[first] if first < len(self.history) else 0
        older = self.history[first + 1] if first + 1 < len(self.history) else 0
        return newer | older << 8

    # -- internals ------------------------------------------------------------------------

    def _check_deadline(self) -> float | None:
        interval = self.parameters[self._check]
        if interval in (SETTING_9999, 0) or self._heard_at is None:
            return None
        return self._heard_at + interval * 0.1

    def _direction(self) -> int:
        return self.run_bits & (RunCommand.STF | RunCommand.STR)

    def _target_hz(self) -> float:
        """The frequency a run command runs at: the set frequency within Pr.2…Pr.1."""
        p = self.parameters
        hz = min(max(self.set_hz, p.value(2)), p.value(1))
        return hz if hz >= p.value(13) else 0.0

    def _apply(self, now: float) -> None:
        self.motor.set_command(self._command(), now)

    def _command(self) -> MotorCommand:
        p = self.parameters
        scale = self.motor.rating.frequency_hz / p.value(20)
        ramps = {"ramp_up_s": p.value(7) * scale, "ramp_down_s": p.value(8) * scale}
        if self.fault is not None or self.run_bits & RunCommand.MRS:
            return MotorCommand(mode=Mode.OFF, **ramps)
        direction = self._direction()
        target = self._target_hz()
        if direction in (RunCommand.STF, RunCommand.STR) and target:
            signed = -target if direction == RunCommand.STR else target
            return MotorCommand(mode=Mode.RUN, target_hz=signed, **ramps)
        return MotorCommand(mode=Mode.STOP, **ramps)  # decelerate on Pr.8, then off
