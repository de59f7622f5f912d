"""Move-and-report: the angle a laser motor driver returns (and a frame is tagged with) is read
after the motor has stopped, so it is where the motor stays. The emulators on ptys take time to
move, like the motors do."""

import math
import time

import numpy as np
import pytest

from binpick.devices import AiMotor, AiMotorConfig, DynamixelConfig, DynamixelMotor, MotorRange, SerialSettings
from binpick.devices.emulators import AiMotorEmulator, DynamixelEmulator
from binpick.errors import DeviceTimeout

TICKS_PER_RAD = 4096 / (2 * math.pi)


def _driven(emulator, driver, config):
    """The emulator serving on its pty and the driver (torque on) opened on it."""
    with emulator as emu:
        motor = driver(emu.slave_path, config=config)
        try:
            motor.enable()
            yield motor, emu
        finally:
            motor.close()
        assert emu.failures == []


@pytest.fixture
def slow_dxl():
    """A Dynamixel turning at 2π rad/s (the simulated cell's speed)."""
    serial = SerialSettings(baudrate=57600, timeout_s=0.1)
    motion = MotorRange(max_speed_rad_s=2 * math.pi, move_timeout_s=2.0, poll_interval_s=0.002)
    yield from _driven(DynamixelEmulator(), DynamixelMotor, DynamixelConfig(serial=serial, range=motion))


def test_dynamixel_sweep_reports_the_angle_it_stopped_at(slow_dxl):
    motor, emu = slow_dxl
    goals = [math.radians(d) for d in (*np.arange(-60.0, 60.0, 1.5), *np.arange(60.0, -60.0, -1.5))]
    for k, goal in enumerate(goals):
        reached = motor.move_to(goal)
        with emu._lock:
            moving, ticks = emu.axis.moving(), emu.axis.position()
        assert not moving, f"step {k}: move_to returned while the motor was still turning"
        assert ticks == pytest.approx(2048 + reached * TICKS_PER_RAD, abs=1e-9), (
            f"step {k}: reported {math.degrees(reached):.3f}°, the motor stopped at "
            f"{math.degrees((ticks - 2048) / TICKS_PER_RAD):.3f}°"
        )
        assert reached == pytest.approx(goal, abs=math.radians(0.5))


def test_dynamixel_reports_at_rest_after_a_long_move(slow_dxl):
    motor, emu = slow_dxl
    t = time.monotonic()
    reached = motor.move_to(math.radians(80))
    assert time.monotonic() - t > math.radians(80) / (2 * math.pi) * 0.8
    assert not emu.axis.moving()
    assert emu.present_position() == pytest.approx(2048 + reached * TICKS_PER_RAD, abs=1e-9)


def test_dynamixel_that_never_settles_times_out(slow_dxl):
    motor, emu = slow_dxl
    motor.range = MotorRange(max_speed_rad_s=0.3, move_timeout_s=0.2, poll_interval_s=0.002)
    motor.enable()  # sends the new speed limit: 60° take 3.5 s
    t = time.monotonic()
    with pytest.raises(DeviceTimeout, match="still at"):
        motor.move_to(math.radians(60))
    assert time.monotonic() - t < 0.6


@pytest.fixture
def ai():
    serial = SerialSettings(baudrate=57600, timeout_s=0.1)
    motion = MotorRange(tolerance_rad=math.radians(1.5), move_timeout_s=2.0, poll_interval_s=0.005)
    yield from _driven(AiMotorEmulator(), AiMotor, AiMotorConfig(serial=serial, range=motion))


def test_ai_motor_reports_the_angle_it_stopped_at(ai):
    motor, emu = ai
    scale = motor.config.degrees_per_unit
    for k in range(1, 9):
        reached = motor.move_to(math.radians(5.0 * k))
        with emu._lock:
            moving, units = emu.axis.moving(), emu.axis.position()
        assert not moving, f"step {k}: move_to returned while the motor was still turning"
        assert units == pytest.approx(127 + math.degrees(reached) / scale, abs=1e-6)


def test_ai_motor_that_never_settles_times_out(ai):
    motor, emu = ai
    motor.range = MotorRange(tolerance_rad=math.radians(1.5), move_timeout_s=0.1, poll_interval_s=0.005)
    with emu._lock:
        emu.axis.speed = 20.0  # 60 units to go: 3 s
    with pytest.raises(DeviceTimeout, match="still at"):
        motor.move_to(math.radians(80))
