"""Emulated cell devices served on pseudo-terminals, speaking the real protocols.

Each emulator opens a pty with :func:`os.openpty`, serves it from a background thread and can
play transport and device faults on request (:class:`Fault`). Drivers open ``slave_path`` with
pyserial exactly as they would open a USB serial adapter.
"""

from __future__ import annotations

from ._pty import Fault, PtyEmulator
from .aimotor import AiMotorEmulator, AiMotorEmulatorConfig
from .gripper import GripperEmulator, GripperEmulatorConfig
from .motor import DynamixelEmulator, DynamixelEmulatorConfig
from .robot import ArmModel, RobotEmulator, RobotEmulatorConfig

__all__ = [
    "Fault",
    "PtyEmulator",
    "ArmModel",
    "RobotEmulator",
    "RobotEmulatorConfig",
    "DynamixelEmulator",
    "DynamixelEmulatorConfig",
    "AiMotorEmulator",
    "AiMotorEmulatorConfig",
    "GripperEmulator",
    "GripperEmulatorConfig",
]
