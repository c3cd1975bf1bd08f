"""Vendor-neutral physics of a drive and its motor: ramps, measured values and counters.

Theory of operation
-------------------
A :class:`Motor` is told what to do by a :class:`MotorCommand` (a mode, a signed target
frequency, ramp times) and integrates lazily: :meth:`Motor.advance` brings the state from
the last update to ``now`` in one go, so nothing runs between telegrams and everything is
deterministic in virtual time. Every vendor's simulated drive translates its own control
telegrams into commands and reads the results back in its own units.

Modes:

* ``OFF``: output switched off at once (coast, trip, never started). The motor free-wheels;
  the drive reports 0 Hz.
* ``STOP`` / ``QUICK_STOP``: ramp to 0 Hz with the ramp-down (or quick-stop) time, then
  switch the output off.
* ``HOLD``: keep the present output frequency (FC "freeze output").
* ``RUN``: ramp towards ``target_hz``; crossing zero decelerates with the ramp-down time
  and accelerates again with the ramp-up time.

Ramp times are, as on real drives, the time from 0 to the motor's rated frequency.

While the frequency changes the state is integrated in steps of at most ``_STEP_S`` (exact
for the frequency, close enough for energy and temperature); at a steady output one step
covers any interval exactly, so a drive left alone for an hour costs one step.

The electrical model is a V/f drive with a load torque that grows with the square of speed
(a pump or fan; ``load_exponent`` 0 gives constant torque), plus acceleration torque while
ramping up and regenerative torque while ramping down.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Final

_STEP_S: Final = 0.05
_ACCEL_TORQUE: Final = 0.25  # fraction of rated torque that ramping up adds
_DECEL_TORQUE: Final = -0.15  # and ramping down returns
_MAGNETISING: Final = 0.35  # no-load current as a fraction of rated current
_EFFICIENCY: Final = 0.95
_HEATSINK_RISE_C: Final = 40.0  # heatsink above ambient at rated current
_HEATSINK_TAU_S: Final = 180.0
_MOTOR_TAU_S: Final = 600.0


class Mode(enum.Enum):
    """What the output stage does (see the module docstring)."""

    OFF = "off"
    STOP = "stop"
    QUICK_STOP = "quick_stop"
    HOLD = "hold"
    RUN = "run"


@dataclass(slots=True, frozen=True, kw_only=True)
class MotorRating:
    """Name-plate data of the motor and the supply the drive sits on."""

    power_kw: float = 5.5
    voltage_v: float = 400.0
    frequency_hz: float = 50.0
    current_a: float = 11.0
    speed_rpm: float = 1450.0
    mains_v: float = 400.0
    ambient_c: float = 30.0

    @property
    def pole_pairs(self) -> int:
        """Pole pairs, from rated frequency and speed (1450 rpm at 50 Hz → 2)."""
        return max(1, round(60.0 * self.frequency_hz / self.speed_rpm))

    @property
    def torque_nm(self) -> float:
        """Rated torque."""
        return self.power_kw * 1000.0 / (2.0 * math.pi * self.speed_rpm / 60.0)


@dataclass(slots=True, frozen=True, kw_only=True)
class MotorCommand:
    """What the drive's control asks of the output stage."""

    mode: Mode = Mode.OFF
    target_hz: float = 0.0  # signed: negative is reverse
    ramp_up_s: float = 3.0
    ramp_down_s: float = 3.0
    quick_stop_s: float = 3.0


class Motor:
    """The output stage, the motor and its load, integrated lazily up to ``now``."""

    def __init__(
        self, rating: MotorRating, now: float, *, load: float = 0.7, load_exponent: float = 2.0
    ) -> None:
        """A motor at standstill, powered up at ``now``.

        Args:
            rating: name-plate data.
            now: the power-up time.
            load: load torque at rated speed as a fraction of rated torque.
            load_exponent: how load torque grows with speed (2 for pumps and fans).
        """
        self.rating = rating
        self.load = load
        self.load_exponent = load_exponent
        self.command = MotorCommand()
        self.frequency_hz = 0.0
        self.output_on = False
        self.heatsink_c = rating.ambient_c
        self.motor_thermal_pct = 0.0
        self.operating_s = 0.0
        self.running_s = 0.0
        self.energy_kwh = 0.0
        self.zero_at: float | None = now  # when the output last reached 0 Hz
        # An external interlock (run enable missing, safe torque off): the drive hears and
        # acknowledges run commands, but the output stays off.
        self.interlocked = False
        self._t = now

    @property
    def updated_at(self) -> float:
        """The time the state was last brought up to."""
        return self._t

    def set_command(self, command: MotorCommand, now: float) -> None:
        """Integrate up to ``now``, then follow ``command``."""
        self.advance(now)
        if self.interlocked and command.mode in (Mode.RUN, Mode.HOLD):
            command = MotorCommand(mode=Mode.OFF)
        self.command = command
        if command.mode in (Mode.RUN, Mode.HOLD):
            self.output_on = True
        elif command.mode is Mode.OFF:
            self._switch_off(now)

    def set_rating(self, rating: MotorRating, now: float) -> None:
        """New name-plate data (the drive only allows this while stopped)."""
        self.advance(now)
        self.rating = rating

    def set_load(self, load: float, now: float) -> None:
        """Change the load torque at rated speed (fraction of rated torque)."""
        self.advance(now)
        self.load = load

    def advance(self, now: float) -> None:
        """Integrate ramps, temperatures and counters up to ``now`` (earlier times are ignored)."""
        while True:
            goal, rate = self._ramp()
            ramping = rate is not None and goal != self.frequency_hz
            if not ramping and self.output_on and self._stops_at_zero() and not self.frequency_hz:
                self._switch_off(self._t)
            if ramping and rate == math.inf:  # a zero ramp time: there at once
                self.frequency_hz = goal
                continue
            if now <= self._t:
                return
            dt = now - self._t
            if ramping:
                assert rate is not None  # ramping implies a rate
                dt = min(dt, _STEP_S, abs(goal - self.frequency_hz) / rate)
            before = self.current_a, self.power_kw
            if ramping:
                assert rate is not None
                if rate * dt >= abs(goal - self.frequency_hz) * (1.0 - 1e-12):
                    self.frequency_hz = goal
                else:
                    self.frequency_hz += math.copysign(rate * dt, goal - self.frequency_hz)
            # Trapezoids: the mean of the step's two ends.
            self._integrate(dt, (before[0] + self.current_a) / 2, (before[1] + self.power_kw) / 2)
            self._t = now if dt == now - self._t else self._t + dt

    # -- measured values ------------------------------------------------------------------

    @property
    def is_ramping(self) -> bool:
        """Whether the output frequency is still changing."""
        goal, rate = self._ramp()
        return self.output_on and rate is not None and goal != self.frequency_hz

    @property
    def torque_fraction(self) -> float:
        """Motor torque as a fraction of rated torque (negative while braking)."""
        if not self.output_on:
            return 0.0
        speed = abs(self.frequency_hz) / self.rating.frequency_hz
        torque = self.load * speed**self.load_exponent if speed else 0.0
        goal, rate = self._ramp()
        if rate is not None and goal != self.frequency_hz:
            speeding_up = abs(goal) > abs(self.frequency_hz) and goal * self.frequency_hz >= 0
            torque += _ACCEL_TORQUE if speeding_up else _DECEL_TORQUE
        return torque

    @property
    def voltage_v(self) -> float:
        """Motor voltage: V/f up to rated frequency, with a small boost near standstill."""
        if not self.output_on:
            return 0.0
        ratio = min(1.0, abs(self.frequency_hz) / self.rating.frequency_hz)
        return self.rating.voltage_v * max(ratio, 0.02)

    @property
    def current_a(self) -> float:
        """Motor current: magnetising plus torque-producing, in quadrature."""
        if not self.output_on:
            return 0.0
        torque_current = self.torque_fraction * (1.0 - _MAGNETISING**2) ** 0.5
        return self.rating.current_a * math.hypot(_MAGNETISING, torque_current)

    @property
    def power_kw(self) -> float:
        """Electrical power drawn (negative while regenerating)."""
        speed = abs(self.frequency_hz) / self.rating.frequency_hz
        shaft = self.rating.power_kw * self.torque_fraction * speed
        return shaft / _EFFICIENCY if shaft >= 0 else shaft * _EFFICIENCY

    @property
    def speed_rpm(self) -> float:
        """Shaft speed, signed, with slip growing with torque."""
        rating = self.rating
        if not self.frequency_hz:
            return 0.0
        synchronous = 60.0 * self.frequency_hz / rating.pole_pairs
        rated_slip = 60.0 * rating.frequency_hz / rating.pole_pairs - rating.speed_rpm
        slip = rated_slip * self.torque_fraction  # negative while braking: above synchronous
        return synchronous - slip if self.frequency_hz > 0 else synchronous + slip

    @property
    def dc_link_v(self) -> float:
        """Rectified mains, sagging with load and rising while the motor feeds energy back."""
        peak = self.rating.mains_v * math.sqrt(2.0)
        return (
            peak
            - 25.0 * max(self.power_kw, 0.0) / self.rating.power_kw
            + 40.0 * (self.power_kw < 0)
        )

    # -- integration ----------------------------------------------------------------------

    def _ramp(self) -> tuple[float, float | None]:
        """The frequency heading for now and the ramp rate in Hz/s (None: not ramping)."""
        command, f = self.command, self.frequency_hz
        if command.mode is Mode.OFF or command.mode is Mode.HOLD or not self.output_on:
            return f, None
        nominal = self.rating.frequency_hz
        if command.mode is not Mode.RUN:
            quick = command.mode is Mode.QUICK_STOP
            return 0.0, _rate(nominal, command.quick_stop_s if quick else command.ramp_down_s)
        target = command.target_hz
        if f == 0.0 or ((f > 0) == (target > 0) and abs(target) >= abs(f)):
            return target, _rate(nominal, command.ramp_up_s)
        # Slowing down: to the target if it lies on this side of zero, else to zero first.
        goal = target if target != 0.0 and (target > 0) == (f > 0) else 0.0
        return goal, _rate(nominal, command.ramp_down_s)

    def _stops_at_zero(self) -> bool:
        mode = self.command.mode
        return mode is Mode.STOP or mode is Mode.QUICK_STOP

    def _switch_off(self, at: float) -> None:
        if self.output_on or self.frequency_hz:
            self.zero_at = at
        self.output_on = False
        self.frequency_hz = 0.0

    def _integrate(self, dt: float, current_a: float, power_kw: float) -> None:
        """Counters and first-order temperatures over ``dt`` at the given mean output."""
        current = current_a / self.rating.current_a
        power = power_kw
        self.operating_s += dt
        if self.output_on:
            self.running_s += dt
        if power > 0:
            self.energy_kwh += power * dt / 3600.0
        heatsink_target = self.rating.ambient_c + 5.0 + _HEATSINK_RISE_C * current**2
        self.heatsink_c += (heatsink_target - self.heatsink_c) * -math.expm1(-dt / _HEATSINK_TAU_S)
        thermal_target = 100.0 * current**2
        self.motor_thermal_pct += (thermal_target - self.motor_thermal_pct) * -math.expm1(
            -dt / _MOTOR_TAU_S
        )


def _rate(nominal_hz: float, ramp_s: float) -> float:
    return math.inf if ramp_s <= 0 else nominal_hz / ramp_s
