"""Property tests of the device layer's public configs and checks over their argument space
(issue 16 item 6): every driver config, the serial settings, the motor range, the cell's limits
and each safety check, the X Y Z A B C conversions and the request encoders end in a result or a
BinpickError (TypeError for a wrong Python type), and what they accept is what they promise."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from _properties import PROPERTY, anything, finite, ints, outcome, reals, rigid, transforms, variations, vectors
from binpick.devices import (
    AiMotorConfig,
    CellLimits,
    DynamixelConfig,
    GripperConfig,
    MelfaConfig,
    MotorRange,
    SerialSettings,
    safety,
    transform_from_xyzabc,
    xyzabc_from_transform,
)
from binpick.devices.aimotor import encode_position, encode_request
from binpick.devices.dynamixel import encode_read, encode_write
from binpick.devices.gripper import encode_read_input_registers, encode_write_registers
from binpick.devices.melfa import encode_command, format_position
from binpick.devices.xyzabc import rotation_from_abc, xyzabc_from_wire, xyzabc_to_wire
from binpick.transforms import look_down

LIMITS = CellLimits()
HOME = look_down(300.0, 0.0, 400.0)


def _made(cls, kwargs):
    return outcome(lambda: cls(**kwargs), cls.__name__)


SERIAL = dict(baudrate=9600, bytesize=8, parity="N", stopbits=1, timeout_s=1.0, write_timeout_s=1.0, retries=2)


@PROPERTY
@given(
    kw=variations(
        SERIAL,
        dict(
            baudrate=ints(0, 30_000_000),
            bytesize=ints(4, 9),
            parity=st.one_of(st.sampled_from(["N", "E", "O", "M", "S", "X", "n"]), anything),
            stopbits=st.one_of(st.sampled_from([1, 1.5, 2, 3, 0, 1.0]), anything),
            timeout_s=reals(-1, 4000),
            write_timeout_s=reals(-1, 4000),
            retries=ints(-1, 12),
        ),
    )
)
def test_property_serial_settings(kw):
    s = _made(SerialSettings, kw)
    if s is not None:
        assert 50 <= s.baudrate <= 20_000_000 and 5 <= s.bytesize <= 8 and s.parity in "NEOMS"
        assert s.stopbits in (1, 1.5, 2) and 0 < s.timeout_s <= 3600 and 0 < s.write_timeout_s <= 3600
        assert 0 <= s.retries <= 10


RANGE = dict(MotorRange().__dict__)


@PROPERTY
@given(
    kw=variations(
        RANGE,
        dict(
            min_angle_rad=reals(-4, 4),
            max_angle_rad=reals(-4, 4),
            max_speed_rad_s=reals(-1, 10),
            tolerance_rad=reals(-0.1, 4),
            move_timeout_s=reals(-1, 20),
            poll_interval_s=reals(-0.01, 0.1),
            settle_s=reals(-0.01, 0.1),
        ),
    )
)
def test_property_motor_range(kw):
    r = _made(MotorRange, kw)
    if r is not None:
        assert -math.pi <= r.min_angle_rad < r.max_angle_rad <= math.pi
        assert r.max_speed_rad_s > 0 and r.move_timeout_s > 0 and r.poll_interval_s > 0 and r.settle_s >= 0


serials = st.one_of(st.just(SerialSettings()), st.just(MotorRange()), anything)
ranges = st.one_of(st.just(MotorRange()), st.just(SerialSettings()), anything)


@PROPERTY
@given(
    kw=variations(
        dict(DynamixelConfig().__dict__),
        dict(
            motor_id=ints(-1, 260),
            serial=serials,
            range=ranges,
            ticks_per_revolution=ints(0, 1 << 25),
            zero_tick=ints(-(1 << 31), 1 << 31),
            velocity_unit_rpm=reals(-1, 200),
        ),
    )
)
def test_property_dynamixel_config(kw):
    c = _made(DynamixelConfig, kw)
    if c is not None:
        assert 0 <= c.motor_id <= 252 and 2 <= c.ticks_per_revolution <= 1 << 24
        assert isinstance(c.serial, SerialSettings) and isinstance(c.range, MotorRange)
        assert 0 < c.velocity_unit_rpm <= 100


@PROPERTY
@given(
    kw=variations(
        dict(AiMotorConfig().__dict__),
        dict(
            motor_id=ints(-1, 31),
            serial=serials,
            range=ranges,
            torque_level=ints(-1, 5),
            degrees_per_unit=reals(-1, 11),
            centre_unit=ints(-1, 255),
        ),
    )
)
def test_property_ai_motor_config(kw):
    c = _made(AiMotorConfig, kw)
    if c is not None:
        assert 0 <= c.motor_id <= 30 and 0 <= c.torque_level <= 4 and 0 <= c.centre_unit <= 254
        assert 1e-3 <= c.degrees_per_unit <= 10
        assert isinstance(c.serial, SerialSettings) and isinstance(c.range, MotorRange)


@PROPERTY
@given(
    kw=variations(
        dict(GripperConfig().__dict__),
        dict(
            slave=ints(0, 248),
            serial=serials,
            stroke_mm=reals(-1, 200),
            speed=ints(-1, 256),
            force=ints(-1, 256),
            max_speed=ints(-1, 256),
            max_force=ints(-1, 256),
            activation_timeout_s=reals(-1, 10),
            move_timeout_s=reals(-1, 10),
            poll_interval_s=reals(-0.01, 0.1),
        ),
    )
)
def test_property_gripper_config(kw):
    c = _made(GripperConfig, kw)
    if c is not None:
        assert 1 <= c.slave <= 247 and c.stroke_mm > 0 and isinstance(c.serial, SerialSettings)
        assert 0 <= c.speed <= c.max_speed <= 255 and 0 <= c.force <= c.max_force <= 255
        assert c.activation_timeout_s > 0 and c.move_timeout_s > 0 and c.poll_interval_s > 0


@PROPERTY
@given(
    kw=variations(
        dict(MelfaConfig().__dict__),
        dict(
            serial=serials,
            robot_number=ints(-1, 100),
            slot=ints(-1, 100),
            client_name=st.one_of(st.sampled_from(["NARCUSR", "a b", "", "x" * 40, "é"]), anything),
            position_variable=ints(0, 1000),
            default_flags=st.one_of(st.tuples(ints(-1, 8), ints(-(2**31), 2**31)), anything),
            initial_override_percent=reals(0, 101),
            initial_linear_speed_mm_s=reals(-1, 500),
            servo_on_timeout_s=reals(-1, 100),
            motion_timeout_s=reals(-1, 100),
            poll_interval_s=reals(-0.1, 1),
            arrival_tolerance_mm=reals(-1, 5),
        ),
    )
)
def test_property_melfa_config(kw):
    c = _made(MelfaConfig, kw)
    if c is not None:
        assert isinstance(c.serial, SerialSettings) and 0 <= c.robot_number <= 99 and 1 <= c.position_variable <= 999
        assert 1 <= c.initial_override_percent <= 100 and c.arrival_tolerance_mm >= 0
        fl1, fl2 = c.default_flags  # sent with every move whose flags cannot be read
        assert 0 <= fl1 <= 7 and -(2**31) <= fl2 < 2**31


@PROPERTY
@given(
    kw=variations(
        dict(CellLimits().__dict__),
        dict(
            workspace_min_mm=vectors(3, -500, 500),
            workspace_max_mm=vectors(3, -500, 800),
            max_tool_tilt_rad=reals(-1, 4),
            approach_height_mm=reals(-100, 600),
            max_lateral_below_mm=reals(-10, 100),
            max_override_percent=reals(0, 101),
            max_linear_speed_mm_s=reals(-1, 1000),
        ),
    )
)
def test_property_cell_limits(kw):
    c = _made(CellLimits, kw)
    if c is not None:
        assert (np.asarray(c.workspace_max_mm, float) > np.asarray(c.workspace_min_mm, float)).all()
        assert 0 <= c.max_tool_tilt_rad <= math.pi and 1 <= c.max_override_percent <= 100
        assert finite([c.approach_height_mm, c.max_lateral_below_mm, c.max_linear_speed_mm_s])


limits = st.one_of(st.just(LIMITS), st.just(CellLimits(max_tool_tilt_rad=0.1)), anything)
poses = st.one_of(
    st.builds(
        lambda x, y, z, a: look_down(x, y, z) @ rigid(a, (0, 0, 1), (0, 0, 0)),
        st.floats(0, 500),
        st.floats(-400, 400),
        st.floats(-50, 600),
        st.floats(-math.pi, math.pi),
    ),
    transforms,
)


def _inside(T, lim):
    lo, hi = np.asarray(lim.workspace_min_mm), np.asarray(lim.workspace_max_mm)
    tilt = math.acos(max(-1.0, min(1.0, -float(T[2, 2]))))
    return bool((lo <= T[:3, 3]).all() and (T[:3, 3] <= hi).all() and tilt <= lim.max_tool_tilt_rad + 1e-9)


@PROPERTY
@given(T=poses, lim=limits, name=st.one_of(st.just("target"), anything))
def test_property_check_pose(T, lim, name):
    out = outcome(lambda: safety.check_pose(T, lim, name=name), "check_pose")
    if out is not None:
        assert out.shape == (4, 4) and _inside(out, lim)


@PROPERTY
@given(start=poses, target=poses, linear=st.one_of(st.booleans(), anything), lim=limits)
def test_property_check_move(start, target, linear, lim):
    out = outcome(lambda: safety.check_move(start, target, linear=linear, limits=lim), "check_move")
    if out is not None:
        assert _inside(out, lim)
        low = min(float(np.asarray(start, float)[2, 3]), out[2, 3]) < lim.approach_height_mm
        assert not low or (bool(linear) and np.hypot(*(out[:2, 3] - np.asarray(start, float)[:2, 3])) <= 30.0)


@PROPERTY
@given(
    start=poses,
    targets=st.one_of(st.lists(poses, max_size=3), anything),
    linear=st.one_of(st.lists(st.booleans(), max_size=3), anything),
    names=st.one_of(st.none(), st.lists(st.text(max_size=3), max_size=3), anything),
    lim=limits,
)
def test_property_check_sequence(start, targets, linear, names, lim):
    out = outcome(lambda: safety.check_sequence(start, targets, linear, lim, names=names), "check_sequence")
    if out is not None:
        assert len(out) == len(targets) and all(_inside(T, lim) for T in out)


@PROPERTY
@given(percent=reals(-5, 120), speed=reals(-5, 400), lim=limits)
def test_property_override_and_speed_never_exceed_the_limits(percent, speed, lim):
    p = outcome(lambda: safety.check_override(percent, lim), "check_override")
    if p is not None:
        assert 1 <= p <= lim.max_override_percent
    v = outcome(lambda: safety.check_linear_speed(speed, lim), "check_linear_speed")
    if v is not None:
        assert 0 < v <= lim.max_linear_speed_mm_s


@PROPERTY
@given(xyzabc=vectors(6, -math.pi, math.pi))
def test_property_xyzabc_round_trip(xyzabc):
    T = outcome(lambda: transform_from_xyzabc(xyzabc), "transform_from_xyzabc")
    if T is not None:
        back = transform_from_xyzabc(xyzabc_from_transform(T))
        np.testing.assert_allclose(back, T, atol=1e-9)
    wire = outcome(lambda: xyzabc_to_wire(xyzabc), "xyzabc_to_wire")
    if wire is not None:
        np.testing.assert_allclose(xyzabc_from_wire(wire), np.asarray(xyzabc, float), atol=1e-12)


@PROPERTY
@given(T=transforms)
def test_property_xyzabc_from_transform(T):
    v = outcome(lambda: xyzabc_from_transform(T), "xyzabc_from_transform")
    if v is not None:
        np.testing.assert_allclose(transform_from_xyzabc(v), np.asarray(T, float), atol=1e-9)


@PROPERTY
@given(a=reals(-4, 4), b=reals(-4, 4), c=reals(-4, 4))
def test_property_rotation_from_abc(a, b, c):
    R = outcome(lambda: rotation_from_abc(a, b, c), "rotation_from_abc")
    if R is not None:
        assert finite(R) and np.allclose(R.T @ R, np.eye(3), atol=1e-12)


@PROPERTY
@given(
    command=st.one_of(st.text(max_size=8), st.sampled_from(["OPEN=X", "a\rb", "x" * 251]), anything),
    robot=ints(-1, 100),
    slot=ints(-1, 100),
    number=ints(0, 1000),
    pose=vectors(6, -1e5, 1e5),
    flags=st.one_of(st.tuples(ints(-1, 8), ints(-5, 5)), anything),
)
def test_property_melfa_request_encoders(command, robot, slot, number, pose, flags):
    raw = outcome(lambda: encode_command(command, robot=robot, slot=slot), "encode_command")
    if raw is not None:
        assert raw.endswith(b"\r") and raw.count(b"\r") == 1 and raw.decode("ascii")
    text = outcome(lambda: format_position(number, pose, flags), "format_position")
    if text is not None:
        assert text.startswith(f"P{number}=(") and "nan" not in text and "inf" not in text


@PROPERTY
@given(
    ids=st.tuples(ints(-1, 260), ints(-1, 70000), ints(-1, 300)),
    data=st.one_of(st.binary(max_size=8), anything),
    regs=st.one_of(st.lists(ints(-1, 70000), max_size=4), anything),
)
def test_property_motor_and_gripper_encoders(ids, data, regs):
    a, b, c = ids
    for name, call in (
        ("dynamixel encode_read", lambda: encode_read(a, b, c)),
        ("dynamixel encode_write", lambda: encode_write(a, b, data)),
        ("ai-motor encode_request", lambda: encode_request(a, c)),
        ("ai-motor encode_position", lambda: encode_position(a, c, torque_level=a)),
        ("modbus encode_write_registers", lambda: encode_write_registers(a, b, regs)),
        ("modbus encode_read_input_registers", lambda: encode_read_input_registers(a, b, c)),
    ):
        raw = outcome(call, name)
        assert raw is None or (isinstance(raw, bytes) and 0 < len(raw) < 300), name
