"""R3 codec: request frames, the four reply statuses, PPOSF/JPOSF/DSTATE data, position literals."""

import numpy as np
import pytest

from binpick.devices.melfa import (
    encode_command,
    format_position,
    parse_joints,
    parse_position,
    parse_reply,
    parse_state,
)
from binpick.errors import InvalidInputError, ProtocolError, UnknownReplyError

# reply lines in the format RV-2A/CR1 integrations record from the controller
PPOSF = "X;535.21;Y;-0.03;Z;779.78;A;-89.97;B;0.03;C;0.00;;7,0;50;0.00;00000000"
JPOSF = "J1;-0.01;J2;8.15;J3;68.99;J4;0.03;J5;12.89;J6;0.00;;****,****;50;0.00;00000000"


def test_request_frame():
    assert encode_command("OPEN=NARCUSR") == b"1;1;OPEN=NARCUSR\r"
    assert encode_command("PPOSF", robot=1, slot=9) == b"1;9;PPOSF\r"


@pytest.mark.parametrize("bad", ["", "A\rB", "P\u00e9", "x" * 300])
def test_request_rejects_bad_commands(bad):
    with pytest.raises(InvalidInputError):
        encode_command(bad)


def test_reply_statuses():
    r = parse_reply(b"QoKRV-1A\r")
    assert (r.ok, r.alarm, r.data, r.error_number) == (True, False, "RV-1A", None)
    r = parse_reply(b"Qok\r")
    assert (r.ok, r.alarm) == (True, True)
    r = parse_reply(b"QeR0060\r")
    assert (r.ok, r.alarm, r.error_number) == (False, False, 60)
    r = parse_reply(b"Qer7000;extra")
    assert (r.ok, r.alarm, r.error_number) == (False, True, 7000)


def test_reply_errors():
    with pytest.raises(UnknownReplyError):
        parse_reply(b"RDY?\r")
    with pytest.raises(ProtocolError, match="garbled"):
        parse_reply(b"Q\xcaK\r")
    with pytest.raises(ProtocolError, match="too short"):
        parse_reply(b"Qo\r")
    with pytest.raises(ProtocolError, match="error number"):
        parse_reply(b"QeR\r")


def test_pposf():
    xyzabc, flags = parse_position(PPOSF)
    np.testing.assert_allclose(xyzabc, [535.21, -0.03, 779.78, -89.97, 0.03, 0.00])
    assert flags == (7, 0)


def test_pposf_with_extra_axes():
    xyzabc, flags = parse_position("X;1;Y;2;Z;3;A;4;B;5;C;6;L1;7.5;;6,1;10")
    np.testing.assert_allclose(xyzabc, [1, 2, 3, 4, 5, 6])
    assert flags == (6, 1)


@pytest.mark.parametrize(
    "bad",
    [
        "X;1;Y;2;Z;3;A;4;B;5;;7,0",
        "X;1;Y;2;Z;3;A;4;B;5;C;oops;;7,0",
        "X;1;Y;2;Z;3;A;4;B;5;C;6;;",
        "X;1;Y",
        "X;1;Y;2;Z;3;A;4;B;5;C;nan;;7,0",
    ],
)
def test_pposf_errors(bad):
    with pytest.raises(ProtocolError):
        parse_position(bad)


def test_jposf():
    np.testing.assert_allclose(parse_joints(JPOSF), [-0.01, 8.15, 68.99, 0.03, 12.89, 0.0])


def test_dstate():
    st = parse_state("A10000")  # 0x80 control + 0x20 servo + bit 0
    assert st.control_on and st.servo_on and not st.moving and st.error_number == 0
    st = parse_state("E04001")
    assert st.moving and st.error_number == 4001
    with pytest.raises(ProtocolError):
        parse_state("zz")


def test_position_literal():
    text = format_position(1, [300, 0, 400.555, 180, 0, -180], (7, 0))
    assert text == "P1=(300.00,0.00,400.56,180.00,0.00,-180.00)(7,0)"
    with pytest.raises(InvalidInputError):
        format_position(1, [0, 0, 0, 0, 0, float("inf")], (7, 0))
    with pytest.raises(InvalidInputError):
        format_position(1, [0, 0, 0, 0, 0, 0], (9, 0))
