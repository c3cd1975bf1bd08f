"""Modbus RTU, sans-I/O: the CRC, the four register functions, exceptions and the framer."""

from fcmaster.protocol.modbus_rtu.crc import crc16, crc_ok, with_crc
from fcmaster.protocol.modbus_rtu.exception_codes import (
    EXCEPTION_TEXTS,
    ExceptionCode,
    exception_text,
)
from fcmaster.protocol.modbus_rtu.frame import (
    ADDRESSES,
    BROADCAST,
    MAX_READ,
    MAX_WRITE,
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    Request,
    Response,
    WriteMultiple,
    WriteSingle,
    Written,
    decode_request,
    decode_response,
    encode_request,
    encode_response,
    reply_length,
)
from fcmaster.protocol.modbus_rtu.framer import MAX_FRAME, Direction, RtuFramer

__all__ = [
    "ADDRESSES",
    "BROADCAST",
    "EXCEPTION_TEXTS",
    "MAX_FRAME",
    "MAX_READ",
    "MAX_WRITE",
    "Direction",
    "ExceptionCode",
    "ExceptionReply",
    "Function",
    "ReadRequest",
    "Registers",
    "Request",
    "Response",
    "RtuFramer",
    "WriteMultiple",
    "WriteSingle",
    "Written",
    "crc16",
    "crc_ok",
    "decode_request",
    "decode_response",
    "encode_request",
    "encode_response",
    "exception_text",
    "reply_length",
    "with_crc",
]
