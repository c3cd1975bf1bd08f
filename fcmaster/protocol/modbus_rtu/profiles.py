"""The built-in drive profiles, one per family, with the manual pages they came from.

Each profile's ``sources`` names the manual and page of its facts; what could not be checked
against a manual page is listed in its ``unverified`` and should be confirmed on a real drive
before it is relied on. Every profile is checked by :func:`~.profile.checked` when this
module is imported, so a broken built-in cannot ship.
"""

from __future__ import annotations

from typing import Final

from fcmaster.protocol.danfoss_fc.watchdog import WATCHDOG as FC_WATCHDOG
from fcmaster.protocol.danfoss_fc.words import ALARM_WORD
from fcmaster.protocol.modbus_rtu.profile import (
    DriveProfile,
    Pacing,
    Register,
    StateMachine,
    Value,
    WatchdogProfile,
    checked,
)

# ------------------------------------------------------------------ ABB Drives profile

_ABB_MANUALS = (
    "ACS850 Firmware Manual, 'Control through the embedded fieldbus interface', p. 329: "
    "ABB Drives classic register map 400001 CW, 400002 REF1, 400004 SW, 400005 ACT1; "
    "16-bit parameter registers 400000 + 100 × group + index",
    "ACS880 Firmware Manual, parameters p. 435: 58.14 Communication loss action (3 speed "
    "ref safe, 4 fault always, 5 warning), 58.15 Communication loss mode (1 any message, "
    "2 Cw/Ref1/Ref2), 58.16 Communication loss time (default 3.0 s), fault 6681 EFB "
    "communication loss",
    "ACS380 Firmware Manual, EFB chapter p. 425: 58.25 Control profile 0 = ABB Drives, "
    "58.33 Addressing mode",
)

ABB_DRIVES: Final = DriveProfile(
    name="abb-drives",
    title="ABB drives with the embedded fieldbus (ACS380/480/580/880), ABB Drives profile",
    state_machine=StateMachine.PROFIDRIVE,
    control=Register(address=0),  # 400001
    reference=Register(address=1, scale=100 / 20000, unit="%", signed=True),  # 400002 REF1
    status=Register(address=3),  # 400004
    output_frequency=Register(address=4, scale=100 / 20000, unit="%", signed=True),  # ACT1
    fault_code=Register(address=400),  # 04.01 Tripping fault (400401)
    commands={
        # bit 10 REMOTE_CMD and bits 4-6 (ramp out/hold/in zero released) set in every word
        "start": (0x047E, 0x047F),  # OFF1 off → ready to switch on; on + enable operation
        "stop": (0x047E,),  # OFF1: ramp stop
        "coast": (0x047D,),  # OFF2 active: coast
        "quick_stop": (0x047B,),  # OFF3 active: emergency ramp
        "reset": (0x04FE, 0x047E),  # bit 7 RESET on its rising edge, then back
    },
    status_bits={
        "ready": 0,  # RDY_ON
        "running": 2,  # RDY_REF: operation enabled
        "fault": 3,  # TRIPPED
        "warning": 7,  # ALARM
        "at_reference": 8,  # AT_SETPOINT
        "remote": 9,  # REMOTE
    },
    faults={
        2310: "Overcurrent",
        2330: "Earth leakage",
        2340: "Short circuit",
        3130: "Input phase loss",
        3210: "DC link overvoltage",
        3220: "DC link undervoltage",
        3381: "Output phase loss",
        4110: "Control board temperature",
        4210: "IGBT overtemperature",
        4310: "Excess temperature",
        5091: "Safe torque off",
        6681: "EFB communication loss",
        7121: "Motor stall",
        7122: "Motor overload",
        9081: "External fault 1",
    },
    watchdog=WatchdogProfile(
        timeout=Register(address=5815, scale=0.1, unit="s"),  # 58.16 (405816)
        action=Register(address=5813),  # 58.14 (405814)
        actions={
            0: ("no action", False),
            1: ("fault", True),
            2: ("last speed", False),
            3: ("safe speed", False),
            4: ("fault always", True),
            5: ("warning", False),
        },
    ),
    values=(
        Value(name="Motor current", register=Register(address=106, scale=0.01, unit="A")),
        Value(
            name="Motor torque", register=Register(address=109, scale=0.1, unit="%", signed=True)
        ),
        Value(name="DC voltage", register=Register(address=110, scale=0.01, unit="V")),
    ),
    parameters=(
        Value(name="Acceleration time 1", register=Register(address=2311, scale=0.1, unit="s")),
        Value(name="Deceleration time 1", register=Register(address=2312, scale=0.1, unit="s")),
    ),
    sources=_ABB_MANUALS,
    unverified=(
        "The classic register map is the ACS850's; ACS580 with 58.33 = mode 0 is assumed the same",
        "REF1 and ACT1 scaling 20000 = 100 % of 46.01/46.02 (ABB Drives profile)",
        "Control words 0x047E/0x047F/0x047D/0x047B/0x04FE and status bit positions",
        "04.01 Tripping fault at register 400401; fault code texts other than 6681",
        "58.14 value 0 = no action, 1 = fault, 2 = last speed; 58.16 in 0.1 s units",
        "01.07, 01.10, 01.11 register scaling (FbEq16)",
        "23.12/23.13 at 402312/402313 (the xx.yy → 4xxyy rule of 58.14) and their 0.1 s scaling",
    ),
)

# ------------------------------------------------------------------ SINAMICS V20

_V20_MANUAL = "SINAMICS V20 Operating Instructions 07/2012, A5E03728167"

SINAMICS_V20: Final = DriveProfile(
    name="sinamics-v20",
    title="Siemens SINAMICS V20, Modbus RTU (P2023 = 2), command source P0700 = 5",
    state_machine=StateMachine.PROFIDRIVE,
    control=Register(address=99),  # 40100 control word (STW1)
    reference=Register(address=100, scale=100 / 0x4000, unit="%", signed=True),  # 40101 HSW
    status=Register(address=109),  # 40110 status word (ZSW1)
    output_frequency=Register(address=23, scale=0.01, unit="Hz", signed=True),  # 40024
    fault_code=Register(address=399),  # 40400, r0947[0]
    commands={
        "start": (0x047E, 0x047F),
        "stop": (0x047E,),  # OFF1
        "coast": (0x047D,),  # OFF2
        "quick_stop": (0x047B,),  # OFF3
        "reset": (0x04FE, 0x047E),  # bit 7 fault acknowledge
        "start_reverse": (0x0C7E, 0x0C7F),  # bit 11 reverse
    },
    status_bits={
        "ready": 0,
        "running": 2,  # operation enabled
        "fault": 3,
        "warning": 7,
        "at_reference": 8,
        "remote": 9,
    },
    faults={
        1: "F1 Overcurrent",
        2: "F2 Overvoltage",
        3: "F3 Undervoltage",
        4: "F4 Inverter overtemperature",
        5: "F5 Inverter I2t",
        6: "F6 Chip temperature exceeded",
        11: "F11 Motor overtemperature",
        12: "F12 Inverter temperature signal lost",
        20: "F20 DC ripple too high",
        35: "F35 Maximum automatic restart attempts",
        41: "F41 Motor data identification failure",
        51: "F51 Parameter EEPROM fault",
        52: "F52 Power stack fault",
        60: "F60 ASIC timeout",
        72: "F72 USS/Modbus setpoint fault (telegram off time)",
        85: "F85 External fault",
    },
    watchdog=WatchdogProfile(
        timeout=Register(address=0, scale=0.001, unit="s"),  # 40001 WDOG TIME, ms
        fixed_action="fault F72",
    ),
    values=(
        Value(name="Output current", register=Register(address=25, scale=0.01, unit="A")),
        Value(name="Torque", register=Register(address=26, scale=0.01, unit="Nm", signed=True)),
        Value(name="Actual power", register=Register(address=27, scale=0.01, unit="kW")),
        Value(name="DC bus voltage", register=Register(address=29, unit="V")),
    ),
    sources=(
        f"{_V20_MANUAL}, §6.2 p. 111: P2014 telegram off time (0 = no fault: watchdog off), "
        "P2021 address, P2023 = 2 Modbus, P0700 = 5, exception codes",
        f"{_V20_MANUAL}, §6.2 p. 112: register table 40001 WDOG TIME (ms), 40002 WDOG ACTION, "
        "40003 FREQ REF, 40024 FREQ OUTPUT (Hz, ×100), 40026 CURRENT (A, ×100), 40027 TORQUE "
        "(Nm, ×100), 40028 ACTUAL PWR (kW, ×100), 40030 DC BUS VOLTS (V); registers 40100 ...",
        "SINAMICS G130/G150 Operating Instructions 07/2016, Modbus TCP register tables: 40100 "
        "control word, 40110 status word (the same PZD layout)",
    ),
    unverified=(
        "40101 main setpoint scaling 0x4000 = 100 % of P2000",
        "40001 WDOG TIME being P2014 and its action being fault F72",
        "40400 holding r0947[0] (the last fault number)",
        "Fault texts: from the V20 fault list, not checked page by page",
        "Status bit positions (PROFIdrive ZSW1) and reverse as control bit 11",
        "40025 SPEED sits between FREQ OUTPUT and CURRENT, so CURRENT is 40026",
    ),
)

# ------------------------------------------------------------------ Altivar, CiA 402

ALTIVAR_CIA402: Final = DriveProfile(
    name="altivar-cia402",
    title="Schneider Altivar (ATV320/340/600/900) with the CiA 402 profile (CHCF = SIM or SEP)",
    state_machine=StateMachine.CIA402,
    control=Register(address=8501),  # CMD
    reference=Register(address=8502, scale=0.1, unit="Hz", signed=True),  # LFR
    status=Register(address=3201),  # ETA
    output_frequency=Register(address=3202, scale=0.1, unit="Hz", signed=True),  # RFR
    fault_code=Register(address=7121),  # LFT
    commands={
        "start": (0x0006, 0x0007, 0x000F),  # shutdown, switch on, enable operation
        "stop": (0x0007,),  # disable operation: stop on the configured stop type
        "coast": (0x0000,),  # disable voltage
        "quick_stop": (0x0002,),  # quick stop
        "reset": (0x0080, 0x0000),  # fault reset on its rising edge
        "start_reverse": (0x0006, 0x0007, 0x080F),  # bit 11: reverse (Altivar-specific)
    },
    status_bits={
        "ready": 0,  # ready to switch on
        "running": 2,  # operation enabled
        "fault": 3,
        "warning": 7,
        "remote": 9,
        "at_reference": 10,  # target reached
        "reverse": 15,
    },
    faults={
        2: "EEF1 Control EEPROM",
        3: "CFF Incorrect configuration",
        4: "CFI Invalid configuration",
        5: "SLF1 Modbus communication interruption",
        6: "ILF Internal communication link",
        7: "CNF Fieldbus communication interruption",
        8: "EPF1 External fault",
        9: "OCF Overcurrent",
        10: "CRF1 Precharge",
        16: "OHF Drive overheat",
        17: "OLF Motor overload",
        18: "OBF DC bus overvoltage",
        19: "OSF Supply overvoltage",
        20: "OPF1 Motor phase loss",
        21: "PHF Input phase loss",
        22: "USF Supply undervoltage",
        23: "SCF1 Motor short circuit",
        24: "SOF Overspeed",
    },
    watchdog=WatchdogProfile(
        timeout=Register(address=6005, scale=0.1, unit="s"),  # TTO Modbus timeout
        action=Register(address=7002),  # SLL Modbus fault management
        # Only what the readings of the option list agree on; 3 and 5 read as a stop in one
        # and as running on in another, so they are judged unknown, never ok.
        actions={
            0: ("ignore", False),
            1: ("freewheel stop", True),
            2: ("ramp stop", True),  # or "stop by the stop type (Stt)", a ramp by default
            3: ("fast stop or fallback speed", None),
            4: ("fallback speed", False),
            5: ("speed maintained or ramp stop", None),
        },
    ),
    values=(
        Value(name="Motor current", register=Register(address=3204, scale=0.1, unit="A")),
        Value(name="Mains voltage", register=Register(address=3207, scale=0.1, unit="V")),
        Value(name="Motor thermal state", register=Register(address=3209, unit="%")),
    ),
    parameters=(
        Value(name="ACC Acceleration", register=Register(address=9001, scale=0.1, unit="s")),
        Value(name="DEC Deceleration", register=Register(address=9002, scale=0.1, unit="s")),
    ),
    sources=(
        "ATV600 Communication Parameters EAV64332 V1.5 (spreadsheet): two logic addresses "
        "for CMD and ETA; 'speed' addresses in rpm, 'frequency' addresses in Hz",
        "CiA 402 / IEC 61800-7-201 drive state machine: 0x06 shutdown, 0x07 switch on, "
        "0x0F enable operation, 0x80 fault reset; status bits 0-3, 5, 6 give the state",
        "ATV12 Modbus Communication Manual BBV28590: CMD 8501 written 6, 7, 15 to run; ETA "
        "3201, ETA & 0x006F = 0x0037 operation enabled; the write example at W9001 (ACC)",
        "ATV312 Modbus manual BBV52816: CMD 8501, LFR 8502, ETA 3201, RFR 3202, faults from "
        "7121 (LFT), communication settings 6001-6005; HSP/LSP at 3104/3105 in 0.1 Hz",
        "Altivar Machine ATV320 communication parameters (NVE41316): TTO at 6005 in 0.1 s, "
        "ACC 9001 and DEC 9002 in 0.1 s",
        "The last three as transcribed from those documents into public register maps; "
        "their pages themselves were not seen",
    ),
    unverified=(
        "The addresses above are checked on ATV12/ATV312/ATV320 lists, not on ATV340, ATV600 "
        "or ATV900 pages; SLL 7002, LCR 3204, ULN 3207, THR 3209 not checked at all",
        "CMD bit 11 as reverse, ETA bit 15 as reverse rotation, ETA bit 9 as remote, bit 10 "
        "as target reached",
        "LFT fault numbers and their texts",
        "SLL option values: 0 ignore and 1 freewheel agree in every reading; 2-5 do not (an "
        "option list nO, YES, Stt, LFF, rLS, rMP, FSt, dCI would make 3 a fallback speed and "
        "5 a ramp stop), so 3 and 5 are judged unknown",
        "CiA 402 with CHCF = SIM (not separate, the factory setting) or SEP; SE8 is the "
        "ATV58-compatible profile, not CiA 402",
    ),
)

# ------------------------------------------------------------------ Yaskawa MEMOBUS

_A1000 = "YASKAWA AC Drive A1000 Technical Manual SIEP C710616 27G, App. C.9"

YASKAWA_MEMOBUS: Final = DriveProfile(
    name="yaskawa-memobus",
    title="Yaskawa A1000/V1000/GA500 (MEMOBUS/Modbus), H5-12 = 0, o1-03 = 0",
    state_machine=StateMachine.BITS,
    control=Register(address=0x0001),  # operation commands
    reference=Register(address=0x0002, scale=0.01, unit="Hz"),  # o1-03 = 0: 0.01 Hz
    # U1-12 drive status, not 002CH (drive status 2): only it says the direction, and the
    # output frequency (0024H) is a magnitude, so without it a drive found running in
    # reverse could not be adopted as it runs
    status=Register(address=0x004B),
    output_frequency=Register(address=0x0024, scale=0.01, unit="Hz"),
    fault_code=Register(address=0x0080),  # U2-01 current fault
    commands={
        "start": (0x0001,),  # bit 0 forward run
        "stop": (0x0000,),
        "start_reverse": (0x0002,),  # bit 1 reverse run
        "reset": (0x0008, 0x0000),  # bit 3 fault reset
    },
    status_bits={
        "running": 0,  # during run
        "reverse": 2,  # during reverse run
        "at_reference": 4,  # during speed agree
        "ready": 5,  # drive ready
        "fault": 7,
    },
    faults={
        0x02: "Uv1 DC bus undervoltage",
        0x07: "oC Overcurrent",
        0x08: "ov DC bus overvoltage",
        0x09: "oH Heatsink overheat",
        0x0C: "oL1 Motor overload",
        0x0D: "oL2 Drive overload",
        0x0F: "GF Ground fault",
        0x1C: "CE MEMOBUS/Modbus communication error",
    },
    watchdog=WatchdogProfile(
        timeout=Register(address=0x0435, scale=0.1, unit="s"),  # H5-09 CE detection time
        action=Register(address=0x0428),  # H5-04 stopping method after CE
        enable=Register(address=0x0429),  # H5-05 comm fault detection selection
        actions={
            0: ("ramp to stop", True),
            1: ("coast to stop", True),
            2: ("fast stop", True),
            3: ("alarm only", False),
        },
    ),
    values=(
        Value(name="Output current", register=Register(address=0x0026, scale=0.1, unit="A")),
        Value(name="DC bus voltage", register=Register(address=0x0031, unit="V")),
    ),
    parameters=(
        Value(
            name="C1-01 Acceleration Time 1", register=Register(address=0x0200, scale=0.1, unit="s")
        ),
        Value(
            name="C1-02 Deceleration Time 1", register=Register(address=0x0201, scale=0.1, unit="s")
        ),
    ),
    # A parameter written by MEMOBUS takes effect after an Enter command; the drive needs
    # time before it answers again.
    pacing=Pacing(after_write_s=0.01),
    sources=(
        f"{_A1000} p. 559: 0001H operation commands (bit 0 forward run, bit 1 reverse run, "
        "bit 3 fault reset), 0002H frequency reference in o1-03 units",
        "YASKAWA AC Drive A1000 Technical Manual SIEP C710616 27C p. 494: 004BH drive status "
        "U1-12 (bit 0 during run, bit 2 during reverse run, bit 4 during speed agree, bit 5 "
        "drive ready, bit 7 fault); the same register on V1000 and GA500 is unverified",
        f"{_A1000} p. 561: 0031H DC bus voltage in 1 V",
        f"{_A1000} p. 494: 0080H-0097H fault trace monitors U2-",
        "YASKAWA HV600 Technical Reference SIEPYAIH6B01A p. 742, 746: broadcast to 00H gets "
        "no response; a parameter write needs the Enter command",
    ),
    unverified=(
        "0024H output frequency and 0026H output current, their units",
        "Fault code numbers of U2-01 and their texts",
        "H5-04/H5-05/H5-09 register addresses 0428H/0429H/0435H",
        "The 10 ms wait after a parameter write",
        "C1-01/C1-02 at 0200H/0201H in 0.1 s (C1-10 = 1)",
    ),
)

# ------------------------------------------------------------------ Danfoss FC, Modbus RTU

_FC202 = "VLT AQUA Drive FC 202 Design Guide MG20Z102, §7.8"

DANFOSS_FC_MODBUS: Final = DriveProfile(
    name="danfoss-fc-modbus",
    title="Danfoss VLT FC 102/202/302 with 8-30 Protocol = Modbus RTU, 8-10 = FC profile",
    state_machine=StateMachine.BITS,
    control=Register(address=49999),  # 50000 CTW
    reference=Register(address=50009, scale=100 / 0x4000, unit="%", signed=True),  # REF
    status=Register(address=50199),  # 50200 STW
    output_frequency=Register(address=50209, scale=100 / 0x4000, unit="%", signed=True),
    fault_code=Register(address=16899, words=2),  # 16-90 Alarm word
    fault_bits=True,
    commands={
        "start": (0x047C,),  # ramp, no coast, no quick stop, no freeze, start, data valid
        "stop": (0x043C,),
        "coast": (0x0474,),
        "quick_stop": (0x046C,),
        "reset": (0x04BC, 0x043C),  # bit 7 on its rising edge
        "start_reverse": (0x847C,),
        "jog": (0x057C,),
    },
    status_bits={
        "ready": 1,
        "fault": 3,
        "warning": 7,
        "at_reference": 8,
        "remote": 9,
        "running": 11,
    },
    faults={bit: text for bit, (_, text) in ALARM_WORD.items()},
    watchdog=WatchdogProfile(
        timeout=Register(address=8029, words=2, scale=0.1, unit="s"),  # 8-03
        action=Register(address=8039, words=2),  # 8-04
        decode=FC_WATCHDOG.decode,
    ),
    values=(
        Value(
            name="Motor current", register=Register(address=16139, words=2, scale=0.01, unit="A")
        ),
        Value(name="DC link voltage", register=Register(address=16299, words=2, unit="V")),
        Value(name="Power", register=Register(address=16099, words=2, scale=0.01, unit="kW")),
    ),
    parameters=(
        Value(
            name="3-41 Ramp 1 Ramp Up Time",
            register=Register(address=3409, words=2, scale=0.01, unit="s"),
        ),
        Value(
            name="3-42 Ramp 1 Ramp Down Time",
            register=Register(address=3419, words=2, scale=0.01, unit="s"),
        ),
    ),
    sources=(
        f"{_FC202} p. 175, table 7.15: holding registers 50000 CTW, 50010 REF, 50200 STW, "
        "50210 MAV; parameter x-yy at register xyy0 (10 registers each)",
        "VLT HVAC Basic Drive FC 101 Design Guide §7.10.6: 1-24 written at PDU address "
        "0x0419 as two registers (parameter number × 10 − 1, 32 bits)",
        "VLT FC 103 Design Guide, table 3.36: FC profile status word bits (0 control ready, "
        "1 drive ready, 2 coasting, 3 alarm, 7 warning, 8 at reference, 9 auto mode, 11 "
        "running)",
        "protocols/danfoss-fc.md §8: the FC profile's control words and reference scaling",
    ),
    unverified=(
        "16-90, 16-14, 16-30, 16-10 at parameter × 10 − 1 as 32-bit values with their "
        "conversion indices (0.01 A, 1 V, 0.01 kW)",
        "8-04 read as two registers",
    ),
)

BUILT_IN: Final[dict[str, DriveProfile]] = {
    profile.name: checked(profile, f"built-in profile {profile.name}: ")
    for profile in (ABB_DRIVES, SINAMICS_V20, ALTIVAR_CIA402, YASKAWA_MEMOBUS, DANFOSS_FC_MODBUS)
}
