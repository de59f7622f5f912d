"""Fixtures: each emulator on a real pty, and the real driver opened on its slave path."""

from __future__ import annotations

import math

import pytest
from device_settings import FAST_ROBOT

from binpick.devices import (
    AiMotor,
    AiMotorConfig,
    CellLimits,
    DynamixelConfig,
    DynamixelMotor,
    GripperConfig,
    MelfaRobot,
    ModbusGripper,
    MotorRange,
    SerialSettings,
)
from binpick.devices.emulators import (
    AiMotorEmulator,
    DynamixelEmulator,
    GripperEmulator,
    RobotEmulator,
    RobotEmulatorConfig,
)
from binpick.errors import DeviceError

FAST_RANGE = MotorRange(max_speed_rad_s=30.0, move_timeout_s=2.0, poll_interval_s=0.005)


def _serve(emulator):
    emulator.start()
    yield emulator
    emulator.close()
    assert emulator.failures == [], "the emulator raised while handling requests"


@pytest.fixture
def robot_emulator():
    yield from _serve(RobotEmulator(config=RobotEmulatorConfig(speed_scale=40.0)))


@pytest.fixture
def robot(robot_emulator):
    r = MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT, limits=CellLimits())
    r.open_session()
    yield r
    try:
        r.close_session()
    except DeviceError:  # tests that kill the port leave no session to close
        pass
    finally:
        r.close()


@pytest.fixture
def dxl_emulator():
    yield from _serve(DynamixelEmulator())


@pytest.fixture
def dxl_motor(dxl_emulator):
    m = DynamixelMotor(
        dxl_emulator.slave_path,
        config=DynamixelConfig(serial=SerialSettings(baudrate=57600, timeout_s=0.1), range=FAST_RANGE),
    )
    yield m
    m.close()


@pytest.fixture
def ai_emulator():
    yield from _serve(AiMotorEmulator())


@pytest.fixture
def ai_motor(ai_emulator):
    m = AiMotor(
        ai_emulator.slave_path,
        config=AiMotorConfig(
            serial=SerialSettings(baudrate=57600, timeout_s=0.1),
            range=MotorRange(tolerance_rad=math.radians(1.5), move_timeout_s=2.0, poll_interval_s=0.005),
        ),
    )
    yield m
    m.close()


@pytest.fixture
def gripper_emulator():
    yield from _serve(GripperEmulator())


@pytest.fixture
def gripper(gripper_emulator):
    g = ModbusGripper(
        gripper_emulator.slave_path,
        config=GripperConfig(
            serial=SerialSettings(baudrate=115200, timeout_s=0.1), poll_interval_s=0.005, move_timeout_s=2.0
        ),
    )
    yield g
    g.close_port()
