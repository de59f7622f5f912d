"""Talking to the cell: serial drivers for the robot, the laser motor and the gripper.

* :class:`MelfaRobot` — Mitsubishi MELFA controller over the R3 protocol (RS-232C), behind :class:`Robot`.
* :class:`DynamixelMotor` (default laser motor, Protocol 2.0) and :class:`AiMotor` behind the
  common :class:`LaserMotor` interface.
* :class:`ModbusGripper` (Robotiq 2F register map, Modbus RTU) and :class:`MelfaHandGripper`
  (the robot's hand outputs) behind :class:`Gripper`.
* :mod:`~binpick.devices.safety` checks every motion before a byte is sent
  (:class:`~binpick.errors.SafetyError`); :mod:`~binpick.devices.xyzabc` is the one place where
  4×4 transforms meet MELFA's (X, Y, Z, A, B, C).
* :mod:`~binpick.devices.emulators` serves each device's protocol on a pty, with fault injection.

This package needs only numpy and pyserial; it does not load binpick's native core itself.
"""

from __future__ import annotations

from ._link import SerialSettings
from .aimotor import AiMotor, AiMotorConfig
from .dynamixel import DynamixelBus, DynamixelConfig, DynamixelMotor
from .gripper import Gripper, GripperConfig, GripperStatus, MelfaHandGripper, ModbusGripper
from .melfa import MelfaConfig, MelfaRobot, R3Reply, RobotState
from .motor import LaserMotor, MotorRange
from .robot import Robot
from .safety import CellLimits
from .xyzabc import transform_from_xyzabc, xyzabc_from_transform

__all__ = [
    "SerialSettings",
    "CellLimits",
    "MelfaConfig",
    "MelfaRobot",
    "R3Reply",
    "RobotState",
    "Robot",
    "LaserMotor",
    "MotorRange",
    "DynamixelBus",
    "DynamixelConfig",
    "DynamixelMotor",
    "AiMotor",
    "AiMotorConfig",
    "Gripper",
    "GripperConfig",
    "GripperStatus",
    "MelfaHandGripper",
    "ModbusGripper",
    "transform_from_xyzabc",
    "xyzabc_from_transform",
]
