"""Modbus RTU gripper codec against the Robotiq 2F manual's published frames."""

import pytest

from binpick.devices.gripper import (
    GripperStatus,
    decode_response,
    encode_read_input_registers,
    encode_write_registers,
    modbus_crc,
)
from binpick.errors import ChecksumError, DeviceFault, TruncatedReplyError, UnknownReplyError

H = bytes.fromhex


def test_published_activation_frames():
    assert encode_write_registers(9, 0x03E8, [0, 0, 0]) == H("09 10 03 E8 00 03 06 00 00 00 00 00 00 73 30")
    assert encode_write_registers(9, 0x03E8, [0x0100, 0, 0]) == H("09 10 03 E8 00 03 06 01 00 00 00 00 00 72 E1")


def test_published_close_frame():
    # rACT + rGTO, position 255, speed 255, force 255
    assert encode_write_registers(9, 0x03E8, [0x0900, 0x00FF, 0xFFFF]) == H(
        "09 10 03 E8 00 03 06 09 00 00 FF FF FF 42 29"
    )


def test_published_status_read_frame():
    assert encode_read_input_registers(9, 0x07D0, 3) == H("09 04 07 D0 00 03 B1 CE")


def test_crc_of_published_holding_read():
    assert modbus_crc(H("09 03 07 D0 00 01")).to_bytes(2, "little") == H("85 CF")


def _frame(body: bytes) -> bytes:
    return body + modbus_crc(body).to_bytes(2, "little")


def test_decode_status_reply():
    raw = _frame(H("09 04 06 F9 00 00 FF BD 00"))
    data = decode_response(raw, slave=9, function=0x04)
    st = GripperStatus.from_bytes(data)
    assert st.activated and st.going and st.object_state == 3 and st.position == 0xBD
    assert not st.holding and not st.moving


def test_decode_write_echo():
    # the manual's published reply to the activation request
    assert decode_response(H("09 10 03 E8 00 03 01 30"), slave=9, function=0x10) == H("03 E8 00 03")


def test_decode_errors():
    with pytest.raises(DeviceFault, match="illegal data address"):
        decode_response(_frame(H("09 84 02")), slave=9, function=0x04)
    with pytest.raises(ChecksumError):
        decode_response(H("09 10 03 E8 00 03 01 31"), slave=9, function=0x10)
    with pytest.raises(TruncatedReplyError):
        decode_response(H("09 10 03 E8 00 03"), slave=9, function=0x10)
    with pytest.raises(UnknownReplyError):
        decode_response(_frame(H("08 10 03 E8 00 03")), slave=9, function=0x10)
    with pytest.raises(UnknownReplyError):
        decode_response(_frame(H("09 2B 0E 01 00 00")), slave=9, function=0x10)
