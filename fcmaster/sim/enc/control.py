"""Run control of a simulated ENC drive: command-12 frames in, motor commands out.

Theory of operation
-------------------
State: whether the drive was told to run or to jog, its direction, its set frequency (F0.01,
which "set the running frequency" and the run-with-frequency commands also change), a
latched fault code and whether its cause is still present, an emergency-stop latch, and the
communication watchdog. What the motor does follows from that state in :meth:`EncControl.
_command`, recomputed whenever an input changes; the :class:`~fcmaster.sim.motor.Motor`
integrates lazily in between.

Priority, highest first: a fault (output off at once); an emergency stop (output off at
once, until the next run or jog command); jog at the jog frequency; run at the set
frequency; otherwise a ramp stop. Ramps use F0.08/F0.09, counted from 0 Hz to the motor's
rated frequency as on the other simulated drives.

Who may command (§5 table 1): run-control frames are obeyed only while F0.02 (run command
channel) is 3, the serial port, and frames that set a frequency only while F0.00 (frequency
channel) is 3 too; otherwise the drive answers 30. ``DriveSettings.local`` sets F0.02 to 0
(keypad) at power-up. A tripped drive refuses run and jog (30) but obeys stop, emergency
stop and fault reset. A reset clears the fault only once its cause is gone; until then it
is refused.

Assumptions where the manuals are silent (§10):

* The emergency stop switches the output off at once; the manuals do not say whether it
  ramps. It is not a fault: a later run command starts the motor again.
* F2.16 (communication timeout) is armed by the first frame the drive accepts after power-up
  and fed by every frame it accepts since, broadcasts included. When it runs out the drive
  trips with fault 16, RS-485 communication fault (§1 guesses so), whose cause clears with
  the next accepted frame, so a reset then succeeds.
* The jog frequency's function code is not in our sources: the simulated drive jogs at
  :data:`JOG_HZ`.
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.enc.codes import FAULT_TEXTS, NO_FAULT
from fcmaster.protocol.enc.frame import RunControl
from fcmaster.sim.enc.parameters import (
    ACCELERATION,
    DECELERATION,
    DIGITAL_FREQUENCY,
    DIRECTION,
    FREQUENCY_CHANNEL,
    RUN_CHANNEL,
    SERIAL_CHANNEL,
    TIMEOUT,
    ParameterStore,
    refused,
)
from fcmaster.sim.motor import Mode, Motor, MotorCommand

JOG_HZ: Final = 5.0
COMMUNICATION_FAULT: Final = 16  # §7
_RUNS: Final = frozenset(
    (
        RunControl.RUN,
        RunControl.RUN_WITH_FREQUENCY,
        RunControl.FORWARD,
        RunControl.REVERSE,
        RunControl.FORWARD_WITH_FREQUENCY,
        RunControl.REVERSE_WITH_FREQUENCY,
    )
)
_JOGS: Final = frozenset((RunControl.JOG, RunControl.JOG_FORWARD, RunControl.JOG_REVERSE))
_SETS_FREQUENCY: Final = frozenset(
    (
        RunControl.SET_FREQUENCY,
        RunControl.RUN_WITH_FREQUENCY,
        RunControl.FORWARD_WITH_FREQUENCY,
        RunControl.REVERSE_WITH_FREQUENCY,
    )
)
_FORWARDS: Final = frozenset(
    (RunControl.FORWARD, RunControl.FORWARD_WITH_FREQUENCY, RunControl.JOG_FORWARD)
)
_REVERSES: Final = frozenset(
    (RunControl.REVERSE, RunControl.REVERSE_WITH_FREQUENCY, RunControl.JOG_REVERSE)
)


class EncControl:
    """Run commands, faults and the communication watchdog of one simulated ENC drive."""

    def __init__(self, parameters: ParameterStore, motor: Motor, now: float) -> None:
        """A drive just powered up at ``now``: stopped, no fault, watchdog not armed."""
        self._p = parameters
        self.motor = motor
        self.running = False  # told to run (not jog)
        self.jogging = False
        self.emergency = False  # emergency-stopped since the last run or jog command
        self.fault = NO_FAULT  # latched fault code (§7)
        self.undervoltage = False  # state-word bit 1, a warning short of a trip
        self._causes: set[int] = set()  # faults whose cause is still present
        self._heard_at: float | None = None  # last accepted frame; None: watchdog not armed
        self.refresh(now)

    # -- inputs ---------------------------------------------------------------------------

    @property
    def reverse(self) -> bool:
        """F0.03: the direction the next run takes (1 = reverse)."""
        return bool(self._p[DIRECTION])

    @property
    def set_hz(self) -> float:
        """F0.01: the frequency the drive runs at."""
        return self._p.value(DIGITAL_FREQUENCY)

    @property
    def accepts_control(self) -> bool:
        """Whether run-control frames from the bus are obeyed (F0.02 = serial port)."""
        return self._p[RUN_CHANNEL] == SERIAL_CHANNEL

    def heard(self, now: float) -> None:
        """A frame for this drive (or a broadcast) was accepted: feed the watchdog."""
        self.advance(now)
        self._heard_at = now
        self._causes.discard(COMMUNICATION_FAULT)

    def run_control(self, index: int, data: int | None, now: float) -> None:
        """Obey command 12 with ``index`` (§4.2); raise Refused as the drive answers it.

        The frame was accepted first, so :meth:`heard` has already brought the drive to ``now``.
        """
        action = RunControl(index)  # the drive checked the index with the frame
        if not self.accepts_control:
            raise refused("the run command channel (F0.02) is not the serial port")
        if action in _SETS_FREQUENCY:
            assert data is not None  # the drive checks the frame's length first
            if self._p[FREQUENCY_CHANNEL] != SERIAL_CHANNEL:
                raise refused("the frequency channel (F0.00) is not the serial port")
        if self.fault and (action in _RUNS or action in _JOGS):
            raise refused(f"tripped with fault {self.fault}: reset first")
        if action in _SETS_FREQUENCY:
            # Beyond the upper limit is refused whole, never clamped (§4.2, §9).
            self._p.set(DIGITAL_FREQUENCY, data or 0, running=False)
        if action in _FORWARDS or action in _REVERSES:
            self._p.set(DIRECTION, int(action in _REVERSES), running=False)
        if action in _RUNS:
            self.running, self.jogging, self.emergency = True, False, False
        elif action in _JOGS:
            self.jogging, self.emergency = True, False
        elif action is RunControl.STOP_JOG:
            self.jogging = False
        elif action is RunControl.STOP:
            self.running = self.jogging = False
        elif action is RunControl.EMERGENCY_STOP:
            self.running = self.jogging = False
            self.emergency = True
        elif action is RunControl.FAULT_RESET:
            if self.fault in self._causes:
                raise refused(f"fault {self.fault} is still present")
            self.fault = NO_FAULT
        self.refresh(now)

    def raise_fault(self, code: int, now: float) -> None:
        """Trip with fault ``code`` (§7); its cause stays until :meth:`clear_fault`."""
        if code not in FAULT_TEXTS:
            raise UsageError(f"no ENC fault {code} (§7 lists {sorted(FAULT_TEXTS)})")
        self.advance(now)
        self._trip(code, now)
        self._causes.add(code)

    def clear_fault(self, code: int, now: float) -> None:
        """The cause of fault ``code`` is gone; a reset may now clear the trip."""
        self.advance(now)
        self._causes.discard(code)

    def refresh(self, now: float) -> None:
        """Recompute what the motor does after an input or a parameter changed."""
        self.motor.set_command(self._command(), now)

    # -- time -----------------------------------------------------------------------------

    def advance(self, now: float) -> None:
        """Bring the motor up to ``now``, tripping on the communication timeout on the way."""
        timeout_s = self._p.value(TIMEOUT)
        if self._heard_at is not None and timeout_s > 0 and not self.fault:
            deadline = self._heard_at + timeout_s
            if deadline <= now:
                self.motor.advance(deadline)
                self._trip(COMMUNICATION_FAULT, deadline)
                self._causes.add(COMMUNICATION_FAULT)  # until a frame is heard again
        self.motor.advance(now)

    def _trip(self, code: int, at: float) -> None:
        if not self.fault:
            self.fault = code
        self.running = self.jogging = False
        self.motor.set_command(self._command(), at)

    # -- outputs --------------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        """What command 10 calls "ready": not tripped."""
        return not self.fault

    def _command(self) -> MotorCommand:
        p = self._p
        mode, wanted = Mode.STOP, 0.0
        if self.fault or self.emergency:
            mode = Mode.OFF
        elif self.jogging:
            mode, wanted = Mode.RUN, min(JOG_HZ, p.upper_limit_hz)
        elif self.running:
            mode, wanted = Mode.RUN, self.set_hz
        return MotorCommand(
            mode=mode,
            target_hz=-wanted if self.reverse else wanted,
            ramp_up_s=p.value(ACCELERATION),
            ramp_down_s=p.value(DECELERATION),
            quick_stop_s=p.value(DECELERATION),
        )
