"""The cell's motion rules, checked before any byte of a motion reaches the robot.

Every check raises :class:`~binpick.errors.SafetyError` naming the rule, the offending value and
what to change. The rules, all in the robot's base frame on the flange pose ``T_base_flange``:

1. **Workspace box** — every target's origin lies inside ``workspace_min_mm``..``workspace_max_mm``.
   A straight-line move between two points of a box stays inside it; a joint move's path is not
   straight, so rule 3 keeps joint moves above the bin.
2. **Tool attitude** — the flange's Z axis points down: its angle to −Z_base is at most
   ``max_tool_tilt_rad``.
3. **Approach** — below ``approach_height_mm`` (the pile's safety plane) the arm only moves in
   straight lines (``linear=True``), and such a move travels at most ``max_lateral_below_mm``
   sideways: it goes into and out of the bin vertically.
4. **Speed** — the speed override never exceeds ``max_override_percent`` and the straight-line
   speed never exceeds ``max_linear_speed_mm_s``.
5. **Push** — a deliberate push of the closed gripper through the pile (the cell's nudge,
   :func:`check_sequence` with ``push=True``) is the one sequence that goes sideways below the approach height: a chain
   of straight moves, each within rule 3's ``max_lateral_below_mm``, whose sideways travel below
   the approach height totals at most ``max_push_mm`` (0 forbids pushes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from .._validate import check_number, check_transform
from ..errors import InvalidInputError, InvalidTypeError, SafetyError

__all__ = [
    "CellLimits",
    "check_pose",
    "check_move",
    "check_sequence",
    "check_override",
    "check_linear_speed",
]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class CellLimits:
    """The cell's motion limits (base frame, flange pose).

    Attributes:
        workspace_min_mm: lower corner (x, y, z) of the box the flange must stay in, mm.
        workspace_max_mm: upper corner (x, y, z) of that box, mm.
        max_tool_tilt_rad: largest angle between the flange's Z axis and straight down, radians.
        approach_height_mm: z below which only straight, near-vertical moves are allowed, mm.
        max_lateral_below_mm: largest sideways (x, y) travel of a move with an end below
            ``approach_height_mm``, mm.
        max_override_percent: largest speed override sent to the controller, percent (1–100).
        max_linear_speed_mm_s: largest straight-line speed sent to the controller, mm/s.
        max_push_mm: largest total sideways travel below ``approach_height_mm`` of a push (rule 5),
            mm; 0 forbids pushes.
    """

    workspace_min_mm: Vec3 = (100.0, -300.0, 0.0)
    workspace_max_mm: Vec3 = (420.0, 300.0, 520.0)
    max_tool_tilt_rad: float = math.radians(45.0)
    approach_height_mm: float = 200.0
    max_lateral_below_mm: float = 30.0
    max_override_percent: float = 50.0
    max_linear_speed_mm_s: float = 250.0
    max_push_mm: float = 120.0

    def __post_init__(self) -> None:
        lo = [check_number(v, "CellLimits.workspace_min_mm", unit="mm") for v in _triple(self.workspace_min_mm, "min")]
        hi = [check_number(v, "CellLimits.workspace_max_mm", unit="mm") for v in _triple(self.workspace_max_mm, "max")]
        if any(h <= low for low, h in zip(lo, hi)):
            raise InvalidInputError(
                f"CellLimits: workspace_max_mm {hi} must exceed workspace_min_mm {lo} on every axis"
            )
        check_number(self.max_tool_tilt_rad, "CellLimits.max_tool_tilt_rad", low=0.0, high=math.pi, unit="rad")
        check_number(self.approach_height_mm, "CellLimits.approach_height_mm", unit="mm")
        check_number(self.max_lateral_below_mm, "CellLimits.max_lateral_below_mm", low=0.0, unit="mm")
        check_number(self.max_override_percent, "CellLimits.max_override_percent", low=1.0, high=100.0, unit="%")
        check_number(self.max_linear_speed_mm_s, "CellLimits.max_linear_speed_mm_s", low=0.001, unit="mm/s")
        check_number(self.max_push_mm, "CellLimits.max_push_mm", low=0.0, unit="mm")


def _triple(value: Any, which: str) -> Sequence[Any]:
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 3:
        raise InvalidInputError(f"CellLimits.workspace_{which}_mm: expected (x, y, z) in mm, got {value!r}")
    return list(value)


def _cell_limits(limits: Any) -> CellLimits:
    if not isinstance(limits, CellLimits):
        raise InvalidTypeError(f"limits: expected binpick.devices.CellLimits, got {type(limits).__name__}")
    return limits


def check_pose(T_base_flange: Any, limits: CellLimits, *, name: str = "target") -> np.ndarray:
    """Rules 1 and 2 for one pose; returns it as a float64 (4, 4) array."""
    limits = _cell_limits(limits)
    T = check_transform(T_base_flange, name)
    p = T[:3, 3]
    lo, hi = np.asarray(limits.workspace_min_mm), np.asarray(limits.workspace_max_mm)
    outside = [(axis, p[i]) for i, axis in enumerate("xyz") if not lo[i] <= p[i] <= hi[i]]
    if outside:
        axis, v = outside[0]
        i = "xyz".index(axis)
        raise SafetyError(
            f"{name}: {axis} = {v:.1f} mm is outside the cell's workspace [{lo[i]:g}, {hi[i]:g}] mm; nothing was "
            "sent — choose a pose inside CellLimits.workspace_min_mm/max_mm"
        )
    tilt = math.acos(max(-1.0, min(1.0, -float(T[2, 2]))))
    if tilt > limits.max_tool_tilt_rad + 1e-12:
        raise SafetyError(
            f"{name}: the tool is tilted {math.degrees(tilt):.1f}° from straight down, more than the allowed "
            f"{math.degrees(limits.max_tool_tilt_rad):.1f}°; nothing was sent — approach with the tool pointing down"
        )
    return T


def check_move(T_start: Any, T_target: Any, *, linear: bool, limits: CellLimits, name: str = "target") -> np.ndarray:
    """Rules 1–3 for one move from ``T_start`` (where the arm is) to ``T_target``; returns the target."""
    start = check_transform(T_start, "T_start")
    target = check_pose(T_target, limits, name=name)
    z0, z1 = float(start[2, 3]), float(target[2, 3])
    low = min(z0, z1) < limits.approach_height_mm
    if low and not linear:
        raise SafetyError(
            f"{name}: a joint move (linear=False) from z = {z0:.1f} mm to z = {z1:.1f} mm goes below the approach "
            f"height {limits.approach_height_mm:g} mm, where its curved path could hit the bin; nothing was sent — "
            "move above the approach height first, then descend with linear=True"
        )
    if low:
        lateral = float(np.hypot(*(target[:2, 3] - start[:2, 3])))
        if lateral > limits.max_lateral_below_mm:
            raise SafetyError(
                f"{name}: a straight move below the approach height {limits.approach_height_mm:g} mm travels "
                f"{lateral:.1f} mm sideways, more than {limits.max_lateral_below_mm:g} mm; nothing was sent — go "
                "up and across above the approach height, then descend vertically"
            )
    return target


def check_sequence(
    T_start: Any,
    targets: Sequence[Any],
    linear: Sequence[bool],
    limits: CellLimits,
    *,
    names: Optional[Sequence[str]] = None,
    push: bool = False,
) -> list:
    """:func:`check_move` for each step of a sequence, each step starting where the previous one
    ends; ``names`` name the steps in errors (``targets[i]`` by default). With ``push``, the
    sequence is a push (rule 5): its sideways travel below the approach height totals at most
    ``max_push_mm``."""
    if len(targets) != len(linear):
        raise InvalidInputError(f"linear: has {len(linear)} entries for {len(targets)} targets; give one per target")
    labels = [f"targets[{i}]" for i in range(len(targets))] if names is None else list(names)
    if len(labels) != len(targets):
        raise InvalidInputError(f"names: has {len(labels)} entries for {len(targets)} targets; give one per target")
    checked = []
    previous = T_start
    travel = 0.0
    for T, lin, label in zip(targets, linear, labels):
        start = previous
        previous = check_move(previous, T, linear=bool(lin), limits=limits, name=label)
        checked.append(previous)
        if min(float(start[2, 3]), float(previous[2, 3])) < limits.approach_height_mm:
            travel += float(np.hypot(*(previous[:2, 3] - start[:2, 3])))
    if push and travel > limits.max_push_mm:
        raise SafetyError(
            f"push: the gripper would travel {travel:.1f} mm sideways below the approach height "
            f"{limits.approach_height_mm:g} mm, more than the {limits.max_push_mm:g} mm a push may; nothing was "
            "sent — push a shorter way or raise CellLimits.max_push_mm"
        )
    return checked


def check_override(percent: Any, limits: CellLimits) -> float:
    """Rule 4 for a speed override, percent."""
    limits = _cell_limits(limits)
    v = check_number(percent, "override_percent", low=1.0, high=100.0, unit="%")
    if v > limits.max_override_percent:
        raise SafetyError(
            f"override_percent: {v:g} % exceeds the cell's limit of {limits.max_override_percent:g} %; "
            "nothing was sent — use a lower override or raise CellLimits.max_override_percent"
        )
    return v


def check_linear_speed(speed_mm_s: Any, limits: CellLimits) -> float:
    """Rule 4 for a straight-line speed, mm/s."""
    limits = _cell_limits(limits)
    v = check_number(speed_mm_s, "speed_mm_s", low=0.001, unit="mm/s")
    if v > limits.max_linear_speed_mm_s:
        raise SafetyError(
            f"speed_mm_s: {v:g} mm/s exceeds the cell's limit of {limits.max_linear_speed_mm_s:g} mm/s; "
            "nothing was sent — use a lower speed or raise CellLimits.max_linear_speed_mm_s"
        )
    return v
