"""The check a pick's plan passes, whole, before the cell sends the arm or the gripper anything."""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from ..devices import safety
from ..errors import InvalidInputError, SafetyError
from .grasp import plan_bin_clash
from .records import PickPlan

__all__ = ["PICK_MOVES", "check_plan"]

#: The moves of one pick in the order :meth:`binpick.cell.Cell.pick` makes them: the waypoint, and its
#: interpolation when the loop fixes it (None: the plan's own).
PICK_MOVES: tuple[tuple[str, Optional[bool]], ...] = (
    ("above", None),
    ("approach", None),
    ("grasp", None),
    ("lift", True),
    ("drop", False),
)


def check_plan(cell: Any, plan: PickPlan) -> dict[str, tuple[np.ndarray, bool]]:
    """The moves of ``plan`` on ``cell`` as :meth:`binpick.cell.Cell.pick` makes them
    (:data:`PICK_MOVES`), checked whole before the first: every waypoint present with a
    boolean interpolation, each pose rigid, inside the workspace and with the tool down (before
    anything is sent), then every move from the arm's pose now to the drop pose against the
    approach rules. A malformed plan raises InvalidInputError and an unsafe one SafetyError
    naming the waypoint; either way the arm and the gripper have been sent nothing. Returns
    waypoint → (pose, linear)."""
    if not isinstance(plan, PickPlan):
        raise InvalidInputError(f"plan: expected a binpick.cell.PickPlan, got {type(plan).__name__}")
    if not isinstance(plan.waypoints, (tuple, list)):
        raise InvalidInputError(
            f"plan.waypoints: expected a tuple of (name, T_base_flange, linear), got {plan.waypoints!r:.80}"
        )
    linear: dict[str, bool] = {}
    for i, entry in enumerate(plan.waypoints):
        if not (isinstance(entry, tuple) and len(entry) == 3 and isinstance(entry[0], str)):
            raise InvalidInputError(f"plan.waypoints[{i}]: expected (name, T_base_flange, linear), got {entry!r:.80}")
        if not isinstance(entry[2], (bool, np.bool_)):
            raise InvalidInputError(f"plan.waypoints[{i}]: linear must be True or False, got {entry[2]!r:.40}")
        linear.setdefault(entry[0], bool(entry[2]))
    missing = [name for name, _ in PICK_MOVES if name not in linear]
    if missing:
        raise InvalidInputError(
            f"plan: waypoints {missing} are missing; a pick plan has {', '.join(n for n, _ in PICK_MOVES)} "
            "(see binpick.cell.grasp.pick_waypoints)"
        )
    names = [name for name, _ in PICK_MOVES]
    flags = [linear[name] if fixed is None else fixed for name, fixed in PICK_MOVES]
    labels = [f"plan waypoint {name!r}" for name in names]
    limits = cell.config.limits
    poses = [safety.check_pose(plan.pose(n), limits, name=label) for n, label in zip(names, labels)]
    safety.check_sequence(cell.robot.read_pose(), poses, flags, limits, names=labels)
    clash = plan_bin_clash(cell.config, list(zip(names, poses, flags)), cell.finger_opening(plan))
    if clash is not None:
        raise SafetyError(
            f"plan waypoint {clash[0]!r}: the gripper (fingers {cell.finger_opening(plan):.0f} mm apart, palm, "
            f"flange) would hit the bin's "
            f"{clash[1]}; nothing was sent — choose a grasp that keeps the whole gripper inside the bin "
            "and above its floor"
        )
    return {name: (T, lin) for name, T, lin in zip(names, poses, flags)}
