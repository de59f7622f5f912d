"""``binpick emulate robot|motor|gripper``: one emulated device alone on a pty.

It prints the pty's path (the serial port to give a driver or a terminal program) on the first
line of standard output and serves until Ctrl-C.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from typing import Optional

from ..errors import BinpickError
from .emulators import PtyEmulator

__all__ = ["emulate_main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="binpick emulate",
        description="Serve one emulated cell device on a pseudo-terminal until Ctrl-C. The first line printed "
        "is the pty path to open as the device's serial port.",
    )
    p.add_argument(
        "device",
        choices=("robot", "motor", "gripper"),
        help="robot: MELFA controller (R3 protocol); motor: laser motor; gripper: Modbus RTU gripper",
    )
    p.add_argument(
        "--protocol",
        choices=("dynamixel", "aimotor"),
        default="dynamixel",
        help="motor protocol (default: dynamixel, Protocol 2.0)",
    )
    p.add_argument(
        "--id",
        type=int,
        default=None,
        help="motor ID (default 1 for dynamixel, 0 for aimotor) or gripper slave address (default 9)",
    )
    p.add_argument(
        "--speed-scale", type=float, default=1.0, help="robot: multiply every speed by this factor (default 1)"
    )
    return p


def _build(args: argparse.Namespace) -> PtyEmulator:
    if args.device == "robot":
        from .emulators.robot import RobotEmulator, RobotEmulatorConfig

        return RobotEmulator(config=RobotEmulatorConfig(speed_scale=args.speed_scale))
    if args.device == "gripper":
        from .emulators.gripper import GripperEmulator, GripperEmulatorConfig

        return GripperEmulator(config=GripperEmulatorConfig(slave=9 if args.id is None else args.id))
    if args.protocol == "aimotor":
        from .emulators.aimotor import AiMotorEmulator, AiMotorEmulatorConfig

        return AiMotorEmulator(config=AiMotorEmulatorConfig(motor_id=0 if args.id is None else args.id))
    from .emulators.motor import DynamixelEmulator, DynamixelEmulatorConfig

    return DynamixelEmulator(config=DynamixelEmulatorConfig(motor_id=1 if args.id is None else args.id))


def emulate_main(argv: Optional[list[str]] = None) -> int:
    """Runs ``binpick emulate`` with ``argv`` (without the program name); returns the exit code.

    0 after Ctrl-C (or when the emulated port closes), 2 for bad arguments or settings.
    """
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # argparse printed the usage and the problem
        return int(exc.code or 0)
    try:
        emulator = _build(args)
    except BinpickError as exc:
        print(f"binpick emulate: {exc}", file=sys.stderr)
        return 2
    # A process started in the background by a shell inherits SIGINT ignored, and Python then
    # never raises KeyboardInterrupt: take Ctrl-C (and SIGTERM) explicitly so it always stops.
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.default_int_handler)
    with emulator:
        print(emulator.slave_path, flush=True)
        print(
            f"binpick emulate: {args.device} emulator serving on {emulator.slave_path}; press Ctrl-C to stop",
            file=sys.stderr,
            flush=True,
        )
        try:
            while not emulator.port_closed:
                time.sleep(0.1)
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(emulate_main(sys.argv[1:]))
