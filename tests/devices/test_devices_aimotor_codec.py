"""AI-motor codec: hand-worked frames from the documented layout FF, D1, D2, (D1 XOR D2) AND 7F."""

import pytest

from binpick.devices.aimotor import decode_reply, encode_position, encode_request
from binpick.errors import InvalidInputError, ProtocolError


def test_position_send_frame():
    # ID 0, torque level 2: D1 = 2 << 5 = 0x40; goal 127 = 0x7F; CS = (0x40 ^ 0x7F) & 0x7F = 0x3F
    assert encode_position(0, 127, torque_level=2) == bytes([0xFF, 0x40, 0x7F, 0x3F])
    # ID 3, torque level 0, goal 254: D1 = 0x03, CS = (0x03 ^ 0xFE) & 0x7F = 0x7D
    assert encode_position(3, 254, torque_level=0) == bytes([0xFF, 0x03, 0xFE, 0x7D])


def test_status_read_frame():
    # mode 5, ID 3: D1 = 0xA3, D2 = 0, CS = 0x23
    assert encode_request(0xA3, 0) == bytes([0xFF, 0xA3, 0x00, 0x23])


def test_reply():
    assert decode_reply(b"\x0a\x7f") == (10, 127)
    for bad in (b"\x0a", b"\x0a\xff", b"\xff\x10", b"\x01\x02\x03"):
        with pytest.raises(ProtocolError):
            decode_reply(bad)


def test_encoder_input_checks():
    with pytest.raises(InvalidInputError):
        encode_position(31, 0)
    with pytest.raises(InvalidInputError):
        encode_position(0, 255)
