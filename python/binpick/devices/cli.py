"""``binpick emulate robot|motor|gripper``: one emulated device alone on a pty; ``binpick
emulate cell --out DIR``: the whole cell's digital twin (:mod:`binpick.sim.twin_process`).

A single device prints the pty's path (the serial port to give a driver or a terminal program)
on the first line of standard output and serves until Ctrl-C. The twin prints the paths of its
files and ptys, then a line per event, and runs until Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from typing import Optional

from ..errors import BinpickError
from ..parts import BUILT_IN
from .emulators import PtyEmulator

__all__ = ["emulate_main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="binpick emulate",
        description="Serve one emulated cell device on a pseudo-terminal until Ctrl-C (the first line printed "
        "is the pty path to open as the device's serial port), or the whole cell's digital twin: "
        "`binpick emulate cell --out DIR` writes DIR/cell.toml for `binpick pick`.",
    )
    p.add_argument(
        "device",
        choices=("robot", "motor", "gripper", "ur", "cell"),
        help="robot: MELFA controller (R3 protocol); motor: laser motor; gripper: Modbus RTU gripper; "
        "ur: Universal Robots controller on TCP (RTDE, dashboard, URScript); "
        "cell: the digital twin (robot, laser motor and gripper on ptys, a pile with physics, a camera on a socket)",
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
        "--speed-scale",
        type=float,
        default=1.0,
        help="robot, cell: multiply every arm speed by this factor (default 1)",
    )
    u = p.add_argument_group("ur")
    u.add_argument("--host", default="127.0.0.1", help="ur: the address to listen on (default 127.0.0.1)")
    u.add_argument(
        "--ports",
        type=int,
        nargs=3,
        default=(30004, 29999, 30002),
        metavar=("RTDE", "DASHBOARD", "SECONDARY"),
        help="ur: the three ports (default the controller's: 30004 29999 30002; 0: any free one)",
    )
    c = p.add_argument_group("cell")
    c.add_argument("--out", default=None, help="cell: the folder for cell.toml, world.json and camera.sock (required)")
    c.add_argument(
        "--part",
        default="tee",
        help="cell: built-in part (tee, elbow, cross, or a near-symmetric part such as keyed_shaft) or a mesh file "
        "(default tee)",
    )
    c.add_argument("--unit", default="mm", help="cell: unit of a mesh file (mm, cm, m, in)")
    c.add_argument("--count", type=int, default=12, help="cell: parts dropped into the bin (default 12)")
    c.add_argument("--seed", type=int, default=0, help="cell: seed of the pile and the sensor noise (default 0)")
    c.add_argument("--frames", type=int, default=90, help="cell: laser frames per scan in cell.toml (default 90)")
    c.add_argument(
        "--camera",
        choices=("arm", "fixed"),
        default="arm",
        help="cell: arm — the laser camera on the arm (the paper's); fixed — a 3-D camera above the bin (eye-to-hand)",
    )
    c.add_argument(
        "--tool",
        choices=("gripper", "ball"),
        default="gripper",
        help="cell: the tool on the flange — the gripper, or the eye-to-hand calibration ball (with --camera fixed)",
    )
    c.add_argument(
        "--robot",
        choices=("melfa", "ur"),
        default="melfa",
        help="cell: the arm — melfa (R3 over a pty, the paper's) or ur (a UR5e-class arm, its controller on TCP)",
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


def _take_signals() -> None:
    # A process started in the background by a shell inherits SIGINT ignored, and Python then
    # never raises KeyboardInterrupt: take Ctrl-C (and SIGTERM) explicitly so it always stops.
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.default_int_handler)


def _cell(args: argparse.Namespace) -> int:
    """``binpick emulate cell``: the digital twin until Ctrl-C or SIGTERM (exit 0)."""
    import os

    from ..cell.loop import ProgressPrinter
    from ..sim.twin_process import CellTwin

    if not args.out:
        print("binpick emulate cell: give the folder for the twin's files: --out DIR", file=sys.stderr)
        return 2
    if args.count < 1 or args.frames < 2:
        print("binpick emulate cell: --count must be at least 1 and --frames at least 2", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    progress = ProgressPrinter()
    _take_signals()
    stop = threading.Event()
    try:
        from .._cli_parts import _model, _Usage, error_text

        model = _model(args.part, args.unit)
        ref = args.part if args.part in BUILT_IN else os.path.abspath(args.part)
        twin = CellTwin(
            args.out,
            model,
            part_ref=ref,
            unit=args.unit,
            progress=progress,
            count=args.count,
            seed=args.seed,
            frames=args.frames,
            speed_scale=args.speed_scale,
            robot=args.robot,
            camera=args.camera,
            tool=args.tool,
        )
    except KeyboardInterrupt:
        return 0
    except (_Usage, BinpickError) as exc:
        print(f"binpick emulate cell: {error_text(exc)}", file=sys.stderr)
        return 2
    try:
        twin.start()
        progress(
            "ready",
            f"twin up in {time.perf_counter() - t0:.1f} s: cell file {twin.cell_file}, world {twin.world_file}, "
            f"camera {twin.socket_path}, true calibration {twin.out / 'true_calibration.toml'}; "
            "copy or solve calibration.toml next to cell.toml, then `binpick pick` it; Ctrl-C stops",
        )
        twin.run(stop)
    except KeyboardInterrupt:
        pass
    finally:
        try:
            twin.close()
        except KeyboardInterrupt:
            twin.close()
    progress("stopped", f"{len(twin.world.removed)} parts removed; {twin.world_file} holds the last state")
    return 0


def _ur(args: argparse.Namespace) -> int:
    """``binpick emulate ur``: a UR controller on TCP until Ctrl-C or SIGTERM (exit 0)."""
    from .emulators.ur import UREmulator

    rtde_port, dashboard_port, secondary_port = args.ports
    try:
        emulator = UREmulator(
            host=args.host,
            rtde_port=rtde_port,
            dashboard_port=dashboard_port,
            secondary_port=secondary_port,
            speed_scale=args.speed_scale,
        )
    except OSError as exc:
        print(f"binpick emulate ur: cannot listen on {args.host} ({exc}); choose other --ports", file=sys.stderr)
        return 2
    _take_signals()
    try:
        with emulator:
            a = emulator.addresses
            print(
                f"{a['rtde'][0]} rtde {a['rtde'][1]} dashboard {a['dashboard'][1]} secondary {a['secondary'][1]}",
                flush=True,
            )
            print("binpick emulate: UR controller emulator serving; press Ctrl-C to stop", file=sys.stderr, flush=True)
            while True:
                time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    return 0


def emulate_main(argv: Optional[list[str]] = None) -> int:
    """Runs ``binpick emulate`` with ``argv`` (without the program name); returns the exit code.

    0 after Ctrl-C (or when the emulated port closes), 2 for bad arguments or settings.
    """
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # argparse printed the usage and the problem
        return int(exc.code or 0)
    if args.device == "cell":
        return _cell(args)
    if args.device == "ur":
        return _ur(args)
    try:
        emulator = _build(args)
    except BinpickError as exc:
        print(f"binpick emulate: {exc}", file=sys.stderr)
        return 2
    _take_signals()
    # Ctrl-C may come as soon as the path is out (a driver is quick), even before the serving
    # loop is entered, or while the emulator closes: each is a clean stop.
    try:
        with emulator:
            print(emulator.slave_path, flush=True)
            print(
                f"binpick emulate: {args.device} emulator serving on {emulator.slave_path}; press Ctrl-C to stop",
                file=sys.stderr,
                flush=True,
            )
            while not emulator.port_closed:
                time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(emulate_main(sys.argv[1:]))
