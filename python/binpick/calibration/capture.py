"""Capturing calibration data from the cell itself: a plan of robot stations looking at a
checkerboard lying in the cell (views for intrinsics and hand-eye, and laser stations where the
line is swept over the board, at several distances as the paper's Table 1 needs), checked whole
against the cell's limits before the first motion, and :func:`capture`, which drives the real
drivers through it and saves frames (PNG), the robot poses read back, the motor angles read at
rest and a versioned manifest (``manifest.json``) that :func:`binpick.calibration.solve.solve` reads.

Lengths mm, angles radians (degrees only in the manifest's human-readable extras).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from .._validate import as_transform, as_vector, check_transform, instance_of, positive
from ..devices import safety
from ..errors import CalibrationError, FileWriteError, InvalidInputError, SafetyError
from ..transforms import inverse, looking_at
from .camera import _pattern

__all__ = ["MANIFEST_VERSION", "Station", "CalibrationPlan", "calibration_plan", "capture"]

#: The manifest format this code writes and :func:`binpick.calibration.solve.solve` reads.
MANIFEST_VERSION = 1

# (azimuth°, tilt°, distance mm, roll°[, dx, dy mm]) of the board-only views: the camera looks at
# the board's centre (shifted by dx, dy in the base frame) from `distance`, tilted `tilt` from
# straight down towards `azimuth` (0 = from +x, 90 = from +y), turned `roll` about its optical axis.
# Tilts towards every side (the steep ones separate the focal length from the distance) and
# rolls of both signs give the rotation diversity intrinsics and
# hand-eye need; |roll| ≤ 45° keeps the corner order unambiguous; the shifted views put the board
# into the image's corners, where the distortion shows.
_BOARD_VIEWS = (
    (0.0, 0.0, 650.0, 0.0, 75.0, 55.0),
    (0.0, 0.0, 650.0, 0.0, -75.0, 55.0),
    (0.0, 0.0, 650.0, 0.0, 75.0, -55.0),
    (0.0, 0.0, 650.0, 0.0, -75.0, -55.0),
    (90.0, 15.0, 640.0, 10.0, 80.0, 0.0),
    (90.0, 15.0, 640.0, -10.0, -80.0, 0.0),
    (0.0, 10.0, 620.0, 15.0, 0.0, 60.0),
    (180.0, 10.0, 620.0, -15.0, 0.0, -60.0),
    (0.0, 0.0, 600.0, 0.0),
    (0.0, 0.0, 640.0, 40.0),
    (90.0, 20.0, 600.0, 0.0),
    (90.0, 32.0, 600.0, -25.0),
    (0.0, 20.0, 560.0, 20.0),
    (180.0, 20.0, 600.0, -20.0),
    (45.0, 28.0, 600.0, 0.0),
    (135.0, 28.0, 600.0, 30.0),
    (60.0, 25.0, 570.0, -40.0),
    (120.0, 25.0, 570.0, 40.0),
    (270.0, 8.0, 620.0, 10.0),
    (0.0, 12.0, 560.0, -45.0),
    (180.0, 12.0, 560.0, 45.0),
    (30.0, 15.0, 640.0, -10.0),
    (90.0, 40.0, 520.0, 0.0),
    (50.0, 40.0, 500.0, 15.0),
    (130.0, 40.0, 500.0, -15.0),
    (60.0, 40.0, 520.0, -30.0),
    (120.0, 40.0, 520.0, 30.0),
    (90.0, 40.0, 520.0, 25.0),
)
# The laser stations: straight down at three distances (Table 1 needs the board at several
# distances along the optical axis) and one tilted, so that each sheet is seen on non-parallel boards.
_LASER_VIEWS = ((0.0, 0.0, 470.0, 0.0), (0.0, 0.0, 550.0, 0.0), (0.0, 0.0, 630.0, 0.0), (90.0, 20.0, 560.0, 0.0))


@dataclass(frozen=True)
class Station:
    """One robot stop: ``T_base_flange``, a board frame with the laser parked off the board, then
    one frame per angle of ``laser_angles`` (rad; empty for a board-only view)."""

    name: str
    T_base_flange: np.ndarray
    laser_angles: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_base_flange", as_transform(self.T_base_flange, f"{self.name}.T_base_flange"))
        object.__setattr__(self, "laser_angles", tuple(float(a) for a in self.laser_angles))


@dataclass(frozen=True)
class CalibrationPlan:
    """Stations to visit in order, the board they look at (``pattern`` = (columns, rows) of inner
    corners, ``square`` mm) and ``park_angle`` (rad), the motor angle that puts the laser line out
    of the camera's view for the board frames."""

    stations: tuple[Station, ...]
    pattern: tuple[int, int] = (9, 6)
    square: float = 20.0
    park_angle: float = math.radians(60.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stations", tuple(self.stations))
        object.__setattr__(self, "pattern", _pattern(self.pattern))
        positive(self.square, "square")
        if not all(isinstance(s, Station) for s in self.stations):
            raise InvalidInputError("stations: expected binpick.calibration.capture.Station objects")
        if len(self.stations) < 3:
            raise CalibrationError(
                f"stations: {len(self.stations)} given; a calibration needs at least 3 (12+ advised)"
            )

    @property
    def laser_stations(self) -> tuple[Station, ...]:
        """The stations where the laser is swept over the board."""
        return tuple(s for s in self.stations if s.laser_angles)

    def check(self, T_start: Any, limits: safety.CellLimits, motor_range: Any = None) -> None:
        """The whole plan against the cell's motion rules (:mod:`binpick.devices.safety`), from the
        arm's pose ``T_start`` through every station by joint moves, and every motor angle against
        ``motor_range`` (a :class:`binpick.devices.MotorRange`); SafetyError naming the station
        when any is refused. Nothing moves."""
        names = [f"calibration station {s.name!r}" for s in self.stations]
        poses = [safety.check_pose(s.T_base_flange, limits, name=n) for s, n in zip(self.stations, names)]
        safety.check_sequence(check_transform(T_start, "T_start"), poses, [False] * len(poses), limits, names=names)
        if motor_range is None:
            return
        for s in self.stations:
            for a in (self.park_angle, *s.laser_angles):
                if not motor_range.min_angle_rad <= a <= motor_range.max_angle_rad:
                    raise SafetyError(
                        f"calibration station {s.name!r}: laser angle {math.degrees(a):.2f}° is outside the motor's "
                        f"range [{math.degrees(motor_range.min_angle_rad):.1f}°, "
                        f"{math.degrees(motor_range.max_angle_rad):.1f}°]; nothing was sent — change the plan's angles"
                    )


def calibration_plan(
    board_center: Sequence[float],
    *,
    T_flange_camera: Any = None,
    pattern: Sequence[int] = (9, 6),
    square: float = 20.0,
    laser_angles: Sequence[float] = tuple(np.radians(np.linspace(-6.0, 10.0, 9))),
    park_angle: float = math.radians(60.0),
) -> CalibrationPlan:
    """The standard plan around a board lying face up with its corner grid centred at
    ``board_center`` (base frame, mm): 28 board views at tilts 0–40° from every side with rolls of
    ±45°, 8 of them with the board in the image's corners and edges, and 4 laser stations
    (straight down at 470, 550 and 630 mm, and tilted 20°) where the
    line is swept through ``laser_angles`` (rad). ``T_flange_camera`` is the nominal hand-eye used
    to aim the camera (the identity when unknown: the flange then aims at the board)."""
    centre = as_vector(board_center, "board_center", 3)
    X = np.eye(4) if T_flange_camera is None else as_transform(T_flange_camera, "T_flange_camera")
    X_inv = inverse(X)
    angles = tuple(float(a) for a in laser_angles)
    if len(angles) < 3:
        raise CalibrationError(f"laser_angles: {len(angles)} given; the rotation axis needs at least 3 distinct angles")
    stations = []
    for kind, views in (("board", _BOARD_VIEWS), ("laser", _LASER_VIEWS)):
        for i, (az, tilt, dist, roll, *shift) in enumerate(views):
            target = centre + np.array([*(shift or (0.0, 0.0)), 0.0])
            T_bc = looking_at(
                target, distance=dist, tilt=math.radians(tilt), azimuth=math.radians(az), roll=math.radians(roll)
            )
            stations.append(Station(f"{kind}{i:02d}", T_bc @ X_inv, angles if kind == "laser" else ()))
    return CalibrationPlan(tuple(stations), pattern=tuple(pattern), square=square, park_angle=park_angle)


def _write_png(path: Path, image: np.ndarray) -> None:
    import cv2

    if not cv2.imwrite(str(path), image):
        raise FileWriteError(f"{path}: cannot write the frame; check the folder is writable and the disk not full")


def _matrix(T: np.ndarray) -> list:
    return [[float(v) for v in row] for row in T]


def capture(
    robot: Any,
    motor: Any,
    camera: Any,
    plan: CalibrationPlan,
    out_dir: str | os.PathLike,
    *,
    limits: Optional[safety.CellLimits] = None,
    progress: Optional[Callable[[str, str], None]] = None,
) -> Path:
    """Drives the robot and the laser motor through ``plan`` and saves what the camera sees.

    ``robot`` (a :class:`binpick.devices.Robot` with its session open), ``motor`` (a
    :class:`binpick.devices.LaserMotor`, enabled) and ``camera`` (a
    :class:`binpick.cell.FrameSource`) are the cell's real drivers. The plan is checked whole
    against ``limits`` (default: the robot driver's) and the motor's range before the first
    motion. At each station: a joint move, the pose read back, ``camera.begin``, the board frame
    with the laser parked, then one frame per laser angle (each tagged with the angle read at
    rest, as the pick loop does). Writes ``out_dir/frames/*.png`` and ``out_dir/manifest.json``;
    returns the manifest's path."""
    from ..cell.frames import FrameSource

    instance_of(plan, CalibrationPlan, "plan", "calibration_plan(...)")
    instance_of(camera, FrameSource, "camera", "a binpick.cell frame source")
    limits = limits if limits is not None else getattr(robot, "limits", None)
    if not isinstance(limits, safety.CellLimits):
        raise InvalidInputError(
            "limits: the robot driver has no CellLimits; pass limits=binpick.devices.CellLimits(...)"
        )
    say = progress or (lambda stage, msg: None)
    plan.check(robot.read_pose(), limits, getattr(motor, "range", None))
    out = Path(out_dir)
    frames_dir = out / "frames"
    try:
        frames_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FileWriteError(f"{out}: cannot create the capture folder ({exc})") from None
    t0 = time.perf_counter()
    records = []
    for k, st in enumerate(plan.stations):
        robot.move_to(st.T_base_flange, linear=False)
        T_bf = robot.read_pose()
        camera.begin(T_bf)
        shots = []
        for a in (plan.park_angle, *st.laser_angles):
            reached = float(motor.move_to(a, wait=True))
            camera.laser_at(reached)
            name = f"{st.name}_{len(shots):02d}.png"
            _write_png(frames_dir / name, camera.grab())
            shots.append({"file": f"frames/{name}", "angle": reached, "goal": float(a)})
        records.append(
            {"name": st.name, "T_base_flange": _matrix(T_bf), "board_frame": shots[0], "laser_frames": shots[1:]}
        )
        say("calibrate", f"station {k + 1}/{len(plan.stations)} {st.name}: {len(shots)} frames")
    manifest = {
        "format": "binpick calibration capture",
        "version": MANIFEST_VERSION,
        "units": "mm, rad; T_base_flange read back from the robot, angles read from the motor at rest",
        "board": {"pattern": list(plan.pattern), "square_mm": float(plan.square)},
        "park_angle": float(plan.park_angle),
        "stations": records,
        "seconds": round(time.perf_counter() - t0, 3),
    }
    path = out / "manifest.json"
    try:
        path.write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    except OSError as exc:
        raise FileWriteError(f"{path}: cannot write the manifest ({exc})") from None
    return path
