"""What the pick loop knows about a cell: :class:`CellConfig` (calibration, part and grasps, bin
box, scan and drop poses, gripper, limits) and :class:`GripperGeometry` (the gripper's TCP and
shape, for planning and collision checks); :func:`sweep_angles`, the motor angles whose laser
sheets sweep the bin.

Lengths in mm, angles in radians; transforms are 4×4 ``T_to_from``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Any, Callable, Optional

import numpy as np

from .. import _core
from .._validate import (
    MAX_COORDINATE,
    as_box,
    as_transform,
    choice,
    count,
    flag,
    instance_of,
    non_negative,
    number,
    positive,
)
from ..calibration import CellCalibration
from ..devices import safety
from ..errors import InvalidInputError, SafetyError
from ..models import Model
from ..transforms import laser_sweep, rotation_about, translation
from .grasp import branch_grasps, grasp_widths, mesh_grasps, opening_for_width, swept_points
from .symmetry import GraspMatcher, continuous_near_axis, continuous_symmetry
from .views import turned_scan_poses

__all__ = [
    "CellConfig",
    "GripperGeometry",
    "RESCANS",
    "SWEEPS",
    "check_static_poses",
    "sweep_angles",
    "turned_scan_poses",
]

#: How the laser can turn through a scan (:attr:`CellConfig.sweep`).
SWEEPS = ("steps", "continuous")
#: What a scan after a clean pick sweeps (:attr:`CellConfig.rescan`).
RESCANS = ("full", "changed")


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
        preshape_clearance_mm: a gripper that can be set to a width (see
            :attr:`binpick.devices.Gripper.sets_width`) opens each grasp only to the part's width
            across the fingers plus this much on each side (at most ``open_width_mm``): narrow
            fingers fit between parts packed together and stay off the floor where open ones would
            not. None = always fully open. Planning checks the fingers at the opening they will have.
    """

    T_flange_gripper: np.ndarray = field(default_factory=lambda: translation(0.0, 0.0, 150.0))
    open_width_mm: float = 50.0
    finger_length_mm: float = 45.0
    finger_width_mm: float = 20.0
    finger_thickness_mm: float = 8.0
    tip_depth_mm: float = 10.0
    body_radius_mm: float = 45.0
    body_length_mm: float = 60.0
    preshape_clearance_mm: Optional[float] = 5.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_flange_gripper", as_transform(self.T_flange_gripper, "T_flange_gripper"))
        for name in (
            "open_width_mm",
            "finger_length_mm",
            "finger_width_mm",
            "finger_thickness_mm",
            "body_radius_mm",
            "body_length_mm",
        ):
            positive(getattr(self, name), name)
        non_negative(self.tip_depth_mm, "tip_depth_mm", "mm")
        if self.preshape_clearance_mm is not None:
            non_negative(self.preshape_clearance_mm, "preshape_clearance_mm", "mm")

    def opening_for(self, width_mm: Optional[float]) -> float:
        """The finger opening (mm) for a grasp across a part ``width_mm`` wide (None: nothing
        between the fingers): the width plus ``preshape_clearance_mm`` on each side, at most
        ``open_width_mm``; ``open_width_mm`` when the gripper does not pre-shape."""
        if self.preshape_clearance_mm is None or width_mm is None:
            return float(self.open_width_mm)
        return float(min(self.open_width_mm, width_mm + 2.0 * self.preshape_clearance_mm))

    @property
    def shape_mm(self) -> tuple[float, float, float, float, float, float]:
        """(tip depth, finger length, finger width, finger thickness, body radius, body length), mm:
        the volume :meth:`occupied` and :meth:`hits` test points against."""
        return (
            float(self.tip_depth_mm),
            float(self.finger_length_mm),
            float(self.finger_width_mm),
            float(self.finger_thickness_mm),
            float(self.body_radius_mm),
            float(self.body_length_mm),
        )

    def occupied(
        self, points_gripper: np.ndarray, opening_mm: Any = None, margin_mm: float = 0.0, grow_mm: float = 0.0
    ) -> np.ndarray:
        """Which points (N, 3, in the gripper frame; or any shape (..., 3)) lie inside the gripper
        (fingers or body), the fingers ``opening_mm`` apart (a number, or an array that
        broadcasts against the points' leading shape; ``open_width_mm`` by default); with
        ``margin_mm``, more than that far inside (a surface grazing the gripper is not in it);
        with ``grow_mm``, the gripper grown by that much on every side but below the fingertips
        (a clearance round it; what lies under the tips is the floor's business)."""
        p = np.asarray(points_gripper, dtype=np.float64)
        lead = p.shape[:-1]
        gap = self.open_width_mm if opening_mm is None else np.asarray(opening_mm, dtype=np.float64)
        gaps = np.ascontiguousarray(np.broadcast_to(gap, lead), dtype=np.float64).reshape(-1)
        flat = np.ascontiguousarray(p.reshape(-1, 3))
        return _core.gripper_occupied(flat, gaps, self.shape_mm, float(margin_mm), float(grow_mm)).reshape(lead)

    def hits(
        self,
        points_base: np.ndarray,
        T_base_grippers: np.ndarray,
        openings_mm: np.ndarray,
        margin_mm: float = 0.0,
        grow_mm: float = 0.0,
        *,
        back_mm: float = 0.0,
        floor_z_mm: Optional[float] = None,
        closing_mm: Optional[np.ndarray] = None,
        at_most: Optional[int] = None,
    ) -> np.ndarray:
        """How many of the points (N, 3, base frame; or :meth:`scene`'s) lie inside the gripper
        (:meth:`occupied`) at each of the poses ``T_base_grippers`` (K, 4, 4), its fingers
        ``openings_mm`` (K,) apart: (K,) counts, from binpick's core (the planner asks this for
        thousands of poses a pick).

        Along a pick's motion: ``back_mm`` — the gripper comes in along its own axis from that far
        behind each pose (the straight approach), and a point in its way counts; ``floor_z_mm`` —
        each point stands for everything straight below it down to that height (base z): what a
        scan cannot see under a seen surface, and what the gripper meets rising straight up from
        anywhere on its approach; ``closing_mm`` (K,) — at each pose the fingers close from their
        opening to that width, sweeping every width between (a finger closing onto a neighbour in
        the gap; ``grow_mm`` grows that sweep but for its inner face, which closes onto the part).
        ``at_most``: a count stops there (a count of ``at_most`` means at least that many): for a
        planner that refuses a pose past some number of points."""
        poses = np.ascontiguousarray(T_base_grippers, dtype=np.float64).reshape(-1, 4, 4)
        gaps = np.ascontiguousarray(np.broadcast_to(np.asarray(openings_mm, dtype=np.float64), (len(poses),)))
        if isinstance(points_base, _core.GripperPoints):
            pts = points_base
        else:
            pts = np.ascontiguousarray(points_base, dtype=np.float64).reshape(-1, 3)
        back = non_negative(back_mm, "back_mm", "mm")
        floor = None if floor_z_mm is None else number(floor_z_mm, "floor_z_mm", unit="mm")
        cap = None if at_most is None else count(at_most, "at_most", 1)
        shut = None
        if closing_mm is not None:
            shut = np.asarray(closing_mm, dtype=np.float64)
            if shut.size != 1 and shut.shape != (len(poses),):
                raise InvalidInputError(f"closing_mm: give one width per pose ({len(poses)}), got shape {shut.shape}")
            shut = np.ascontiguousarray(np.broadcast_to(shut.reshape(-1)[:1] if shut.size == 1 else shut, len(poses)))
            if not np.isfinite(shut).all() or (shut < 0.0).any() or (shut > gaps).any():
                raise InvalidInputError(
                    "closing_mm: give each pose a finite width (mm) from 0 up to its opening, the width its "
                    "fingers close to"
                )
        return _core.gripper_hits(
            pts, poses, gaps, shut, self.shape_mm, float(margin_mm), float(grow_mm), back, floor, cap, 1
        )

    @staticmethod
    def scene(points_base: np.ndarray) -> Any:
        """The points (N, 3, base frame) bucketed once for many :meth:`hits` counts (which takes
        the result in place of the array): the planner counts one scene at batch after batch of
        grasps."""
        return _core.GripperPoints(np.ascontiguousarray(points_base, dtype=np.float64).reshape(-1, 3))

    def widest(self, points_object: np.ndarray, T_gripper_objects: np.ndarray, graze_mm: float) -> np.ndarray:
        """For each grasp ``T_gripper_objects`` (K, 4, 4): the farthest |x| (mm) of the part's
        ``points_object`` (N, 3, object frame) in the slab the open fingers sweep — more than
        ``graze_mm`` inside it along y and z, out to the fingers' outer faces — half the part's
        width across the fingers there; −1 where no point lies between them. (K,), from binpick's core."""
        pts = np.ascontiguousarray(points_object, dtype=np.float64).reshape(-1, 3)
        grasps = np.ascontiguousarray(T_gripper_objects, dtype=np.float64).reshape(-1, 4, 4)
        return _core.gripper_widest(pts, grasps, self.shape_mm, float(self.open_width_mm), float(graze_mm), 1)

    def outline(self, opening_mm: Optional[float] = None, *, sides: int = 16) -> np.ndarray:
        """Points (M, 3, gripper frame) whose convex hull per piece covers the whole gripper with
        the fingers ``opening_mm`` apart (``open_width_mm`` by default): the 8 corners of each
        finger, ``sides`` points round the bottom and top of the body (palm) and round the flange
        (a disc of the body's radius at the flange origin). Against a convex box such as the bin's
        inner volume, checking these points checks every finger, the palm and the flange whole."""
        gap = self.open_width_mm if opening_mm is None else non_negative(opening_mm, "opening_mm", "mm")
        return self.outlines(np.array([gap]), sides=sides)[0]

    def outlines(self, openings_mm: np.ndarray, *, sides: int = 16) -> np.ndarray:
        """:meth:`outline` for each of the openings (K,), as (K, M, 3): the palm and flange
        points are the same, the finger corners move out with the opening."""
        gap = np.asarray(openings_mm, dtype=np.float64).reshape(-1)
        top = self.tip_depth_mm - self.finger_length_mm
        t, w = self.finger_thickness_mm, self.finger_width_mm / 2
        # The finger corners at zero opening, and the side (±1) each moves out to.
        corners = np.array(
            [
                (sign * dx, dy, z, sign)
                for sign in (-1.0, 1.0)
                for dx in (0.0, t)
                for dy in (-w, w)
                for z in (top, self.tip_depth_mm)
            ]
        )
        fingers = np.broadcast_to(corners[:, :3], (len(gap), len(corners), 3)).copy()
        fingers[..., 0] += corners[:, 3] * gap[:, None] / 2
        a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
        ring = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]) * self.body_radius_mm
        palm = [ring + (0.0, 0.0, z) for z in (top, top - self.body_length_mm)]
        T_gf = np.linalg.inv(self.T_flange_gripper)
        rest = np.vstack([*palm, ring @ T_gf[:3, :3].T + T_gf[:3, 3]])
        return np.concatenate([fingers, np.broadcast_to(rest, (len(gap), *rest.shape))], axis=1)

    def boxes(self, opening_mm: float) -> list[tuple[tuple[float, float, float], np.ndarray]]:
        """The gripper as boxes ``(half_extents, T_gripper_box)`` (gripper frame, mm) for a physics
        tool: the two fingers ``opening_mm`` apart and the body (palm) as two squares inscribed in
        its circle, one turned 45° (an eight-pointed star that stays inside the cylinder)."""
        gap = max(0.0, float(opening_mm))
        top = self.tip_depth_mm - self.finger_length_mm
        t = self.finger_thickness_mm
        finger = (t / 2, self.finger_width_mm / 2, self.finger_length_mm / 2)
        out = []
        for sign in (-1.0, 1.0):
            out.append((finger, translation(sign * (gap / 2 + t / 2), 0.0, (top + self.tip_depth_mm) / 2)))
        a = self.body_radius_mm / np.sqrt(2.0)
        body = (a, a, self.body_length_mm / 2)
        for turn in (0.0, np.pi / 4):
            T = translation(0.0, 0.0, top - self.body_length_mm / 2)
            T[:3, :3] = rotation_about((0.0, 0.0, 1.0), turn)
            out.append((body, T))
        return out

    def between_fingers(self, points_gripper: np.ndarray, margin_mm: float = 0.0) -> np.ndarray:
        """Which points (N, 3, in the gripper frame) lie in the slab the closing fingers sweep
        (more than ``margin_mm`` inside it along the fingers' width and length)."""
        _, y, z = points_gripper.T
        return (
            (np.abs(y) <= self.finger_width_mm / 2 - margin_mm)
            & (z <= self.tip_depth_mm - margin_mm)
            & (z >= self.tip_depth_mm - self.finger_length_mm + margin_mm)
        )


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
        sweep: how the laser turns through them: ``"steps"`` (the motor stops at each angle and
            a frame is taken at rest) or ``"continuous"`` (the paper's: the motor turns at a set
            speed while the camera streams, ``frames`` frames over the sweep at the camera's
            rate; each frame's angle is the motor's reported position interpolated to the
            middle of its exposure). Continuous needs a motor whose speed can be set and a
            camera that reports its rate and each frame's time on the cell's clock.
        rescan: what a scan after a clean pick sweeps: ``"full"``, the whole bin; or
            ``"changed"``, only the angles whose sheets cross the region around the part that
            left, the rest kept from the last scan — with a full scan when the fresh lines show
            that anything else moved, after anything but a clean pick, and for more than one
            scan pose (:mod:`binpick.cell.rescan`).
        plan_ahead: plan the next pick on a thread while the arm carries the last one away, and
            use that plan when the next scan shows the region it works in unchanged (else
            locate and plan on the new scan as without it): :mod:`binpick.cell.ahead`.
        scan_angles: motor angles (rad) per scan pose; None = computed from the calibration to sweep the bin.
        grasps: name → ``T_gripper_object``; None = the model's declared grasps, or
            :func:`~binpick.cell.branch_grasps` for a model with branches and no declared grasps,
            or :func:`~binpick.cell.grasp.mesh_grasps` (sampled antipodal pairs) for any other mesh.
        gripper: the gripper's TCP and shape.
        limits: the cell's motion limits (also given to the robot driver).
        approach_distance_mm: the straight approach along the gripper axis before the grasp, mm.
        clearance_z_mm: flange height for travelling over the bin, mm; None = the approach height + 20 mm.
        scan_clearance_mm: how far the gripper is grown sideways and up (not below the fingertips,
            where the floor is the floor clearance's) against the scan's points, not against the
            located part's exact model: a neighbour's flank bulges out unseen past the last line
            or pixel that caught it (by up to about a line's spacing, 3.3 mm in the default sweep),
            and the pose's error and the arm's repeatability add to it, mm.
        max_collision_points: a grasp is refused when more scene points than this (stray points)
            lie in the open gripper's way (fingers or body, on the approach along its axis and
            the rise from it; each point standing for what lies below it, which no scan sees);
            the located part's own model (at the located pose) may not lie inside it at all
            (more than ``binpick.cell.grasp.GRAZE_MM``).
        floor_clearance_mm: how far above the bin's floor every point of the gripper (fingers at
            the planned opening, palm, flange) must stay along approach, grasp and retreat, mm; a
            plan closer to the floor, or crossing the bin's walls below the rim, is refused.
        min_confidence: a located pose whose ``confidence`` is lower is not picked (skipped with the
            reason "low confidence"); 0.3 by default — poses that confident were pick-grade at
            least 30 % of the time on the project's test sets (see PoseResult.confidence). A pose
            the scan left undecided, planned with a grasp the same on every pose it leaves open,
            is held to it by its ``confidence_any`` instead.
        orientation_needed: the cell places parts by their orientation (into a fixture, a machine's
            chuck): a pose the scan cannot decide (``ambiguous``, or a ``free_axis`` a near-symmetric
            part turns about) is not picked — the cell looks again, and a look judged with the first
            that decides it is; False (the default): such a pose is picked with a grasp the same on
            every pose it leaves open, staking ``confidence_any``, and the pick record says the
            orientation was undecided.
        ambiguity_tolerance_deg: how closely (degrees) a grasp must land the same way on every
            alternative of an ambiguous pose, and align with a free axis …
        ambiguity_tolerance_mm: … and in translation, mm (see :func:`binpick.cell.grasp.grasp_filter`).
        max_candidates: located parts tried per scan before the cell looks again (each part found
            is tried in turn, most pickable first).
        look_again_poses: flange poses to scan from again, one after the other, when a scan shows
            nothing pickable (the camera rides on the arm: a view from the side shows what the first
            one could not); None = :func:`turned_scan_poses` (the first scan pose turned about the
            bin floor's centre toward each side); () = no second look.
        reachable: optional test ``T_base_flange → bool`` from the arm's kinematics; None = trust
            the controller (it refuses unreachable targets, and the cell then stops).
        max_nudges: at a dead end (the parts located but none pickable from any view), how
            many times per pick the closed gripper may push a blocked part over before the cell
            looks again (:mod:`binpick.cell.nudge`); 0 = never. With a nudge to come, a look
            whose parts were all refused for where they lie leaves out the other views
            (:func:`binpick.cell.views.worth_another_look`); they are taken when none is found.
            Default 5: a nudge then costs one look, not one per view, and parts lying flat side
            by side (elbows) often need a fourth or fifth push before one can be gripped.
        symmetries: ``T_object_object`` maps of the part onto itself, for judging pose errors.
        min_score: a located pose scoring lower counts as not found.
        estimate_options: extra keyword arguments for :func:`binpick.estimate_pose`.
        keep_frames: how many frames of each scan to keep in memory (evenly spaced; for pictures).
        scan_height_mm: how far above the bin's rim the scan looks for parts, mm; None = the bin's
            depth or the part's diameter, whichever is larger. Each frame's laser line is looked
            for only where the sheet can meet :attr:`scan_volume` (:class:`~binpick.vision.LaserWindow`).
        num_threads: worker threads for extraction and pose estimation, 0 = all cores.
    """

    calibration: CellCalibration
    model: Model
    bin_bounds: Any
    scan_poses: Sequence[Any]
    drop_pose: Any
    frames: int = 90
    sweep: str = "steps"
    rescan: str = "full"
    plan_ahead: bool = False
    scan_angles: Optional[Sequence[Sequence[float]]] = None
    grasps: Optional[Mapping[str, Any]] = None
    gripper: GripperGeometry = field(default_factory=GripperGeometry)
    limits: safety.CellLimits = field(default_factory=safety.CellLimits)
    approach_distance_mm: float = 40.0
    clearance_z_mm: Optional[float] = None
    max_collision_points: int = 15
    scan_clearance_mm: float = 3.0
    floor_clearance_mm: float = 0.0
    min_confidence: float = 0.3
    orientation_needed: bool = False
    ambiguity_tolerance_deg: float = 5.0
    ambiguity_tolerance_mm: float = 3.0
    max_candidates: int = 8
    look_again_poses: Optional[Sequence[Any]] = None
    reachable: Optional[Callable[[np.ndarray], bool]] = None
    max_nudges: int = 5
    symmetries: Sequence[Any] = ()
    min_score: float = 0.0
    estimate_options: Mapping[str, Any] = field(default_factory=dict)
    keep_frames: int = 6
    scan_height_mm: Optional[float] = None
    num_threads: int = 0

    def __post_init__(self) -> None:
        self._check_types()
        object.__setattr__(self, "bin_bounds", np.array(as_box(self.bin_bounds)))
        self._set_poses()
        self._set_grasps()
        positive(self.approach_distance_mm, "approach_distance_mm")
        if self.clearance_z_mm is None:
            object.__setattr__(self, "clearance_z_mm", float(self.limits.approach_height_mm) + 20.0)
        count(self.max_collision_points, "max_collision_points")
        non_negative(self.scan_clearance_mm, "scan_clearance_mm", "mm")
        count(self.max_candidates, "max_candidates", 1)
        count(self.max_nudges, "max_nudges", 0, 20)
        non_negative(self.floor_clearance_mm, "floor_clearance_mm", "mm")
        number(self.min_confidence, "min_confidence", 0.0, 1.0)
        object.__setattr__(self, "orientation_needed", flag(self.orientation_needed, "orientation_needed"))
        object.__setattr__(self, "plan_ahead", flag(self.plan_ahead, "plan_ahead"))
        positive(self.ambiguity_tolerance_deg, "ambiguity_tolerance_deg", "deg")
        positive(self.ambiguity_tolerance_mm, "ambiguity_tolerance_mm")
        object.__setattr__(
            self, "symmetries", tuple(as_transform(S, f"symmetries[{i}]") for i, S in enumerate(self.symmetries))
        )
        non_negative(self.min_score, "min_score")
        count(self.keep_frames, "keep_frames")
        if self.scan_height_mm is not None:
            height = number(self.scan_height_mm, "scan_height_mm", 0.0, MAX_COORDINATE, unit="mm")
            object.__setattr__(self, "scan_height_mm", height)
        count(self.num_threads, "num_threads")
        if self.reachable is not None and not callable(self.reachable):
            raise InvalidInputError("reachable: expected a function T_base_flange -> bool, or None")
        looks = turned_scan_poses(self) if self.look_again_poses is None else self.look_again_poses
        if np.asarray(looks, dtype=object).ndim == 2:
            looks = [looks]
        object.__setattr__(
            self, "look_again_poses", tuple(as_transform(T, f"look_again_poses[{i}]") for i, T in enumerate(looks))
        )

    def _check_types(self) -> None:
        for name, kind, what in (
            ("calibration", CellCalibration, "a CellCalibration"),
            ("model", Model, "a binpick.Model"),
            ("gripper", GripperGeometry, "a GripperGeometry"),
            ("limits", safety.CellLimits, "a binpick.devices.CellLimits"),
        ):
            value = getattr(self, name)
            if not isinstance(value, kind):
                raise InvalidInputError(f"{name}: expected {what}, got {type(value).__name__}")

    def _set_poses(self) -> None:
        poses = [self.scan_poses] if np.asarray(self.scan_poses, dtype=object).ndim == 2 else list(self.scan_poses)
        if not poses:
            raise InvalidInputError("scan_poses: give at least one flange pose to scan from")
        object.__setattr__(self, "scan_poses", tuple(as_transform(T, f"scan_poses[{i}]") for i, T in enumerate(poses)))
        object.__setattr__(self, "drop_pose", as_transform(self.drop_pose, "drop_pose"))
        count(self.frames, "frames", 1)
        choice(self.sweep, "sweep", SWEEPS)
        choice(self.rescan, "rescan", RESCANS)
        if self.sweep == "continuous" and self.frames < 2:
            raise InvalidInputError("frames: a continuous sweep takes at least 2 frames a scan pose")
        if self.scan_angles is not None:
            angles = tuple(np.asarray(a, dtype=np.float64).ravel() for a in self.scan_angles)
            if len(angles) != len(self.scan_poses) or any(len(a) == 0 or not np.isfinite(a).all() for a in angles):
                raise InvalidInputError(
                    "scan_angles: give one non-empty list of finite motor angles (rad) per scan pose"
                )
            object.__setattr__(self, "scan_angles", angles)

    def _set_grasps(self) -> None:
        given = self.grasps if self.grasps is not None else self.model.grasps
        if not given:
            # Generated here, rigid by construction: thousands of them need no check one by one.
            object.__setattr__(self, "grasps", MappingProxyType(self._generated_grasps()))
            if not self.grasps:
                raise self._no_grasps()
            return
        object.__setattr__(
            self, "grasps", MappingProxyType({str(k): as_transform(v, f"grasps[{k!r}]") for k, v in given.items()})
        )

    def _no_grasps(self) -> InvalidInputError:
        """The part has no grasps and none could be made (:func:`mesh_grasps`: no pair of facing
        sides fits between the open fingers): the Python fix, and the command's (a cell file's key)."""
        opening = self.gripper.open_width_mm
        problem = (
            f"grasps: the part {self.model.name!r} ({self.model.diameter:.1f} mm across) has no grasps: it declares "
            f"none and no cylindrical branches, and no two facing sides of it lie 1 to {opening - 2.0:g} mm apart, "
            f"where the gripper's {opening:g} mm opening can close on them"
        )
        error = InvalidInputError(
            f"{problem}; declare grasps with model.add_grasp(name, T_gripper_object), or give the gripper a "
            "wider opening (GripperGeometry.open_width_mm)"
        )
        error.cli_message = f"{problem}; a gripper that opens wider may hold it (a cell file's [gripper] open_width_mm)"
        return error

    def _generated_grasps(self) -> dict:
        """Branch grasps for a part with cylindrical branches, else grasps sampled from its mesh."""
        if self.model.branches:
            return branch_grasps(
                self.model, finger_width_mm=self.gripper.finger_width_mm, tip_depth_mm=self.gripper.tip_depth_mm
            )
        return mesh_grasps(self.model, self.gripper)

    def openings(self, names: Sequence[str], *, swept: bool = False) -> np.ndarray:
        """The finger opening (mm) of each named grasp, the one its plan is checked with and the
        gripper opens to (:func:`~binpick.cell.grasp.grasp_openings`), NaN where the part does
        not fit between the open fingers; each grasp measured on first use and remembered.
        ``swept``: for the part at any turn about its continuous near-symmetry axis
        (:func:`~binpick.cell.grasp.swept_points`: its key or pin may be anywhere about it)."""
        return self.openings_for(self.grip_widths(names, swept=swept))

    def openings_for(self, widths: np.ndarray) -> np.ndarray:
        """The finger opening (mm) for each of the part's ``widths`` across the fingers (NaN:
        nothing between them), NaN where the part does not fit between the open fingers."""
        out = [opening_for_width(self.gripper, None if np.isnan(w) else w) for w in np.asarray(widths).tolist()]
        return np.array([np.nan if o is None else o for o in out], dtype=np.float64)

    def grip_widths(self, names: Sequence[str], *, swept: bool = False) -> np.ndarray:
        """The part's width (mm) across the fingers at each named grasp, what the fingers close to
        (:func:`~binpick.cell.grasp.grasp_widths`), NaN where none of it lies between them; each
        grasp measured on first use and remembered. ``swept`` as for :meth:`openings`."""
        known = self._widths.setdefault(swept, {})
        todo = [n for n in dict.fromkeys(names) if n not in known]
        if todo:
            c0 = time.process_time()
            points = self.swept_points if swept else None
            known.update(grasp_widths(self.gripper, self.model, {n: self.grasps[n] for n in todo}, points))
            self._openings_cpu[0] += time.process_time() - c0
        return np.array([np.nan if known[n] is None else known[n] for n in names], dtype=np.float64)

    @cached_property
    def grasp_frames(self) -> tuple[tuple[str, ...], np.ndarray]:
        """The grasps' names and their ``T_object_gripper`` (G, 4, 4), stacked and inverted once
        per cell: the planner turns every grasp to the located pose at each plan."""
        names = tuple(self.grasps)
        T_go = np.stack([np.asarray(self.grasps[n], dtype=np.float64) for n in names])
        T_og = np.zeros_like(T_go)
        T_og[:, :3, :3] = np.transpose(T_go[:, :3, :3], (0, 2, 1))
        T_og[:, :3, 3] = -np.einsum("nji,nj->ni", T_go[:, :3, :3], T_go[:, :3, 3])
        T_og[:, 3, 3] = 1.0
        T_og.flags.writeable = False
        return names, T_og

    @cached_property
    def swept_points(self) -> np.ndarray:
        """The part's points with the feature of its continuous near-symmetry turned all the way
        about it (:func:`~binpick.cell.grasp.swept_points`), made once per cell: what the gripper
        must clear where the part's turn is open."""
        return swept_points(self.model)

    @property
    def openings_cpu_ms(self) -> float:
        """CPU time (ms) spent so far measuring grasp openings: once per grasp and part, so the
        pick loop counts it apart from each pick's planning."""
        return self._openings_cpu[0] * 1e3

    @cached_property
    def ambiguity_matcher(self) -> GraspMatcher:
        """The declared grasps matched with the ambiguity tolerances (the test a grasp must pass
        on every alternative of an undecided pose): built once per cell, not per plan."""
        return GraspMatcher(
            self.grasps,
            self.symmetries,
            tolerance_deg=self.ambiguity_tolerance_deg,
            tolerance_mm=self.ambiguity_tolerance_mm,
            continuous=continuous_symmetry(self.model.symmetries) or continuous_near_axis(self.model),
        )

    @cached_property
    def _widths(self) -> dict[bool, dict[str, Optional[float]]]:
        return {}

    @cached_property
    def _openings_cpu(self) -> list[float]:
        return [0.0]

    @property
    def scan_volume(self) -> np.ndarray:
        """Where the scan looks for parts, ((xmin, ymin, zmin), (xmax, ymax, zmax)) mm: the bin's
        inner volume, widened by half the part's diameter around (a part lying over the rim),
        10 mm below the floor (sensor noise) and ``scan_height_mm`` above the rim (a full pile)."""
        lo, hi = self.bin_bounds
        depth = hi[2] - lo[2]
        height = max(depth, self.model.diameter) if self.scan_height_mm is None else self.scan_height_mm
        side = self.model.diameter / 2
        return np.array([lo - (side, side, 10.0), hi + (side, side, height)])

    def angles_for(self, i: int) -> np.ndarray:
        """The motor angles (rad) of scan pose ``i``."""
        if self.scan_angles is not None:
            return self.scan_angles[i]
        return self.sweep_from(self.scan_poses[i])

    def sweep_from(self, T_base_flange: np.ndarray) -> np.ndarray:
        """``frames`` motor angles (rad) whose laser sheets sweep the bin seen from ``T_base_flange``."""
        cal = self.calibration
        T_base_laser = T_base_flange @ cal.T_flange_camera @ cal.T_camera_laser
        return laser_sweep(T_base_laser, self.bin_bounds[0], self.bin_bounds[1], self.frames)


def sweep_angles(
    calibration: CellCalibration, T_base_flange: Any, bin_bounds: Any, frames: int, *, margin: float = 10.0
) -> np.ndarray:
    """``frames`` motor angles (rad), evenly spaced, whose laser sheets sweep the bin box
    ``bin_bounds`` (floor corners widened by ``margin`` mm along x, and the rim) seen from ``T_base_flange``."""
    if not isinstance(calibration, CellCalibration):
        raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(calibration).__name__}")
    T_bf = as_transform(T_base_flange, "T_base_flange")
    lo, hi = as_box(bin_bounds)
    n = count(frames, "frames", 1)
    return laser_sweep(T_bf @ calibration.T_flange_camera @ calibration.T_camera_laser, lo, hi, n, margin)


def check_static_poses(config: CellConfig) -> None:
    """The scan and drop poses and the clearance height against the cell's limits (SafetyError);
    the cell checks them when it is built, before any byte is sent."""
    lim = instance_of(config, CellConfig, "config", "CellConfig(...) or config_from_file(...)").limits
    named = [(f"scan_poses[{i}]", T) for i, T in enumerate(config.scan_poses)]
    named += [(f"look_again_poses[{i}]", T) for i, T in enumerate(config.look_again_poses)]
    for name, T in named:
        safety.check_pose(T, lim, name=name)
        if T[2, 3] < lim.approach_height_mm:
            raise SafetyError(
                f"{name}: z = {T[2, 3]:.1f} mm is below the approach height {lim.approach_height_mm:g} mm; "
                "nothing was sent — scan from above the approach height"
            )
    safety.check_pose(config.drop_pose, lim, name="drop_pose")
    if config.drop_pose[2, 3] < lim.approach_height_mm:
        raise SafetyError(
            f"drop_pose: z = {config.drop_pose[2, 3]:.1f} mm is below the approach height "
            f"{lim.approach_height_mm:g} mm; nothing was sent — drop from above the approach height"
        )
    if not lim.approach_height_mm <= config.clearance_z_mm <= lim.workspace_max_mm[2]:
        raise SafetyError(
            f"clearance_z_mm: {config.clearance_z_mm:g} mm must lie between the approach height "
            f"{lim.approach_height_mm:g} mm and the workspace top {lim.workspace_max_mm[2]:g} mm; nothing was sent"
        )
