"""The cell's rules: workspace box, tool attitude, approach below the safety plane, speed, push."""

import math

import numpy as np
import pytest

from binpick.devices.safety import (
    CellLimits,
    check_linear_speed,
    check_move,
    check_override,
    check_pose,
    check_sequence,
)
from binpick.devices.xyzabc import transform_from_xyzabc
from binpick.errors import InvalidInputError, SafetyError

LIMITS = CellLimits()


def down(x, y, z):
    return transform_from_xyzabc([x, y, z, math.pi, 0, math.pi])


def test_inside_box_pointing_down_passes():
    check_pose(down(300, 0, 300), LIMITS)


@pytest.mark.parametrize(
    "xyz,axis", [((50, 0, 300), "x"), ((300, 400, 300), "y"), ((300, 0, -5), "z"), ((300, 0, 600), "z")]
)
def test_outside_box_is_refused(xyz, axis):
    with pytest.raises(SafetyError, match=f"{axis} = .* outside the cell's workspace"):
        check_pose(down(*xyz), LIMITS)


def test_tilted_tool_is_refused():
    T = transform_from_xyzabc([300, 0, 300, math.pi - math.radians(60), 0, math.pi])
    with pytest.raises(SafetyError, match="tilted 60.0°"):
        check_pose(T, LIMITS)
    check_pose(transform_from_xyzabc([300, 0, 300, math.pi - math.radians(40), 0, math.pi]), LIMITS)


def test_joint_move_below_approach_height_is_refused():
    with pytest.raises(SafetyError, match="joint move"):
        check_move(down(300, 0, 300), down(300, 0, 150), linear=False, limits=LIMITS)
    with pytest.raises(SafetyError, match="joint move"):
        check_move(down(300, 0, 150), down(300, 0, 300), linear=False, limits=LIMITS)


def test_vertical_linear_descent_passes_and_sideways_is_refused():
    check_move(down(300, 0, 300), down(305, 0, 100), linear=True, limits=LIMITS)
    with pytest.raises(SafetyError, match="sideways"):
        check_move(down(300, 0, 300), down(300, 100, 100), linear=True, limits=LIMITS)


def test_sequence_is_checked_step_by_step():
    start = down(300, 0, 300)
    check_sequence(start, [down(300, 0, 150), down(300, 0, 300), down(200, 100, 300)], [True, True, False], LIMITS)
    with pytest.raises(SafetyError, match=r"targets\[2\]"):
        check_sequence(start, [down(300, 0, 150), down(300, 0, 300), down(300, 0, 150)], [True, True, False], LIMITS)
    with pytest.raises(InvalidInputError):
        check_sequence(start, [down(300, 0, 150)], [True, False], LIMITS)


def test_a_push_is_a_chain_of_allowed_steps_within_its_total_sideways_travel():
    above, down_at = down(300, 0, 300), down(300, 0, 100)
    steps = [down(300, 25 * k, 100) for k in range(1, 5)]  # 100 mm across in 25 mm steps
    path = [above, down_at, *steps, down(300, 100, 300)]
    linear = [False, True, True, True, True, True, True]
    check_sequence(down(300, 0, 350), path, linear, LIMITS, push=True)  # within the default 120 mm
    with pytest.raises(SafetyError, match="travel 100.0 mm sideways .* more than the 80 mm a push may"):
        check_sequence(down(300, 0, 350), path, linear, CellLimits(max_push_mm=80.0), push=True)
    # Not a push: the same chain is checked step by step only (rule 3).
    check_sequence(down(300, 0, 350), path, linear, CellLimits(max_push_mm=0.0))
    with pytest.raises(SafetyError, match="more than the 0 mm"):
        check_sequence(down(300, 0, 350), path, linear, CellLimits(max_push_mm=0.0), push=True)
    # Each step is still rule 3's: one 50 mm step is refused whatever the push allows.
    with pytest.raises(SafetyError, match="sideways, more than 30 mm"):
        check_sequence(down(300, 0, 350), [above, down_at, down(300, 50, 100)], [False, True, True], LIMITS, push=True)


def test_speed_limits():
    assert check_override(50, LIMITS) == 50
    with pytest.raises(SafetyError, match="override"):
        check_override(80, LIMITS)
    with pytest.raises(InvalidInputError):
        check_override(0, LIMITS)
    with pytest.raises(SafetyError, match="mm/s"):
        check_linear_speed(400, LIMITS)


def test_limits_validate_themselves():
    with pytest.raises(InvalidInputError, match="must exceed"):
        CellLimits(workspace_min_mm=(0, 0, 0), workspace_max_mm=(10, -5, 10))
    with pytest.raises(InvalidInputError):
        CellLimits(max_override_percent=150)
    with pytest.raises(InvalidInputError):
        CellLimits(workspace_min_mm=(0, 0))


def test_non_rigid_target_is_refused_as_bad_input():
    with pytest.raises(InvalidInputError):
        check_pose(np.diag([1.0, 1.0, 2.0, 1.0]), LIMITS)
