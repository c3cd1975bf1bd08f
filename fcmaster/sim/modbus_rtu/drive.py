"""A simulated Modbus RTU drive that follows one drive profile.

It serves the registers its profile names: the control word (written words go to its
:class:`~fcmaster.sim.modbus_rtu.machine.Machine`), the reference, the status word, the
output frequency, the fault register, the monitored values and the watchdog registers, plus
any register preset in ``DriveSettings.parameters`` (``{"hr600": 30}``, raw values). Any
other register is answered with exception 02 (illegal data address), a write to a register
that is only read with 02 too, a request with a bad CRC not at all (Serial Line §2.5.1.2),
a broadcast (address 0) obeyed and not answered. After a parameter write it hears nothing
for its profile's ``pacing.after_write_s``, as the family's drives do.

Which profile: ``DriveSettings.profile`` (a built-in's name or a profile), else the line's
``profile`` (``fcmaster sim --profile``), else the built-ins in turn by address (1 ABB
Drives, 2 SINAMICS V20, 3 Altivar, 4 Yaskawa, 5 Danfoss, 6 ABB again, …), so ``fcmaster
sim --protocol modbus-rtu --addresses 1-5`` has one of each.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from fcmaster.errors import FcmasterError, MalformedReply, UsageError
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ
from fcmaster.protocol.modbus_rtu.exception_codes import ExceptionCode
from fcmaster.protocol.modbus_rtu.frame import (
    BROADCAST,
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    Request,
    Response,
    WriteSingle,
    Written,
    decode_request,
    encode_response,
)
from fcmaster.protocol.modbus_rtu.keys import key_register, parse_register
from fcmaster.protocol.modbus_rtu.profile import DriveProfile, Register, StateMachine
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.protocol.modbus_rtu.spec import SPEC
from fcmaster.sim.modbus_rtu.machine import Machine, State
from fcmaster.sim.motor import Mode, Motor, MotorCommand
from fcmaster.sim.settings import DriveSettings, LineSettings

FACTORY_DELAY_S: Final = 0.002
ORDER: Final = tuple(BUILT_IN)  # the built-ins in turn, by address
# Words in a fault text that name a lost link (EFB communication loss, CE MEMOBUS/Modbus
# communication error, control word timeout, USS/Modbus setpoint fault)
_LINK_WORDS: Final = ("communication", "control word timeout", "setpoint fault")


class Refused(FcmasterError):
    """A request answered with a Modbus exception."""

    def __init__(self, code: ExceptionCode) -> None:
        self.code = code
        super().__init__(code.name)


def profile_for(
    address: int, settings: DriveSettings, line: LineSettings | None = None
) -> DriveProfile:
    """The profile a simulated drive at ``address`` follows (the line's ``profile`` next)."""
    chosen = settings.profile
    if chosen is None and line is not None:
        chosen = SPEC.options_of(line).profile
    if isinstance(chosen, DriveProfile):
        return chosen
    if chosen is None:
        return BUILT_IN[ORDER[(address - 1) % len(ORDER)]]
    if not isinstance(chosen, str) or chosen not in BUILT_IN:
        raise UsageError(f"profile {chosen!r} is not a built-in ({', '.join(BUILT_IN)})")
    return BUILT_IN[chosen]


class ModbusSimDrive:
    """One simulated Modbus RTU drive (a :class:`~fcmaster.sim.line.SimDrive`)."""

    def __init__(
        self,
        address: int,
        settings: DriveSettings | None = None,
        *,
        now: float,
        line: LineSettings | None = None,
    ) -> None:
        """A drive powered up at ``now`` at ``address``, following its profile."""
        settings = settings or DriveSettings()
        self._address = address
        self.profile = profile_for(address, settings, line)
        self.settings = settings
        self.machine = Machine(self.profile)
        self.motor: Motor = settings.motor(settings.started_at(now))
        self.nominal_hz = (
            settings.reference_100_hz or settings.rating.frequency_hz or DEFAULT_NOMINAL_HZ
        )
        self.ramp_up_s = float(settings.parameters.get("ramp_up_s", 1.0))
        self.ramp_down_s = float(settings.parameters.get("ramp_down_s", 1.0))
        self.reference_hz = 0.0
        self.warning = False
        # Stored registers (written words), by (input, address).
        self.stored: dict[tuple[bool, int], int] = {}
        for register in self.profile.watchdog.registers:
            for offset in range(register.words):
                self.stored[(register.input, register.address + offset)] = 0
        for setting in self.profile.parameters:  # a factory-like 10 s (ramps, mostly)
            register = setting.register
            try:
                words = register.raw(10.0)
            except UsageError:
                words = (0,) * register.words
            for offset, word in enumerate(words):
                self.stored[(register.input, register.address + offset)] = word
        for name, value in settings.parameters.items():
            if name in ("ramp_up_s", "ramp_down_s"):
                continue
            register = key_register(parse_register(name))
            for offset, word in enumerate(register.raw(value)):
                self.stored[(register.input, register.address + offset)] = word
        self._control_word = 0
        self._heard_at: float | None = None
        # The profile's pacing: after a parameter write the drive hears nothing for a while
        # (a Yaskawa storing it); requests it missed are counted, for the tests.
        self._busy_until = -1.0
        self.unheard = 0
        self._char_s = (line or LineSettings()).char_bits / (line or LineSettings()).baudrate
        self._reference_words: tuple[int, ...] = (0,) * self.profile.reference.words
        if settings.running_hz:
            self._adopt_running(settings.running_hz, now)
        self._computed = self._computed_registers()

    @property
    def address(self) -> int:
        """The drive's Modbus address."""
        return self._address

    @property
    def response_delay_s(self) -> float:
        """How long the drive takes before it answers."""
        if self.settings.response_delay_s is not None:
            return self.settings.response_delay_s
        return FACTORY_DELAY_S

    # ------------------------------------------------------------------ the line

    def handle(self, frame: bytes, now: float) -> bytes | None:
        """Act on a request that ended at ``now``; return the answer, or None."""
        if frame[0] not in (BROADCAST, self._address):
            return None
        if now - len(frame) * self._char_s < self._busy_until:  # it began too soon
            self.unheard += 1
            return None
        try:
            request = decode_request(frame)
        except MalformedReply:
            return None  # a bad CRC or a frame that is no request: a server stays silent
        broadcast = request.address == BROADCAST
        if broadcast and isinstance(request, ReadRequest):
            return None
        self._watch(now)
        try:
            response = self._serve(request, now)
        except Refused as refusal:
            response = ExceptionReply(
                address=self._address, function=_function(request), code=refusal.code
            )
        else:
            self._paced(request, response, now)
        return None if broadcast else encode_response(response)

    def _serve(self, request: Request, now: float) -> Response:
        self._follow(now)
        if isinstance(request, ReadRequest):
            table_input = request.function is Function.READ_INPUT
            values = tuple(
                self._read(table_input, a, now)
                for a in range(request.start, request.start + request.count)
            )
            return Registers(address=self._address, function=request.function, values=values)
        if isinstance(request, WriteSingle):
            self._write(request.register, (request.value,), now)
            return WriteSingle(
                address=self._address, register=request.register, value=request.value
            )
        self._write(request.start, request.values, now)
        return Written(address=self._address, start=request.start, count=len(request.values))

    # ------------------------------------------------------------------ registers

    def _computed_registers(
        self,
    ) -> dict[tuple[bool, int], tuple[Register, int, Callable[[], float]]]:
        """Read-only registers: (input, address) → (register, word index, its value now)."""
        profile, motor = self.profile, self.motor
        sources: list[tuple[Register, Callable[[], float]]] = [
            (profile.status, lambda: float(self.status_word())),
            (profile.output_frequency, lambda: self._frequency_value(motor.frequency_hz)),
        ]
        if profile.fault_code is not None:
            sources.append((profile.fault_code, self._fault_value))
        for value in profile.values:
            sources.append((value.register, _reading(value.name, value.register, motor)))
        table: dict[tuple[bool, int], tuple[Register, int, Callable[[], float]]] = {}
        for register, source in sources:
            for offset in range(register.words):
                table[(register.input, register.address + offset)] = (register, offset, source)
        return table

    def _read(self, table_input: bool, address: int, now: float) -> int:
        profile = self.profile
        if not table_input and address == profile.control.address:
            return self._control_word
        reference = profile.reference
        if not table_input and reference.address <= address < reference.address + reference.words:
            return self._reference_words[address - reference.address]
        computed = self._computed.get((table_input, address))
        if computed is not None:
            register, offset, source = computed
            value = source()
            # An unsigned register holds a magnitude: a drive running in reverse shows its
            # direction in its status, not as a negative frequency (Yaskawa's 0024H).
            return register.raw(value if register.signed else abs(value))[offset]
        stored = self.stored.get((table_input, address))
        if stored is None:
            raise Refused(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        return stored

    def _write(self, start: int, words: tuple[int, ...], now: float) -> None:
        profile = self.profile
        for offset, word in enumerate(words):
            address = start + offset
            if address == profile.control.address:
                self._control_word = word
                if not self.settings.local:
                    self.machine.write(word)
            elif (
                profile.reference.address
                <= address
                < profile.reference.address + profile.reference.words
            ):
                index = address - profile.reference.address
                self._reference_words = tuple(
                    word if i == index else w for i, w in enumerate(self._reference_words)
                )
                self.reference_hz = self._hz(
                    profile.reference.value(self._reference_words), profile.reference
                )
            elif (False, address) in self.stored:
                self.stored[(False, address)] = word
            else:
                raise Refused(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        self._follow(now)

    def _paced(self, request: Request, response: Response, now: float) -> None:
        """After a parameter write, deaf for the profile's wait from the end of its answer."""
        wait = self.profile.pacing.after_write_s
        if not wait or isinstance(request, ReadRequest):
            return
        start = request.register if isinstance(request, WriteSingle) else request.start
        if (False, start) in self.stored:  # not the control word or the reference
            answer = len(encode_response(response)) * self._char_s
            self._busy_until = now + self.response_delay_s + answer + wait

    # ------------------------------------------------------------------ the drive

    def status_word(self) -> int:
        """The status word now: the state machine's bits and the profile's named bits."""
        machine, profile = self.machine, self.profile
        named = {
            "running": machine.state is State.OPERATION_ENABLED
            or (machine.mode is Mode.RUN and machine.profile.state_machine.value == "bits"),
            "fault": machine.state is State.FAULT,
            "warning": self.warning,
            "at_reference": machine.running and not self.motor.is_ramping,
            "remote": not self.settings.local,
            "ready": machine.state is not State.FAULT,
            "reverse": self.motor.frequency_hz < 0 or (machine.running and machine.reverse),
        }
        word = machine.status_bits()
        # A state machine's own bits (0-6) say ready, running and fault by its states.
        owned = 0 if profile.state_machine is StateMachine.BITS else 0x7F
        for name, bit in profile.status_bits.items():
            if named.get(name) and not owned >> bit & 1:
                word |= 1 << bit
        return word

    def raise_fault(self, code: int, now: float) -> None:
        """Trip with fault ``code`` (a bit-field fault register: the bit number).

        It stays until :meth:`clear_fault` and then a reset.
        """
        self.machine.trip(code)
        self._follow(now)

    def clear_fault(self, now: float) -> None:
        """The fault's cause is gone: a reset now clears it."""
        self.machine.clear()
        self._follow(now)

    def _watch(self, now: float) -> None:
        """The drive's own watchdog, as its registers set it: trip if the master fell silent.

        Judged when the drive next hears the master (lazily, as the motor runs); the fault's
        cause is gone at once, since the master is heard again, so a reset clears it.
        """
        heard, self._heard_at = self._heard_at, now
        watchdog = self.profile.watchdog
        if heard is None or not watchdog.registers or self.machine.state is State.FAULT:
            return
        values = [register.value(self._stored_words(register)) for register in watchdog.registers]
        setting = watchdog.setting(values)
        if setting.timeout_s is None or not setting.stops or now - heard <= setting.timeout_s:
            return
        self.motor.advance(heard + setting.timeout_s)
        self.machine.trip(self._communication_fault())
        self.machine.clear()
        self._follow(heard + setting.timeout_s)

    def _stored_words(self, register: Register) -> tuple[int, ...]:
        return tuple(
            self.stored.get((register.input, register.address + i), 0)
            for i in range(register.words)
        )

    def _communication_fault(self) -> int:
        """The profile's fault (or fault bit) for a lost link: the first whose text says so."""
        for code, text in self.profile.faults.items():
            if any(word in text.lower() for word in _LINK_WORDS):
                return code
        return 1

    def _fault_value(self) -> float:
        code = self.machine.fault
        register = self.profile.fault_code
        assert register is not None  # only asked where the profile has one
        raw = (1 << code if code else 0) if self.profile.fault_bits else code
        return raw * register.scale

    def _follow(self, now: float) -> None:
        """The motor follows what the control now asks."""
        machine = self.machine
        target = self.reference_hz
        if machine.reverse and "start_reverse" in self.profile.commands:
            target = -abs(target)
        if machine.jog:
            target = min(5.0, self.nominal_hz)
        self.motor.set_command(
            MotorCommand(
                mode=machine.mode,
                target_hz=target if machine.mode is Mode.RUN else 0.0,
                ramp_up_s=self.ramp_up_s,
                ramp_down_s=self.ramp_down_s,
                quick_stop_s=self.ramp_down_s / 2,
            ),
            now,
        )

    def _adopt_running(self, hz: float, now: float) -> None:
        """Found running at power-up, as a former master left it."""
        profile = self.profile
        self.reference_hz = abs(hz)
        self._reference_words = profile.reference.raw(self._reference_value(abs(hz)))
        for word in profile.commands["start"]:
            self._control_word = word
            self.machine.write(word)
        self.motor.frequency_hz = hz
        self.motor.output_on = True
        self._follow(now)

    def _hz(self, value: float, register: Register) -> float:
        return value * self.nominal_hz / 100 if register.unit == "%" else value

    def _reference_value(self, hz: float) -> float:
        register = self.profile.reference
        return hz / self.nominal_hz * 100 if register.unit == "%" else hz

    def _frequency_value(self, hz: float) -> float:
        register = self.profile.output_frequency
        return hz / self.nominal_hz * 100 if register.unit == "%" else hz


def _reading(name: str, register: Register, motor: Motor) -> Callable[[], float]:
    """What a monitored value shows, by its name (0 for a name the simulator does not know)."""
    words = name.lower()
    if "current" in words:
        return lambda: motor.current_a
    if "mains" in words:  # a six-pulse bridge's DC link is about 1.35 times the mains
        return lambda: motor.dc_link_v / 1.35
    if "voltage" in words:
        return lambda: motor.dc_link_v
    if "power" in words:
        return lambda: motor.power_kw
    if "torque" in words:
        if register.unit == "Nm":
            return lambda: motor.torque_fraction * motor.rating.torque_nm
        return lambda: motor.torque_fraction * 100
    if "thermal" in words:
        return lambda: motor.motor_thermal_pct
    return lambda: 0.0


def _function(request: Request) -> int:
    if isinstance(request, ReadRequest):
        return request.function
    return Function.WRITE_SINGLE if isinstance(request, WriteSingle) else Function.WRITE_MULTIPLE
