"""pcapng, the capture file format Wireshark reads, as pure bytes in and out (no I/O).

Only what a capture of serial lines needs (draft-ietf-opsawg-pcapng): a Section Header
Block, one Interface Description Block per line, and Enhanced Packet Blocks, written
little-endian with microsecond timestamps (the format's default resolution, so no
``if_tsresol``). The reader takes either byte order and any timestamp resolution, and
skips blocks and options it does not know.

Each protocol always has the same link-layer type (its spec's ``link_type``). No type is
registered for the drive vendors' protocols, so they get types reserved for private use
(LINKTYPE_USER0-15, 147-162). Modbus RTU goes under LINKTYPE_RTAC_SERIAL (250), a
registered serial-line type whose payload Wireshark dissects as Modbus RTU once told to
(*Decode As… → RTAC Serial → Modbus RTU*; ``tshark -d rtacser.data,mbrtu``). Its packets
carry a 12-byte header before the frame: the time (seconds and microseconds since 1970,
each a big-endian u32), the event (0x01 data sent, 0x02 data received), the control lines
and a footer (both 0 here). The writer adds it and the reader takes it off, so a
:class:`Packet`'s ``data`` is always the frame.

=================  ===========  ===
protocol           link type    DLT
=================  ===========  ===
danfoss-fc         USER0        147
mitsubishi         USER1        148
enc                USER2        149
modbus-rtu         RTAC_SERIAL  250
=================  ===========  ===

A packet is one frame as the master's port saw it: outbound (``epb_flags`` direction 2)
is a request the master wrote, inbound (1) bytes it read. A line's interface carries its
bus name (``if_name``), its protocol and character format (``if_description``, as
:class:`LineFormat` writes it: ``danfoss-fc 19200 8E1``) and its baud rate (``if_speed``),
which is what a replay needs to serve it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Final

from fcmaster.errors import ProtocolError
from fcmaster.protocol.registry import PROTOCOLS as REGISTRY

LINK_TYPES: Final[dict[str, int]] = {name: spec.link_type for name, spec in REGISTRY.items()}
PROTOCOLS: Final[dict[int, str]] = {code: name for name, code in LINK_TYPES.items()}

SHB: Final = 0x0A0D0D0A
IDB: Final = 0x00000001
EPB: Final = 0x00000006
BYTE_ORDER_MAGIC: Final = 0x1A2B3C4D

OPT_ENDOFOPT: Final = 0
OPT_COMMENT: Final = 1
SHB_USERAPPL: Final = 4
IF_NAME: Final = 2
IF_DESCRIPTION: Final = 3
IF_SPEED: Final = 8
IF_TSRESOL: Final = 9
EPB_FLAGS: Final = 2

INBOUND: Final = 1  # epb_flags bits 0-1
OUTBOUND: Final = 2

RTAC_SERIAL: Final = 250  # LINKTYPE_RTAC_SERIAL: a 12-byte header before each frame
_RTAC_HEADER: Final = struct.Struct(">IIBBH")  # seconds, microseconds, event, lines, footer
_RTAC_SENT: Final = 0x01  # DATA_TX_START
_RTAC_RECEIVED: Final = 0x02  # DATA_RX_START


class PcapngError(ProtocolError, ValueError):
    """The bytes are not a pcapng file this reader understands."""


@dataclass(slots=True, frozen=True)
class Interface:
    """One captured line."""

    link_type: int
    name: str = ""
    description: str = ""
    speed: int | None = None  # bits per second
    comment: str = ""
    tsresol: int = 6  # as the option byte: 6 is microseconds


@dataclass(slots=True, frozen=True)
class Packet:
    """One frame: on which interface, when (in microseconds since 1970), which way."""

    interface: int
    timestamp_us: int
    data: bytes
    direction: int = 0  # 0 unknown, INBOUND or OUTBOUND
    comment: str = ""


@dataclass(slots=True)
class Capture:
    """What a pcapng file holds, as far as this reader understands it."""

    application: str = ""
    interfaces: list[Interface] = field(default_factory=list)
    packets: list[Packet] = field(default_factory=list)


@dataclass(slots=True, frozen=True)
class LineFormat:
    """A serial line as an interface's description gives it: ``danfoss-fc 19200 8E1``."""

    protocol: str
    baudrate: int
    databits: int = 8
    parity: str = "E"
    stopbits: int = 1

    def __str__(self) -> str:
        return f"{self.protocol} {self.baudrate} {self.databits}{self.parity}{self.stopbits}"

    @classmethod
    def parse(cls, text: str) -> LineFormat | None:
        """The format in ``text``, or None where it is not one."""
        parts = text.split()
        if len(parts) != 3 or not parts[1].isdigit() or len(parts[2]) != 3:
            return None
        bits, parity, stop = parts[2][0], parts[2][1], parts[2][2]
        if not (bits.isdigit() and stop.isdigit() and parity in "NEO"):
            return None
        return cls(parts[0], int(parts[1]), int(bits), parity, int(stop))


def _pad(data: bytes) -> bytes:
    return data + b"\0" * (-len(data) % 4)


def _option(code: int, value: bytes) -> bytes:
    return struct.pack("<HH", code, len(value)) + _pad(value)


def _options(options: list[tuple[int, bytes]]) -> bytes:
    if not options:
        return b""
    return b"".join(_option(code, value) for code, value in options) + _option(OPT_ENDOFOPT, b"")


def _block(block_type: int, body: bytes) -> bytes:
    length = 12 + len(body)
    return struct.pack("<II", block_type, length) + body + struct.pack("<I", length)


def section_header(application: str = "") -> bytes:
    """A Section Header Block of unknown section length, little-endian, version 1.0."""
    options = [(SHB_USERAPPL, application.encode())] if application else []
    body = struct.pack("<IHHq", BYTE_ORDER_MAGIC, 1, 0, -1) + _options(options)
    return _block(SHB, body)


def interface_description(interface: Interface, snaplen: int = 0) -> bytes:
    """An Interface Description Block (``snaplen`` 0: frames are never cut)."""
    options: list[tuple[int, bytes]] = []
    if interface.comment:
        options.append((OPT_COMMENT, interface.comment.encode()))
    if interface.name:
        options.append((IF_NAME, interface.name.encode()))
    if interface.description:
        options.append((IF_DESCRIPTION, interface.description.encode()))
    if interface.speed is not None:
        options.append((IF_SPEED, struct.pack("<Q", interface.speed)))
    if interface.tsresol != 6:
        options.append((IF_TSRESOL, bytes([interface.tsresol])))
    body = struct.pack("<HHI", interface.link_type, 0, snaplen) + _options(options)
    return _block(IDB, body)


def enhanced_packet(packet: Packet, link_type: int = 0) -> bytes:
    """An Enhanced Packet Block; the timestamp in the interface's units (microseconds).

    ``link_type``: its interface's, which may put a header before the frame (RTAC serial).
    """
    options: list[tuple[int, bytes]] = []
    if packet.comment:
        options.append((OPT_COMMENT, packet.comment.encode()))
    if packet.direction or link_type == RTAC_SERIAL:  # its event says a direction: say ours
        options.append((EPB_FLAGS, struct.pack("<I", packet.direction)))
    ts = packet.timestamp_us
    data = packet.data
    if link_type == RTAC_SERIAL:
        event = _RTAC_RECEIVED if packet.direction == INBOUND else _RTAC_SENT
        seconds, micros = divmod(ts, 1_000_000)
        data = _RTAC_HEADER.pack(seconds & 0xFFFFFFFF, micros, event, 0, 0) + data
    head = struct.pack("<IIIII", packet.interface, ts >> 32, ts & 0xFFFFFFFF, len(data), len(data))
    return _block(EPB, head + _pad(data) + _options(options))


def encode(capture: Capture) -> bytes:
    """A whole file: one section with the capture's interfaces and packets."""
    parts = [section_header(capture.application)]
    parts += [interface_description(i) for i in capture.interfaces]
    links = [i.link_type for i in capture.interfaces]
    parts += [
        enhanced_packet(p, links[p.interface] if p.interface < len(links) else 0)
        for p in capture.packets
    ]
    return b"".join(parts)


def _parse_options(data: bytes, order: str) -> list[tuple[int, bytes]]:
    options = []
    offset = 0
    while offset + 4 <= len(data):
        code, length = struct.unpack_from(order + "HH", data, offset)
        offset += 4
        if code == OPT_ENDOFOPT:
            break
        if offset + length > len(data):
            raise PcapngError(f"option {code} runs past its block")
        options.append((code, data[offset : offset + length]))
        offset += length + (-length % 4)
    return options


def _text(options: list[tuple[int, bytes]], code: int) -> str:
    return next((v.decode(errors="replace") for c, v in options if c == code), "")


def _microseconds(ticks: int, tsresol: int) -> int:
    if tsresol & 0x80:
        return (ticks * 1_000_000) >> (tsresol & 0x7F)
    if tsresol >= 6:
        return ticks // int(10 ** (tsresol - 6))
    return int(ticks * 10 ** (6 - tsresol))


def decode(data: bytes) -> Capture:
    """Read a pcapng file's first section; raise PcapngError where it is not pcapng."""
    if len(data) < 28 or struct.unpack_from("<I", data)[0] != SHB:
        raise PcapngError("not a pcapng file: no section header block at the start")
    magic = data[8:12]
    if magic == struct.pack("<I", BYTE_ORDER_MAGIC):
        order = "<"
    elif magic == struct.pack(">I", BYTE_ORDER_MAGIC):
        order = ">"
    else:
        raise PcapngError("not a pcapng file: bad byte-order magic")
    capture = Capture()
    offset = 0
    while offset < len(data):
        if offset + 12 > len(data):
            raise PcapngError(f"truncated block at byte {offset}")
        block_type, length = struct.unpack_from(order + "II", data, offset)
        if length < 12 or length % 4 or offset + length > len(data):
            raise PcapngError(f"block at byte {offset} has a bad length {length}")
        (trailer,) = struct.unpack_from(order + "I", data, offset + length - 4)
        if trailer != length:
            raise PcapngError(f"block at byte {offset}: its two lengths differ")
        body = data[offset + 8 : offset + length - 4]
        if block_type == SHB:
            if offset:
                break  # a second section: this reader keeps to the first
            major = struct.unpack_from(order + "H", body, 4)[0]
            if major != 1:
                raise PcapngError(f"pcapng version {major} is not supported")
            capture.application = _text(_parse_options(body[16:], order), SHB_USERAPPL)
        elif block_type == IDB:
            capture.interfaces.append(_interface(body, order))
        elif block_type == EPB:
            capture.packets.append(_packet(body, order, capture.interfaces))
        offset += length
    return capture


def _interface(body: bytes, order: str) -> Interface:
    link_type, _, _ = struct.unpack_from(order + "HHI", body)
    options = _parse_options(body[8:], order)
    speeds = [v for c, v in options if c == IF_SPEED and len(v) == 8]
    speed: int | None = struct.unpack(order + "Q", speeds[0])[0] if speeds else None
    tsresol = next((v[0] for c, v in options if c == IF_TSRESOL and v), 6)
    return Interface(
        link_type=link_type,
        name=_text(options, IF_NAME),
        description=_text(options, IF_DESCRIPTION),
        speed=speed,
        comment=_text(options, OPT_COMMENT),
        tsresol=tsresol,
    )


def _packet(body: bytes, order: str, interfaces: list[Interface]) -> Packet:
    interface, high, low, captured, _ = struct.unpack_from(order + "IIIII", body)
    if interface >= len(interfaces):
        raise PcapngError(f"a packet names interface {interface}, which is not described")
    if 20 + captured > len(body):
        raise PcapngError("a packet's data runs past its block")
    options = _parse_options(body[20 + captured + (-captured % 4) :], order)
    flags = next(
        (struct.unpack(order + "I", v)[0] for c, v in options if c == EPB_FLAGS and len(v) == 4),
        None,
    )
    data, direction = body[20 : 20 + captured], (flags or 0) & 3
    if interfaces[interface].link_type == RTAC_SERIAL:
        if len(data) < _RTAC_HEADER.size:
            raise PcapngError("an RTAC serial packet shorter than its 12-byte header")
        event = data[8]
        if flags is None:  # written elsewhere, without flags: the event says which way
            direction = {_RTAC_SENT: OUTBOUND, _RTAC_RECEIVED: INBOUND}.get(event, 0)
        data = data[_RTAC_HEADER.size :]
    return Packet(
        interface=interface,
        timestamp_us=_microseconds(high << 32 | low, interfaces[interface].tsresol),
        data=data,
        direction=direction,
        comment=_text(options, OPT_COMMENT),
    )
