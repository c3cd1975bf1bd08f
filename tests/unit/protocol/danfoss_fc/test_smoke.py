from fcmaster.protocol.danfoss_fc import FcFramer, Telegram, decode_telegram, encode_telegram
from fcmaster.protocol.framing import Frame


def test_process_telegram_to_address_1_has_hand_computed_bcc() -> None:
    # 02 06 81 04 7C 20 00: XOR by hand = 02^06=04, ^81=85, ^04=81, ^7C=FD, ^20=DD, ^00=DD
    wire = encode_telegram(Telegram(address=1, pcd1=0x047C, pcd2=0x2000))
    assert wire == bytes.fromhex("02 06 81 04 7C 20 00 DD")


def test_framer_finds_telegram_after_noise() -> None:
    wire = bytes.fromhex("02 06 81 04 7C 20 00 DD")
    framer = FcFramer()
    framer.feed(b"\xff\x00" + wire)
    pieces = []
    while (piece := framer.next_frame()) is not None:
        pieces.append(piece)
    assert pieces[-1] == Frame(wire)
    assert decode_telegram(wire, from_drive=False).pcd1 == 0x047C
