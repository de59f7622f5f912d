"""The simulated cell, the digital twin of the real one: a settled physics pile, the robot,
laser motor and gripper emulators serving their real protocols on ptys, the real drivers opened
on those ptys, and a camera that renders the pile from the pose the robot emulator reports with
the laser at the angle the motor emulator reports — driven by the same pick loop
(:class:`binpick.cell.Cell`) as the real cell. The simulated gripper closes on a part only when
the part really lies between its fingers; the part leaves the pile when the gripper lets go;
a motion of the closed, empty gripper through the bin pushes the pile (:meth:`binpick.sim.Pile.push`).

:class:`TwinWorld` is the twin's physical side (pile, emulators, ground truth) that both the
in-process :class:`SimulatedCell` and the twin process (``binpick emulate cell``,
:mod:`binpick.sim.twin_process`) run; :class:`SimulatedCell` adds the drivers and the pick loop.

Lengths in mm, angles in radians; transforms are 4×4 ``T_to_from``.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from dataclasses import replace
from typing import Any, Callable, Optional

import numpy as np

from .. import _validate, parts
from .._sizes import check_part
from .._validate import positive, thread_count
from ..cell.config import CellConfig, GripperGeometry
from ..cell.grasp import GraspMatcher, continuous_symmetry, grip_width, symmetry_maps
from ..cell.loop import Cell, quiet
from ..cell.records import PoseTruth
from ..cell.symmetry import continuous_near_axis
from ..devices import (
    DynamixelConfig,
    DynamixelMotor,
    GripperConfig,
    MelfaConfig,
    MelfaRobot,
    ModbusGripper,
    MotorRange,
    SerialSettings,
    safety,
)
from ..devices.emulators import (
    DynamixelEmulator,
    GripperEmulator,
    GripperEmulatorConfig,
    RobotEmulator,
    RobotEmulatorConfig,
)
from ..devices.emulators.clock import PhysicalClock
from ..devices.emulators.ur import URArm, UREmulator
from ..devices.gripper import GTO
from ..errors import InvalidInputError, NoObjectFound
from ..models import Model
from ..transforms import inverse, look_down, rotation_angle_deg
from .camera import SimCamera
from .cell import Cell as Layout
from .contacts import contacts_along
from .hardware import (
    SIM_FINGER_SPEED_MM_S,
    SIM_JOINT_SPEEDS_DEG_S,
    SIM_RAMP_S,
    _layout_and_gripper,
    _Reach,
    sim_arm,
    sim_limits,
)
from .pile import Pile, PushReport

#: The gripper counts as closed (a pushing tool) when its fingers are at most this far apart, mm.
CLOSED_OPENING_MM = 10.0
#: A part's surface more than this far inside a finger (mm) means the finger came down on the
#: part instead of beside it: no grip. Twice the planner's :data:`binpick.cell.grasp.GRAZE_MM`.
FINGER_LANDING_MM = 1.0

#: Most model points per part the contact check uses (evenly thinned): their spacing on the
#: part's surface is well under a finger's thickness.
CONTACT_POINTS = 3000

#: Fastest sweep the physics is asked to run, mm/s: faster motions are pushed at this speed.
MAX_SWEEP_SPEED = 1000.0

__all__ = ["TwinWorld", "SimulatedCell", "simulated_cell"]


class TwinWorld:
    """The digital twin's physical world: a settled pile, the robot, laser-motor and gripper
    emulators serving their protocols on ptys (the gripper's fingers stop on a part only when the
    part lies between them, and a held part leaves the bin when let go outside it), and the
    ground truth (:meth:`judge`, :meth:`take_picked`, :meth:`parts_left`). :class:`binpick.sim.SimCamera`
    renders it.

    Use as a context manager (starts and stops the emulators). Its state is changed under
    :attr:`lock` (the gripper emulator's thread, the camera and the caller share it).

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
        speed_scale: plays the emulated arm and gripper this many times faster than they move
            (1 = real time); the hardware time they take is kept on :attr:`clock` at their own
            speeds (:data:`SIM_JOINT_SPEEDS_DEG_S`, :data:`SIM_RAMP_S`, :data:`SIM_FINGER_SPEED_MM_S`,
            the laser motor's, the camera's ``layout.camera_fps``).
        progress: stage printer (see :class:`ProgressPrinter`).
        num_threads: rendering and pose-estimation threads, 0 = all cores.
        robot: the arm: ``"melfa"`` (the paper's, R3 over a pty) or ``"ur"`` (a UR5e-class arm,
            its controller on TCP: RTDE, dashboard, URScript).
        max_override_percent, max_linear_speed_mm_s: the arm's speed limits in place of the
            simulated cell's (50 %, 250 mm/s); the simulated cell runs at its limits' speeds.
        config_overrides: fields of :class:`CellConfig` to set (e.g. ``estimate_options``, ``limits``).
    """

    def __init__(
        self,
        model: Model,
        *,
        count: int = 12,
        seed: int = 0,
        frames: int = 90,
        layout: Any = None,
        gripper: Optional[GripperGeometry] = None,
        drop_pose: Any = None,
        grip_tolerance_mm: float = 6.0,
        grip_tolerance_deg: float = 12.0,
        speed_scale: float = 10.0,
        progress: Optional[Callable[[str, str], None]] = None,
        num_threads: int = 0,
        robot: str = "melfa",
        max_override_percent: Optional[float] = None,
        max_linear_speed_mm_s: Optional[float] = None,
        **config_overrides: Any,
    ) -> None:
        if not isinstance(model, Model):
            raise InvalidInputError(f"model: expected a binpick.Model, got {type(model).__name__}")
        given = layout is not None
        if layout is None:
            layout = Layout.for_part(model)
        self.layout, self.gripper_geometry = _layout_and_gripper(layout, gripper, model)
        # Before the arm is sized and the pile dropped: a part no cell holds (a mesh read in the
        # wrong unit) is named, not met as an arm that reaches no bin or a part with no grasps. A
        # layout made for the part holds it by construction; a given one must.
        check_part(
            model,
            bin_bounds=self.layout.bin.bounds if given else None,
            opening_mm=self.gripper_geometry.open_width_mm,
        )
        self.robot = _validate.choice(robot, "robot", ("melfa", "ur"))
        self.arm = sim_arm(self.layout, self.gripper_geometry) if self.robot == "melfa" else URArm()
        self.model = model
        self.seed = _validate.count(seed, "seed")
        self.num_threads = thread_count(num_threads)
        self.grip_tolerance_mm = positive(grip_tolerance_mm, "grip_tolerance_mm")
        self.grip_tolerance_deg = positive(grip_tolerance_deg, "grip_tolerance_deg", "deg")
        self.speed_scale = positive(speed_scale, "speed_scale", "")
        self.progress = progress or quiet
        self.frames = frames
        self.count = count
        given = config_overrides.pop("limits", None)
        self.limits = given or sim_limits(self.layout, self.gripper_geometry)
        speeds = {
            k: v
            for k, v in (
                ("max_override_percent", max_override_percent),
                ("max_linear_speed_mm_s", max_linear_speed_mm_s),
            )
            if v is not None
        }
        if speeds:  # the arm's speeds as the limits allow them (the cell runs at them)
            self.limits = replace(self.limits, **speeds)
        #: The cell's hardware time, kept by its emulators (see :mod:`binpick.devices.emulators.clock`).
        self.clock = PhysicalClock()
        self.config_overrides = config_overrides
        self.lock = threading.RLock()
        t0 = time.perf_counter()
        self.pile = self._fitting_pile(count, seed, raise_approach=given is None)
        self.progress(
            "pile", f"{len(self.pile)} {model.name} parts dropped and settled in {time.perf_counter() - t0:.1f} s"
        )
        lo, hi = self.layout.bin.bounds
        # Beside the bin, 350 mm up (higher when the approach height of a deep bin or a high pile asks for it).
        drop_z = max(350.0, float(self.limits.approach_height_mm) + 20.0)
        self.drop_pose = (
            drop_pose if drop_pose is not None else look_down(float(lo[0] + hi[0]) / 2, float(lo[1]) - 150.0, drop_z)
        )
        self.removed: list[int] = []
        self._held: Optional[int] = None
        self._release_pending: Optional[int] = None
        self._picked: Optional[int] = None
        # Motions queued for the physics, in order: (gripper path, opening, push speed or -1 for
        # a contact check, first flange pose, the part not checked).
        self._pushes: list[tuple] = []
        #: Every contact of the gripper with a part other than the one held, or with the bin
        #: (:mod:`binpick.sim.contacts`), in order: ``with``, ``points``, ``opening_mm``,
        #: ``T_base_flange`` and ``T_base_gripper`` (at the first touch), ``T_base_flange_start``
        #: (the motion's start).
        self.collisions: list[dict] = []
        self._new_collisions: list[dict] = []
        #: The parts a push threw over a wall or through the floor, in order: out of the pile
        #: (and of the cell's reach), neither picked nor left in the bin.
        self.lost: list[int] = []
        pts = np.asarray(model.points, dtype=np.float64)
        self._contact_points = pts[:: max(1, len(pts) // CONTACT_POINTS)]
        #: Every sweep of the closed, empty gripper through the bin the physics ran, in order.
        self.pushes: list[PushReport] = []
        self.config = self._config(self.limits)
        self._matcher: Optional[GraspMatcher] = None
        self._centre = np.zeros(3)
        self._grasp_reach = math.inf
        self._gripper_config = GripperConfig(serial=SerialSettings(baudrate=115200, timeout_s=0.3), speed=255)
        self.robot_emulator = self.motor_emulator = self.gripper_emulator = None

    def _fitting_pile(self, count: int, seed: int, raise_approach: bool) -> Pile:
        """The pile of ``count`` parts, or of as many as the cell can work over. The gripper's tips
        pass over the bin at the approach height less the gripper's reach; a pile heaped above
        that gets the approach height raised to clear it by the same margin (``raise_approach``,
        the cell's own limits: an integrator sets the approach over the highest part), up to
        where the tips would come within that margin of where they are at the scan pose (whose
        camera must see the pile from above); with the caller's limits, the pass height is the
        ceiling. A pile above the ceiling is dropped again with as many parts as lay below it (at
        least one fewer), and says so (:attr:`heaped`: how many were left out); a part that stands
        above it alone is refused (InvalidInputError)."""
        g = self.gripper_geometry
        reach = float(g.T_flange_gripper[2, 3]) + g.tip_depth_mm
        pass_z = float(self.limits.approach_height_mm) - reach
        margin = pass_z - float(self.layout.bin.bounds[1][2])  # the approach's clearance over the rim
        ceiling = float(self.layout.T_base_flange[2, 3]) - reach - 2.0 * margin if raise_approach else pass_z
        vertices = np.asarray(self.model.vertices, dtype=np.float64)
        n = count
        while True:
            pile = Pile(self.model, n, bin=self.layout.bin, seed=seed)
            poses = np.asarray(pile.poses)
            tops = (vertices @ poses[:, 2, :3].T).max(axis=0) + poses[:, 2, 3] if n else np.zeros(1)
            if tops.max() <= ceiling:
                break
            if n == 1:
                raise InvalidInputError(
                    f"model: one {self.model.name} alone stands {tops.max() - float(self.layout.bin.bounds[0][2]):.0f}"
                    f" mm above the bin's floor, above the {ceiling:.0f} mm the cell can pass over; pass a layout "
                    "with a deeper bin"
                )
            n = max(1, min(n - 1, int((tops <= ceiling).sum())))
        #: How many of the parts asked for were left out, as they heaped too high.
        self.heaped = count - n
        if self.heaped:
            self.progress(
                "pile",
                f"{count} {self.model.name} parts heap above z = {ceiling:.0f} mm, as high as the gripper can pass "
                f"over the bin and the camera still see it: {n} dropped instead",
            )
        top = float(tops.max())
        if top > pass_z:
            approach = top + margin + reach
            self.limits = dataclasses.replace(self.limits, approach_height_mm=approach)
            self.progress(
                "pile",
                f"the pile stands {top - float(self.layout.bin.bounds[1][2]):.0f} mm above the rim: the arm's approach "
                f"height over the bin is raised to {approach:.0f} mm",
            )
        return pile

    # -- life cycle
    def __enter__(self) -> TwinWorld:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def start(self) -> Any:
        """Starts the emulators on their ptys."""
        self._start_emulators()
        return self

    def _start_emulators(self) -> None:
        # The grip matcher of the cell's grasps, built now: built on the first gripper command it
        # held up the emulator's reply past the driver's timeout (thousands of grasps, under load).
        self._matcher = None
        _ = self.grasp_matcher
        if self.robot == "ur":  # a UR controller on TCP, free ports on loopback
            self.robot_emulator = UREmulator(
                rtde_port=0,
                dashboard_port=0,
                secondary_port=0,
                arm=self.arm,
                start_pose=self.layout.T_base_flange,
                speed_scale=self.speed_scale,
            )
            self.robot_emulator.clock = self.clock
            self.robot_emulator.start()
            where = "UR controller on " + ", ".join(
                f"{k} {h}:{p}" for k, (h, p) in self.robot_emulator.addresses.items()
            )
        else:
            self.robot_emulator = RobotEmulator(
                config=RobotEmulatorConfig(
                    arm=self.arm,
                    speed_scale=self.speed_scale,
                    joint_speeds_deg_s=SIM_JOINT_SPEEDS_DEG_S,
                    ramp_s=SIM_RAMP_S,
                )
            )
            self.robot_emulator.clock = self.clock
            self.robot_emulator.start()
            where = f"robot on {self.robot_emulator.slave_path}"
        self.robot_emulator.on_motion = self._on_motion
        self.motor_emulator = DynamixelEmulator()
        self.gripper_emulator = _SimGripperEmulator(self)
        for emulator in (self.motor_emulator, self.gripper_emulator):
            emulator.clock = self.clock
            emulator.start()
        self.progress(
            "emulate",
            f"{where}, laser motor on {self.motor_emulator.slave_path}, gripper on {self.gripper_emulator.slave_path}",
        )

    @property
    def held(self) -> Optional[int]:
        """The part the gripper holds now, or None."""
        return self._held

    def _config(self, limits: safety.CellLimits) -> CellConfig:
        """The pick loop's view of the simulated cell: its exact calibration, bin, scan pose and
        arm, and the part's symmetries (so that a grip of a part turned by one counts)."""
        overrides = dict(self.config_overrides)
        overrides.setdefault("symmetries", symmetry_maps(self.model.symmetries))
        overrides.setdefault("reachable", _Reach(self.arm) if self.robot == "melfa" else self.arm.reaches)
        return CellConfig(
            calibration=self.layout.calibration(),
            model=self.model,
            bin_bounds=self.layout.bin.bounds,
            scan_poses=(self.layout.T_base_flange,),
            drop_pose=self.drop_pose,
            frames=self.frames,
            gripper=self.gripper_geometry,
            limits=limits,
            num_threads=self.num_threads,
            **overrides,
        )

    def close(self) -> None:
        """Stops the emulators."""
        for emu in (self.robot_emulator, self.motor_emulator, self.gripper_emulator):
            if emu is not None:
                emu.close()

    @property
    def emulator_failures(self) -> list[str]:
        """Exceptions the emulators raised while serving (an emulator bug; should stay empty)."""
        return [
            f
            for emu in (self.robot_emulator, self.motor_emulator, self.gripper_emulator)
            if emu is not None
            for f in emu.failures
        ]

    # -- the physical world
    def laser_angle(self) -> float:
        """Where the laser motor really is, radians."""
        ticks = self.motor_emulator.present_position()
        return (ticks - 2048) * 2 * math.pi / 4096

    def T_base_tcp(self) -> np.ndarray:
        """Where the gripper's TCP really is."""
        return self.robot_emulator.pose() @ self.gripper_geometry.T_flange_gripper

    def finger_opening_mm(self, widest: bool = False) -> float:
        """How far apart the gripper emulator's fingers are now, mm; with ``widest``, the widest
        they will be before they stop (they may be moving while the arm does)."""
        axis = self.gripper_emulator.axis
        position = min(axis.position(), axis.goal) if widest else axis.position()  # 0 is open
        return self._gripper_config.stroke_mm * (1.0 - position / 255.0)

    @property
    def grasp_matcher(self) -> GraspMatcher:
        """The declared grasps of the running cell, matched with the grip tolerances."""
        if self._matcher is None:
            cfg = self.config
            # A grasp turned about a continuous near-symmetry's axis (a keyed shaft's) grips the
            # round body the same: the feature is a small share of where the fingers land.
            self._matcher = GraspMatcher(
                cfg.grasps,
                cfg.symmetries,
                tolerance_deg=self.grip_tolerance_deg,
                tolerance_mm=self.grip_tolerance_mm,
                continuous=continuous_symmetry(self.model.symmetries) or continuous_near_axis(self.model),
            )
            # How far from the part's centre any grasp puts the TCP (the matcher's reach, with its tolerance).
            T = np.stack(list(cfg.grasps.values()))
            tcp = -np.einsum("kji,kj->ki", T[:, :3, :3], T[:, :3, 3])
            self._centre = np.asarray(self.model.points, dtype=np.float64).mean(axis=0)
            self._grasp_reach = float(np.linalg.norm(tcp - self._centre, axis=1).max()) + self.grip_tolerance_mm
        return self._matcher

    def grip_check(self) -> Optional[tuple[int, float]]:
        """The part between the fingers now, if any, and its width across them (mm): the part
        nearest the TCP whose pose in the gripper is within the grip tolerance of a declared grasp,
        and which fits between the fingers as they are open now — a part wider than the opening,
        or off to one side of it, had a finger land on it on the way in and is not held. (The
        contact checks of the motions since the last push wait: the gripper's reply must not.)"""
        self.settle_pending(contacts=False)
        matcher = self.grasp_matcher
        T_bg = self.T_base_tcp()
        T_gb = inverse(T_bg)
        best = None
        for pid, T_bo in zip(self.pile.ids, self.pile.poses):
            if int(pid) == self._held:
                continue
            if np.linalg.norm(T_bo[:3, :3] @ self._centre + T_bo[:3, 3] - T_bg[:3, 3]) > self._grasp_reach:
                continue  # no grasp of this part puts the TCP here (the fingers pre-shaping above the bin)
            T_go = T_gb @ T_bo
            err = matcher.error(T_go)
            if best is None or matcher.cost(err) < matcher.cost(best[1]):
                best = (int(pid), err, T_go)
        if best is None or not matcher.within(best[1]):
            return None
        pid, _, T_go = best
        g = self.gripper_geometry
        local = np.asarray(self.model.points) @ T_go[:3, :3].T + T_go[:3, 3]
        x, d = np.abs(local[:, 0]), FINGER_LANDING_MM
        inner = self.finger_opening_mm() / 2.0
        in_finger = g.between_fingers(local, d) & (x > inner + d) & (x < inner + g.finger_thickness_mm - d)
        if in_finger.any():
            return None
        width = grip_width(g, self.model.points, T_go)
        return None if width is None else (pid, width)

    def on_gripper_command(self, closing: bool, emulator: Any) -> None:
        """Called by the gripper emulator on every motion command: on closing it finds the part
        between the fingers (the fingers stop on it); on opening a held part is let go."""
        with self.lock:
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

    def _on_motion(self, T_base_flange: np.ndarray, speed: float) -> None:
        """The robot emulator's motion hook (its serving thread, its lock held: nothing here may
        call back into it). A motion of the closed, empty gripper that sweeps any of its points
        through the bin's inner volume is queued to push the pile; any other motion is queued to
        be checked for contacts (:mod:`binpick.sim.contacts`). Both run in order, against the
        pile as the motions before left it, in :meth:`settle_pending`."""
        if self.gripper_emulator is None:
            return
        opening = self.finger_opening_mm(widest=True)
        path = T_base_flange @ self.gripper_geometry.T_flange_gripper
        if self._held is not None or opening > CLOSED_OPENING_MM:
            # The part held (or let go and not yet out of the pile) is where the fingers are.
            skip = self._held if self._held is not None else self._release_pending
            self._pushes.append((path, opening, -1.0, T_base_flange[0], skip))
            return
        if speed <= 0:
            return
        outline = self.gripper_geometry.outline(max(opening, 1.0))
        pts = np.einsum("kij,mj->kmi", path[:, :3, :3], outline) + path[:, None, :3, 3]
        lo, hi = self.layout.bin.bounds
        if ((pts >= lo) & (pts <= hi)).all(axis=2).any():
            # ``speed`` is the flange's along its path; the physics paces a push by the tool's
            # fastest point (its travel plus its turn times its reach), so that the push lasts
            # as long as the motion did (a joint move that mostly turns the tool is fast there).
            flange = float(np.linalg.norm(np.diff(T_base_flange[:, :3, 3], axis=0), axis=1).sum())
            if flange <= 1e-9:
                return
            reach = float(np.linalg.norm(outline, axis=1).max())
            turns = np.einsum("kji,kjl->kil", path[:-1, :3, :3], path[1:, :3, :3])
            angles = np.radians(rotation_angle_deg(turns))
            travel = float((np.linalg.norm(np.diff(path[:, :3, 3], axis=0), axis=1) + angles * reach).sum())
            tool_speed = travel * speed / flange
            self._pushes.append((path, opening, min(max(tool_speed, 1.0), MAX_SWEEP_SPEED), None, None))

    def _check_contacts(self, path: np.ndarray, opening: float, T_start: np.ndarray, skip: Optional[int]) -> None:
        """Records every contact of the open (or holding) gripper along ``path`` (gripper poses)."""
        T_bf = path @ inverse(self.gripper_geometry.T_flange_gripper)
        for c in contacts_along(
            self.gripper_geometry,
            path,
            opening,
            zip(self.pile.ids, np.asarray(self.pile.poses)),
            self._contact_points,
            bounds=self.layout.bin.bounds,
            wall_mm=self.layout.bin.wall_thickness,
            held=skip,
        ):
            event = {
                "with": c.what,
                "points": c.points,
                "opening_mm": round(float(opening), 2),
                "T_base_flange": np.round(T_bf[c.first], 6).tolist(),
                "T_base_gripper": np.round(path[c.first], 6).tolist(),
                "T_base_flange_start": np.round(T_start, 6).tolist(),
            }
            self.collisions.append(event)
            self._new_collisions.append(event)
            self.progress("COLLISION", f"the gripper touches {c.what} ({c.points} points inside it)")

    def _run_pushes(self, contacts: bool = True) -> None:
        """Runs the queued motions in order: contact checks, and sweeps of the closed gripper
        through the pile; sweeps that follow on from each other (one ends where the next starts,
        same opening and speed) run as one push, as the arm makes them without a pause long
        enough for the pile to settle. ``contacts=False``: only up to the last sweep queued
        (the contact checks after it need nothing that happens before they run)."""
        if not contacts:  # only as far as the last push: the checks after it wait for the pile as it is
            pushes = [k for k, item in enumerate(self._pushes) if item[2] >= 0]
            if not pushes:
                return
            later, self._pushes = self._pushes[pushes[-1] + 1 :], self._pushes[: pushes[-1] + 1]
            try:
                self._run_pushes()
            finally:
                self._pushes = later + self._pushes
            return
        while self._pushes:
            path, opening, speed, T_start, skip = self._pushes.pop(0)
            if speed < 0:
                self._check_contacts(path, opening, T_start, skip)
                continue
            while self._pushes:
                nxt, o2, v2, _, _ = self._pushes[0]
                if abs(o2 - opening) > 0.5 or abs(v2 - speed) > 0.05 * speed or np.abs(nxt[0] - path[-1]).max() > 1e-3:
                    break
                self._pushes.pop(0)
                path = np.concatenate([path, nxt[1:]])
            t0 = time.perf_counter()
            report = self.pile.push(self.gripper_geometry.boxes(opening), path, speed)
            self.pushes.append(report)
            self.progress(
                "physics",
                f"the closed gripper swept the bin at {speed:.0f} mm/s: parts {report.moved or 'none'} moved "
                f"({report.push_steps} steps, settled in {time.perf_counter() - t0:.1f} s)",
            )
            self._out_of_bin(report.moved, path, opening)

    def _out_of_bin(self, moved: list[int], path: np.ndarray, opening: float) -> None:
        """Records a collision for each of the parts ``moved`` by the push along ``path`` that
        came to rest out of the bin: over a wall, or higher above the rim than the part is long
        (jammed against a wall and forced up it — a push a real arm would have crushed it in). A
        part over a wall or below the floor (thrown out of the bin, or through its floor) leaves the
        pile, into :attr:`lost`: it is recorded once, not again with every later push that finds
        it still falling."""
        lo, hi = (np.asarray(b, dtype=float) for b in self.layout.bin.bounds)
        T_fg = inverse(self.gripper_geometry.T_flange_gripper)
        for pid in moved:
            if pid not in self.pile.ids:
                continue
            T = self.pile.pose(pid)
            c = (self._contact_points @ T[:3, :3].T + T[:3, 3]).mean(axis=0)
            over_floor = bool((c[:2] >= lo[:2]).all() and (c[:2] <= hi[:2]).all())
            if over_floor and lo[2] - self.model.diameter <= c[2] <= hi[2] + self.model.diameter:
                continue
            event = {
                "with": f"part {pid}, pushed out of the bin (to ({c[0]:.0f}, {c[1]:.0f}, {c[2]:.0f}) mm)",
                "points": 0,
                "opening_mm": round(float(opening), 2),
                "T_base_flange": np.round(path[-1] @ T_fg, 6).tolist(),
                "T_base_gripper": np.round(path[-1], 6).tolist(),
                "T_base_flange_start": np.round(path[0] @ T_fg, 6).tolist(),
            }
            self.collisions.append(event)
            self._new_collisions.append(event)
            self.progress("COLLISION", f"the push left {event['with']}")
            if not over_floor or c[2] < lo[2]:
                self.pile.remove(pid)
                self.lost.append(pid)

    def settle_pending(self, contacts: bool = True) -> None:
        """Runs the gripper's queued sweeps through the pile, takes a released part out of the
        pile and lets the rest settle (done lazily: by the camera before it renders, the judge, or
        the twin process's world ticks); the queued contact checks too, unless ``contacts`` is
        False (then those after the last sweep wait)."""
        with self.lock:
            self._run_pushes(contacts)
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
                self.progress(
                    "physics",
                    f"part {pid} left the bin; {len(self.pile)} remain, settled in {time.perf_counter() - t0:.1f} s "
                    f"({report.steps} steps)",
                )

    # -- ground truth
    def judge(self, T_base_object: np.ndarray, *, turn_about: Any = None) -> PoseTruth:
        """The located pose against the nearest part of the pile, its errors modulo the part's
        proper symmetries (:meth:`binpick.Model.pose_error`): a pose turned by a symmetry is as
        good as the true one, as the BOP benchmark judges; with ``turn_about`` (centre, axis in the
        model frame) modulo the turns about that axis too (a free axis, gripped across)."""
        self.settle_pending()
        best = None
        for pid, T_bo in zip(self.pile.ids, self.pile.poses):
            deg, mm = self.model.pose_error(T_base_object, T_bo, turn_about=turn_about)
            if best is None or mm < best.translation_error_mm:
                best = PoseTruth(instance=int(pid), rotation_error_deg=deg, translation_error_mm=mm, T_base_truth=T_bo)
        if best is None:
            raise NoObjectFound("the simulated bin is empty")
        return best

    def parts_left(self) -> int:
        """How many parts are in the bin."""
        self.settle_pending()
        return len(self.pile)

    def take_picked(self) -> Optional[int]:
        """The part that left the bin since the last call, or None."""
        self.settle_pending()
        pid, self._picked = self._picked, None
        return pid

    def take_collisions(self) -> list[dict]:
        """The gripper's contacts (:attr:`collisions` entries) since the last call."""
        self.settle_pending()
        with self.lock:
            new, self._new_collisions = self._new_collisions, []
        return new


class SimulatedCell(TwinWorld):
    """The simulated cell in one process: the :class:`TwinWorld` (pile, emulators on ptys), the
    real drivers opened on those ptys, the simulated camera, and the :class:`Cell` running the
    pick loop (``.cell``). Use as a context manager (it starts the emulators and opens the cell);
    it is also the cell's ground truth. The arguments are :class:`TwinWorld`'s."""

    def __init__(self, model: Model, **kwargs: Any) -> None:
        super().__init__(model, **kwargs)
        self.cell: Optional[Cell] = None

    def start(self) -> Cell:
        """Starts the emulators, opens the drivers on their ptys and the cell; returns the cell.
        The cell's configuration is built here, so that ``config_overrides`` changed after
        construction take effect."""
        self.config = self._config(self.limits)
        self._start_emulators()
        robot, motor, gripper = self._drivers(self.limits)
        self.cell = Cell(
            self.config,
            robot=robot,
            motor=motor,
            gripper=gripper,
            camera=SimCamera(self, seed=self.seed),
            progress=self.progress,
            truth=self,
            clock=self.clock,
        )
        self.cell.open()
        return self.cell

    def _drivers(self, limits: safety.CellLimits) -> tuple[MelfaRobot, DynamixelMotor, ModbusGripper]:
        """The real drivers opened on the emulators' ptys, with timings for an emulated cell."""
        robot = MelfaRobot(
            self.robot_emulator.slave_path,
            limits=limits,
            config=MelfaConfig(
                serial=SerialSettings(baudrate=9600, parity="E", stopbits=2, timeout_s=1.0, retries=2),
                # As fast as the cell's limits allow (50 % and 250 mm/s by default).
                initial_override_percent=limits.max_override_percent,
                initial_linear_speed_mm_s=limits.max_linear_speed_mm_s,
                poll_interval_s=0.01,
                motion_timeout_s=30.0,
            ),
        )
        motor = DynamixelMotor(
            self.motor_emulator.slave_path,
            config=DynamixelConfig(
                serial=SerialSettings(baudrate=57600, timeout_s=0.2),
                range=MotorRange(max_speed_rad_s=2 * math.pi, poll_interval_s=0.002),
            ),
        )
        return robot, motor, ModbusGripper(self.gripper_emulator.slave_path, config=self._gripper_config)

    def close(self) -> None:
        """Closes the cell and stops the emulators."""
        if self.cell is not None:
            self.cell.close()
        super().close()


class _SimGripperEmulator(GripperEmulator):
    """The Modbus gripper emulator whose fingers stop on the simulated part between them."""

    def __init__(self, sim: TwinWorld) -> None:
        stroke = sim._gripper_config.stroke_mm
        slow, fast = (255.0 * v / stroke for v in SIM_FINGER_SPEED_MM_S)
        super().__init__(
            config=GripperEmulatorConfig(min_speed_units_s=slow, max_speed_units_s=fast, speed_scale=sim.speed_scale)
        )
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
        model = parts.tee()
    return SimulatedCell(model, **kwargs)
