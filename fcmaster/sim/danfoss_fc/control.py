"""The FC profile's control logic of a simulated drive: control word in, status word out.

Theory of operation
-------------------
State: the last *valid* control word and reference (CTW bit 10 = 1; a word with bit 10 = 0
is ignored whole, reference included, so a monitor-only master never moves the motor),
the latched alarm word and the causes behind it, injected warnings, and the control-word
timeout. Everything the motor does follows from that state through :meth:`FcControl.
_command`, recomputed whenever an input changes; the :class:`~fcmaster.sim.motor.Motor`
integrates lazily in between.

Priority, highest first (protocols/danfoss-fc.md §8.1): a trip (output off); the 8-04
action while the control word has timed out; bit 3 = 0 coast; bit 2 = 0 DC brake (modelled
as an immediate stop); bit 4 = 0 quick stop on 3-81; bit 8 jog at 3-19; bit 6 = 0 ramp stop;
bit 5 = 0 freeze; otherwise run at the reference. Bit 9 picks ramp 2 (3-51/3-52), bit 15
reverses. Bit 7 resets on its 0 → 1 edge between valid words: latched alarms whose cause is
gone clear, trip-lock alarms stay until :meth:`FcControl.power_cycle`. Preset-reference bits
0-1 select a 3-10 preset that the factory setting leaves at 0 %, so the bus reference
alone counts; set-up and relay bits have no effect.

Assumptions where the manual is silent (§11 [U]): only valid control words feed the
timeout, and the timeout is armed by the first valid word after power-up, so a drive that
was only ever monitored never times out. The reference maps linearly from 0 % = 3-02 to
100 % = 3-03; a negative result runs in reverse, as with 3-00 = −Max…+Max; the magnitude
is held between 4-12 and 4-14.

Control-word timeout (8-03/8-04): when 8-03 passes without a valid word and 8-04 ≠ Off, the
drive raises warning 17 and does what 8-04 says — freeze, stop, jog, max speed, or "stop and
trip", which ramps down and then trips with alarm 17. A valid word ends the timeout.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc.profile import (
    REFERENCE_MAX_PCT,
    REFERENCE_MIN_PCT,
    ControlWord,
    StatusWord,
    decode_reference,
    encode_reference,
)
from fcmaster.protocol.danfoss_fc.words import ALARM_WORD, WARNING_WORD
from fcmaster.sim.danfoss_fc.parameters import ParameterStore
from fcmaster.sim.motor import Mode, Motor, MotorCommand

_CW = ControlWord
ALARM_BITS: Final = {number: 1 << bit for bit, (number, _) in ALARM_WORD.items() if number}
WARNING_BITS: Final = {number: 1 << bit for bit, (number, _) in WARNING_WORD.items() if number}
TRIP_LOCK_ALARMS: Final = frozenset(
    {14, 16, 33, 38}
)  # earth fault, short circuit, inrush, internal
CW_TIMEOUT: Final = 17  # alarm and warning number
_VOLTAGE: Final = ALARM_BITS[7] | ALARM_BITS[8]
_VOLTAGE_WARNINGS: Final = WARNING_BITS[5] | WARNING_BITS[6] | WARNING_BITS[7] | WARNING_BITS[8]
_TORQUE_WARNINGS: Final = WARNING_BITS[12] | WARNING_BITS[13] | WARNING_BITS[59]
_THERMAL_WARNINGS: Final = WARNING_BITS[9] | WARNING_BITS[10] | WARNING_BITS[11]
ALARM_LOG_LENGTH: Final = 10

# 8-04 options
_FREEZE, _STOP, _JOG, _MAX_SPEED, _STOP_AND_TRIP = 1, 2, 3, 4, 5


class FcControl:
    """Control word, alarms, warnings and timeout of one simulated FC drive."""

    def __init__(
        self, parameters: ParameterStore, motor: Motor, now: float, *, local: bool = False
    ) -> None:
        """A drive just powered up at ``now``: stopped, no valid control word seen."""
        self._p = parameters
        self.motor = motor
        self.local = local  # hand operation: bus control words are ignored
        self.control_word = 0  # last valid CTW, as 16-00 shows it
        self.reference_pct = 0.0
        self.alarm_word = 0  # latched trips (16-90)
        self.trip_locked = False
        self.warnings = 0  # injected warning bits
        self.timed_out = False
        self.alarm_log: deque[tuple[int, float]] = deque(maxlen=ALARM_LOG_LENGTH)  # newest first
        self._causes = 0  # alarm bits whose cause is still present
        self._valid_at: float | None = None  # last valid control word; None: timeout not armed
        self._timed_out_at = 0.0
        self._trip_when_stopped = False

    # -- inputs ---------------------------------------------------------------------------

    def apply(self, ctw: int, reference: int, now: float) -> None:
        """A control word and reference from the bus, at ``now``."""
        self.advance(now)
        if not ctw & _CW.DATA_VALID or self.local:
            return
        if self.timed_out:
            self.timed_out = self._trip_when_stopped = False
        self._causes &= ~ALARM_BITS[CW_TIMEOUT]
        previous, self.control_word = self.control_word, ctw
        self.reference_pct = decode_reference(reference)
        self._valid_at = now
        if ctw & _CW.RESET and not previous & _CW.RESET:
            self.reset(now)
        self.refresh(now)

    def reset(self, now: float) -> None:
        """Clear latched alarms whose cause is gone (not a trip lock)."""
        self.advance(now)
        if not self.trip_locked:
            self.alarm_word &= self._causes
        self.refresh(now)

    def raise_alarm(self, number: int, now: float, *, trip_lock: bool | None = None) -> None:
        """Trip with alarm ``number`` (its cause stays until :meth:`clear_alarm`)."""
        bit = _bit(ALARM_BITS, number, "alarm")
        self.advance(now)
        self._trip(bit, number, now)
        self._causes |= bit
        self.trip_locked |= number in TRIP_LOCK_ALARMS if trip_lock is None else trip_lock
        self.refresh(now)

    def clear_alarm(self, number: int, now: float) -> None:
        """The cause of alarm ``number`` is gone; a reset may now clear the trip."""
        self.advance(now)
        self._causes &= ~_bit(ALARM_BITS, number, "alarm")

    def raise_warning(self, number: int, now: float) -> None:
        """Warning ``number`` becomes active."""
        self.advance(now)
        self.warnings |= _bit(WARNING_BITS, number, "warning")

    def clear_warning(self, number: int, now: float) -> None:
        """Warning ``number`` is no longer active."""
        self.advance(now)
        self.warnings &= ~_bit(WARNING_BITS, number, "warning")

    def power_cycle(self, now: float) -> None:
        """Mains off and on: trips (trip lock too) clear unless their cause is present."""
        self.advance(now)
        self.alarm_word = self._causes & ~ALARM_BITS[CW_TIMEOUT]
        self._causes = self.alarm_word
        self.trip_locked = any(self.alarm_word & ALARM_BITS[number] for number in TRIP_LOCK_ALARMS)
        self.control_word, self.reference_pct = 0, 0.0
        self._valid_at, self.timed_out, self._trip_when_stopped = None, False, False
        self.refresh(now)

    def refresh(self, now: float) -> None:
        """Recompute what the motor does after an input or a parameter changed."""
        if self.timed_out and not self._p[804]:
            self.timed_out = self._trip_when_stopped = False
        self.motor.set_command(self._command(), now)

    # -- time -----------------------------------------------------------------------------

    def advance(self, now: float) -> None:
        """Bring the motor up to ``now``, acting on a control-word timeout on the way."""
        deadline = self._timeout_deadline()
        if deadline is not None and deadline <= now:
            self.motor.advance(deadline)
            self.timed_out, self._timed_out_at = True, deadline
            self._trip_when_stopped = self._p[804] == _STOP_AND_TRIP
            self.motor.set_command(self._command(), deadline)
        self.motor.advance(now)
        if self._trip_when_stopped and not self.motor.output_on:
            self._trip_when_stopped = False
            at = max(self.motor.zero_at or now, self._timed_out_at)
            self._trip(ALARM_BITS[CW_TIMEOUT], CW_TIMEOUT, at)
            self._causes |= ALARM_BITS[CW_TIMEOUT]  # until valid control words come back
            self.motor.set_command(self._command(), now)

    def _timeout_deadline(self) -> float | None:
        if self._valid_at is None or self.timed_out or not self._p[804]:
            return None
        return self._valid_at + self._p.value(803)

    # -- outputs --------------------------------------------------------------------------

    @property
    def warning_word(self) -> int:
        """16-92: injected warnings, plus warning 17 while the control word has timed out."""
        return self.warnings | (WARNING_BITS[CW_TIMEOUT] if self.timed_out else 0)

    @property
    def reference_hz(self) -> float:
        """The reference in Hz, before direction and speed limits."""
        low, high = self._p.value(302), self._p.value(303)
        return low + self.reference_pct / 100.0 * (high - low)

    @property
    def at_speed_limit(self) -> bool:
        """Whether the output sits at 4-12/4-14 because the reference asks for more (or less)."""
        motor = self.motor
        if not motor.output_on or motor.command.mode is not Mode.RUN:
            return False
        wanted = abs(self._wanted_hz())
        limited = abs(motor.command.target_hz)
        return wanted != limited and abs(motor.frequency_hz) == limited

    @property
    def status_word(self) -> int:
        """The FC status word (§8.4) for the present state."""
        motor, ctw = self.motor, self.control_word
        word = StatusWord.CONTROL_READY
        if self.alarm_word:
            word |= StatusWord.TRIP_LOCK if self.trip_locked else StatusWord.TRIP
        else:
            word |= StatusWord.DRIVE_READY
            if ctw & _CW.NO_COAST or self._valid_at is None:
                word |= StatusWord.ENABLED
        warnings = self.warning_word
        if warnings:
            word |= StatusWord.WARNING
        if motor.output_on and motor.command.mode is Mode.RUN and not motor.is_ramping:
            word |= StatusWord.AT_REFERENCE
        if not self.local:
            word |= StatusWord.BUS_CONTROL
        if not self.at_speed_limit:
            word |= StatusWord.FREQUENCY_OK
        if motor.output_on:
            word |= StatusWord.RUNNING
        if self.alarm_word & _VOLTAGE or warnings & _VOLTAGE_WARNINGS:
            word |= StatusWord.VOLTAGE_EXCEEDED
        if warnings & _TORQUE_WARNINGS:
            word |= StatusWord.TORQUE_EXCEEDED
        if warnings & _THERMAL_WARNINGS:
            word |= StatusWord.TIMER_EXCEEDED
        return int(word)

    @property
    def main_actual_value(self) -> int:
        """MAV: the output frequency scaled like the reference (0x4000 = 3-03)."""
        low, high = self._p.value(302), self._p.value(303)
        pct = 0.0 if high == low else (self.motor.frequency_hz - low) / (high - low) * 100.0
        if not self.motor.frequency_hz:
            pct = 0.0
        return encode_reference(min(max(pct, REFERENCE_MIN_PCT), REFERENCE_MAX_PCT))

    # -- internals ------------------------------------------------------------------------

    def _trip(self, bit: int, number: int, at: float) -> None:
        if not self.alarm_word & bit:
            self.alarm_log.appendleft((number, self.motor.operating_s + at - self.motor.updated_at))
        self.alarm_word |= bit

    def _wanted_hz(self) -> float:
        """Signed frequency the control word asks for, before speed limits."""
        ctw = self.control_word
        hz = self._p.value(319) if ctw & _CW.JOG else self.reference_hz
        return -hz if ctw & _CW.REVERSE else hz

    def _command(self) -> MotorCommand:
        p, ctw = self._p, self.control_word
        mode, wanted = Mode.RUN, self._wanted_hz()
        if self.alarm_word:
            mode = Mode.OFF
        elif self.timed_out and p[804] in (_FREEZE, _STOP, _JOG, _MAX_SPEED, _STOP_AND_TRIP):
            function = p[804]
            if function == _FREEZE:
                mode = Mode.HOLD
            elif function == _JOG:
                wanted = p.value(319)
            elif function == _MAX_SPEED:
                wanted = math.copysign(p.value(414), self.motor.frequency_hz or 1.0)
            else:
                mode = Mode.STOP
        elif self._valid_at is None:
            mode = Mode.STOP  # never commanded since power-up
        elif not ctw & _CW.NO_COAST or not ctw & _CW.NO_DC_BRAKE:
            mode = Mode.OFF
        elif not ctw & _CW.NO_QUICK_STOP:
            mode = Mode.QUICK_STOP
        elif ctw & _CW.JOG:
            pass
        elif not ctw & _CW.START:
            mode = Mode.STOP
        elif not ctw & _CW.NO_FREEZE:
            mode = Mode.HOLD
        low, high = p.value(412), p.value(414)
        target = math.copysign(min(max(abs(wanted), low), high), wanted)
        ramp_2 = bool(ctw & _CW.RAMP_2)
        return MotorCommand(
            mode=mode,
            target_hz=target,
            ramp_up_s=p.value(351 if ramp_2 else 341),
            ramp_down_s=p.value(352 if ramp_2 else 342),
            quick_stop_s=p.value(381),
        )


def _bit(table: dict[int, int], number: int, kind: str) -> int:
    try:
        return table[number]
    except KeyError:
        raise UsageError(f"no {kind} {number} in the FC {kind} word (16-9x)") from None
