"""The pick loop — the same code drives the simulated cell and the real one.

A :class:`Cell` holds the drivers (robot, laser motor, gripper), a :class:`FrameSource` (the
camera) and a :class:`CellConfig` (calibration, part model and grasps, bin box, scan and drop
poses, gripper geometry, motion limits). One pick is::

    cell.scan()    robot to the scan pose (checked by the safety layer), sweep the laser motor,
                   grab a frame per angle, extract the line, triangulate → cloud in the base frame
    cell.locate()  estimate_pose(cloud, model, bin box) → T_base_object
    cell.plan()    every declared grasp: T_base_gripper = T_base_object · T_gripper_object⁻¹ (Eq. 30),
                   T_base_flange = T_base_gripper · T_flange_gripper⁻¹; keep the ones within the
                   tool-tilt limit, reachable, free of the scene, whose whole motion passes the
                   safety rules; take the most vertical
    cell.pick()    open, above → approach → grasp (straight along the gripper axis), close, lift
                   straight up, drop pose, open; on any fault the arm is stopped and the fault raised

:func:`simulated_cell` builds the whole simulated cell: a physics pile in the bin, the robot,
laser motor and gripper emulators serving their real protocols on ptys, the drivers opened on
those ptys, and a camera that renders the pile from the pose the robot emulator reports with the
laser at the angle the motor emulator reports. The simulated gripper closes on a part only when
the part really lies between its fingers; the part leaves the pile when the gripper lets go.

Lengths in mm, angles in radians; transforms are 4×4 ``T_to_from``.
"""

from __future__ import annotations

import abc
import math
import sys
import time
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, TextIO, Tuple

import numpy as np

from ._validate import as_transform, count, non_negative, positive
from .calibration import CellCalibration
from .devices import safety
from .devices.emulators import GripperEmulator
from .devices.gripper import GTO, Gripper
from .devices.melfa import MelfaRobot
from .devices.motor import LaserMotor
from .errors import BinpickError, DeviceError, InvalidInputError, NoObjectFound, SafetyError
from .models import Model

__all__ = [
    "CellConfig",
    "GripperGeometry",
    "Cell",
    "FrameSource",
    "OpenCVCamera",
    "ScanResult",
    "Located",
    "PickPlan",
    "PickRecord",
    "PoseTruth",
    "RunReport",
    "ProgressPrinter",
    "NoGraspError",
    "branch_grasps",
    "sweep_angles",
    "pose_error",
    "SimulatedCell",
    "SimCamera",
    "simulated_cell",
    "sim_limits",
    "SIM_ARM",
    "RenderedCamera",
    "CellFile",
    "CELL_FILE_EXAMPLE",
    "load_cell_file",
    "cell_from_file",
    "check_static_poses",
]


class NoGraspError(BinpickError):
    """The located part has no declared grasp that is reachable, collision-free and safe to approach."""


# --------------------------------------------------------------------------- geometry

def _inv(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _rotation_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def pose_error(T_est: Any, T_true: Any, symmetries: Sequence[np.ndarray] = ()) -> Tuple[float, float]:
    """(rotation error in degrees, translation error in mm) of ``T_est`` against ``T_true``,
    the smallest over the part's ``symmetries`` (4×4 ``T_object_object`` that map the part onto
    itself; the identity is always included)."""
    A = as_transform(T_est, "T_est")
    B = as_transform(T_true, "T_true")
    errors = []
    for S in [np.eye(4), *symmetries]:
        Bs = B @ np.asarray(S, dtype=np.float64)
        errors.append((_rotation_deg(Bs[:3, :3].T @ A[:3, :3]), float(np.linalg.norm(A[:3, 3] - Bs[:3, 3]))))
    # The symmetry closest in pick-grade units (5° ~ 3 mm).
    return min(errors, key=lambda e: e[0] / 5.0 + e[1] / 3.0)


def _rot_about(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def branch_grasps(model: Model, *, finger_width_mm: float = 20.0, steps: int = 72) -> Dict[str, np.ndarray]:
    """Grasps across every cylindrical branch of ``model`` (``model.branches``): the TCP on the
    branch axis, ``finger_width_mm / 2 + 7`` mm in from the end face, the fingers closing across
    the axis, approached from ``steps`` directions around it (and each turned half a turn about
    the approach axis, the same grip with the wrist the other way round).

    The steps are fine (5° by default) because a part in a pile usually has a branch tilted and
    neighbours close by: the approaches within the tool-tilt limit and clear of the neighbours are
    often a narrow range about the branch (12 steps of 30° routinely missed all of them).

    The gripper frame: z is the approach direction (into the part), x the fingers' closing
    direction, the origin the TCP between the fingertips. Returns name → ``T_gripper_object``.
    """
    if not isinstance(model, Model):
        raise InvalidInputError(f"model: expected a binpick.Model, got {type(model).__name__}")
    if not model.branches:
        raise InvalidInputError(
            f"model: {model.name!r} declares no cylindrical branches, so no grasps can be derived; declare grasps "
            "with model.add_grasp(name, T_gripper_object)"
        )
    half = positive(finger_width_mm, "finger_width_mm") / 2.0
    n = count(steps, "steps", 1)
    grasps: Dict[str, np.ndarray] = {}
    for i, b in enumerate(model.branches):
        d = np.asarray(b.direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        s = max(b.length - half - 7.0, 0.0)
        helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        z0 = np.cross(d, helper)
        z0 /= np.linalg.norm(z0)
        for k in range(n):
            z = _rot_about(d, 2 * math.pi * k / n) @ z0
            for flip in (0, 1):
                x = np.cross(d, z) * (1 if flip == 0 else -1)
                T_object_gripper = np.eye(4)
                T_object_gripper[:3, :3] = np.column_stack([x, np.cross(z, x), z])
                T_object_gripper[:3, 3] = s * d
                grasps[f"branch{i}/{round(360 * k / n)}°{'/flipped' if flip else ''}"] = _inv(T_object_gripper)
    return grasps


def sweep_angles(calibration: CellCalibration, T_base_flange: Any, bin_bounds: Any, frames: int, *, margin: float = 10.0) -> np.ndarray:
    """``frames`` motor angles (rad), evenly spaced, whose laser sheets sweep the bin box
    ``bin_bounds`` (floor corners widened by ``margin`` mm along x, and the rim) seen from ``T_base_flange``."""
    if not isinstance(calibration, CellCalibration):
        raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(calibration).__name__}")
    T_bf = as_transform(T_base_flange, "T_base_flange")
    lo, hi = _box(bin_bounds)
    n = count(frames, "frames", 1)
    corners = [[x, y, lo[2]] for x in (lo[0] - margin, hi[0] + margin) for y in (lo[1], hi[1])]
    corners += [[x, y, hi[2]] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]
    T_laser_base = _inv(T_bf @ calibration.T_flange_camera @ calibration.T_camera_laser)
    local = np.asarray(corners) @ T_laser_base[:3, :3].T + T_laser_base[:3, 3]
    # At motor angle θ the sheet is x cos θ − z sin θ = 0 in the laser frame: it meets a point at θ = atan2(x, z).
    theta = np.arctan2(local[:, 0], local[:, 2])
    return np.array([float(theta.mean())]) if n == 1 else np.linspace(theta.min(), theta.max(), n)


def _box(bounds: Any) -> Tuple[np.ndarray, np.ndarray]:
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (2, 3) or not np.isfinite(b).all():
        raise InvalidInputError(f"bin: expected ((xmin, ymin, zmin), (xmax, ymax, zmax)) in mm, got {np.asarray(bounds).tolist()}")
    if not (b[1] > b[0]).all():
        raise InvalidInputError(f"bin: the max corner {b[1].tolist()} must exceed the min corner {b[0].tolist()} on every axis")
    return b[0], b[1]


# --------------------------------------------------------------------------- configuration

@dataclass(frozen=True)
class GripperGeometry:
    """The gripper on the flange, for planning and collision checks (gripper frame: z = approach
    direction into the part, x = the fingers' closing direction, origin = the TCP between the fingertips).

    Attributes:
        T_flange_gripper: the TCP frame in the flange frame (4×4, mm).
        open_width_mm: finger opening when open, mm.
        finger_length_mm: length of the fingers along z, mm.
        finger_width_mm: width of a finger along y, mm.
        finger_thickness_mm: thickness of a finger along x, mm.
        tip_depth_mm: how far the fingertips reach past the TCP along +z, mm.
        body_radius_mm: radius of the gripper body above the fingers (a cylinder about z), mm.
        body_length_mm: length of that body along z, mm.
    """

    T_flange_gripper: np.ndarray = field(default_factory=lambda: _translation(0.0, 0.0, 150.0))
    open_width_mm: float = 50.0
    finger_length_mm: float = 45.0
    finger_width_mm: float = 20.0
    finger_thickness_mm: float = 8.0
    tip_depth_mm: float = 10.0
    body_radius_mm: float = 45.0
    body_length_mm: float = 60.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_flange_gripper", as_transform(self.T_flange_gripper, "T_flange_gripper"))
        for name in ("open_width_mm", "finger_length_mm", "finger_width_mm", "finger_thickness_mm", "body_radius_mm", "body_length_mm"):
            positive(getattr(self, name), name)
        non_negative(self.tip_depth_mm, "tip_depth_mm", "mm")

    def occupied(self, points_gripper: np.ndarray) -> np.ndarray:
        """Which points (N, 3, in the gripper frame) lie inside the open gripper (fingers or body)."""
        x, y, z = points_gripper.T
        top = self.tip_depth_mm - self.finger_length_mm
        in_z = (z <= self.tip_depth_mm) & (z >= top)
        offset = self.open_width_mm / 2 + self.finger_thickness_mm / 2
        finger = in_z & (np.abs(y) <= self.finger_width_mm / 2) & (
            (np.abs(x - offset) <= self.finger_thickness_mm / 2) | (np.abs(x + offset) <= self.finger_thickness_mm / 2))
        body = (z < top) & (z >= top - self.body_length_mm) & (np.hypot(x, y) <= self.body_radius_mm)
        return finger | body


def _translation(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


@dataclass(frozen=True)
class CellConfig:
    """What the pick loop needs to know about a cell (base frame, mm, radians).

    Attributes:
        calibration: camera intrinsics, laser pose at motor angle 0, hand-eye.
        model: the part model.
        bin_bounds: the bin's inner volume ((xmin, ymin, zmin), (xmax, ymax, zmax)), mm.
        scan_poses: the flange poses ``T_base_flange`` to scan from (one or more).
        drop_pose: the flange pose where a picked part is released.
        frames: laser frames per scan pose.
        scan_angles: motor angles (rad) per scan pose; None = computed from the calibration to sweep the bin.
        grasps: name → ``T_gripper_object``; None = the model's declared grasps, or
            :func:`branch_grasps` for a model with branches and no declared grasps.
        gripper: the gripper's TCP and shape.
        limits: the cell's motion limits (also given to the robot driver).
        approach_distance_mm: the straight approach along the gripper axis before the grasp, mm.
        clearance_z_mm: flange height for travelling over the bin, mm; None = the approach height + 20 mm.
        max_collision_points: a grasp is refused when more scene points than this lie inside the open gripper
            (fingers or body), or more points of the located part's own model (at the located pose).
        max_candidates: parts tried per scan when the top part has no usable grasp.
        reachable: optional test ``T_base_flange → bool`` from the arm's kinematics; None = trust
            the controller (it refuses unreachable targets, and the cell then stops).
        symmetries: ``T_object_object`` maps of the part onto itself, for judging pose errors.
        min_score: a located pose scoring lower counts as not found.
        estimate_options: extra keyword arguments for :func:`binpick.estimate_pose`.
        keep_frames: how many frames of each scan to keep in memory (evenly spaced; for pictures).
        num_threads: worker threads for extraction and pose estimation, 0 = all cores.
    """

    calibration: CellCalibration
    model: Model
    bin_bounds: Any
    scan_poses: Sequence[Any]
    drop_pose: Any
    frames: int = 90
    scan_angles: Optional[Sequence[Sequence[float]]] = None
    grasps: Optional[Mapping[str, Any]] = None
    gripper: GripperGeometry = field(default_factory=GripperGeometry)
    limits: safety.CellLimits = field(default_factory=safety.CellLimits)
    approach_distance_mm: float = 40.0
    clearance_z_mm: Optional[float] = None
    max_collision_points: int = 15
    max_candidates: int = 5
    reachable: Optional[Callable[[np.ndarray], bool]] = None
    symmetries: Sequence[Any] = ()
    min_score: float = 0.0
    estimate_options: Mapping[str, Any] = field(default_factory=dict)
    keep_frames: int = 6
    num_threads: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.calibration, CellCalibration):
            raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(self.calibration).__name__}")
        if not isinstance(self.model, Model):
            raise InvalidInputError(f"model: expected a binpick.Model, got {type(self.model).__name__}")
        if not isinstance(self.gripper, GripperGeometry):
            raise InvalidInputError(f"gripper: expected a GripperGeometry, got {type(self.gripper).__name__}")
        if not isinstance(self.limits, safety.CellLimits):
            raise InvalidInputError(f"limits: expected a binpick.devices.CellLimits, got {type(self.limits).__name__}")
        lo, hi = _box(self.bin_bounds)
        object.__setattr__(self, "bin_bounds", np.array([lo, hi]))
        poses = [self.scan_poses] if np.asarray(self.scan_poses, dtype=object).ndim == 2 else list(self.scan_poses)
        if not poses:
            raise InvalidInputError("scan_poses: give at least one flange pose to scan from")
        object.__setattr__(self, "scan_poses", tuple(as_transform(T, f"scan_poses[{i}]") for i, T in enumerate(poses)))
        object.__setattr__(self, "drop_pose", as_transform(self.drop_pose, "drop_pose"))
        count(self.frames, "frames", 1)
        if self.scan_angles is not None:
            angles = tuple(np.asarray(a, dtype=np.float64).ravel() for a in self.scan_angles)
            if len(angles) != len(self.scan_poses) or any(len(a) == 0 or not np.isfinite(a).all() for a in angles):
                raise InvalidInputError("scan_angles: give one non-empty list of finite motor angles (rad) per scan pose")
            object.__setattr__(self, "scan_angles", angles)
        grasps = self.grasps if self.grasps is not None else (
            self.model.grasps or branch_grasps(self.model, finger_width_mm=self.gripper.finger_width_mm))
        if not grasps:
            raise InvalidInputError(f"grasps: the part {self.model.name!r} has no grasps; declare some with model.add_grasp")
        object.__setattr__(self, "grasps", MappingProxyType({str(k): as_transform(v, f"grasps[{k!r}]") for k, v in grasps.items()}))
        positive(self.approach_distance_mm, "approach_distance_mm")
        if self.clearance_z_mm is None:
            object.__setattr__(self, "clearance_z_mm", float(self.limits.approach_height_mm) + 20.0)
        count(self.max_collision_points, "max_collision_points")
        count(self.max_candidates, "max_candidates", 1)
        object.__setattr__(self, "symmetries", tuple(as_transform(S, f"symmetries[{i}]") for i, S in enumerate(self.symmetries)))
        non_negative(self.min_score, "min_score")
        count(self.keep_frames, "keep_frames")
        count(self.num_threads, "num_threads")
        if self.reachable is not None and not callable(self.reachable):
            raise InvalidInputError("reachable: expected a function T_base_flange -> bool, or None")

    def angles_for(self, i: int) -> np.ndarray:
        """The motor angles (rad) of scan pose ``i``."""
        if self.scan_angles is not None:
            return self.scan_angles[i]
        return sweep_angles(self.calibration, self.scan_poses[i], self.bin_bounds, self.frames)


# --------------------------------------------------------------------------- frame sources

class FrameSource(abc.ABC):
    """The camera as the pick loop sees it: told where the robot is before a sweep, then asked
    for one frame per laser angle (after the motor has arrived)."""

    def begin(self, T_base_flange: np.ndarray) -> None:
        """Called before a sweep with the flange pose read back from the robot."""

    def laser_at(self, angle: float) -> None:
        """Called before each grab with the laser angle the motor reported (rad)."""

    @abc.abstractmethod
    def grab(self) -> np.ndarray:
        """One frame, uint8 BGR (H, W, 3), as the camera sees the cell now."""

    def close(self) -> None:
        """Releases the camera."""


class OpenCVCamera(FrameSource):
    """A camera opened with ``cv2.VideoCapture`` (a device index, a device path or a stream URL).

    Args:
        device: what ``cv2.VideoCapture`` opens.
        width: requested frame width, px (None = the camera's default).
        height: requested frame height, px.
        flush: frames read and dropped before each grab, so that the frame kept was exposed
            after the motor arrived (drivers keep a small buffer).
    """

    def __init__(self, device: Any = 0, *, width: Optional[int] = None, height: Optional[int] = None, flush: int = 2) -> None:
        import cv2

        self.device = device
        self.flush = count(flush, "flush")
        self._cap = cv2.VideoCapture(device)
        if not self._cap.isOpened():
            raise DeviceError(f"camera: cannot open {device!r}; check the device index or path and that no other program holds it")
        if width is not None:
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(width))
        if height is not None:
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(height))

    def grab(self) -> np.ndarray:
        for _ in range(self.flush):
            self._cap.grab()
        ok, frame = self._cap.read()
        if not ok or frame is None:
            raise DeviceError(f"camera: {self.device!r} returned no frame; check the cable and the trigger settings")
        return frame

    def close(self) -> None:
        self._cap.release()


# --------------------------------------------------------------------------- results

@dataclass(frozen=True, eq=False)
class ScanResult:
    """One scan: the cloud in the base frame, the motor angle (rad) and flange pose of every frame,
    a few kept frames (index → BGR image) and the stage timings (ms)."""

    cloud: Any
    angles: np.ndarray
    T_base_flanges: np.ndarray
    frames: Mapping[int, np.ndarray]
    timings: Mapping[str, float]

    @property
    def points(self) -> np.ndarray:
        """(N, 3) points, mm, base frame."""
        return self.cloud.points


@dataclass(frozen=True)
class PoseTruth:
    """A located pose judged against ground truth: the nearest true instance, the errors
    (minimised over the part's symmetries) and whether they are pick-grade (< 5°, < 3 mm)."""

    instance: int
    rotation_error_deg: float
    translation_error_mm: float

    @property
    def pick_grade(self) -> bool:
        """Rotation error under 5° and translation error under 3 mm."""
        return self.rotation_error_deg < 5.0 and self.translation_error_mm < 3.0


@dataclass(frozen=True, eq=False)
class Located:
    """The part found in a scan: the pose result, ``T_base_object``, the indices of its points in
    the scan's cloud and, when the cell knows the truth (the simulator), how good it is."""

    scan: ScanResult
    result: Any
    T_base_object: np.ndarray
    indices: np.ndarray
    truth: Optional[PoseTruth] = None


@dataclass(frozen=True, eq=False)
class PickPlan:
    """The chosen grasp and the motion: ``waypoints`` are (name, T_base_flange, linear) in order."""

    grasp: str
    T_base_gripper: np.ndarray
    T_base_flange: np.ndarray
    tilt_deg: float
    waypoints: Tuple[Tuple[str, np.ndarray, bool], ...]
    considered: int
    rejected: Mapping[str, int]

    def pose(self, name: str) -> np.ndarray:
        """The flange pose of waypoint ``name``."""
        for n, T, _ in self.waypoints:
            if n == name:
                return T
        raise KeyError(name)


@dataclass(frozen=True, eq=False)
class PickRecord:
    """What one pick attempt did.

    ``success``: the part was lifted out (with ground truth: the removed part is the located one and
    its pose was pick-grade); ``held``: what the gripper reported (None when it cannot tell);
    ``error``: why the attempt failed, None on success; ``timings``: stage → ms.
    """

    index: int
    success: bool
    T_base_object: Optional[np.ndarray] = None
    score: Optional[float] = None
    rmse: Optional[float] = None
    method: Optional[str] = None
    points: int = 0
    grasp: Optional[str] = None
    held: Optional[bool] = None
    truth: Optional[PoseTruth] = None
    picked_instance: Optional[int] = None
    error: Optional[str] = None
    fault: bool = False
    timings: Mapping[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """A JSON-ready summary."""
        return {
            "index": self.index,
            "success": self.success,
            "T_base_object": None if self.T_base_object is None else np.round(self.T_base_object, 6).tolist(),
            "score": self.score,
            "rmse_mm": self.rmse,
            "method": self.method,
            "points": self.points,
            "grasp": self.grasp,
            "held": self.held,
            "truth": None if self.truth is None else {
                "instance": self.truth.instance, "rotation_error_deg": self.truth.rotation_error_deg,
                "translation_error_mm": self.truth.translation_error_mm, "pick_grade": self.truth.pick_grade},
            "picked_instance": self.picked_instance,
            "error": self.error,
            "timings_ms": dict(self.timings),
        }


@dataclass(frozen=True, eq=False)
class RunReport:
    """The picks of :meth:`Cell.run`, why it stopped (None when every pick was tried), and the last scan and location."""

    records: Tuple[PickRecord, ...]
    stopped: Optional[str]
    last_scan: Optional[ScanResult] = None
    last_located: Optional[Located] = None

    @property
    def successes(self) -> int:
        """How many picks succeeded."""
        return sum(r.success for r in self.records)


# --------------------------------------------------------------------------- progress

class ProgressPrinter:
    """Prints one line per stage: elapsed time, the pick, the stage and what it did."""

    def __init__(self, stream: Optional[TextIO] = None) -> None:
        self.stream = stream
        self._t0 = time.perf_counter()

    def __call__(self, stage: str, message: str) -> None:
        stream = self.stream if self.stream is not None else sys.stdout
        print(f"[{time.perf_counter() - self._t0:7.2f} s] {stage:<10} {message}", file=stream, flush=True)


def _quiet(stage: str, message: str) -> None:
    return None


# --------------------------------------------------------------------------- the cell

def check_static_poses(config: CellConfig) -> None:
    """The scan and drop poses and the clearance height against the cell's limits (SafetyError);
    the cell checks them when it is built, before any byte is sent."""
    lim = config.limits
    for i, T in enumerate(config.scan_poses):
        safety.check_pose(T, lim, name=f"scan_poses[{i}]")
        if T[2, 3] < lim.approach_height_mm:
            raise SafetyError(f"scan_poses[{i}]: z = {T[2, 3]:.1f} mm is below the approach height {lim.approach_height_mm:g} mm; "
                              "nothing was sent — scan from above the approach height")
    safety.check_pose(config.drop_pose, lim, name="drop_pose")
    if config.drop_pose[2, 3] < lim.approach_height_mm:
        raise SafetyError(f"drop_pose: z = {config.drop_pose[2, 3]:.1f} mm is below the approach height "
                          f"{lim.approach_height_mm:g} mm; nothing was sent — drop from above the approach height")
    if not lim.approach_height_mm <= config.clearance_z_mm <= lim.workspace_max_mm[2]:
        raise SafetyError(f"clearance_z_mm: {config.clearance_z_mm:g} mm must lie between the approach height "
                          f"{lim.approach_height_mm:g} mm and the workspace top {lim.workspace_max_mm[2]:g} mm; nothing was sent")


class Cell:
    """The pick loop on a cell's drivers (see the module docstring).

    Args:
        config: the cell's calibration, part, poses, gripper and limits.
        robot: the robot driver; its ``limits`` must be ``config.limits`` (the driver checks every motion).
        motor: the laser motor driver.
        gripper: the gripper driver.
        camera: where frames come from.
        progress: called with (stage, message) as the work goes on; None = silent.
        truth: optional ground truth (the simulator) with ``judge(T_base_object) -> PoseTruth`` and
            ``take_picked() -> Optional[int]`` (the instance that left the bin since the last call).
    """

    def __init__(self, config: CellConfig, *, robot: MelfaRobot, motor: LaserMotor, gripper: Gripper, camera: FrameSource,
                 progress: Optional[Callable[[str, str], None]] = None, truth: Any = None) -> None:
        if not isinstance(config, CellConfig):
            raise InvalidInputError(f"config: expected a CellConfig, got {type(config).__name__}")
        if not isinstance(camera, FrameSource):
            raise InvalidInputError(f"camera: expected a binpick.cell.FrameSource, got {type(camera).__name__}")
        if getattr(robot, "limits", config.limits) != config.limits:
            raise InvalidInputError("robot: the driver's CellLimits differ from config.limits; open the robot with limits=config.limits")
        self.config = config
        self.robot = robot
        self.motor = motor
        self.gripper = gripper
        self.camera = camera
        self.progress = progress or _quiet
        self.truth = truth
        self._empty_grips: List[np.ndarray] = []
        check_static_poses(config)

    # -- life cycle
    def open(self) -> "Cell":
        """Opens the robot session, enables the laser motor, activates and opens the gripper."""
        self.progress("connect", "robot session, laser motor torque, gripper activation")
        self.robot.open_session()
        self.motor.enable()
        activate = getattr(self.gripper, "activate", None)
        if activate is not None:
            activate()
        self.gripper.open()
        return self

    def close(self) -> None:
        """Closes the robot session and releases the motor, the camera and the ports (best effort)."""
        for action in (self.robot.close_session, self.motor.disable):
            try:
                action()
            except DeviceError:
                pass
        for closer in (self.robot.close, self.motor.close, getattr(self.gripper, "close_port", None), self.camera.close):
            if closer is not None:
                try:
                    closer()
                except (DeviceError, OSError):
                    pass

    def __enter__(self) -> "Cell":
        try:
            return self.open()
        except BaseException:
            self.close()
            raise

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- stages
    def _halt(self) -> str:
        try:
            self.robot.stop()
        except DeviceError as exc:
            return f"STOP could not be sent ({exc}); stop the arm by hand"
        return "the arm was stopped"

    def _move(self, T: np.ndarray, *, linear: bool) -> None:
        self.robot.move_to(T, linear=linear)

    def _go_above_approach(self) -> None:
        """From wherever the arm is, straight up to the clearance height if it is below the approach height."""
        here = self.robot.read_pose()
        if here[2, 3] < self.config.limits.approach_height_mm:
            up = here.copy()
            up[2, 3] = self.config.clearance_z_mm
            self._move(up, linear=True)

    def scan(self) -> ScanResult:
        """Scans the bin from every scan pose; returns the cloud in the base frame."""
        from .vision import extract_line, triangulate

        cfg = self.config
        timings: Dict[str, float] = {"move": 0.0, "sweep": 0.0, "extract": 0.0}
        pixels: List[np.ndarray] = []
        frame_of: List[np.ndarray] = []
        angles: List[float] = []
        poses: List[np.ndarray] = []
        kept: Dict[int, np.ndarray] = {}
        for i, T_scan in enumerate(cfg.scan_poses):
            t0 = time.perf_counter()
            self._go_above_approach()
            self._move(T_scan, linear=False)
            T_bf = self.robot.read_pose()
            t1 = time.perf_counter()
            timings["move"] += (t1 - t0) * 1e3
            wanted = cfg.angles_for(i)
            keep = set(np.unique(np.linspace(0, len(wanted) - 1, min(cfg.keep_frames, len(wanted))).round().astype(int)).tolist()) if cfg.keep_frames else set()
            self.camera.begin(T_bf)
            extract_s = 0.0
            for k, a in enumerate(wanted):
                reached = self.motor.move_to(float(a), wait=True)
                self.camera.laser_at(float(reached))
                img = self.camera.grab()
                te = time.perf_counter()
                uv = extract_line(img)
                extract_s += time.perf_counter() - te
                index = len(angles)
                pixels.append(uv)
                frame_of.append(np.full(len(uv), index, dtype=np.int64))
                angles.append(float(reached))
                poses.append(T_bf)
                if k in keep:
                    kept[index] = img
            timings["sweep"] += (time.perf_counter() - t1 - extract_s) * 1e3
            timings["extract"] += extract_s * 1e3
            self.progress("scan", f"{len(wanted)} frames from flange ({T_bf[0, 3]:.1f}, {T_bf[1, 3]:.1f}, {T_bf[2, 3]:.1f}) mm, "
                                  f"laser {math.degrees(min(angles[-len(wanted):])):.1f}°..{math.degrees(max(angles[-len(wanted):])):.1f}°")
        t2 = time.perf_counter()
        cloud = triangulate(np.concatenate(pixels), np.concatenate(frame_of), np.array(angles), np.stack(poses), cfg.calibration,
                            num_threads=cfg.num_threads)
        timings["triangulate"] = (time.perf_counter() - t2) * 1e3
        self.progress("cloud", f"{len(cloud)} points (extract {timings['extract']:.0f} ms, triangulate {timings['triangulate']:.0f} ms)")
        return ScanResult(cloud=cloud, angles=np.array(angles), T_base_flanges=np.stack(poses), frames=MappingProxyType(kept),
                          timings=MappingProxyType(timings))

    def locate(self, scan: Optional[ScanResult] = None, *, exclude: Optional[np.ndarray] = None) -> Located:
        """The top pickable part in ``scan`` (a new scan when None), leaving out the points where
        ``exclude`` (bool, one per point) is true; NoObjectFound when there is none."""
        from .poses import estimate_pose

        scan = self.scan() if scan is None else scan
        cfg = self.config
        keep = np.arange(len(scan.points)) if exclude is None else np.flatnonzero(~np.asarray(exclude, dtype=bool))
        if len(keep) < 10:
            raise NoObjectFound(f"the scan holds {len(keep)} usable points; is the laser on and the bin in view?")
        options = dict(cfg.estimate_options)
        options.setdefault("num_threads", cfg.num_threads)
        # The camera's position at the first scan pose orients the scan's normals (PPF).
        options.setdefault("viewpoint", (np.asarray(scan.T_base_flanges[0]) @ cfg.calibration.T_flange_camera)[:3, 3])
        result = estimate_pose(scan.points[keep], cfg.model, bin=cfg.bin_bounds, **options)
        if result.score < cfg.min_score:
            raise NoObjectFound(f"the best pose scores {result.score:.2f}, below the cell's min_score {cfg.min_score:.2f}")
        T = np.asarray(result.T_scene_model, dtype=np.float64)
        truth = self.truth.judge(T) if self.truth is not None else None
        t = T[:3, 3]
        judged = "" if truth is None else (f"; vs truth {truth.rotation_error_deg:.2f}°, {truth.translation_error_mm:.2f} mm "
                                           f"({'pick-grade' if truth.pick_grade else 'NOT pick-grade'})")
        self.progress("locate", f"{result.method} score {result.score:.2f}, rmse {result.rmse:.2f} mm, at ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm "
                                f"in {sum(result.timings.values()):.0f} ms{judged}")
        idx = np.asarray(result.indices, dtype=np.int64)
        return Located(scan=scan, result=result, T_base_object=T, indices=keep[idx[(idx >= 0) & (idx < len(keep))]], truth=truth)

    EMPTY_GRIP_RADIUS_MM = 15.0
    """A part located within this distance of where the gripper closed on nothing earlier in the
    run is passed over: the same (wrong) pose would most likely be found and tried again."""

    def locate_and_plan(self, scan: ScanResult) -> Tuple[Located, PickPlan]:
        """Locates the top part and plans its pick; when no grasp of it can be used (or the gripper
        already closed on nothing there earlier in the run), leaves its points out and tries the
        next part, up to ``config.max_candidates`` parts."""
        excluded = np.zeros(len(scan.points), dtype=bool)
        last: Optional[NoGraspError] = None
        for _ in range(self.config.max_candidates):
            try:
                located = self.locate(scan, exclude=excluded)
            except NoObjectFound:
                if last is None:
                    raise
                break  # the parts found had no usable grasp: that is the reason to report
            try:
                t = located.T_base_object[:3, 3]
                if any(np.linalg.norm(t - spot) < self.EMPTY_GRIP_RADIUS_MM for spot in self._empty_grips):
                    raise NoGraspError(f"the gripper closed on nothing at this located {self.config.model.name} "
                                       f"({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm in an earlier pick of this run")
                return located, self.plan(located)
            except NoGraspError as exc:
                last = exc
                self.progress("plan", f"{exc}; trying the next part")
                if len(located.indices) == 0:
                    break
                excluded[located.indices] = True
        assert last is not None
        raise last

    def plan(self, located: Located) -> PickPlan:
        """The most vertical declared grasp that is within the tilt limit, reachable, clear of the
        scene and of the located part's own other branches, and whose whole motion passes the safety
        rules; NoGraspError when none is."""
        from .poses import grasp_pose

        cfg = self.config
        lim = cfg.limits
        T_fg_inv = _inv(cfg.gripper.T_flange_gripper)
        pts = np.asarray(located.scan.points)
        others = np.ones(len(pts), dtype=bool)
        others[located.indices] = False
        scene = pts[others]
        # The located part's own points are left out of the scene (they lie between the fingers), but
        # the gripper must not run into the part's other branches either: those are checked against
        # the model at the located pose, which also covers the part's unseen underside.
        part = np.asarray(cfg.model.points) @ located.T_base_object[:3, :3].T + located.T_base_object[:3, 3]
        here = self.robot.read_pose()
        rejected = {"tilt": 0, "reach": 0, "collision": 0, "self-collision": 0, "safety": 0}
        candidates = []
        for name, T_go in cfg.grasps.items():
            T_bg = grasp_pose(located.T_base_object, T_go)
            T_bf = T_bg @ T_fg_inv
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, -float(T_bf[2, 2])))))
            if math.radians(tilt) > lim.max_tool_tilt_rad:
                rejected["tilt"] += 1
                continue
            candidates.append((tilt, name, T_bg, T_bf))
        candidates.sort(key=lambda c: c[0])
        for tilt, name, T_bg, T_bf in candidates:
            waypoints = self._waypoints(T_bf, T_bg)
            if cfg.reachable is not None and not all(cfg.reachable(T) for _, T, _ in waypoints):
                rejected["reach"] += 1
                continue
            local = scene @ T_bg[:3, :3] - T_bg[:3, 3] @ T_bg[:3, :3]
            hits = int(cfg.gripper.occupied(local).sum())
            if hits > cfg.max_collision_points:
                rejected["collision"] += 1
                continue
            own = int(cfg.gripper.occupied(part @ T_bg[:3, :3] - T_bg[:3, 3] @ T_bg[:3, :3]).sum())
            if own > cfg.max_collision_points:
                rejected["self-collision"] += 1
                continue
            try:
                safety.check_sequence(here, [T for _, T, _ in waypoints], [lin for _, _, lin in waypoints], lim)
            except SafetyError:
                rejected["safety"] += 1
                continue
            plan = PickPlan(grasp=name, T_base_gripper=T_bg, T_base_flange=T_bf, tilt_deg=tilt, waypoints=tuple(waypoints),
                            considered=len(cfg.grasps), rejected=MappingProxyType(dict(rejected)))
            self.progress("plan", f"grasp {name}, tool tilt {tilt:.1f}°, {hits} scene points in the gripper "
                                  f"({len(cfg.grasps)} grasps: {', '.join(f'{v} {k}' for k, v in rejected.items() if v) or 'none rejected'})")
            return plan
        raise NoGraspError(
            f"none of the {len(cfg.grasps)} grasps of the located {cfg.model.name} can be used (rejected: "
            + ", ".join(f"{v} for {k}" for k, v in rejected.items() if v)
            + "); declare more grasps, widen CellLimits.max_tool_tilt_rad, or let the pile be stirred"
        )

    def _waypoints(self, T_bf: np.ndarray, T_bg: np.ndarray) -> List[Tuple[str, np.ndarray, bool]]:
        cfg = self.config
        axis = T_bg[:3, 2]
        approach = T_bf.copy()
        approach[:3, 3] -= cfg.approach_distance_mm * axis
        above = approach.copy()
        above[2, 3] = max(cfg.clearance_z_mm, approach[2, 3])
        lift = T_bf.copy()
        lift[2, 3] = max(cfg.clearance_z_mm, T_bf[2, 3])
        return [("above", above, False), ("approach", approach, True), ("grasp", T_bf, True),
                ("lift", lift, True), ("drop", cfg.drop_pose, False)]

    def pick(self, located: Optional[Located] = None, *, plan: Optional[PickPlan] = None, index: int = 1) -> PickRecord:
        """Scans and locates (unless ``located`` is given), plans and picks one part.

        Device faults and safety refusals stop the arm and are raised; a failed grip is a record
        with ``success=False``.
        """
        times: Dict[str, float] = {}
        t0 = time.perf_counter()
        if located is None:
            scan = self.scan()
            times.update({f"scan.{k}": v for k, v in scan.timings.items()})
            t1 = time.perf_counter()
            located, plan = self.locate_and_plan(scan)
            times["locate+plan"] = (time.perf_counter() - t1) * 1e3
        elif plan is None:
            t1 = time.perf_counter()
            plan = self.plan(located)
            times["plan"] = (time.perf_counter() - t1) * 1e3
        res = located.result
        times.update({f"estimate.{k}": float(v) for k, v in dict(getattr(res, "timings", {})).items()})
        t3 = time.perf_counter()
        held = self._execute(plan)
        times["motion"] = (time.perf_counter() - t3) * 1e3
        picked = self.truth.take_picked() if self.truth is not None else None
        if held is False:
            ok, error = False, "the gripper closed on nothing (no part between the fingers)"
            self._empty_grips.append(located.T_base_object[:3, 3].copy())
        elif self.truth is not None:
            ok = picked is not None and located.truth is not None and picked == located.truth.instance and located.truth.pick_grade
            error = None if ok else (
                "no part left the bin" if picked is None else
                f"part {picked} left the bin, but the located pose was not pick-grade or belonged to part "
                f"{None if located.truth is None else located.truth.instance}")
        else:
            ok, error = True, None
        times["total"] = (time.perf_counter() - t0) * 1e3
        self.progress("pick", ("picked" if ok else "FAILED") + (f" part {picked}" if picked is not None else "")
                      + f" with grasp {plan.grasp} in {times['motion'] / 1e3:.1f} s" + (f" — {error}" if error else ""))
        return PickRecord(index=index, success=ok, T_base_object=located.T_base_object, score=float(res.score), rmse=float(res.rmse),
                          method=getattr(res, "method", None), points=len(located.scan.points), grasp=plan.grasp, held=held,
                          truth=located.truth, picked_instance=picked, error=error, timings=MappingProxyType(times))

    def _execute(self, plan: PickPlan) -> Optional[bool]:
        """Runs the plan; returns what the gripper said about holding. Faults stop the arm and are raised."""
        try:
            self._open_for_grasp()
            for name in ("above", "approach", "grasp"):
                self._move(plan.pose(name), linear=dict((n, lin) for n, _, lin in plan.waypoints)[name])
            held = self.gripper.close()
            self._move(plan.pose("lift"), linear=True)
            if held is False:
                self.gripper.open()
                return False
            self._move(plan.pose("drop"), linear=False)
            self.gripper.open()
            return held
        except BinpickError as exc:
            note = self._halt()
            self.progress("FAULT", f"{exc} — {note}")
            raise

    def _open_for_grasp(self) -> None:
        """Opens the fingers as wide as the collision check assumed (fully when the gripper cannot be set to a width)."""
        to_width = getattr(self.gripper, "move_to_width", None)
        stroke = getattr(getattr(self.gripper, "config", None), "stroke_mm", None)
        if to_width is not None and stroke is not None:
            to_width(min(self.config.gripper.open_width_mm, float(stroke)))
        else:
            self.gripper.open()

    def run(self, n_picks: int) -> RunReport:
        """Up to ``n_picks`` picks; stops early when nothing is found, no grasp fits, or a device faults (the arm is stopped)."""
        n = count(n_picks, "n_picks", 1)
        self._empty_grips = []
        records: List[PickRecord] = []
        stopped: Optional[str] = None
        last_scan: Optional[ScanResult] = None
        last_located: Optional[Located] = None
        for i in range(1, n + 1):
            self.progress("pick", f"— pick {i} of {n} —")
            t0 = time.perf_counter()
            scan: Optional[ScanResult] = None
            located: Optional[Located] = None
            try:
                scan = last_scan = self.scan()
                t1 = time.perf_counter()
                located, plan = self.locate_and_plan(scan)
                last_located = located
                times = {f"scan.{k}": v for k, v in scan.timings.items()}
                times["locate+plan"] = (time.perf_counter() - t1) * 1e3
                record = self.pick(located, plan=plan, index=i)
                times.update(record.timings)
                times["total"] = (time.perf_counter() - t0) * 1e3
                records.append(replace(record, timings=MappingProxyType(times)))
            except (NoObjectFound, NoGraspError) as exc:
                stopped = f"pick {i}: {exc}"
                records.append(self._failed(i, scan, located, exc, t0, fault=False))
                break
            except BinpickError as exc:
                stopped = f"pick {i}: {type(exc).__name__}: {exc}"
                records.append(self._failed(i, scan, located, exc, t0, fault=True))
                break
        return RunReport(records=tuple(records), stopped=stopped, last_scan=last_scan, last_located=last_located)

    @staticmethod
    def _failed(i: int, scan: Optional[ScanResult], loc: Optional[Located], exc: BaseException, t0: float, *, fault: bool) -> PickRecord:
        res = None if loc is None else loc.result
        return PickRecord(index=i, success=False, T_base_object=None if loc is None else loc.T_base_object,
                          score=None if res is None else float(res.score), rmse=None if res is None else float(res.rmse),
                          method=None if res is None else res.method, points=0 if scan is None else len(scan.points),
                          truth=None if loc is None else loc.truth, error=str(exc), fault=fault,
                          timings=MappingProxyType({"total": (time.perf_counter() - t0) * 1e3}))


# --------------------------------------------------------------------------- the simulated cell

def _sim_arm():
    from .devices.emulators import ArmModel

    # A larger arm than the emulator's default RV-1A class, so that the simulated cell's scan pose
    # 620 mm above the bin floor and every corner of the bin are within reach.
    return ArmModel(base_height_mm=250.0, upper_arm_mm=400.0, forearm_mm=450.0, flange_mm=90.0,
                    workspace_min_mm=(-900.0, -900.0, -200.0), workspace_max_mm=(900.0, 900.0, 1100.0))


SIM_ARM = _sim_arm()
"""The simulated cell's arm (see :class:`binpick.devices.emulators.ArmModel`)."""


def sim_limits(layout: Any = None, gripper: Optional[GripperGeometry] = None) -> safety.CellLimits:
    """The simulated cell's motion limits: a workspace around the bin and the drop area, and an
    approach height that keeps the gripper above the bin's rim for joint moves."""
    from .sim import Cell as Layout

    layout = layout if layout is not None else Layout()
    gripper = gripper or GripperGeometry()
    lo, hi = layout.bin.bounds
    reach = float(gripper.T_flange_gripper[2, 3]) + gripper.tip_depth_mm
    return safety.CellLimits(
        workspace_min_mm=(float(lo[0]) - 150.0, float(lo[1]) - 250.0, float(lo[2]) + 60.0),
        workspace_max_mm=(float(hi[0]) + 100.0, float(hi[1]) + 250.0, float(layout.T_base_flange[2, 3]) + 80.0),
        approach_height_mm=float(hi[2]) + reach + 30.0,
        max_lateral_below_mm=40.0,
    )


class _Reach:
    """``T_base_flange → bool``: whether the arm's inverse kinematics reaches the pose in posture FL1."""

    def __init__(self, arm: Any, fl1: int = 7) -> None:
        self.arm = arm
        self.fl1 = fl1
        self.q_ref = np.radians([0.0, 0.0, 90.0, 0.0, 90.0, 0.0])

    def __call__(self, T: np.ndarray) -> bool:
        try:
            self.arm.inverse(T, self.fl1, self.q_ref)
        except Exception:  # the arm model raises its refusal (joint limit, out of reach) as an exception
            return False
        return True


class SimCamera(FrameSource):
    """The simulated camera: renders the pile of a :class:`SimulatedCell` from the flange pose the
    robot emulator reports, with the laser at the angle the motor emulator reports."""

    def __init__(self, sim: "SimulatedCell", *, seed: int = 0) -> None:
        self.sim = sim
        self.seed = int(seed)
        self._view = None
        self._frame = 0

    def begin(self, T_base_flange: np.ndarray) -> None:
        from .sim import World

        self.sim.settle_pending()
        world = World.of_pile(self.sim.pile)
        actual = self.sim.robot_emulator.pose()
        self._view = world.view(self.sim.layout, actual, num_threads=self.sim.num_threads)

    def grab(self) -> np.ndarray:
        if self._view is None:
            raise InvalidInputError("camera: call begin(T_base_flange) before grab(); the cell does this at each scan pose")
        angle = self.sim.laser_angle()
        rgb = self._view.frame(angle, seed=self.seed + self._frame)
        self._frame += 1
        return np.ascontiguousarray(rgb[:, :, ::-1])


class RenderedCamera(FrameSource):
    """A simulated camera for trying a cell configuration without one: a pile of ``model``
    rendered from the flange pose and laser angle the drivers report (``begin``/``laser_at``)."""

    def __init__(self, model: Model, *, count: int = 8, seed: int = 0, layout: Any = None, num_threads: int = 0) -> None:
        from .sim import Cell as Layout
        from .sim import Pile, World

        self.layout = layout if layout is not None else Layout()
        self.pile = Pile(model, count, bin=self.layout.bin, seed=seed)
        self.world = World.of_pile(self.pile)
        self.seed = int(seed)
        self.num_threads = int(num_threads)
        self._view = None
        self._angle = 0.0
        self._frame = 0

    def begin(self, T_base_flange: np.ndarray) -> None:
        self._view = self.world.view(self.layout, as_transform(T_base_flange, "T_base_flange"), num_threads=self.num_threads)

    def laser_at(self, angle: float) -> None:
        self._angle = float(angle)

    def grab(self) -> np.ndarray:
        if self._view is None:
            raise InvalidInputError("camera: call begin(T_base_flange) before grab(); the cell does this at each scan pose")
        rgb = self._view.frame(self._angle, seed=self.seed + self._frame)
        self._frame += 1
        return np.ascontiguousarray(rgb[:, :, ::-1])


class SimulatedCell:
    """The simulated cell: a settled pile, the three emulators on ptys, the real drivers on them,
    the simulated camera, and the :class:`Cell` running the pick loop (``.cell``).

    Use as a context manager (it starts the emulators and opens the cell). It is also the cell's
    ground truth (:meth:`judge`, :meth:`take_picked`).

    Args:
        model: the part.
        count: parts dropped into the bin.
        seed: seed of the pile and the sensor noise.
        frames: laser frames per scan.
        layout: the simulated hardware (camera, laser, bin, lighting, noise, scan pose), a ``binpick.sim.Cell``.
        gripper: the gripper geometry.
        drop_pose: where parts are released (default: beside the bin, 350 mm up).
        grip_tolerance_mm: the gripper holds a part when the part's pose in the gripper is within
            this distance of a declared grasp …
        grip_tolerance_deg: … and within this angle.
        speed_scale: speeds up the emulated arm (1 = real time).
        progress: stage printer (see :class:`ProgressPrinter`).
        num_threads: rendering and pose-estimation threads, 0 = all cores.
        config_overrides: fields of :class:`CellConfig` to set (e.g. ``estimate_options``).
    """

    def __init__(self, model: Model, *, count: int = 12, seed: int = 0, frames: int = 90, layout: Any = None,
                 gripper: Optional[GripperGeometry] = None, drop_pose: Any = None, grip_tolerance_mm: float = 6.0,
                 grip_tolerance_deg: float = 12.0, speed_scale: float = 10.0, progress: Optional[Callable[[str, str], None]] = None,
                 num_threads: int = 0, **config_overrides: Any) -> None:
        from .sim import Cell as Layout
        from .sim import Pile

        if not isinstance(model, Model):
            raise InvalidInputError(f"model: expected a binpick.Model, got {type(model).__name__}")
        self.layout = layout if layout is not None else Layout()
        self.model = model
        self.seed = int(seed)
        self.num_threads = int(num_threads)
        self.gripper_geometry = gripper or GripperGeometry()
        self.grip_tolerance_mm = positive(grip_tolerance_mm, "grip_tolerance_mm")
        self.grip_tolerance_deg = positive(grip_tolerance_deg, "grip_tolerance_deg", "deg")
        self.speed_scale = positive(speed_scale, "speed_scale", "")
        self.progress = progress or _quiet
        self.frames = frames
        self.count = count
        self.config_overrides = config_overrides
        lo, hi = self.layout.bin.bounds
        self.drop_pose = drop_pose if drop_pose is not None else _look_down(float(lo[0] + hi[0]) / 2, float(lo[1]) - 150.0, 350.0)
        t0 = time.perf_counter()
        self.pile = Pile(model, count, bin=self.layout.bin, seed=seed)
        self.progress("pile", f"{len(self.pile)} {model.name} parts dropped and settled in {time.perf_counter() - t0:.1f} s")
        self.removed: List[int] = []
        self._held: Optional[int] = None
        self._release_pending: Optional[int] = None
        self._picked: Optional[int] = None
        self.cell: Optional[Cell] = None
        self._grasp_stack: Optional[np.ndarray] = None
        self.robot_emulator = self.motor_emulator = self.gripper_emulator = None

    # -- life cycle
    def __enter__(self) -> "SimulatedCell":
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def start(self) -> Cell:
        """Starts the emulators, opens the drivers on their ptys and the cell; returns the cell."""
        from .devices import DynamixelConfig, DynamixelMotor, GripperConfig, MelfaConfig, ModbusGripper, MotorRange, SerialSettings
        from .devices.emulators import DynamixelEmulator, RobotEmulator, RobotEmulatorConfig

        self.robot_emulator = RobotEmulator(config=RobotEmulatorConfig(arm=SIM_ARM, speed_scale=self.speed_scale)).start()
        self.motor_emulator = DynamixelEmulator().start()
        self.gripper_emulator = _SimGripperEmulator(self).start()
        limits = self.config_overrides.pop("limits", None) or sim_limits(self.layout, self.gripper_geometry)
        config = CellConfig(calibration=self.layout.calibration(), model=self.model, bin_bounds=self.layout.bin.bounds,
                            scan_poses=(self.layout.T_base_flange,), drop_pose=self.drop_pose, frames=self.frames,
                            gripper=self.gripper_geometry, limits=limits, reachable=_Reach(SIM_ARM),
                            num_threads=self.num_threads, **self.config_overrides)
        robot = MelfaRobot(self.robot_emulator.slave_path, limits=limits, config=MelfaConfig(
            serial=SerialSettings(baudrate=9600, parity="E", stopbits=2, timeout_s=1.0, retries=2),
            initial_override_percent=min(50.0, limits.max_override_percent),
            initial_linear_speed_mm_s=min(250.0, limits.max_linear_speed_mm_s), poll_interval_s=0.01, motion_timeout_s=30.0))
        motor = DynamixelMotor(self.motor_emulator.slave_path, config=DynamixelConfig(
            serial=SerialSettings(baudrate=57600, timeout_s=0.2), range=MotorRange(max_speed_rad_s=2 * math.pi, poll_interval_s=0.002)))
        self._gripper_config = GripperConfig(serial=SerialSettings(baudrate=115200, timeout_s=0.3), speed=255)
        gripper = ModbusGripper(self.gripper_emulator.slave_path, config=self._gripper_config)
        self.progress("emulate", f"robot on {self.robot_emulator.slave_path}, laser motor on {self.motor_emulator.slave_path}, "
                                 f"gripper on {self.gripper_emulator.slave_path}")
        self.cell = Cell(config, robot=robot, motor=motor, gripper=gripper, camera=SimCamera(self, seed=self.seed),
                         progress=self.progress, truth=self)
        self.cell.open()
        return self.cell

    def close(self) -> None:
        """Closes the cell and stops the emulators."""
        if self.cell is not None:
            self.cell.close()
        for emu in (self.robot_emulator, self.motor_emulator, self.gripper_emulator):
            if emu is not None:
                emu.close()

    @property
    def emulator_failures(self) -> List[str]:
        """Exceptions the emulators raised while serving (an emulator bug; should stay empty)."""
        return [f for emu in (self.robot_emulator, self.motor_emulator, self.gripper_emulator) if emu is not None for f in emu.failures]

    # -- the physical world
    def laser_angle(self) -> float:
        """Where the laser motor really is, radians."""
        ticks = self.motor_emulator.present_position()
        return (ticks - 2048) * 2 * math.pi / 4096

    def T_base_tcp(self) -> np.ndarray:
        """Where the gripper's TCP really is."""
        return self.robot_emulator.pose() @ self.gripper_geometry.T_flange_gripper

    def _grasp_error(self, T_gripper_object: np.ndarray) -> Tuple[float, float]:
        """:func:`pose_error` of ``T_gripper_object`` against the nearest declared grasp, for all
        grasps at once (the gripper emulator answers within its serial timeout even with hundreds)."""
        assert self.cell is not None
        if self._grasp_stack is None:
            cfg = self.cell.config
            grasps = np.stack([np.asarray(T, dtype=np.float64) for T in cfg.grasps.values()])
            syms = np.stack([np.eye(4), *[np.asarray(S, dtype=np.float64) for S in cfg.symmetries]])
            self._grasp_stack = np.einsum("gij,sjk->gsik", grasps, syms)  # T_go · S for every grasp and symmetry
        B = self._grasp_stack
        A = np.asarray(T_gripper_object, dtype=np.float64)
        # trace(B_Rᵀ A_R) per grasp and symmetry, then the angle as in _rotation_deg
        trace = np.einsum("gsji,ji->gs", B[:, :, :3, :3], A[:3, :3])
        deg = np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0)))
        mm = np.linalg.norm(B[:, :, :3, 3] - A[:3, 3], axis=-1)
        s = np.argmin(deg / 5.0 + mm / 3.0, axis=1)  # pose_error's choice of symmetry, per grasp
        g_idx = np.arange(len(B))
        deg, mm = deg[g_idx, s], mm[g_idx, s]
        g = int(np.argmin(deg / self.grip_tolerance_deg + mm / self.grip_tolerance_mm))
        return float(deg[g]), float(mm[g])

    def grip_check(self) -> Optional[Tuple[int, float]]:
        """The part between the fingers now, if any, and its width across them (mm): the part
        nearest the TCP whose pose in the gripper is within the grip tolerance of a declared grasp."""
        self.settle_pending()
        T_gb = _inv(self.T_base_tcp())
        best = None
        for pid, T_bo in zip(self.pile.ids, self.pile.poses):
            if int(pid) == self._held:
                continue
            deg, mm = self._grasp_error(T_gb @ T_bo)
            if best is None or deg / self.grip_tolerance_deg + mm / self.grip_tolerance_mm < best[1] / self.grip_tolerance_deg + best[2] / self.grip_tolerance_mm:
                best = (int(pid), deg, mm, T_gb @ T_bo)
        if best is None or best[2] > self.grip_tolerance_mm or best[1] > self.grip_tolerance_deg:
            return None
        pid, _, _, T_go = best
        g = self.gripper_geometry
        local = self.model.points @ T_go[:3, :3].T + T_go[:3, 3]
        between = (np.abs(local[:, 1]) <= g.finger_width_mm / 2) & (local[:, 2] <= g.tip_depth_mm) & (local[:, 2] >= g.tip_depth_mm - g.finger_length_mm)
        if not between.any():
            return None
        return pid, float(2.0 * np.abs(local[between, 0]).max())

    def on_gripper_command(self, closing: bool, emulator: Any) -> None:
        """Called by the gripper emulator on every motion command: on closing it finds the part
        between the fingers (the fingers stop on it); on opening a held part is let go."""
        if closing:
            hit = self.grip_check()
            if hit is None:
                emulator.object_at = None
                self._held = None
            else:
                pid, width = hit
                stroke = self._gripper_config.stroke_mm
                emulator.object_at = int(round((1.0 - min(width, stroke) / stroke) * 255))
                self._held = pid
        else:
            emulator.object_at = None
            if self._held is not None:
                self._release_pending = self._held
                self._held = None

    def settle_pending(self) -> None:
        """Takes a released part out of the pile and lets the rest settle (done lazily, off the emulator thread)."""
        pid = self._release_pending
        if pid is not None:
            self._release_pending = None
            tcp = self.T_base_tcp()[:3, 3]
            lo, hi = self.layout.bin.bounds
            inside = bool((tcp[:2] >= lo[:2]).all() and (tcp[:2] <= hi[:2]).all() and tcp[2] < hi[2] + 20)
            if inside:
                self.pile.settle()  # let go above the pile: it falls back in
                return
            t0 = time.perf_counter()
            report = self.pile.remove(pid)
            self.removed.append(pid)
            self._picked = pid
            self.progress("physics", f"part {pid} left the bin; {len(self.pile)} remain, settled in {time.perf_counter() - t0:.1f} s "
                                     f"({report.steps} steps)")

    # -- ground truth
    def judge(self, T_base_object: np.ndarray) -> PoseTruth:
        """The located pose against the nearest part of the pile (errors modulo the part's symmetries)."""
        self.settle_pending()
        syms = self.cell.config.symmetries if self.cell is not None else ()
        best = None
        for pid, T_bo in zip(self.pile.ids, self.pile.poses):
            deg, mm = pose_error(T_base_object, T_bo, syms)
            if best is None or mm < best.translation_error_mm:
                best = PoseTruth(instance=int(pid), rotation_error_deg=deg, translation_error_mm=mm)
        if best is None:
            raise NoObjectFound("the simulated bin is empty")
        return best

    def take_picked(self) -> Optional[int]:
        """The part that left the bin since the last call, or None."""
        self.settle_pending()
        pid, self._picked = self._picked, None
        return pid


def _look_down(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (x, y, z)
    return T


class _SimGripperEmulator(GripperEmulator):
    """The Modbus gripper emulator whose fingers stop on the simulated part between them."""

    def __init__(self, sim: SimulatedCell) -> None:
        super().__init__()
        self.sim = sim

    def _apply(self) -> None:
        action, request = self.command[0], self.command[3]
        if action & GTO:
            try:
                self.sim.on_gripper_command(request > self.axis.position(), self)
            except Exception as exc:  # keep serving; the failure shows in emulator.failures
                self.failures.append(f"simulated grip: {type(exc).__name__}: {exc}")
        super()._apply()


def simulated_cell(model: Optional[Model] = None, **kwargs: Any) -> SimulatedCell:
    """A :class:`SimulatedCell` (the built-in tee when ``model`` is None); use it as a context manager."""
    if model is None:
        from . import parts

        model = parts.tee()
    return SimulatedCell(model, **kwargs)


# --------------------------------------------------------------------------- the real cell's file

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
    from .devices.xyzabc import transform_from_xyzabc

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
    import os

    try:
        import tomllib
    except ModuleNotFoundError:  # Python < 3.11
        import tomli as tomllib  # type: ignore[no-redef]
    from .errors import MeshFileNotFoundError

    p = os.fspath(path)
    try:
        with open(p, "rb") as f:
            doc = tomllib.load(f)
    except FileNotFoundError:
        raise MeshFileNotFoundError(f"{p}: cell file not found; write one after `binpick pick --example`") from None
    except tomllib.TOMLDecodeError as exc:
        raise InvalidInputError(f"{p}: not valid TOML ({exc})") from None
    return CellFile(path=p, doc=doc)


def cell_from_file(cell_file: CellFile, *, progress: Optional[Callable[[str, str], None]] = None, num_threads: int = 0) -> Cell:
    """Builds the drivers, camera and :class:`CellConfig` a cell file describes (nothing is sent
    yet: open the returned cell as a context manager)."""
    import os

    from . import parts
    from .devices import (AiMotor, AiMotorConfig, DynamixelConfig, DynamixelMotor, GripperConfig, MelfaConfig,
                          MelfaHandGripper, ModbusGripper, SerialSettings)

    f = cell_file
    here = os.path.dirname(os.path.abspath(f.path))
    name = str(f.get("part", "model"))
    model = getattr(parts, name)() if name in ("tee", "elbow", "cross") else Model.from_mesh(
        os.path.join(here, name), unit=str(f.get("part", "unit", "mm")))
    calibration = CellCalibration.load(os.path.join(here, str(f.get("cell", "calibration"))))
    lim_t = f.doc.get("limits", {})
    defaults = safety.CellLimits()
    limits = safety.CellLimits(
        workspace_min_mm=tuple(float(v) for v in lim_t.get("workspace_min_mm", defaults.workspace_min_mm)),
        workspace_max_mm=tuple(float(v) for v in lim_t.get("workspace_max_mm", defaults.workspace_max_mm)),
        approach_height_mm=float(lim_t.get("approach_height_mm", defaults.approach_height_mm)),
        max_tool_tilt_rad=math.radians(float(lim_t.get("max_tool_tilt_deg", math.degrees(defaults.max_tool_tilt_rad)))),
        max_lateral_below_mm=float(lim_t.get("max_lateral_below_mm", defaults.max_lateral_below_mm)),
        max_override_percent=float(lim_t.get("max_override_percent", defaults.max_override_percent)),
        max_linear_speed_mm_s=float(lim_t.get("max_linear_speed_mm_s", defaults.max_linear_speed_mm_s)),
    )
    gripper_geometry = GripperGeometry(T_flange_gripper=_pose_deg(f.get("cell", "tool", [0, 0, 150, 0, 0, 0]), f"{f.path}: [cell] tool"))
    config = CellConfig(
        calibration=calibration, model=model,
        bin_bounds=(f.get("cell", "bin_min_mm"), f.get("cell", "bin_max_mm")),
        scan_poses=(_pose_deg(f.get("cell", "scan_pose"), f"{f.path}: [cell] scan_pose"),),
        drop_pose=_pose_deg(f.get("cell", "drop_pose"), f"{f.path}: [cell] drop_pose"),
        frames=int(f.get("cell", "frames", 90)), gripper=gripper_geometry, limits=limits, num_threads=num_threads,
        estimate_options=dict(f.doc.get("estimate", {})),
    )
    check_static_poses(config)  # before any port is opened
    robot = MelfaRobot(str(f.get("robot", "port")), limits=limits, config=MelfaConfig(
        serial=SerialSettings(baudrate=int(f.get("robot", "baudrate", 9600)), parity="E", stopbits=2, timeout_s=2.0),
        initial_override_percent=float(f.get("robot", "override_percent", 10.0)),
        initial_linear_speed_mm_s=float(f.get("robot", "linear_speed_mm_s", 50.0))))
    protocol = str(f.get("motor", "protocol", "dynamixel"))
    motor_serial = SerialSettings(baudrate=int(f.get("motor", "baudrate", 57600)), timeout_s=0.2)
    if protocol == "dynamixel":
        motor: LaserMotor = DynamixelMotor(str(f.get("motor", "port")), config=DynamixelConfig(motor_id=int(f.get("motor", "id", 1)), serial=motor_serial))
    elif protocol == "aimotor":
        motor = AiMotor(str(f.get("motor", "port")), config=AiMotorConfig(motor_id=int(f.get("motor", "id", 0)), serial=motor_serial))
    else:
        raise InvalidInputError(f"{f.path}: [motor] protocol = {protocol!r}; use 'dynamixel' or 'aimotor'")
    kind = str(f.get("gripper", "kind", "modbus"))
    if kind == "modbus":
        gripper: Gripper = ModbusGripper(str(f.get("gripper", "port")), config=GripperConfig(
            slave=int(f.get("gripper", "slave", 9)), serial=SerialSettings(baudrate=int(f.get("gripper", "baudrate", 115200)), timeout_s=0.3)))
    elif kind == "hand":
        gripper = MelfaHandGripper(robot, hand=int(f.get("gripper", "hand", 1)))
    else:
        raise InvalidInputError(f"{f.path}: [gripper] kind = {kind!r}; use 'modbus' or 'hand'")
    source = str(f.get("camera", "source", "opencv"))
    if source == "opencv":
        camera: FrameSource = OpenCVCamera(f.get("camera", "device", 0))
    elif source == "simulated":
        camera = RenderedCamera(model, count=int(f.get("camera", "count", 8)), seed=int(f.get("camera", "seed", 0)), num_threads=num_threads)
    else:
        raise InvalidInputError(f"{f.path}: [camera] source = {source!r}; use 'opencv' or 'simulated'")
    return Cell(config, robot=robot, motor=motor, gripper=gripper, camera=camera, progress=progress)
