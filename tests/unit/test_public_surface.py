"""Each package face exports exactly the names intended, and each of them is documented.

The intended sets are written out here, not read from the code: a name added to or dropped
from an ``__all__`` must be added or dropped here too, on purpose (STYLE.md §8).
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import fcmaster

# fmt: off
FACES: dict[str, set[str]] = {
    "fcmaster": {
        "__version__",
    },
    "fcmaster.adapters": {
        "BeyondLimits", "Gateway", "LineInfo", "parse_command", "refusal",
    },
    "fcmaster.adapters.sparkplug": {
        "EdgeNode", "Payload", "SparkplugAdapter", "decode_payload", "encode_payload",
    },
    "fcmaster.bus": {
        "Action", "BusMaster", "BusObserver", "Command", "CommandResult", "DrivePlan",
        "DriveStats", "LinePlan", "LineStats", "OnStart", "Outcome", "SerialTransport",
        "Transport",
    },
    "fcmaster.transport": {
        "SerialTransport", "Transport",
    },
    "fcmaster.protocol": {
        "Access", "Condition", "ConditionReport", "ControlIntent", "DriveCodec", "DriveError",
        "DriveStatus", "Exchange", "Frame", "Framer", "FramerBuffer", "Motion", "ParameterKey",
        "ParameterValue", "Reply", "SkipReason", "Skipped",
    },
    "fcmaster.protocol.danfoss_fc": {
        "AddressFormat", "ControlWord", "DEFAULT_MONITOR", "DataType", "ERROR_CODES", "FcCodec",
        "FcFramer", "IGNORED_CONTROL_WORD", "PARAMETERS", "ParameterSpec", "RequestAk",
        "ResponseAk", "StatusWord", "Telegram", "bcc", "control_word", "decode_address",
        "decode_alarm_word", "decode_alarm_word_2", "decode_ext_status_word",
        "decode_reference", "decode_status", "decode_telegram", "decode_warning_word",
        "decode_warning_word_2", "describe_telegram", "encode_address", "encode_reference",
        "encode_telegram", "error_text", "format_parameter", "lookup", "make_pke",
        "parse_parameter",
    },
    "fcmaster.protocol.enc": {
        "BROADCAST", "Command", "DEFAULT_MONITOR", "EncCodec", "EncFramer", "FAULT_TEXTS",
        "FUNCTION_CODES", "NumberEncoding", "RESPONSE_TEXTS", "RUNNING_FREQUENCY",
        "RUNNING_VALUES", "Request", "Response", "ResponseCode", "RunControl", "STATE_WORD",
        "StateWord", "ValueSpec", "checksum", "decode_request", "decode_response",
        "decode_status", "describe_frame", "encode_number", "encode_request", "encode_response",
        "fault_report", "fault_text", "format_parameter", "lookup", "number_encoding",
        "parse_parameter", "read_fault", "read_response", "readings", "response_text",
    },
    "fcmaster.protocol.mitsubishi": {
        "ACK", "Ack", "BY_CODE", "CR", "DEFAULT_MONITOR", "DEFAULT_WAIT_MS", "DataReply", "ENQ",
        "ERROR_CODES", "ETX", "FAULT_CODES", "INSTRUCTIONS", "Instruction", "Kind", "LF",
        "Message", "MitsubishiCodec", "MitsubishiFramer", "NAK", "Nak", "OperationMode",
        "PARAMETERS", "ParameterSpec", "RESTART_S", "Request", "RunCommand", "STX",
        "StatusBits", "Terminator", "answer_delay_s", "decode_frame", "decode_status",
        "describe_code", "describe_frame", "encode_frame", "error_text", "fault_pair",
        "fault_text", "format_ascii_frame", "frame_length", "frequency_hz", "frequency_raw",
        "is_paged", "lookup", "parse_ascii_frame", "parse_parameter", "resolve", "run_command",
        "split_terminator", "sum_check", "wait_digit",
    },
    "fcmaster.protocol.modbus_rtu": {
        "ADDRESSES", "BROADCAST", "EXCEPTION_TEXTS", "MAX_FRAME", "MAX_READ", "MAX_WRITE",
        "Direction", "ExceptionCode", "ExceptionReply", "Function", "ReadRequest", "Registers",
        "Request", "Response", "RtuFramer", "WriteMultiple", "WriteSingle", "Written", "crc16",
        "crc_ok", "decode_request", "decode_response", "encode_request", "encode_response",
        "exception_text", "reply_length", "with_crc",
    },
    "fcmaster.sim": {
        "DriveSettings", "EncSimDrive", "FaultPlan", "FcSimDrive", "LineCounters",
        "LineSettings", "MitsubishiSimDrive", "Mode", "Motor", "MotorCommand", "MotorRating",
        "PtyServer", "RequestFramer", "SIM_PROTOCOLS", "SIM_SCHEME", "SimDrive", "SimLine",
        "SimProtocol", "SimRegistry", "SimTransport", "Transaction", "build_line",
        "parse_faults", "sim_name",
    },
    "fcmaster.sim.danfoss_fc": {
        "ALARM_BITS", "FcControl", "FcSimDrive", "ParameterStore", "Refused", "SETTINGS",
        "TRIP_LOCK_ALARMS", "WARNING_BITS",
    },
    "fcmaster.sim.modbus_rtu": {
        "Machine", "ModbusSimDrive", "State", "profile_for",
    },
    "fcmaster.sim.enc": {
        "COMMUNICATION_FAULT", "EncControl", "EncRequestFramer", "EncSimDrive", "JOG_HZ",
        "ParameterStore", "READINGS", "Refused", "SETTINGS", "SOFTWARE_VERSION", "state_word",
    },
    "fcmaster.sim.mitsubishi": {
        "MitsubishiControl", "MitsubishiSimDrive", "ParameterStore", "RequestReceiver",
        "Setting", "line_parameters", "line_receiver",
    },
}
# fmt: on

# Packages that are not a face: the CLI's commands are loaded one module at a time, and so
# are the OPC UA server process's (the daemon loads its pipe's module, never asyncua).
NOT_FACES = {"fcmaster.subcommands", "fcmaster.opcua"}


@pytest.mark.parametrize("face", sorted(FACES))
def test_a_face_exports_exactly_the_intended_names(face: str) -> None:
    module = importlib.import_module(face)
    exported: list[str] = module.__all__
    assert len(exported) == len(set(exported)), "a name is listed twice"
    assert set(exported) == FACES[face]


@pytest.mark.parametrize("face", sorted(FACES))
def test_every_exported_name_exists_and_is_documented(face: str) -> None:
    module = importlib.import_module(face)
    assert (module.__doc__ or "").strip(), f"{face} has no docstring"
    for name in FACES[face]:
        assert hasattr(module, name), f"{face}.{name} does not exist"
        value = getattr(module, name)
        # Classes and functions carry their own docstring (a class's is not inherited);
        # constants cannot carry one and are described where they are defined.
        if inspect.isclass(value):
            assert (value.__dict__.get("__doc__") or "").strip(), f"{face}.{name}"
        elif inspect.isfunction(value):
            assert (value.__doc__ or "").strip(), f"{face}.{name}"


def test_every_package_is_a_face_listed_here() -> None:
    packages = {
        info.name
        for info in pkgutil.walk_packages(fcmaster.__path__, prefix="fcmaster.")
        if info.ispkg
    }
    assert packages | {"fcmaster"} == set(FACES) | NOT_FACES
