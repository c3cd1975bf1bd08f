"""What a simulated Modbus drive does with the control words written to it.

Three kinds, as a profile's ``state_machine`` says (:class:`~fcmaster.protocol.modbus_rtu.
profile.StateMachine`):

* CiA 402 (IEC 61800-7-201): switch on disabled → 0x06 ready to switch on → 0x07 switched
  on → 0x0F operation enabled. A word out of sequence is ignored, as the real drive ignores
  it: 0x0F written to a drive that is switched on disabled leaves it there. 0x07 from
  operation enabled ramps to a stop (Altivar's disable operation); 0x06 from there cuts the
  output; bit 1 clear (disable voltage) coasts; bit 2 clear quick-stops; a fault reset acts
  on the rising edge of bit 7 once the fault's cause is gone.
* PROFIdrive / ABB Drives: switch-on inhibited → OFF1 off (…110) ready to switch on → OFF1
  on (…111) ready to run → bit 3 operation. A word with bit 10 clear (no remote command) is
  ignored; OFF2 (bit 1 clear) coasts, OFF3 (bit 2 clear) quick-stops, both to switch-on
  inhibited; OFF1 from operation ramps to a stop.
* Bit per command (Yaskawa, the Danfoss FC profile): a word equal to the last word of one of
  the profile's commands does that command; any other word is ignored.

A tripped drive stays tripped until reset, and ignores run words meanwhile.
"""

from __future__ import annotations

import enum

from fcmaster.protocol.modbus_rtu.profile import DriveProfile, StateMachine
from fcmaster.sim.motor import Mode


class State(enum.Enum):
    """Where the drive's control stands (the names are CiA 402's)."""

    SWITCH_ON_DISABLED = "switch_on_disabled"  # PROFIdrive: switch-on inhibited
    READY_TO_SWITCH_ON = "ready_to_switch_on"
    SWITCHED_ON = "switched_on"  # PROFIdrive: ready to run
    OPERATION_ENABLED = "operation_enabled"
    QUICK_STOP_ACTIVE = "quick_stop_active"
    FAULT = "fault"


# CiA 402 status word, bits 0-6, by state (bit 5 set: quick stop not active)
_CIA402_STATUS = {
    State.SWITCH_ON_DISABLED: 0x0040,
    State.READY_TO_SWITCH_ON: 0x0021,
    State.SWITCHED_ON: 0x0023,
    State.OPERATION_ENABLED: 0x0027,
    State.QUICK_STOP_ACTIVE: 0x0007,
    State.FAULT: 0x0008,
}
# PROFIdrive status word, bits 0-6: RDY_ON, RDY_RUN, RDY_REF, TRIPPED, OFF2 and OFF3
# inactive, switch-on inhibited
_PROFIDRIVE_STATUS = {
    State.SWITCH_ON_DISABLED: 0x0070,
    State.READY_TO_SWITCH_ON: 0x0031,
    State.SWITCHED_ON: 0x0033,
    State.OPERATION_ENABLED: 0x0037,
    State.QUICK_STOP_ACTIVE: 0x0010,
    State.FAULT: 0x0038,
}
_REMOTE = 0x0400  # PROFIdrive bit 10: control by the fieldbus
_REVERSE = 0x0800  # bit 11: reverse (SINAMICS, Altivar)


class Machine:
    """The control state of one simulated drive, driven by control-word writes."""

    def __init__(self, profile: DriveProfile) -> None:
        self.profile = profile
        self.state = State.SWITCH_ON_DISABLED
        self.mode = Mode.OFF  # what the output stage is told
        self.reverse = False
        self.jog = False
        self.fault = 0  # the fault code (0: none)
        self.cause_present = False
        self._last = 0

    @property
    def running(self) -> bool:
        """Whether the drive is commanded to turn the motor."""
        return self.mode is Mode.RUN

    def write(self, word: int) -> None:
        """The master wrote ``word`` to the control register."""
        last, self._last = self._last, word
        machine = self.profile.state_machine
        if machine is StateMachine.BITS:
            self._bits(word, last)
        elif machine is StateMachine.CIA402:
            self._cia402(word, last)
        else:
            self._profidrive(word, last)

    def trip(self, code: int) -> None:
        """A fault with ``code``; its cause stays until :meth:`clear`."""
        self.fault, self.cause_present = code, True
        self.state, self.mode = State.FAULT, Mode.OFF

    def clear(self) -> None:
        """The fault's cause is gone (a reset may now clear the fault)."""
        self.cause_present = False

    def status_bits(self) -> int:
        """The state part of the status word (the profile's named bits are added later)."""
        machine = self.profile.state_machine
        if machine is StateMachine.CIA402:
            return _CIA402_STATUS[self.state]
        if machine is StateMachine.PROFIDRIVE:
            return _PROFIDRIVE_STATUS[self.state]
        return 0

    def _reset(self) -> None:
        if self.state is State.FAULT and not self.cause_present:
            self.fault = 0
            self.state, self.mode = State.SWITCH_ON_DISABLED, Mode.OFF

    # ------------------------------------------------------------------ CiA 402

    def _cia402(self, word: int, last: int) -> None:
        if word & 0x80 and not last & 0x80:
            self._reset()
            return
        if self.state is State.FAULT:
            return
        self.reverse = bool(word & _REVERSE)
        running = self.state is State.OPERATION_ENABLED
        if not word & 0x02:  # disable voltage
            self._go(State.SWITCH_ON_DISABLED, Mode.OFF)
        elif not word & 0x04:  # quick stop
            self._go(
                State.QUICK_STOP_ACTIVE if running else State.SWITCH_ON_DISABLED, Mode.QUICK_STOP
            )
        elif not word & 0x01:  # shutdown
            if self.state is not State.QUICK_STOP_ACTIVE:
                self._go(State.READY_TO_SWITCH_ON, Mode.OFF)
        elif not word & 0x08:  # switch on / disable operation
            if self.state is State.READY_TO_SWITCH_ON:
                self._go(State.SWITCHED_ON, Mode.OFF)
            elif running:
                self._go(State.SWITCHED_ON, Mode.STOP)
        elif self.state in (State.SWITCHED_ON, State.QUICK_STOP_ACTIVE):  # enable operation
            self._go(State.OPERATION_ENABLED, Mode.RUN)
        if self.state is State.OPERATION_ENABLED:
            self.mode = Mode.STOP if word & 0x0100 else Mode.RUN  # bit 8: halt

    # ------------------------------------------------------------------ PROFIdrive

    def _profidrive(self, word: int, last: int) -> None:
        if word & 0x80 and not last & 0x80:
            self._reset()
        if self.state is State.FAULT or not word & _REMOTE:
            return
        self.reverse = bool(word & _REVERSE)
        if not word & 0x02:  # OFF2: coast
            self._go(State.SWITCH_ON_DISABLED, Mode.OFF)
        elif not word & 0x04:  # OFF3: emergency stop
            self._go(State.SWITCH_ON_DISABLED, Mode.QUICK_STOP)
        elif not word & 0x01:  # OFF1 active: ready to switch on; from operation a ramp stop
            stopping = self.state is State.OPERATION_ENABLED or self.mode is Mode.STOP
            self._go(State.READY_TO_SWITCH_ON, Mode.STOP if stopping else self.mode)
        elif self.state is State.READY_TO_SWITCH_ON or self.state is State.SWITCHED_ON:
            if word & 0x08:
                self._go(State.OPERATION_ENABLED, Mode.RUN)
            else:
                self._go(State.SWITCHED_ON, Mode.OFF)
        elif self.state is State.OPERATION_ENABLED and not word & 0x08:
            self._go(State.SWITCHED_ON, Mode.OFF)  # inhibit operation: output off

    # ------------------------------------------------------------------ bit per command

    def _bits(self, word: int, last: int) -> None:
        commands = self.profile.commands
        reset = commands.get("reset", ())
        if reset and word == reset[0] and last != word:
            self._reset()
            return
        if self.state is State.FAULT:
            return
        meaning = next((n for n, w in commands.items() if n != "reset" and w[-1] == word), None)
        if meaning in ("start", "start_reverse", "jog"):
            self.reverse, self.jog = meaning == "start_reverse", meaning == "jog"
            self._go(State.OPERATION_ENABLED, Mode.RUN)
        elif meaning == "stop":
            self._go(State.SWITCHED_ON, Mode.STOP)
        elif meaning == "coast":
            self._go(State.SWITCHED_ON, Mode.OFF)
        elif meaning == "quick_stop":
            self._go(State.SWITCHED_ON, Mode.QUICK_STOP)

    def _go(self, state: State, mode: Mode) -> None:
        self.state, self.mode = state, mode
