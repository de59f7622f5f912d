"""Protocol 2.0 codec against published byte vectors and hand-worked ones."""

import pytest

from binpick.devices.dynamixel import (
    crc16,
    decode_packet,
    decode_status,
    encode_packet,
    encode_ping,
    encode_read,
    encode_write,
    stuff,
    unstuff,
)
from binpick.errors import ChecksumError, InvalidInputError, ProtocolError, TruncatedReplyError, UnknownReplyError

H = bytes.fromhex


def reference_crc(data: bytes) -> int:
    """Bit-by-bit CRC-16, polynomial 0x8005, init 0, unreflected: independent of the module's table."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


# published examples (ROBOTIS Protocol 2.0 documentation)
PING_ID1 = H("FF FF FD 00 01 03 00 01 19 4E")
WRITE_512_AT_116_ID1 = H("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89")
READ_4_AT_132_ID1 = H("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")
PING_STATUS_ID1 = H("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")  # model 1030, firmware 38
READ_STATUS_ID1 = H("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0")  # present position 166


def test_ping_matches_published_bytes():
    assert encode_ping(1) == PING_ID1


def test_write_matches_published_bytes():
    assert encode_write(1, 116, (512).to_bytes(4, "little")) == WRITE_512_AT_116_ID1


def test_read_matches_published_bytes():
    assert encode_read(1, 132, 4) == READ_4_AT_132_ID1


@pytest.mark.parametrize(
    "packet", [PING_ID1, WRITE_512_AT_116_ID1, READ_4_AT_132_ID1, PING_STATUS_ID1, READ_STATUS_ID1]
)
def test_crc_of_published_packets(packet):
    want = int.from_bytes(packet[-2:], "little")
    assert crc16(packet[:-2]) == want == reference_crc(packet[:-2])


def test_crc_known_values():
    assert crc16(b"") == 0
    assert crc16(H("FF FF FD 00 01 03 00 01")) == 0x4E19


def test_decode_published_ping_status():
    st = decode_status(PING_STATUS_ID1)
    assert (st.motor_id, st.error, st.params) == (1, 0, H("06 04 26"))
    assert int.from_bytes(st.params[:2], "little") == 1030


def test_decode_published_read_status():
    st = decode_status(READ_STATUS_ID1)
    assert int.from_bytes(st.params, "little", signed=True) == 166
    assert not st.alert and st.error_code == 0


def test_status_error_byte():
    raw = encode_packet(1, 0x55, bytes([0x80 | 0x06]))
    st = decode_status(raw)
    assert st.alert and st.error_code == 6
    assert "data limit" in st.describe_error() and "hardware alert" in st.describe_error()


def test_byte_stuffing_hand_worked():
    # WRITE at 0x0074 of the bytes FF FF FD 00: the parameters 74 00 FF FF FD 00 carry the header
    # pattern FF FF FD, so an FD is inserted after it: 74 00 FF FF FD FD 00 (7 bytes).
    # LEN = 1 instruction + 7 parameters + 2 CRC = 10.
    body = H("FF FF FD 00 01 0A 00 03 74 00 FF FF FD FD 00")
    expected = body + reference_crc(body).to_bytes(2, "little")
    assert encode_write(1, 0x74, H("FF FF FD 00")) == expected
    packet = decode_packet(expected)
    assert packet.params == H("74 00 FF FF FD 00")


def test_stuff_and_unstuff():
    assert stuff(H("FF FF FD")) == H("FF FF FD FD")
    assert stuff(H("01 FF FF FD FF FF FD")) == H("01 FF FF FD FD FF FF FD FD")
    assert stuff(H("FF FF FC FD")) == H("FF FF FC FD")
    assert unstuff(H("FF FF FD FD 00")) == H("FF FF FD 00")


def test_decode_rejects_bad_crc():
    bad = READ_STATUS_ID1[:-1] + bytes([READ_STATUS_ID1[-1] ^ 1])
    with pytest.raises(ChecksumError):
        decode_status(bad)


def test_decode_rejects_truncated_and_garbled():
    with pytest.raises(TruncatedReplyError):
        decode_packet(READ_STATUS_ID1[:-3])
    with pytest.raises(TruncatedReplyError):
        decode_packet(READ_STATUS_ID1[:5])
    with pytest.raises(ProtocolError):
        decode_packet(H("FF 00 FD 00") + READ_STATUS_ID1[4:])
    with pytest.raises(ProtocolError):
        decode_packet(READ_STATUS_ID1 + b"\x00")


def test_instruction_packet_is_not_a_status():
    with pytest.raises(UnknownReplyError):
        decode_status(PING_ID1)


def test_encoder_input_checks():
    with pytest.raises(InvalidInputError):
        encode_ping(300)
    with pytest.raises(InvalidInputError):
        encode_write(1, 116, b"")
