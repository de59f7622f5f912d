"""Property tests of the drivers' motion and setting methods over their argument space (issue 16
item 6), each driver against its emulator on a pty (one per module): MelfaRobot's move_to,
move_sequence, set_override, set_linear_speed, open_hand and close_hand, error_message and
wait_until_idle, and the laser motor's move_to (LaserMotor's, on the Dynamixel driver). Each call
ends in a result or a BinpickError (TypeError for a wrong Python type), within seconds, and
nothing unsafe reaches the emulator: every position the robot is sent, and where the arm ends
up, lies within the cell's limits; no override or speed above them is ever set; a refused call
sends no motion, setting or hand command at all; the motor is never sent a goal outside its range."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from device_settings import FAST_ROBOT
from hypothesis import given
from hypothesis import strategies as st

from _properties import PROPERTY, anything, attempt, ints, mostly, reals, transforms
from binpick.devices import CellLimits, DynamixelConfig, DynamixelMotor, MelfaRobot, MotorRange, SerialSettings, safety
from binpick.devices.emulators import DynamixelEmulator, RobotEmulator, RobotEmulatorConfig
from binpick.devices.xyzabc import transform_from_xyzabc, xyzabc_from_wire
from binpick.errors import InvalidInputError, SafetyError

LIMITS = CellLimits()
#: The limits widened by the wire's rounding (positions go out with two decimals, in mm and degrees).
WIRE_LIMITS = replace(
    LIMITS,
    workspace_min_mm=tuple(v - 0.01 for v in LIMITS.workspace_min_mm),
    workspace_max_mm=tuple(v + 0.01 for v in LIMITS.workspace_max_mm),
    max_tool_tilt_rad=LIMITS.max_tool_tilt_rad + math.radians(0.01),
)
#: What moves the arm, changes its speed or works the hand.
ACTING = ("EXEC", "OVRD", "HND")


@pytest.fixture(scope="module")
def arm():
    """The MELFA driver with its session open on the R3 controller emulator."""
    emulator = RobotEmulator(config=RobotEmulatorConfig(speed_scale=40.0)).start()
    try:
        with MelfaRobot(emulator.slave_path, config=FAST_ROBOT, limits=LIMITS) as robot:
            yield robot, emulator
    finally:
        emulator.close()
    assert emulator.failures == [], "the emulator raised while handling requests"


def _commands(emulator, since: int) -> list[str]:
    return [r.split(";", 2)[2] for r in emulator.requests[since:]]


def _acted(robot, emulator, call, what):
    """Runs ``call`` (an attempt: a result or an allowed error), then checks what reached the
    controller: every position sent and the arm's pose within the limits, no override or speed
    above them, and nothing acting at all after a refusal. Leaves the arm at rest, alarm reset."""
    since = len(emulator.requests)
    result, error = attempt(call, what)
    sent = _commands(emulator, since)
    if isinstance(error, (SafetyError, InvalidInputError)):
        assert not [c for c in sent if c.startswith(ACTING)], f"{what} was refused ({error}) but sent {sent}"
    for c in sent:
        if m := re.fullmatch(r"EXECP\d+=\(([^)]*)\)\(([^)]*)\)", c):
            safety.check_pose(transform_from_xyzabc(xyzabc_from_wire([float(v) for v in m[1].split(",")])), WIRE_LIMITS)
        elif m := re.fullmatch(r"OVRD=(\d+)", c):
            assert 1 <= int(m[1]) <= LIMITS.max_override_percent, c
        elif m := re.fullmatch(r"EXECSPD (\S+)", c):
            assert 0 < float(m[1]) <= LIMITS.max_linear_speed_mm_s, c
        else:
            assert not c.startswith(("EXEC", "OVRD")) or c in ("EXECMOV P1", "EXECMVS P1"), c
    robot.wait_until_idle(timeout_s=5.0) if emulator.is_moving() else None
    if emulator.alarm:  # an unreachable target: the controller refused it (DeviceFault), the arm stopped
        robot.reset_alarm()
    safety.check_pose(emulator.pose(), WIRE_LIMITS)
    override, speed = emulator.speeds
    assert override <= LIMITS.max_override_percent and speed <= LIMITS.max_linear_speed_mm_s
    return result, error


#: Flange poses pointing down (up to 50° off), around and beyond the workspace, three times in four.
poses = mostly(
    st.builds(
        lambda x, y, z, a, b: transform_from_xyzabc([x, y, z, math.pi + a, b, math.pi]),
        st.floats(60.0, 460.0),
        st.floats(-340.0, 340.0),
        st.floats(-40.0, 560.0),
        st.floats(-0.9, 0.9),
        st.floats(-0.9, 0.9),
    ),
    transforms,
)
switches = mostly(st.booleans())


@PROPERTY
@given(
    T=poses,
    linear=switches,
    flags=mostly(st.none(), st.sampled_from([(7, 0), (6, 0), (9, 9), (1.5, 0), ()]), anything),
    wait=switches,
)
def test_property_move_to(arm, T, linear, flags, wait):
    robot, emulator = arm
    _acted(robot, emulator, lambda: robot.move_to(T, linear=linear, flags=flags, wait=wait), "move_to")


@PROPERTY
@given(
    targets=mostly(st.lists(poses, max_size=3)),
    linear=mostly(st.booleans(), st.lists(switches, max_size=3), anything),
)
def test_property_move_sequence(arm, targets, linear):
    robot, emulator = arm
    _acted(robot, emulator, lambda: robot.move_sequence(targets, linear=linear), "move_sequence")


@PROPERTY
@given(
    setting=st.sampled_from(["set_override", "set_linear_speed"]),
    value=st.one_of(reals(-10.0, 120.0), reals(-10.0, 400.0)),
)
def test_property_speed_settings(arm, setting, value):
    robot, emulator = arm
    try:
        _, error = _acted(robot, emulator, lambda: getattr(robot, setting)(value), setting)
        if error is None:
            override, speed = emulator.speeds
            assert (
                (override == int(round(value)))
                if setting == "set_override"
                else math.isclose(speed, value, abs_tol=0.005)
            )
    finally:  # back to the driver's speeds, so that later moves take as long as ever
        robot.set_override(FAST_ROBOT.initial_override_percent)
        robot.set_linear_speed(FAST_ROBOT.initial_linear_speed_mm_s)


@PROPERTY
@given(opening=st.booleans(), hand=ints(-1, 10))
def test_property_open_and_close_hand(arm, opening, hand):
    robot, emulator = arm
    _, error = _acted(robot, emulator, lambda: (robot.open_hand if opening else robot.close_hand)(hand), "hand")
    if error is None:
        assert emulator.hands[hand] is opening


@PROPERTY
@given(number=ints(-1, 120_000))
def test_property_error_message(arm, number):
    robot, emulator = arm
    text, error = _acted(robot, emulator, lambda: robot.error_message(number), "error_message")
    if error is None:
        assert isinstance(text, str)


@PROPERTY
@given(timeout=st.one_of(st.none(), reals(-1.0, 3.0)))
def test_property_wait_until_idle(arm, timeout):
    robot, emulator = arm
    _, error = _acted(robot, emulator, lambda: robot.wait_until_idle(timeout), "wait_until_idle")
    if error is None:
        assert not emulator.is_moving()


# --------------------------------------------------------------------------- the laser motor

RANGE = MotorRange(max_speed_rad_s=30.0, move_timeout_s=2.0, poll_interval_s=0.005)


@pytest.fixture(scope="module")
def motor():
    emulator = DynamixelEmulator().start()
    try:
        config = DynamixelConfig(serial=SerialSettings(baudrate=57600, timeout_s=0.1), range=RANGE)
        with DynamixelMotor(emulator.slave_path, config=config) as m:
            m.enable()
            yield m
    finally:
        emulator.close()
    assert emulator.failures == []


@PROPERTY
@given(angle=reals(-4.0, 4.0), wait=switches)
def test_property_motor_move_to(motor, angle, wait):
    before = motor.read_goal_angle()
    reached, error = attempt(lambda: motor.move_to(angle, wait=wait), "LaserMotor.move_to")
    goal = motor.read_goal_angle()
    assert RANGE.min_angle_rad - 1e-3 <= goal <= RANGE.max_angle_rad + 1e-3, f"goal {goal} outside the range"
    if error is not None:
        assert goal == before, f"a refused move ({error}) changed the goal"
    else:
        assert abs(goal - angle) < 2e-3  # one tick
        assert not wait or abs(reached - angle) <= RANGE.tolerance_rad
    motor.wait_until_reached()


#: What these properties found, refused now with nothing sent.
FOUND = [
    (lambda robot: robot.move_to(robot.read_pose(), linear="no"), "linear"),  # taken for True: a straight move
    (lambda robot: robot.move_to(robot.read_pose(), linear=np.zeros(2)), "linear"),  # ValueError
    (lambda robot: robot.move_to(robot.read_pose(), wait=np.zeros(2)), "wait"),  # ValueError
    (lambda robot: robot.move_to(robot.read_pose(), flags=np.array([7, 0])), "flags"),  # ValueError
    (lambda robot: robot.move_sequence([robot.read_pose()], linear=None), "linear"),  # TypeError
    (lambda robot: robot.move_sequence([robot.read_pose()], linear=[np.zeros(2)]), r"linear\[0\]"),  # ValueError
]


@pytest.mark.parametrize("call, name", FOUND)
def test_driver_arguments_found_by_the_properties(arm, call, name):
    robot, emulator = arm
    since = len(emulator.requests)
    with pytest.raises(InvalidInputError, match=name):
        call(robot)
    assert not [c for c in _commands(emulator, since) if c.startswith(ACTING)]


def test_a_motor_wait_that_is_not_a_bool_is_refused_before_the_goal_is_sent(motor):
    before = motor.read_goal_angle()
    with pytest.raises(InvalidInputError, match="wait"):
        motor.move_to(0.2, wait=np.zeros(2))
    assert motor.read_goal_angle() == before
