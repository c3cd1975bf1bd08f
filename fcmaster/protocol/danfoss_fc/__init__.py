"""The Danfoss FC protocol, sans-I/O (protocols/danfoss-fc.md)."""

from fcmaster.protocol.danfoss_fc.codec import DEFAULT_MONITOR, FcCodec, decode_status
from fcmaster.protocol.danfoss_fc.describe import describe_telegram
from fcmaster.protocol.danfoss_fc.error_codes import ERROR_CODES, error_text
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.danfoss_fc.parameters import (
    PARAMETERS,
    DataType,
    ParameterSpec,
    format_parameter,
    lookup,
    parse_parameter,
)
from fcmaster.protocol.danfoss_fc.profile import (
    IGNORED_CONTROL_WORD,
    ControlWord,
    StatusWord,
    control_word,
    decode_reference,
    encode_reference,
)
from fcmaster.protocol.danfoss_fc.telegram import (
    AddressFormat,
    RequestAk,
    ResponseAk,
    Telegram,
    bcc,
    decode_address,
    decode_telegram,
    encode_address,
    encode_telegram,
    make_pke,
)
from fcmaster.protocol.danfoss_fc.words import (
    decode_alarm_word,
    decode_alarm_word_2,
    decode_ext_status_word,
    decode_warning_word,
    decode_warning_word_2,
)

__all__ = [
    "DEFAULT_MONITOR",
    "ERROR_CODES",
    "IGNORED_CONTROL_WORD",
    "PARAMETERS",
    "AddressFormat",
    "ControlWord",
    "DataType",
    "FcCodec",
    "FcFramer",
    "ParameterSpec",
    "RequestAk",
    "ResponseAk",
    "StatusWord",
    "Telegram",
    "bcc",
    "control_word",
    "decode_address",
    "decode_alarm_word",
    "decode_alarm_word_2",
    "decode_ext_status_word",
    "decode_reference",
    "decode_status",
    "decode_telegram",
    "decode_warning_word",
    "decode_warning_word_2",
    "describe_telegram",
    "encode_address",
    "encode_reference",
    "encode_telegram",
    "error_text",
    "format_parameter",
    "lookup",
    "make_pke",
    "parse_parameter",
]
