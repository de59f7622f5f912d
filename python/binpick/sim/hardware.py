"""The simulated cell's hardware beside its layout (:mod:`binpick.sim.cell`): the arm that
reaches its bin (:func:`sim_arm`), its motion limits (:func:`sim_limits`), its gripper
(:func:`sim_gripper`), and the speeds of the arm and the gripper's fingers on the cell's clock.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from .._validate import instance_of
from ..cell.config import GripperGeometry
from ..devices import GripperConfig, safety
from ..devices.emulators import ArmModel
from ..errors import InvalidInputError
from ..models import Model
from ..transforms import look_down
from .cell import Cell as Layout

__all__ = [
    "SIM_ARM",
    "SIM_FINGER_SPEED_MM_S",
    "SIM_JOINT_SPEEDS_DEG_S",
    "SIM_RAMP_S",
    "sim_arm",
    "sim_gripper",
    "sim_limits",
]


#: The simulated arm's top joint speeds J1…J6, deg/s, at 100 % override, and the time each
#: takes to reach its top speed (and to stop), s: a small six-axis arm of the paper's RV-1A
#: class (its slow shoulder J2, its fast wrist). Assumed figures of the class, not one
#: datasheet's; a cell's own arm is measured on the cell.
SIM_JOINT_SPEEDS_DEG_S = (180.0, 90.0, 135.0, 180.0, 200.0, 330.0)
SIM_RAMP_S = 0.2

#: The simulated gripper's finger speed range, mm/s (SPEED 0 … 255): an electric parallel
#: gripper of the Robotiq 2F-85 class, 20–150 mm/s.
SIM_FINGER_SPEED_MM_S = (20.0, 150.0)


def _sim_arm(scale: float = 1.0) -> ArmModel:
    # A larger arm than the emulator's default RV-1A class, so that the simulated cell's scan pose
    # 620 mm above the bin floor and every corner of the bin are within reach; ``scale`` grows its
    # links (and workspace) for the larger cells of large parts.
    return ArmModel(
        base_height_mm=250.0,
        upper_arm_mm=400.0 * scale,
        forearm_mm=450.0 * scale,
        flange_mm=90.0,
        workspace_min_mm=(-900.0 * scale, -900.0 * scale, -200.0),
        workspace_max_mm=(900.0 * scale, 900.0 * scale, 1100.0 * scale),
    )


SIM_ARM = _sim_arm()
"""The simulated cell's arm (see :class:`binpick.devices.emulators.ArmModel`)."""

#: Arm sizes tried by :func:`sim_arm`: the links of :data:`SIM_ARM` scaled by these factors.
_ARM_SCALES = (1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0)


def sim_arm(layout: Any = None, gripper: Optional[GripperGeometry] = None) -> ArmModel:
    """The arm of a simulated cell: :data:`SIM_ARM` when it reaches the layout's scan pose and,
    tool straight down, every point of the bin (a grid 30 mm in from the walls, with the fingertips
    20 mm above the floor, at the approach height above the rim, and at the scan height); else the
    smallest arm with its links (not its base height) scaled by 1.25, 1.5, … that does — the
    larger robot a cell for large parts has. InvalidInputError when none up to 3× does."""
    layout, gripper = _layout_and_gripper(layout, gripper)
    lo, hi = layout.bin.bounds
    reach = float(gripper.T_flange_gripper[2, 3]) + gripper.tip_depth_mm
    xs = np.linspace(lo[0] + 30.0, hi[0] - 30.0, 7)
    ys = np.linspace(lo[1] + 30.0, hi[1] - 30.0, 5)
    zs = (float(lo[2]) + reach + 20.0, float(hi[2]) + reach + 30.0, float(layout.T_base_flange[2, 3]))
    poses = [layout.T_base_flange] + [look_down(x, y, z) for x in xs for y in ys for z in zs]
    for k in _ARM_SCALES:
        arm = SIM_ARM if k == 1.0 else _sim_arm(k)
        if all(_Reach(arm)(T) for T in poses):
            return arm
    raise InvalidInputError(
        f"layout: no simulated arm up to {_ARM_SCALES[-1]:g}× the default reaches the whole bin "
        f"{np.round(lo, 1).tolist()}..{np.round(hi, 1).tolist()} mm; use a smaller bin or place it nearer the robot"
    )


def sim_limits(layout: Any = None, gripper: Optional[GripperGeometry] = None) -> safety.CellLimits:
    """The simulated cell's motion limits: a workspace around the bin and the drop area, and an
    approach height that keeps the gripper above the bin's rim for joint moves."""
    layout, gripper = _layout_and_gripper(layout, gripper)
    lo, hi = layout.bin.bounds
    reach = float(gripper.T_flange_gripper[2, 3]) + gripper.tip_depth_mm
    return safety.CellLimits(
        workspace_min_mm=(float(lo[0]) - 150.0, float(lo[1]) - 250.0, float(lo[2]) + 60.0),
        workspace_max_mm=(float(hi[0]) + 100.0, float(hi[1]) + 250.0, float(layout.T_base_flange[2, 3]) + 80.0),
        approach_height_mm=float(hi[2]) + reach + 30.0,
        max_lateral_below_mm=40.0,
    )


#: The longest fingers :func:`sim_gripper` gives a simulated gripper, mm: deeper bins (those of
#: large parts) get fingers this long, and parts against their walls may be out of reach.
MAX_SIM_FINGER_MM = 150.0


#: A part thinner than this share of its footprint's width is flat: lying on its face, it can be
#: gripped only across that face.
FLAT_SHARE = 0.25


def sim_gripper(layout: Any = None, model: Optional[Model] = None) -> GripperGeometry:
    """The simulated cell's gripper: :class:`GripperGeometry`'s defaults but for fingers long
    enough to reach the bin's floor with the palm above the rim (the bin's depth plus the
    fingertips' reach past the TCP; at least the default 45 mm, at most :data:`MAX_SIM_FINGER_MM`),
    the TCP moved away from the flange by what the fingers grew — the fingers a bin-picking cell
    fits so that the palm clears the walls when a part lies against them. For a flat part
    (``model``: thinner than :data:`FLAT_SHARE` of its footprint's narrowest width — a flange, a
    plate), which lying on its face can be gripped only across it, the fingers open as far as that
    width and the pre-shape's clearance need, within the simulated gripper's stroke."""
    layout = instance_of(Layout() if layout is None else layout, Layout, "layout", "binpick.sim.Cell()")
    base = GripperGeometry()
    lo, hi = layout.bin.bounds
    length = float(np.clip(float(hi[2] - lo[2]) + base.tip_depth_mm, base.finger_length_mm, MAX_SIM_FINGER_MM))
    T = base.T_flange_gripper.copy()
    T[:3, 3] += T[:3, 2] * (length - base.finger_length_mm)
    opening = base.open_width_mm
    if model is not None:
        width, thickness = _footprint(instance_of(model, Model, "model", "binpick.parts.flange()"))
        if thickness < FLAT_SHARE * width:
            needed = width + 2.0 * (base.preshape_clearance_mm or 0.0) + 2.0
            opening = float(min(max(opening, needed), GripperConfig().stroke_mm))
    return GripperGeometry(T_flange_gripper=T, finger_length_mm=length, open_width_mm=opening)


def _footprint(model: Model) -> tuple[float, float]:
    """The narrowest width of a part's footprint on its largest face (its caliper width across the
    two longest principal axes, over directions every 2°) and its thickness along the third, mm."""
    pts = np.asarray(model.points, dtype=np.float64)
    _, axes = np.linalg.eigh(np.cov((pts - pts.mean(axis=0)).T))
    face = pts @ axes[:, 1:]  # the two longest axes (eigh sorts ascending)
    angles = np.radians(np.arange(0.0, 180.0, 2.0))
    widths = np.ptp(face @ np.stack([np.cos(angles), np.sin(angles)]), axis=0)
    return float(widths.min()), float(np.ptp(pts @ axes[:, 0]))


def _layout_and_gripper(layout: Any, gripper: Any, model: Optional[Model] = None) -> tuple[Layout, GripperGeometry]:
    """The simulated hardware and the gripper, each its default when None (:func:`sim_gripper` of
    the layout and the part; InvalidTypeError naming it when it is not one)."""
    layout = instance_of(Layout() if layout is None else layout, Layout, "layout", "binpick.sim.Cell()")
    return (
        layout,
        sim_gripper(layout, model)
        if gripper is None
        else instance_of(gripper, GripperGeometry, "gripper", "binpick.sim.sim_gripper(layout)"),
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
