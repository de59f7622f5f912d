"""Random bytes into every reply parser and through the real stream readers: documented errors only, no hang."""

import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from binpick.devices import (
    AiMotor,
    AiMotorConfig,
    DynamixelBus,
    GripperConfig,
    MelfaConfig,
    MelfaRobot,
    ModbusGripper,
    SerialSettings,
)
from binpick.devices.aimotor import decode_reply
from binpick.devices.dynamixel import HEADER, decode_packet, decode_status
from binpick.devices.emulators import PtyEmulator
from binpick.devices.gripper import GripperStatus, decode_response
from binpick.devices.melfa import parse_joints, parse_position, parse_reply, parse_state
from binpick.errors import DeviceError, ProtocolError

FAST = settings(max_examples=300, deadline=None)
text = st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=120)
# strings shaped like the real replies, so the parsers get past their first checks
pose_like = st.lists(
    st.sampled_from(
        ["X", "Y", "Z", "A", "B", "C", "J1", "J6", "", "7,0", "1.5", "-3", "nan", "1e999", "****,****", "x"]
    ),
    max_size=20,
).map(";".join)


@FAST
@given(st.binary(max_size=200))
def test_r3_reply_parser(raw):
    try:
        parse_reply(raw)
    except ProtocolError:
        pass


@FAST
@given(st.one_of(text, pose_like))
def test_r3_data_parsers(data):
    for parse in (parse_position, parse_joints, parse_state):
        try:
            parse(data)
        except ProtocolError:
            pass


@FAST
@given(st.one_of(st.binary(max_size=120), st.binary(max_size=80).map(lambda b: HEADER + b)))
def test_dynamixel_parsers(raw):
    for parse in (decode_packet, decode_status):
        try:
            parse(raw)
        except ProtocolError:
            pass


@FAST
@given(st.binary(max_size=40), st.sampled_from([0x03, 0x04, 0x10]))
def test_modbus_and_aimotor_parsers(raw, function):
    for parse in (lambda r: decode_response(r, slave=9, function=function), decode_reply, GripperStatus.from_bytes):
        try:
            parse(raw)
        except ProtocolError:
            pass


class Chatter(PtyEmulator):
    """Answers every burst of request bytes with the next random payload."""

    device = "chatter"

    def __init__(self):
        super().__init__()
        self.payload = b""

    def _take_requests(self, buf):
        if not buf:
            return []
        data = bytes(buf)
        buf.clear()
        return [data]

    def _handle(self, request):
        return self.payload


@pytest.fixture(scope="module")
def chatter():
    emu = Chatter().start()
    yield emu
    emu.close()


@pytest.fixture(scope="module")
def drivers(chatter):
    line = dict(timeout_s=0.02, retries=1)
    made = [
        MelfaRobot(chatter.slave_path, config=MelfaConfig(serial=SerialSettings(parity="E", stopbits=2, **line))),
        DynamixelBus(chatter.slave_path, settings=SerialSettings(baudrate=57600, **line)),
        AiMotor(chatter.slave_path, config=AiMotorConfig(serial=SerialSettings(baudrate=57600, **line))),
        ModbusGripper(chatter.slave_path, config=GripperConfig(serial=SerialSettings(baudrate=115200, **line))),
    ]
    yield made
    for d in made:
        (d.close_port if isinstance(d, ModbusGripper) else d.close)()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.one_of(
        st.binary(max_size=64),
        st.binary(max_size=32).map(lambda b: HEADER + b),
        st.binary(max_size=32).map(lambda b: b"QoK" + b + b"\r"),
    )
)
def test_stream_readers_on_random_bytes_end_in_documented_errors(chatter, drivers, payload):
    chatter.payload = payload
    robot, bus, ai, gripper = drivers
    calls = [
        robot.read_pose,
        robot.state,
        lambda: bus.ping(1),
        lambda: bus.read(1, 132, 4),
        ai.present_angle,
        gripper.status,
    ]
    for call in calls:
        t = time.monotonic()
        try:
            call()
        except DeviceError:
            pass
        # every read is bounded: 2 attempts × 20 ms plus slack
        assert time.monotonic() - t < 2.0
    assert chatter.failures == []
