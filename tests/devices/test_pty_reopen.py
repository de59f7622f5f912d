"""A port served by an emulator reopens as a real serial line does: the MELFA line (9600 8E2,
parity a pty cannot hold) and the parity-free motor and gripper lines, each closed and opened
again by its real driver, with a request in every session."""

from __future__ import annotations

import termios
import time

import numpy as np
from device_settings import FAST_ROBOT

from binpick.devices import DynamixelMotor, GripperConfig, MelfaRobot, ModbusGripper, SerialSettings
from binpick.devices.emulators import DynamixelEmulator, GripperEmulator, RobotEmulator
from binpick.devices.emulators._pty import IDLE_BAUD, REST_DELAY_S
from binpick.errors import PortClosedError

REOPENS = 8


def test_the_robot_port_reopens_and_rests_at_the_idle_speed():
    with RobotEmulator() as emu:
        for _ in range(REOPENS):
            robot = MelfaRobot(emu.slave_path, config=FAST_ROBOT)
            robot.open_session()
            assert np.isfinite(robot.read_pose()).all()
            robot.close_session()
            robot.close()
        time.sleep(10 * REST_DELAY_S)
        assert termios.tcgetattr(emu._slave)[4] == IDLE_BAUD
        assert emu.failures == []


def test_a_port_opened_and_closed_without_a_request_reopens_after_a_pause():
    with RobotEmulator() as emu:
        for _ in range(REOPENS):
            MelfaRobot(emu.slave_path, config=FAST_ROBOT).close()
            time.sleep(5 * REST_DELAY_S)
        robot = MelfaRobot(emu.slave_path, config=FAST_ROBOT)
        robot.open_session()
        robot.close()


def test_the_motor_and_gripper_ports_reopen():
    with DynamixelEmulator() as motor_emu, GripperEmulator() as gripper_emu:
        for k in range(REOPENS):
            motor = DynamixelMotor(motor_emu.slave_path)
            motor.enable()
            assert abs(motor.move_to(0.01 * k, wait=True) - 0.01 * k) < 0.01
            motor.close()
            gripper = ModbusGripper(
                gripper_emu.slave_path, config=GripperConfig(serial=SerialSettings(baudrate=115200))
            )
            assert gripper.activate().activated
            gripper.close_port()
        assert motor_emu.failures == [] and gripper_emu.failures == []


def test_a_port_reopened_at_once_is_opened_on_a_later_try():
    # No pause between opens: the emulator may not have rested the line yet, and the driver tries again.
    with RobotEmulator() as emu:
        for _ in range(REOPENS):
            MelfaRobot(emu.slave_path, config=FAST_ROBOT).close()
        robot = MelfaRobot(emu.slave_path, config=FAST_ROBOT)
        robot.open_session()
        assert np.isfinite(robot.read_pose()).all()
        robot.close()


def test_line_settings_a_port_keeps_refusing_raise_port_closed_naming_them():
    # An emulator that is not serving never rests the line: the parity-only reopen is refused every time.
    emu = RobotEmulator()
    try:
        MelfaRobot(emu.slave_path, config=FAST_ROBOT).close()
        try:
            MelfaRobot(emu.slave_path, config=FAST_ROBOT).close()
        except PortClosedError as exc:
            assert "refuses the line settings 9600 baud 8E2" in str(exc)
        else:  # a kernel whose ptys hold the parity bit accepts the reopen: nothing to refuse
            assert termios.tcgetattr(emu._slave)[2] & termios.PARENB
    finally:
        emu.close()
