"""The physical clock the emulators keep: motion times computed by hand for known paths."""

from __future__ import annotations

import math

import numpy as np
import pytest
from device_settings import FAST_ROBOT

from binpick.devices import CellLimits, GripperConfig, MelfaRobot, ModbusGripper, SerialSettings
from binpick.devices.emulators import GripperEmulator, GripperEmulatorConfig, RobotEmulator, RobotEmulatorConfig
from binpick.devices.emulators.clock import PhysicalClock, trapezoid_s
from binpick.devices.emulators.motor import STATUS_POLL_S
from binpick.errors import InvalidInputError

RV1A_CLASS = (180.0, 90.0, 135.0, 180.0, 200.0, 330.0)


def test_trapezoid_by_hand():
    # 90° at 180°/s reaching full speed in 0.2 s: 0.5 s at speed + 0.2 s of ramps.
    assert trapezoid_s(90.0, 180.0, 0.2) == pytest.approx(0.7)
    # 10° never reaches full speed (it would need 36°): accelerate 900°/s² to the middle and back.
    assert trapezoid_s(10.0, 180.0, 0.2) == pytest.approx(2 * math.sqrt(2 * 5.0 / 900.0))
    assert trapezoid_s(-90.0, 180.0, 0.0) == pytest.approx(0.5)
    assert trapezoid_s(0.0, 180.0, 0.2) == 0.0


def test_clock_refuses_negative_time():
    with pytest.raises(InvalidInputError, match="seconds"):
        PhysicalClock().spend(-1.0, "robot")


@pytest.fixture
def timed_arm():
    clock = PhysicalClock()
    emulator = RobotEmulator(config=RobotEmulatorConfig(joint_speeds_deg_s=RV1A_CLASS, ramp_s=0.2, speed_scale=40.0))
    emulator.clock = clock
    emulator.start()
    robot = MelfaRobot(emulator.slave_path, config=FAST_ROBOT, limits=CellLimits())
    robot.open_session()
    yield robot, emulator, clock
    robot.close_session()
    robot.close()
    emulator.close()
    assert emulator.failures == []


def test_joint_move_takes_the_time_of_its_slowest_joint(timed_arm):
    robot, emulator, clock = timed_arm
    home = emulator.pose()
    turn = np.eye(4)
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    turn[:2, :2] = [[c, -s], [s, c]]
    before = clock.now()
    robot.move_to(turn @ home)  # only J1 turns, 30°
    q = np.degrees(emulator.joints())
    assert q[0] == pytest.approx(30.0, abs=1e-3)
    # J1 at 180°/s × 50 % override = 90°/s: 30/90 s at speed, 0.2 s of ramps.
    # (the pose travels as text rounded to 0.01 mm and 0.01°: within 0.1 ms)
    assert clock.now() - before == pytest.approx(30.0 / 90.0 + 0.2, abs=1e-4)
    assert clock.by_device == {"robot": pytest.approx(clock.now())}


def test_straight_move_takes_its_length_at_the_commanded_speed(timed_arm):
    robot, emulator, clock = timed_arm
    start = emulator.pose()
    target = start.copy()
    target[2, 3] -= 100.0
    before = clock.now()
    robot.move_to(target, linear=True)
    np.testing.assert_allclose(emulator.pose()[:3, 3], target[:3, 3], atol=0.02)
    # 200 mm/s × 50 % = 100 mm/s over 100 mm: 1 s at speed, 0.2 s of ramps (the joints, J2 at
    # 45°/s, turn well under 45° for a 100 mm drop, so the straight line decides).
    assert clock.now() - before == pytest.approx(1.2, abs=1e-4)


@pytest.fixture
def gripper_on_a_clock():
    """A Modbus gripper driver and its emulator (fingers at 60–450 units/s, activation 0.05 s)
    on a fresh clock."""
    clock = PhysicalClock()
    emulator = GripperEmulator(
        config=GripperEmulatorConfig(
            activation_s=0.05, min_speed_units_s=60.0, max_speed_units_s=450.0, speed_scale=20.0
        )
    )
    emulator.clock = clock
    emulator.start()
    gripper = ModbusGripper(
        emulator.slave_path, config=GripperConfig(serial=SerialSettings(baudrate=115200, timeout_s=0.3), speed=255)
    )
    yield gripper, clock
    gripper.close_port()
    emulator.close()
    assert emulator.failures == []


def test_gripper_fingers_take_their_travel_at_their_speed(gripper_on_a_clock):
    gripper, clock = gripper_on_a_clock
    gripper.activate()
    assert clock.now() == pytest.approx(0.05)
    gripper.close()  # 255 units at 450 units/s (SPEED 255), nothing between the fingers
    assert clock.now() == pytest.approx(0.05 + 255.0 / 450.0, abs=1e-6)
    gripper.open()
    assert clock.now() == pytest.approx(0.05 + 2 * 255.0 / 450.0, abs=1e-6)


def test_the_fingers_move_while_the_arm_does_and_a_wait_takes_only_what_is_left(gripper_on_a_clock):
    gripper, clock = gripper_on_a_clock
    travel = 255.0 / 450.0  # fully closed to fully open at SPEED 255
    gripper.activate()
    gripper.close()
    t0 = clock.now()
    gripper.open_for_grasp(85.0, wait=False)  # sent; the arm moves meanwhile for longer than the fingers
    clock.spend(travel + 0.3, "robot")
    gripper.settle()
    assert clock.now() - t0 == pytest.approx(travel + 0.3, abs=1e-6)
    # An arm move shorter than the fingers' travel: the wait takes what is left of it.
    t0 = clock.now()
    gripper.close(wait=False)
    clock.spend(0.2, "robot")
    gripper.settle()
    assert clock.now() - t0 == pytest.approx(travel, abs=1e-6)
    # Releasing a part opens only to the width asked: 40 mm of the 85 mm stroke.
    t0 = clock.now()
    gripper.release(40.0)
    assert clock.now() - t0 == pytest.approx(round(255 * 40.0 / 85.0) / 450.0, abs=1e-6)


def test_a_motor_whose_protocol_sends_no_speed_cannot_sweep_continuously(ai_motor):
    with pytest.raises(InvalidInputError, match=r'AiMotor protocol sets no speed.*sweep = "steps"'):
        ai_motor.set_speed(0.2)


def test_the_servo_turns_on_the_clock_and_a_wait_for_it_takes_its_travel(dxl_emulator, dxl_motor):
    clock = PhysicalClock()
    dxl_emulator.clock = clock
    dxl_motor.enable()
    speed = dxl_motor.set_speed(math.radians(90.0))  # the profile velocity's units round it
    assert speed == pytest.approx(math.radians(90.0), rel=0.01)
    start = dxl_motor.present_angle()
    dxl_motor.move_to(start + math.radians(30.0), wait=False)
    # A read while it turns takes its bus time; the position is the one at the read's middle.
    here = dxl_motor.present_angle()
    assert clock.now() == pytest.approx(STATUS_POLL_S)
    assert here == pytest.approx(start + speed * STATUS_POLL_S / 2, abs=2 * math.pi / 4096)  # a tick
    reached = dxl_motor.wait_until_reached()
    assert reached == pytest.approx(start + math.radians(30.0), abs=math.radians(0.1))
    # Waiting polls the moving status; the polls take the servo's travel (whole ticks), no more.
    assert clock.now() == pytest.approx(abs(reached - start) / speed, abs=1e-6)
