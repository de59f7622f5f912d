"""``binpick serve CELL.toml``: the vision server for the cell a cell file describes.

The cell file's ``[server]`` table (every key optional; the command line's options win)::

    [server]
    host = "127.0.0.1"         # the address to listen on; "0.0.0.0" opens it to the cell network
    port = 50100
    brand = "ur"               # the robot's pose convention: ur, abb, kuka, fanuc, yaskawa, melfa
    idle_timeout_s = 60.0      # a robot program silent this long is disconnected
    gripper_sets_width = true  # the program opens the gripper to the width NEXT gives (false: fully)

The laser motor and the camera of the file are opened; the ``[robot]`` and ``[gripper]`` ports
are not (the robot program drives them). The first line printed is the address listened on.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from ..cell.cell_file import cell_from_file, load_cell_file
from ..cell.loop import ProgressPrinter
from ..errors import BinpickError, InvalidInputError
from .conventions import convention
from .protocol import PROTOCOL_VERSION
from .server import DEFAULT_PORT, VisionServer
from .service import ProgramGripper, ProgramRobot, VisionService

__all__ = ["serve_main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="binpick serve",
        description="Serve the vision of a cell to its robot program over TCP (protocol: docs/protocol.md): the "
        "program sends SCAN with its flange pose, NEXT for the next pick, RESULT when it knows; binpick sweeps its "
        "laser, locates and plans, and checks every waypoint against the cell's limits. Runs until Ctrl-C.",
    )
    p.add_argument("config", help="the cell file (TOML); its [server] table sets the defaults below")
    p.add_argument("--host", default=None, help="address to listen on (default [server] host, else 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help=f"TCP port, 0: any free one (default {DEFAULT_PORT})")
    p.add_argument(
        "--brand",
        default=None,
        help="pose convention: ur, abb, kuka, fanuc, yaskawa, melfa (default [server] brand, else melfa)",
    )
    p.add_argument("--out", default=None, help="folder for picks.jsonl, one line per pick result (default none)")
    return p


def serve_main(argv: list[str]) -> int:
    """Runs ``binpick serve``; returns the exit code (0 after Ctrl-C or SIGTERM, 2 for bad input, 1 for a fault)."""
    args = _parser().parse_args(argv)
    try:
        return _serve(args)
    except InvalidInputError as exc:
        print(f"binpick serve: {exc}", file=sys.stderr)
        return 2
    except BinpickError as exc:
        print(f"binpick serve: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1


def _serve(args: argparse.Namespace) -> int:
    f = load_cell_file(args.config)
    brand = convention(args.brand if args.brand is not None else f.text("server", "brand", "melfa"))
    host = args.host if args.host is not None else f.text("server", "host", "127.0.0.1")
    port = args.port if args.port is not None else f.integer("server", "port", DEFAULT_PORT)
    idle = f.number("server", "idle_timeout_s", 60.0)
    progress = ProgressPrinter(sys.stderr)
    robot = ProgramRobot(limits=None)
    gripper = ProgramGripper(f.boolean("server", "gripper_sets_width", True))
    cell = cell_from_file(f, progress=progress, robot=robot, gripper=gripper)
    robot.limits = cell.config.limits
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        cell.motor.enable()
        service = VisionService(cell, brand, out=args.out, progress=progress)
        with VisionServer(service, host, port, idle_timeout_s=idle, progress=progress) as server:
            h, p = server.address
            print(
                f"binpick serve: listening on {h}:{p} — protocol {PROTOCOL_VERSION}, brand {brand.brand} "
                f"({', '.join(brand.fields)}), part {cell.config.model.name}",
                flush=True,
            )
            while not stop.wait(0.2):
                pass
    finally:
        cell.close()
    print("binpick serve: stopped", flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(serve_main(sys.argv[1:]))
