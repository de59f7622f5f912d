"""A pick plan is checked whole before its first motion: a plan refused anywhere sends the arm and
the gripper nothing (the simulated cell's emulators on real ptys, the real drivers)."""

from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType, SimpleNamespace

import numpy as np
import pytest
from _cell_helpers import located

import binpick
from binpick.cell import PickPlan
from binpick.cell.grasp import pick_waypoints
from binpick.cell.records import Located
from binpick.errors import InvalidInputError, SafetyError
from binpick.sim import SimulatedCell
from binpick.transforms import look_down


@pytest.fixture(scope="module")
def sim():
    with SimulatedCell(binpick.parts.tee(), count=1, seed=0, frames=4) as s:
        yield s


def _plan(sim, *, drop=None, grasp_linear=True) -> PickPlan:
    """A plan over the middle of the bin whose first moves are valid; ``drop`` replaces its last pose."""
    cfg = sim.cell.config
    lo, hi = sim.layout.bin.bounds
    T_bf = look_down(float(lo[0] + hi[0]) / 2, float(lo[1] + hi[1]) / 2, cfg.limits.approach_height_mm - 20.0)
    T_bg = T_bf @ cfg.gripper.T_flange_gripper
    waypoints = pick_waypoints(
        T_bf,
        T_bg,
        approach_distance_mm=cfg.approach_distance_mm,
        clearance_z_mm=cfg.clearance_z_mm,
        drop_pose=cfg.drop_pose if drop is None else drop,
    )
    waypoints = [(n, T, grasp_linear if n == "grasp" else lin) for n, T, lin in waypoints]
    return PickPlan(
        grasp="custom",
        T_base_gripper=T_bg,
        T_base_flange=T_bf,
        tilt_deg=0.0,
        waypoints=tuple(waypoints),
        considered=1,
        rejected=MappingProxyType({}),
    )


def _located() -> Located:
    return located(np.eye(4), SimpleNamespace(score=1.0, rmse=0.0, method="custom", timings={}))


def _motion_requests(sim) -> tuple[list, list]:
    robot = [r for r in sim.robot_emulator.requests if r.split(";", 2)[-1].startswith(("EXEC", "OVRD", "HND"))]
    return robot, list(sim.gripper_emulator.requests)


def _assert_refused_without_motion(sim, plan, error, match):
    before = _motion_requests(sim)
    pose = sim.robot_emulator.pose()
    with pytest.raises(error, match=match):
        sim.cell.pick(_located(), plan=plan)
    assert _motion_requests(sim) == before, "a refused plan sent a motion or a gripper command"
    np.testing.assert_allclose(sim.robot_emulator.pose(), pose, atol=1e-9)


def test_a_plan_whose_last_step_leaves_the_workspace_moves_nothing(sim):
    outside = look_down(sim.cell.config.limits.workspace_max_mm[0] + 200.0, 0.0, 350.0)
    plan = _plan(sim, drop=outside)
    sim.cell.check_plan(_plan(sim))  # the same plan with the configured drop pose is fine
    _assert_refused_without_motion(sim, plan, SafetyError, "plan waypoint 'drop'.*outside the cell's workspace")


def test_a_plan_breaking_the_approach_rule_part_way_moves_nothing(sim):
    plan = _plan(sim, grasp_linear=False)  # a joint move down into the bin, after two valid moves
    _assert_refused_without_motion(sim, plan, SafetyError, "plan waypoint 'grasp'.*joint move")


def test_a_plan_with_a_tilted_pose_moves_nothing(sim):
    tilted = _plan(sim).pose("drop").copy()
    tilted[:3, :3] = np.eye(3)  # tool pointing up
    _assert_refused_without_motion(sim, _plan(sim, drop=tilted), SafetyError, "'drop'.*tilted")


def test_a_malformed_plan_moves_nothing(sim):
    plan = _plan(sim)
    no_lift = replace(plan, waypoints=tuple(w for w in plan.waypoints if w[0] != "lift"))
    _assert_refused_without_motion(sim, no_lift, InvalidInputError, r"\['lift'\] are missing")
    odd_flag = replace(plan, waypoints=tuple((n, T, "yes" if n == "grasp" else lin) for n, T, lin in plan.waypoints))
    _assert_refused_without_motion(sim, odd_flag, InvalidInputError, "linear must be True or False")
    not_rigid = replace(
        plan, waypoints=tuple((n, T * (2.0 if n == "lift" else 1.0), lin) for n, T, lin in plan.waypoints)
    )
    _assert_refused_without_motion(sim, not_rigid, InvalidInputError, "'lift'")
    _assert_refused_without_motion(sim, "plan", InvalidInputError, "PickPlan")


def test_a_valid_custom_plan_runs_through_the_lift(sim):
    record = sim.cell.pick(_located(), plan=_plan(sim))
    assert record.held is False  # nothing between the fingers: lifted, opened, not carried to the drop
    np.testing.assert_allclose(sim.robot_emulator.pose()[:3, 3], _plan(sim).pose("lift")[:3, 3], atol=0.05)


def _descend(plan: PickPlan, dz: float) -> PickPlan:
    """``plan`` with its approach and grasp lowered by ``dz`` mm (still vertical moves)."""
    moved = []
    for n, T, lin in plan.waypoints:
        T = T.copy()
        if n in ("approach", "grasp"):
            T[2, 3] -= dz
        moved.append((n, T, lin))
    return replace(plan, waypoints=tuple(moved), T_base_flange=moved[2][1])


def test_a_plan_whose_fingers_go_below_the_floor_moves_nothing(sim):
    cfg = sim.cell.config
    plan = _plan(sim)
    grasp_z = plan.pose("grasp")[2, 3]
    # Fingertips at the flange height minus the TCP offset minus their depth past the TCP.
    tips = grasp_z - cfg.gripper.T_flange_gripper[2, 3] - cfg.gripper.tip_depth_mm
    floor = float(cfg.bin_bounds[0][2])
    low = _descend(plan, tips - floor + 29.0)  # the case: fingertips 29 mm below the floor
    with pytest.raises(SafetyError, match="plan waypoint 'grasp'.*bin's floor"):
        sim.cell.check_plan(low)
    _assert_refused_without_motion(sim, low, SafetyError, "bin's floor")


def test_a_plan_whose_fingers_cross_a_wall_moves_nothing(sim):
    cfg = sim.cell.config
    lo, hi = cfg.bin_bounds
    plan = _plan(sim)
    # The TCP 30 mm above the floor and 5 mm inside the wall: the fingers (20 mm wide along the
    # wall's normal) reach through it below the rim on the way down.
    plan = _descend(plan, plan.pose("grasp")[2, 3] - (cfg.gripper.T_flange_gripper[2, 3] + float(lo[2]) + 30.0))
    shifted = []
    for n, T, lin in plan.waypoints:
        T = T.copy()
        if n != "drop":
            T[1, 3] = float(hi[1]) - 5.0
        shifted.append((n, T, lin))
    plan = replace(plan, waypoints=tuple(shifted))
    _assert_refused_without_motion(sim, plan, SafetyError, "plan waypoint '(approach|grasp)'.*bin's wall")


def test_the_planner_skips_grasps_whose_gripper_hits_the_floor():
    from binpick.cell.grasp import bin_clash

    g = binpick.cell.GripperGeometry()
    bounds = np.array([[250.0, -100.0, 0.0], [550.0, 100.0, 80.0]])
    T_bf = look_down(400.0, 0.0, g.T_flange_gripper[2, 3] + g.tip_depth_mm + 1.0)  # tips 1 mm above
    assert bin_clash(g, T_bf, bounds) is None
    T_bf[2, 3] -= 2.0
    assert bin_clash(g, T_bf, bounds).startswith("floor (1.0 mm below")
