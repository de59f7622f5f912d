"""The real cell's file: a TOML file naming the ports, the calibration, the part and the poses
(:data:`CELL_FILE_EXAMPLE`), read by :func:`load_cell_file` and turned into a :class:`Cell` by
:func:`cell_from_file`. Lengths in mm; poses as [X, Y, Z, A, B, C] with A, B, C in degrees."""

from __future__ import annotations

import inspect
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from .. import parts
from .._paths import no_such_file
from .._sizes import check_cell
from .._validate import instance_of, parse_toml, read_text_file, unit_scale
from ..calibration import CellCalibration
from ..devices import (
    AiMotor,
    AiMotorConfig,
    DynamixelConfig,
    DynamixelMotor,
    GripperConfig,
    MelfaConfig,
    MelfaHandGripper,
    MelfaRobot,
    ModbusGripper,
    SerialSettings,
    safety,
)
from ..devices.gripper import Gripper
from ..devices.motor import LaserMotor
from ..devices.robot import Robot
from ..devices.xyzabc import transform_from_xyzabc
from ..errors import BinpickError, CalibrationError, InvalidInputError, MeshFileNotFoundError
from ..models import Model
from ..poses import estimate_pose
from .config import CellConfig, GripperGeometry, check_static_poses
from .frames import FolderReplay, FrameSource, OpenCVCamera, TwinCamera, is_device_path
from .loop import Cell

__all__ = [
    "CELL_FILE_EXAMPLE",
    "CellFile",
    "load_cell_file",
    "cell_from_file",
    "config_from_file",
    "robot_from_file",
    "gripper_from_file",
    "capture_calibration",
]


CELL_FILE_EXAMPLE = """\
# binpick cell file: the real cell's ports, calibration, part and poses.
# Lengths in mm; poses as [X, Y, Z, A, B, C] with A, B, C in degrees (MELFA: R = Rz(C)·Ry(B)·Rx(A)).
#
# Edit the lines marked EDIT for your cell: the three ports and the [camera] table. Everything else
# is the layout of the digital twin (`binpick emulate cell --out DIR`): this file, with the ports and
# the [camera] table of DIR/cell.toml, picks from the twin as written. Then measure your own cell and
# change the bin, the poses, the tool, the calibration board and the limits to match it.

[robot]
port = "/dev/ttyUSB0"        # EDIT: the MELFA controller's port, R3 protocol
baudrate = 9600
override_percent = 10        # slow for a first run; at most [limits] max_override_percent
linear_speed_mm_s = 50

[motor]
port = "/dev/ttyUSB1"        # EDIT: the laser motor's port
protocol = "dynamixel"       # or "aimotor"
id = 1
baudrate = 57600

[gripper]
kind = "modbus"              # or "hand": the robot's hand outputs (HNDON/HNDOFF), no port
port = "/dev/ttyUSB2"        # EDIT: the gripper's port
slave = 9
baudrate = 115200
# The gripper's shape, for collision checks (gripper frame: z = approach, x = closing; mm):
open_width_mm = 50.0
finger_length_mm = 90.0      # along z, from the fingertips up to the palm
finger_width_mm = 20.0
finger_thickness_mm = 8.0
tip_depth_mm = 10.0          # how far the fingertips reach past the TCP
body_radius_mm = 45.0        # the palm: a cylinder about z above the fingers …
body_length_mm = 60.0        # … this long
preshape_clearance_mm = 5.0  # a gripper set to a width opens to the part's width plus this on each side (false: fully)

[camera]                     # EDIT: the whole table
source = "opencv"            # or "gige" (GigE Vision through Aravis: device = "Vendor-Model-Serial" or an IP,
                             # exposure_us, trigger = "software" or "free"),
                             # "twin": the camera of `binpick emulate cell` (socket = "DIR/camera.sock"),
device = 0                   # "replay": a recorded scan folder (folder = "scan"), "simulated": a rendered pile;
                             # device: an index, a video device or file path (relative to this file), a URL

[part]
model = "tee"                # built-in tee, elbow, cross, or a mesh file (STL, PLY, OBJ)
unit = "mm"                  # the mesh file's unit: mm, cm, m, in

[cell]
calibration = "calibration.toml"       # relative to this file
bin_min_mm = [250.0, -100.0, 0.0]
bin_max_mm = [550.0, 100.0, 80.0]
scan_pose = [400.0, 0.0, 620.0, 180.0, 0.0, 0.0]
drop_pose = [400.0, -250.0, 350.0, 180.0, 0.0, 0.0]
frames = 90
sweep = "steps"              # or "continuous": the motor turns while the camera streams (it must time its frames)
rescan = "full"              # or "changed": after a clean pick, sweep only around the part that left
plan_ahead = false           # true: plan the next pick during the carry, used where the next scan shows no change
tool = [0.0, 0.0, 195.0, 0.0, 0.0, 0.0]   # the gripper's TCP in the flange frame
# scan_height_mm = 120.0     # how far above the rim parts are looked for (default: the bin's depth or the part's size)
orientation_needed = false   # true: parts are placed by their orientation, an undecided pose is not picked
# min_confidence = 0.3       # a located pose less sure than this is not picked

[calibration_board]          # the printed checkerboard lying face up, for `binpick calibrate capture`
pattern = [9, 6]             # inner corners: columns, rows
square_mm = 20.0
center_mm = [400.0, -250.0, -5.0]      # the centre of the corner grid in the base frame

[estimate]                   # optional: keyword arguments of binpick.estimate_pose
# d_star = 12.0
# min_points = 500

[limits]
workspace_min_mm = [100.0, -350.0, 60.0]
workspace_max_mm = [650.0, 350.0, 700.0]
approach_height_mm = 315.0
max_tool_tilt_deg = 45.0
max_lateral_below_mm = 40.0
max_override_percent = 50
max_linear_speed_mm_s = 250
max_push_mm = 120            # sideways travel of a nudge below the approach height
"""


#: Largest cell file read, bytes (a real one is about two kilobytes).
MAX_FILE_BYTES = 1 << 20

_EXAMPLE = "see `binpick pick --example`"


@dataclass(frozen=True, eq=False)
class CellFile:
    """A parsed cell file (see ``CELL_FILE_EXAMPLE``): the tables as read, the file's folder, the path.

    The typed getters (:meth:`text`, :meth:`integer`, :meth:`number`, :meth:`numbers`) raise
    InvalidInputError naming the file, the table and the key for a value of the wrong type.
    """

    path: Any
    doc: Mapping[str, Any]

    def table(self, name: str, *, optional: bool = False) -> Mapping[str, Any]:
        """One table; InvalidInputError naming the file when it is missing (an empty table when
        ``optional``) or is not a table."""
        t = self.doc.get(name)
        if t is None and optional:
            return {}
        if not isinstance(t, dict):
            raise InvalidInputError(f"{self.path}: the [{name}] table is missing; {_EXAMPLE}")
        return t

    def get(self, table: str, key: str, default: Any = ...) -> Any:
        """``[table] key``; InvalidInputError naming the file and key when it is missing and has no default."""
        t = self.table(table, optional=default is not ...)
        if key not in t:
            if default is ...:
                raise InvalidInputError(f"{self.path}: [{table}] {key} is missing; {_EXAMPLE}")
            return default
        return t[key]

    def _wrong(self, table: str, key: str, value: Any, expected: str) -> InvalidInputError:
        return InvalidInputError(f"{self.path}: [{table}] {key} must be {expected}, got {value!r:.60}; {_EXAMPLE}")

    def text(self, table: str, key: str, default: Any = ...) -> str:
        """``[table] key`` as a string."""
        v = self.get(table, key, default)
        if not isinstance(v, str) or "\x00" in v:
            raise self._wrong(table, key, v, "a string")
        return v

    def integer(self, table: str, key: str, default: Any = ...) -> int:
        """``[table] key`` as a whole number (not a boolean)."""
        v = self.get(table, key, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self._wrong(table, key, v, "a whole number")
        return v

    def boolean(self, table: str, key: str, default: Any = ...) -> bool:
        """``[table] key`` as true or false."""
        v = self.get(table, key, default)
        if not isinstance(v, bool):
            raise self._wrong(table, key, v, "true or false")
        return v

    def number(self, table: str, key: str, default: Any = ...) -> float:
        """``[table] key`` as a finite number."""
        v = self.get(table, key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self._wrong(table, key, v, "a finite number")
        return float(v)

    def numbers(self, table: str, key: str, size: int, default: Any = ...) -> np.ndarray:
        """``[table] key`` as a list of ``size`` finite numbers."""
        v = self.get(table, key, default)
        ok = isinstance(v, (list, tuple)) and len(v) == size
        ok = ok and all(not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x) for x in v)
        if not ok:
            raise self._wrong(table, key, v, f"a list of {size} finite numbers")
        return np.array(v, dtype=np.float64)

    def pose(self, table: str, key: str, default: Any = ...) -> np.ndarray:
        """``[table] key`` as [X, Y, Z, A, B, C] (mm, degrees), returned as a 4×4 transform."""
        v = self.numbers(table, key, 6, default)
        return transform_from_xyzabc(np.concatenate([v[:3], np.radians(v[3:])]))


def load_cell_file(path: Any) -> CellFile:
    """Reads a cell file (TOML); InvalidInputError naming the file for one that cannot be read,
    is too large, is not UTF-8 or is not valid TOML."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise MeshFileNotFoundError(no_such_file(p, "cell file", fix="write one after `binpick pick --example`"))
    text = read_text_file(p, "cell file", InvalidInputError, max_bytes=MAX_FILE_BYTES)
    return CellFile(path=p, doc=parse_toml(text, p, InvalidInputError))


def cell_from_file(
    cell_file: CellFile,
    *,
    progress: Optional[Callable[[str, str], None]] = None,
    num_threads: int = 0,
    robot: Optional[Robot] = None,
    gripper: Optional[Gripper] = None,
) -> Cell:
    """Builds the drivers, camera and :class:`CellConfig` a cell file describes (nothing is sent
    yet: open the returned cell as a context manager). Every value of the file is read and
    checked before the first port is opened. ``robot`` and ``gripper``, when given, are used
    instead of the file's ``[robot]`` and ``[gripper]`` ports (the vision server's arm and gripper,
    which the robot program drives); their limits must be the file's."""
    config = config_from_file(cell_file, num_threads=num_threads)
    check_static_poses(config)
    try:
        open_robot = _robot(cell_file, config.limits) if robot is None else lambda: robot
        open_motor = _motor(cell_file)
        open_gripper = _gripper(cell_file) if gripper is None else lambda _: gripper
        open_camera = _camera(cell_file, config.model, num_threads)
    except InvalidInputError as exc:
        if str(exc).startswith(str(cell_file.path)):
            raise
        raise InvalidInputError(f"{cell_file.path}: {exc}") from None
    opened: list[Any] = []
    try:
        arm = open_robot()
        opened.append(arm.close)
        motor = open_motor()
        opened.append(motor.close)
        hand = open_gripper(arm)
        opened.append(hand.close_port)
        camera = open_camera()
        opened.append(camera.close)
        truth = _twin_truth(cell_file, config.model) if robot is None else None
        return Cell(
            config,
            robot=arm,
            motor=motor,
            gripper=hand,
            camera=camera,
            progress=progress,
            truth=truth,
            clock=None if truth is None else truth.clock,  # the twin's hardware time
        )
    except BaseException:  # nothing opened is left open
        for close in reversed(opened):
            try:
                close()
            except (BinpickError, OSError):
                pass
        raise


def _twin_truth(cell_file: CellFile, model: Any) -> Any:
    """The digital twin's ground truth (:class:`~binpick.cell.twin_truth.TwinTruth`) when the
    file's camera is the twin's (``source = "twin"`` or ``"twin_depth"``): a rehearsal on the twin
    reports the part each pick removed, the located poses' errors and the gripper's collisions."""
    f = cell_file
    if f.text("camera", "source", "opencv") not in ("twin", "twin_depth"):
        return None
    from .twin_truth import TwinTruth

    here = os.path.dirname(os.path.abspath(f.path))
    path = os.path.join(here, f.text("camera", "socket", "camera.sock"))
    return TwinTruth(path, model, timeout_s=f.number("camera", "timeout_s", 60.0))


def robot_from_file(cell_file: CellFile) -> Robot:
    """The robot driver of the file's ``[robot]`` table, with the file's limits (opened, no session yet)."""
    return _robot(cell_file, _limits(cell_file))()


def gripper_from_file(cell_file: CellFile, robot: Robot) -> Gripper:
    """The gripper driver of the file's ``[gripper]`` table (``robot``: the arm a hand gripper is wired to)."""
    return _gripper(cell_file)(robot)


def config_from_file(cell_file: CellFile, *, num_threads: int = 0) -> CellConfig:
    """The :class:`CellConfig` of a cell file: part, calibration, bin, poses, tool and limits."""
    f = instance_of(cell_file, CellFile, "cell_file", "load_cell_file(path)")
    here = os.path.dirname(os.path.abspath(f.path))
    name, unit = f.text("part", "model"), f.text("part", "unit", "mm")
    if name not in parts.BUILT_IN:
        model = Model.from_mesh(os.path.join(here, name), unit=unit)
    elif unit_scale(unit) == 1.0:
        model = parts.built_in(name)
    else:  # a built-in part is in mm: the unit of a mesh file means nothing for it
        raise InvalidInputError(
            f"{f.path}: [part] unit = {unit!r:.40}: the built-in part {name!r} is in mm; leave unit out"
        )
    bin_bounds = (f.numbers("cell", "bin_min_mm", 3), f.numbers("cell", "bin_max_mm", 3))
    gripper = _gripper_geometry(f, f.pose("cell", "tool", [0, 0, 150, 0, 0, 0]))
    # Before the calibration is read and any port opened: the part, the bin and the gripper in
    # sizes one cell can mean together (a mesh, a bin or a gripper written in metres is named).
    check_cell(f.path, model, unit=unit, bin_bounds=bin_bounds, opening_mm=gripper.open_width_mm)
    calibration_path = os.path.join(here, f.text("cell", "calibration"))
    if not os.path.exists(calibration_path):
        raise CalibrationError(
            f"{f.path}: [cell] calibration = {calibration_path} does not exist; solve the cell's calibration "
            "(binpick calibrate) and write it there"
        )
    calibration = CellCalibration.load(calibration_path)
    return CellConfig(
        calibration=calibration,
        model=model,
        bin_bounds=bin_bounds,
        scan_poses=(f.pose("cell", "scan_pose"),),
        drop_pose=f.pose("cell", "drop_pose"),
        frames=f.integer("cell", "frames", 90),
        sweep=f.text("cell", "sweep", "steps"),
        rescan=f.text("cell", "rescan", "full"),
        plan_ahead=f.boolean("cell", "plan_ahead", False),
        scan_height_mm=None if f.get("cell", "scan_height_mm", None) is None else f.number("cell", "scan_height_mm"),
        **_stake(f),
        gripper=gripper,
        limits=_limits(f),
        num_threads=num_threads,
        estimate_options=_estimate_options(f),
    )


def _stake(f: CellFile) -> dict[str, Any]:
    """``[cell] orientation_needed`` and ``min_confidence`` where the file sets them (else CellConfig's defaults)."""
    out: dict[str, Any] = {}
    if f.get("cell", "orientation_needed", None) is not None:
        out["orientation_needed"] = f.boolean("cell", "orientation_needed")
    if f.get("cell", "min_confidence", None) is not None:
        out["min_confidence"] = f.number("cell", "min_confidence")
    return out


def capture_calibration(
    cell_file: CellFile, out_dir: Any, *, progress: Optional[Callable[[str, str], None]] = None
) -> tuple[Path, int]:
    """Drives the cell a cell file describes through the standard calibration plan
    (:func:`binpick.calibration.capture.calibration_plan` around the file's
    ``[calibration_board]``: ``pattern`` (inner corners), ``square_mm``, ``center_mm``; each
    defaults to the twin's board) and saves the capture into ``out_dir``
    (:func:`binpick.calibration.capture.capture`). The cell's present calibration, when its file
    exists, aims the camera at the board; a first calibration aims the flange. Only the robot,
    the laser motor and the camera are opened. Returns the manifest's path and the number of stations."""
    from ..calibration.capture import calibration_plan, capture
    from ..sim.cell import CalibrationBoard  # the defaults: the twin's board

    f = cell_file
    if f.text("camera", "source", "opencv") in ("twin_depth", "shots"):
        return _capture_eye_to_hand(f, out_dir, progress)
    board = CalibrationBoard()
    pattern = f.numbers("calibration_board", "pattern", 2, list(board.pattern))
    if (pattern != np.round(pattern)).any() or (pattern < 2).any():
        raise f._wrong("calibration_board", "pattern", pattern.tolist(), "[columns, rows] of inner corners, 2 or more")
    square = f.number("calibration_board", "square_mm", board.square)
    centre = f.numbers("calibration_board", "center_mm", 3, board.center.tolist())
    try:
        config = config_from_file(f)
        nominal, model = config.calibration.T_flange_camera, config.model
    except CalibrationError:
        nominal, model = None, parts.tee()
    plan = calibration_plan(centre, T_flange_camera=nominal, pattern=tuple(int(p) for p in pattern), square=square)
    limits = _limits(f)
    open_robot, open_motor, open_camera = _robot(f, limits), _motor(f), _camera(f, model, 0)
    robot = open_robot()
    motor = camera = None
    try:
        motor = open_motor()
        camera = open_camera()
        robot.open_session()
        motor.enable()
        manifest = capture(robot, motor, camera, plan, out_dir, limits=limits, progress=progress)
    finally:
        for close in (robot.close_session, robot.close, *(() if motor is None else (motor.disable, motor.close))):
            try:
                close()
            except (BinpickError, OSError):
                pass
        if camera is not None:
            camera.close()
    return manifest, len(plan.stations)


def _capture_eye_to_hand(f: CellFile, out_dir: Any, progress: Optional[Callable[[str, str], None]]) -> tuple[Path, int]:
    """``calibrate capture`` for a fixed camera: the ball of ``[calibration_ball] radius_mm``
    carried through :func:`binpick.calibration.eye_to_hand.capture_plan` over the bin."""
    from ..calibration import eye_to_hand as e2h

    limits = _limits(f)
    radius = f.number("calibration_ball", "radius_mm", e2h.BALL_RADIUS_MM)
    plan = e2h.capture_plan((f.numbers("cell", "bin_min_mm", 3), f.numbers("cell", "bin_max_mm", 3)))
    robot = _robot(f, limits)()
    camera = None
    try:
        camera = _camera(f, parts.tee(), 0)()
        robot.open_session()
        manifest = e2h.capture(robot, camera, plan, out_dir, radius_mm=radius, progress=progress)
    finally:
        for close in (robot.close_session, robot.close, *(() if camera is None else (camera.close,))):
            try:
                close()
            except (BinpickError, OSError):
                pass
    return Path(manifest), len(plan)


def _estimate_options(f: CellFile) -> dict:
    """The [estimate] table, each key a keyword argument of :func:`binpick.estimate_pose`."""
    options = dict(f.table("estimate", optional=True))
    known = [n for n in inspect.signature(estimate_pose).parameters if n not in ("scene", "model", "bin")]
    unknown = [k for k in options if k not in known]
    if unknown:
        raise InvalidInputError(
            f"{f.path}: [estimate] {unknown[0]!r:.40} is not an option of binpick.estimate_pose; use {', '.join(known)}"
        )
    return options


def _limits(f: CellFile) -> safety.CellLimits:
    d = safety.CellLimits()
    return safety.CellLimits(
        workspace_min_mm=tuple(f.numbers("limits", "workspace_min_mm", 3, d.workspace_min_mm)),
        workspace_max_mm=tuple(f.numbers("limits", "workspace_max_mm", 3, d.workspace_max_mm)),
        approach_height_mm=f.number("limits", "approach_height_mm", d.approach_height_mm),
        max_tool_tilt_rad=math.radians(f.number("limits", "max_tool_tilt_deg", math.degrees(d.max_tool_tilt_rad))),
        max_lateral_below_mm=f.number("limits", "max_lateral_below_mm", d.max_lateral_below_mm),
        max_override_percent=f.number("limits", "max_override_percent", d.max_override_percent),
        max_linear_speed_mm_s=f.number("limits", "max_linear_speed_mm_s", d.max_linear_speed_mm_s),
        max_push_mm=f.number("limits", "max_push_mm", d.max_push_mm),
    )


#: The keys of the ``[gripper]`` table that give its shape (:class:`GripperGeometry`'s fields, mm).
GRIPPER_SHAPE_KEYS = (
    "open_width_mm",
    "finger_length_mm",
    "finger_width_mm",
    "finger_thickness_mm",
    "tip_depth_mm",
    "body_radius_mm",
    "body_length_mm",
    "preshape_clearance_mm",
)


def _gripper_geometry(f: CellFile, tool: np.ndarray) -> GripperGeometry:
    """The gripper's shape: ``[cell] tool`` and the ``[gripper]`` keys of :data:`GRIPPER_SHAPE_KEYS`
    (each :class:`GripperGeometry`'s default where absent; ``preshape_clearance_mm = false``: always
    open fully)."""
    d = GripperGeometry()
    shape: dict[str, Any] = {
        k: None
        if k == "preshape_clearance_mm" and f.get("gripper", k, 0.0) is False
        else f.number("gripper", k, getattr(d, k))
        for k in GRIPPER_SHAPE_KEYS
    }
    try:
        return GripperGeometry(T_flange_gripper=tool, **shape)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{f.path}: [gripper] {exc}") from None


def _robot(f: CellFile, limits: safety.CellLimits) -> Callable[[], Robot]:
    driver = f.text("robot", "driver", "melfa")
    if driver == "ur":
        from ..devices.ur import URConfig, URRobot

        d = URConfig()
        ur = URConfig(
            rtde_port=f.integer("robot", "rtde_port", d.rtde_port),
            dashboard_port=f.integer("robot", "dashboard_port", d.dashboard_port),
            secondary_port=f.integer("robot", "secondary_port", d.secondary_port),
            linear_speed_mm_s=f.number("robot", "linear_speed_mm_s", d.linear_speed_mm_s),
        )
        host = f.text("robot", "host")
        return lambda: URRobot(host, limits=limits, config=ur)
    if driver != "melfa":
        raise InvalidInputError(f"{f.path}: [robot] driver = {driver!r:.40}; use 'melfa' or 'ur'")
    port = f.text("robot", "port")
    config = MelfaConfig(
        serial=SerialSettings(baudrate=f.integer("robot", "baudrate", 9600), parity="E", stopbits=2, timeout_s=2.0),
        initial_override_percent=f.number("robot", "override_percent", 10.0),
        initial_linear_speed_mm_s=f.number("robot", "linear_speed_mm_s", 50.0),
    )
    return lambda: MelfaRobot(port, limits=limits, config=config)


def _motor(f: CellFile) -> Callable[[], LaserMotor]:
    protocol = f.text("motor", "protocol", "dynamixel")
    port = f.text("motor", "port")
    motor_serial = SerialSettings(baudrate=f.integer("motor", "baudrate", 57600), timeout_s=0.2)
    if protocol == "dynamixel":
        dxl = DynamixelConfig(motor_id=f.integer("motor", "id", 1), serial=motor_serial)
        return lambda: DynamixelMotor(port, config=dxl)
    if protocol == "aimotor":
        ai = AiMotorConfig(motor_id=f.integer("motor", "id", 0), serial=motor_serial)
        return lambda: AiMotor(port, config=ai)
    raise InvalidInputError(f"{f.path}: [motor] protocol = {protocol!r:.40}; use 'dynamixel' or 'aimotor'")


def _gripper(f: CellFile) -> Callable[[Any], Gripper]:
    kind = f.text("gripper", "kind", "modbus")
    if kind == "modbus":
        port = f.text("gripper", "port")
        config = GripperConfig(
            slave=f.integer("gripper", "slave", 9),
            serial=SerialSettings(baudrate=f.integer("gripper", "baudrate", 115200), timeout_s=0.3),
        )
        return lambda robot: ModbusGripper(port, config=config)
    if kind == "hand":
        hand = f.integer("gripper", "hand", 1)
        return lambda robot: MelfaHandGripper(robot, hand=hand)
    raise InvalidInputError(f"{f.path}: [gripper] kind = {kind!r:.40}; use 'modbus' or 'hand'")


def _camera(f: CellFile, model: Model, num_threads: int) -> Callable[[], FrameSource]:
    source = f.text("camera", "source", "opencv")
    here = os.path.dirname(os.path.abspath(f.path))
    if source == "opencv":
        # A path is relative to this file, like the twin's socket and a replay's folder; a device
        # index and a stream URL are what they say.
        device = f.get("camera", "device", 0)
        index_or_path = f.text("camera", "device") if isinstance(device, str) else f.integer("camera", "device", 0)
        if is_device_path(index_or_path):
            index_or_path = os.path.join(here, index_or_path)
        return lambda: OpenCVCamera(index_or_path)
    if source == "simulated":
        count, seed = f.integer("camera", "count", 8), f.integer("camera", "seed", 0)

        def rendered() -> FrameSource:
            from ..sim.camera import RenderedCamera  # the simulator loads only when a cell file asks for it

            return RenderedCamera(model, count=count, seed=seed, num_threads=num_threads)

        return rendered
    if source == "twin":
        path = os.path.join(here, f.text("camera", "socket", "camera.sock"))
        timeout = f.number("camera", "timeout_s", 60.0)
        return lambda: TwinCamera(path, timeout_s=timeout)
    if source == "replay":
        folder = os.path.join(here, f.text("camera", "folder"))
        return lambda: FolderReplay(folder)
    if source in ("twin_depth", "shots"):
        from ..ros import is_rosbag
        from .shots import BagShots, EyeToHand, ShotReplay, TwinDepthCamera

        pose_file = os.path.join(here, f.text("camera", "eye_to_hand", "eye_to_hand.toml"))
        if source == "twin_depth":
            path, timeout = (
                os.path.join(here, f.text("camera", "socket", "camera.sock")),
                f.number("camera", "timeout_s", 60.0),
            )
            return lambda: TwinDepthCamera(path, EyeToHand.load_if_there(pose_file), timeout_s=timeout)
        folder = os.path.join(here, f.text("camera", "folder"))
        if is_rosbag(folder):  # a ROS 2 bag of PointCloud2 shots
            topic = f.text("camera", "topic") if f.get("camera", "topic", None) is not None else None
            unit = f.text("camera", "unit", "m")
            return lambda: BagShots(folder, EyeToHand.load_if_there(pose_file), topic=topic, unit=unit)
        return lambda: ShotReplay(folder, EyeToHand.load_if_there(pose_file))
    if source == "gige":
        from .gige import GigEVisionCamera  # Aravis loads only when a cell file asks for it

        device = f.text("camera", "device") if f.get("camera", "device", None) is not None else None
        exposure = None if f.get("camera", "exposure_us", None) is None else f.number("camera", "exposure_us")
        trigger = f.text("camera", "trigger", "software")
        return lambda: GigEVisionCamera(device, exposure_us=exposure, trigger=trigger)
    raise InvalidInputError(
        f"{f.path}: [camera] source = {source!r:.40}; use 'opencv', 'gige', 'twin', 'twin_depth', 'shots', "
        "'replay' or 'simulated'"
    )
