"""The pcapng codec against block layouts written out by hand from the format's spec."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.protocol import pcapng
from fcmaster.protocol.pcapng import Capture, Interface, Packet, PcapngError


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", "").replace("\n", ""))


# Section Header Block: type 0A0D0D0A, total length 40, byte-order magic 1A2B3C4D (LE),
# version 1.0, section length -1, shb_userappl (4) "fcm" padded to 4, opt_endofopt, length.
SHB = h(
    """
    0a0d0d0a 28000000 4d3c2b1a 0100 0000 ffffffffffffffff
    0400 0300 66636d00
    0000 0000
    28000000
    """
)

# Interface Description Block: type 1, link type 147 (USER0), reserved, snaplen 0, then
# opt_comment "fc" (1, len 2, padded), if_name "l1" (2), if_description "8E1" (3),
# if_speed 19200 (8, len 8, u64), opt_endofopt; total 60 bytes.
IDB = h(
    """
    01000000 3c000000 9300 0000 00000000
    0100 0200 66630000
    0200 0200 6c310000
    0300 0300 38453100
    0800 0800 004b000000000000
    0000 0000
    3c000000
    """
)

# Enhanced Packet Block: type 6, interface 0, timestamp 0x00000001_00000002 µs split high/
# low, captured and original length 3, data 02 0e 01 + 1 byte pad, epb_flags (2, len 4)
# = 2 (outbound), opt_endofopt; total 48 bytes.
EPB = h(
    """
    06000000 30000000 00000000 01000000 02000000 03000000 03000000
    020e0100
    0200 0400 02000000
    0000 0000
    30000000
    """
)


def test_a_section_header_block_is_laid_out_as_the_spec_says() -> None:
    assert pcapng.section_header("fcm") == SHB


def test_an_interface_description_block_is_laid_out_as_the_spec_says() -> None:
    interface = Interface(link_type=147, name="l1", description="8E1", speed=19200, comment="fc")
    assert pcapng.interface_description(interface) == IDB


def test_an_enhanced_packet_block_is_laid_out_as_the_spec_says() -> None:
    packet = Packet(0, (1 << 32) | 2, b"\x02\x0e\x01", direction=pcapng.OUTBOUND)
    assert pcapng.enhanced_packet(packet) == EPB


def test_a_file_reads_back_as_written() -> None:
    capture = pcapng.decode(SHB + IDB + EPB)
    assert capture.application == "fcm"
    assert capture.interfaces == [
        Interface(link_type=147, name="l1", description="8E1", speed=19200, comment="fc")
    ]
    assert capture.packets == [Packet(0, (1 << 32) | 2, b"\x02\x0e\x01", pcapng.OUTBOUND)]


def test_a_big_endian_file_with_nanosecond_stamps_and_unknown_blocks_is_read() -> None:
    shb = h("0a0d0d0a 0000001c 1a2b3c4d 0001 0000 ffffffffffffffff 0000001c")
    idb = h("00000001 0000001c 0094 0000 00000000 0009 0001 09000000 0000001c")
    unknown = h("00000bad 0000000c 0000000c")
    epb = h(
        "00000006 0000002c 00000000 00000000 000f4240 00000001 00000001 aa000000"
        " 0002 0004 00000001 0000002c"
    )
    capture = pcapng.decode(shb + idb + unknown + epb)
    assert capture.interfaces[0].link_type == 148
    (packet,) = capture.packets
    assert (packet.timestamp_us, packet.data, packet.direction) == (1000, b"\xaa", 1)


@pytest.mark.parametrize(
    "data",
    [b"", b"\0" * 40, SHB[:-4], SHB[:4] + b"\xff" * 8 + SHB[12:], SHB + EPB, SHB + IDB[:-4]],
    ids=["empty", "zeros", "truncated", "bad magic", "undescribed interface", "cut block"],
)
def test_what_is_not_pcapng_is_refused_clearly(data: bytes) -> None:
    with pytest.raises(PcapngError):
        pcapng.decode(data)


def test_every_protocol_has_its_own_private_link_type() -> None:
    codes = list(pcapng.LINK_TYPES.values())
    assert len(set(codes)) == len(codes)
    # private-use USER types, but Modbus RTU, which a registered type's dissector knows
    assert all(147 <= code <= 162 for p, code in pcapng.LINK_TYPES.items() if p != "modbus-rtu")
    assert pcapng.LINK_TYPES["modbus-rtu"] == pcapng.RTAC_SERIAL == 250
    assert struct.calcsize("<IIIII") == 20


# A Modbus RTU request and its answer at 2026-09-21T14:13:20.000123Z, as an RTAC serial
# packet: 12 bytes of header (seconds, microseconds, event 1 sent / 2 received, control
# lines, footer), then the frame.
RTAC_SENT = h(
    "06000000 40000000 00000000 fe5b0600 7be025da 14000000 14000000"  # EPB, 20 bytes
    " 6ab13b80 0000007b 01 00 0000"  # 1790000000 s, 123 µs (big-endian), sent, lines, footer
    " 01030003 0002340b"  # the frame
    " 0200 0400 02000000 0000 0000 40000000"  # epb_flags outbound, end, length
)


def test_a_modbus_rtu_frame_goes_under_the_rtac_serial_header() -> None:
    request = h("01030003 0002340b")
    packet = Packet(0, 1_790_000_000_000_123, request, direction=pcapng.OUTBOUND)
    assert pcapng.enhanced_packet(packet, pcapng.RTAC_SERIAL) == RTAC_SENT
    answer = pcapng.enhanced_packet(
        Packet(0, 1_790_000_000_000_123, b"\x01", direction=pcapng.INBOUND), pcapng.RTAC_SERIAL
    )
    assert answer[28 + 8] == 0x02  # received
    rtu = Interface(link_type=pcapng.RTAC_SERIAL, name="rtu", description="modbus-rtu 19200 8E1")
    (read,) = pcapng.decode(SHB + pcapng.interface_description(rtu) + RTAC_SENT).packets
    assert read == packet  # the header is taken off: the data is the frame


def test_an_rtac_serial_packet_without_flags_is_told_by_its_event() -> None:
    rtu = Interface(link_type=pcapng.RTAC_SERIAL, name="rtu")
    flagless = h(
        "06000000 30000000 00000000 00000000 00000000 0d000000 0d000000"
        " 00000000 00000000 02 00 0000 01 000000 30000000"  # received, no epb_flags
    )
    (read,) = pcapng.decode(SHB + pcapng.interface_description(rtu) + flagless).packets
    assert (read.data, read.direction) == (b"\x01", pcapng.INBOUND)
    with pytest.raises(PcapngError, match="12-byte header"):
        pcapng.decode(SHB + pcapng.interface_description(rtu) + EPB)


interfaces = st.builds(
    Interface,
    link_type=st.sampled_from(sorted(pcapng.PROTOCOLS)),
    name=st.text(max_size=20),
    description=st.text(max_size=30),
    speed=st.none() | st.integers(0, 2**64 - 1),
    comment=st.text(max_size=30),
)


@st.composite
def captures(draw: st.DrawFn) -> Capture:
    ifaces = draw(st.lists(interfaces, min_size=1, max_size=3))
    packets = draw(
        st.lists(
            st.builds(
                Packet,
                interface=st.integers(0, len(ifaces) - 1),
                timestamp_us=st.integers(0, 2**64 - 1),
                data=st.binary(max_size=64),
                direction=st.sampled_from([0, pcapng.INBOUND, pcapng.OUTBOUND]),
                comment=st.text(max_size=20),
            ),
            max_size=20,
        )
    )
    return Capture(draw(st.text(max_size=20)), ifaces, packets)


@given(captures())
def test_any_capture_survives_a_round_trip(capture: Capture) -> None:
    data = pcapng.encode(capture)
    assert len(data) % 4 == 0
    assert pcapng.decode(data) == capture
