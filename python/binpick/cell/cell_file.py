"""The real cell's file: a TOML file naming the ports, the calibration, the part and the poses
(:data:`CELL_FILE_EXAMPLE`), read by :func:`load_cell_file` and turned into a :class:`Cell` by
:func:`cell_from_file`. Lengths in mm; poses as [X, Y, Z, A, B, C] with A, B, C in degrees."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

from .. import parts
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
from ..devices.xyzabc import transform_from_xyzabc
from ..errors import InvalidInputError, MeshFileNotFoundError
from ..models import Model
from .config import CellConfig, GripperGeometry, check_static_poses
from .frames import FrameSource, OpenCVCamera
from .loop import Cell

__all__ = ["CELL_FILE_EXAMPLE", "CellFile", "load_cell_file", "cell_from_file", "config_from_file"]


CELL_FILE_EXAMPLE = """\
# binpick cell file: the real cell's ports, calibration, part and poses.
# Lengths in mm; poses as [X, Y, Z, A, B, C] with A, B, C in degrees (MELFA: R = Rz(C)·Ry(B)·Rx(A)).

[robot]
port = "/dev/ttyUSB0"        # MELFA controller, R3 protocol
baudrate = 9600
override_percent = 10
linear_speed_mm_s = 50

[motor]
port = "/dev/ttyUSB1"        # laser motor
protocol = "dynamixel"       # or "aimotor"
id = 1
baudrate = 57600

[gripper]
kind = "modbus"              # or "hand": the robot's hand outputs (HNDON/HNDOFF)
port = "/dev/ttyUSB2"
slave = 9
baudrate = 115200

[camera]
source = "opencv"            # or "simulated": render a simulated pile (to try a configuration)
device = 0

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
tool = [0.0, 0.0, 150.0, 0.0, 0.0, 0.0]   # the gripper's TCP in the flange frame

[estimate]                   # optional: keyword arguments of binpick.estimate_pose
# d_star = 12.0
# min_points = 500

[limits]
workspace_min_mm = [100.0, -350.0, 60.0]
workspace_max_mm = [650.0, 350.0, 700.0]
approach_height_mm = 270.0
max_tool_tilt_deg = 45.0
"""


def _pose_deg(value: Any, where: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64) if isinstance(value, (list, tuple)) else None
    if v is None or v.shape != (6,) or not np.isfinite(v).all():
        raise InvalidInputError(f"{where}: expected [X, Y, Z, A, B, C] (mm, degrees), got {value!r}")
    return transform_from_xyzabc(np.concatenate([v[:3], np.radians(v[3:])]))


@dataclass(frozen=True, eq=False)
class CellFile:
    """A parsed cell file (see ``CELL_FILE_EXAMPLE``): the tables as read, the file's folder, the path."""

    path: Any
    doc: Mapping[str, Any]

    def table(self, name: str) -> Mapping[str, Any]:
        """One table; InvalidInputError naming the file when it is missing."""
        t = self.doc.get(name)
        if not isinstance(t, dict):
            raise InvalidInputError(f"{self.path}: the [{name}] table is missing; see `binpick pick --example`")
        return t

    def get(self, table: str, key: str, default: Any = ...) -> Any:
        """``[table] key``; InvalidInputError naming the file and key when it is missing and has no default."""
        t = self.table(table)
        if key not in t:
            if default is ...:
                raise InvalidInputError(f"{self.path}: [{table}] {key} is missing; see `binpick pick --example`")
            return default
        return t[key]


def load_cell_file(path: Any) -> CellFile:
    """Reads a cell file (TOML)."""
    p = os.fspath(path)
    try:
        with open(p, "rb") as f:
            doc = tomllib.load(f)
    except FileNotFoundError:
        raise MeshFileNotFoundError(f"{p}: cell file not found; write one after `binpick pick --example`") from None
    except tomllib.TOMLDecodeError as exc:
        raise InvalidInputError(f"{p}: not valid TOML ({exc})") from None
    return CellFile(path=p, doc=doc)


def cell_from_file(
    cell_file: CellFile, *, progress: Optional[Callable[[str, str], None]] = None, num_threads: int = 0
) -> Cell:
    """Builds the drivers, camera and :class:`CellConfig` a cell file describes (nothing is sent
    yet: open the returned cell as a context manager)."""
    config = config_from_file(cell_file, num_threads=num_threads)
    check_static_poses(config)  # before any port is opened
    robot = _robot(cell_file, config.limits)
    return Cell(
        config,
        robot=robot,
        motor=_motor(cell_file),
        gripper=_gripper(cell_file, robot),
        camera=_camera(cell_file, config.model, num_threads),
        progress=progress,
    )


def config_from_file(cell_file: CellFile, *, num_threads: int = 0) -> CellConfig:
    """The :class:`CellConfig` of a cell file: part, calibration, bin, poses, tool and limits."""
    f = cell_file
    here = os.path.dirname(os.path.abspath(f.path))
    name = str(f.get("part", "model"))
    model = (
        getattr(parts, name)()
        if name in ("tee", "elbow", "cross")
        else Model.from_mesh(os.path.join(here, name), unit=str(f.get("part", "unit", "mm")))
    )
    calibration = CellCalibration.load(os.path.join(here, str(f.get("cell", "calibration"))))
    tool = _pose_deg(f.get("cell", "tool", [0, 0, 150, 0, 0, 0]), f"{f.path}: [cell] tool")
    return CellConfig(
        calibration=calibration,
        model=model,
        bin_bounds=(f.get("cell", "bin_min_mm"), f.get("cell", "bin_max_mm")),
        scan_poses=(_pose_deg(f.get("cell", "scan_pose"), f"{f.path}: [cell] scan_pose"),),
        drop_pose=_pose_deg(f.get("cell", "drop_pose"), f"{f.path}: [cell] drop_pose"),
        frames=int(f.get("cell", "frames", 90)),
        gripper=GripperGeometry(T_flange_gripper=tool),
        limits=_limits(f),
        num_threads=num_threads,
        estimate_options=dict(f.doc.get("estimate", {})),
    )


def _limits(f: CellFile) -> safety.CellLimits:
    lim_t = f.doc.get("limits", {})
    defaults = safety.CellLimits()
    return safety.CellLimits(
        workspace_min_mm=tuple(float(v) for v in lim_t.get("workspace_min_mm", defaults.workspace_min_mm)),
        workspace_max_mm=tuple(float(v) for v in lim_t.get("workspace_max_mm", defaults.workspace_max_mm)),
        approach_height_mm=float(lim_t.get("approach_height_mm", defaults.approach_height_mm)),
        max_tool_tilt_rad=math.radians(float(lim_t.get("max_tool_tilt_deg", math.degrees(defaults.max_tool_tilt_rad)))),
        max_lateral_below_mm=float(lim_t.get("max_lateral_below_mm", defaults.max_lateral_below_mm)),
        max_override_percent=float(lim_t.get("max_override_percent", defaults.max_override_percent)),
        max_linear_speed_mm_s=float(lim_t.get("max_linear_speed_mm_s", defaults.max_linear_speed_mm_s)),
    )


def _robot(f: CellFile, limits: safety.CellLimits) -> MelfaRobot:
    return MelfaRobot(
        str(f.get("robot", "port")),
        limits=limits,
        config=MelfaConfig(
            serial=SerialSettings(
                baudrate=int(f.get("robot", "baudrate", 9600)), parity="E", stopbits=2, timeout_s=2.0
            ),
            initial_override_percent=float(f.get("robot", "override_percent", 10.0)),
            initial_linear_speed_mm_s=float(f.get("robot", "linear_speed_mm_s", 50.0)),
        ),
    )


def _motor(f: CellFile) -> LaserMotor:
    protocol = str(f.get("motor", "protocol", "dynamixel"))
    motor_serial = SerialSettings(baudrate=int(f.get("motor", "baudrate", 57600)), timeout_s=0.2)
    if protocol == "dynamixel":
        return DynamixelMotor(
            str(f.get("motor", "port")),
            config=DynamixelConfig(motor_id=int(f.get("motor", "id", 1)), serial=motor_serial),
        )
    if protocol == "aimotor":
        return AiMotor(
            str(f.get("motor", "port")),
            config=AiMotorConfig(motor_id=int(f.get("motor", "id", 0)), serial=motor_serial),
        )
    raise InvalidInputError(f"{f.path}: [motor] protocol = {protocol!r}; use 'dynamixel' or 'aimotor'")


def _gripper(f: CellFile, robot: MelfaRobot) -> Gripper:
    kind = str(f.get("gripper", "kind", "modbus"))
    if kind == "modbus":
        return ModbusGripper(
            str(f.get("gripper", "port")),
            config=GripperConfig(
                slave=int(f.get("gripper", "slave", 9)),
                serial=SerialSettings(baudrate=int(f.get("gripper", "baudrate", 115200)), timeout_s=0.3),
            ),
        )
    if kind == "hand":
        return MelfaHandGripper(robot, hand=int(f.get("gripper", "hand", 1)))
    raise InvalidInputError(f"{f.path}: [gripper] kind = {kind!r}; use 'modbus' or 'hand'")


def _camera(f: CellFile, model: Model, num_threads: int) -> FrameSource:
    source = str(f.get("camera", "source", "opencv"))
    if source == "opencv":
        return OpenCVCamera(f.get("camera", "device", 0))
    if source == "simulated":
        from ..sim.camera import RenderedCamera  # the simulator loads only when a cell file asks for it

        return RenderedCamera(
            model, count=int(f.get("camera", "count", 8)), seed=int(f.get("camera", "seed", 0)), num_threads=num_threads
        )
    raise InvalidInputError(f"{f.path}: [camera] source = {source!r}; use 'opencv' or 'simulated'")
