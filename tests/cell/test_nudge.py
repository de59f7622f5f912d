"""The nudge: at a dead end the closed gripper pushes a blocked part over, the physics moves it,
and the cell picks it; a nudge through the floor, into a wall or out of reach is refused with
nothing sent."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import binpick
from binpick.cell import nudge
from binpick.errors import SafetyError
from binpick.sim import SimulatedCell

#: Tee pile seed 1 of 9 parts (benches/bin_clearing.py): taken out in this order, the last part
#: left stands against the +y wall, where no grasp within the 45° tool-tilt limit can take it.
DEAD_END_SEED, DEAD_END_COUNT, DEAD_END_REMOVED = 1, 9, (8, 7, 2, 0, 5, 3, 4, 6)


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee()


def _dead_end(tee, **kwargs):
    sim = SimulatedCell(tee, count=DEAD_END_COUNT, seed=DEAD_END_SEED, frames=90, **kwargs)
    for pid in DEAD_END_REMOVED:
        sim.pile.remove(pid)
    return sim


def _lowest_tip_above_floor(cfg, plans) -> float:
    g, floor = cfg.gripper, float(cfg.bin_bounds[0][2])
    lowest = np.inf
    for plan in plans:
        for _, T, _ in plan.waypoints:
            T_bg = T @ g.T_flange_gripper
            lowest = min(lowest, float((g.outline() @ T_bg[:3, :3].T + T_bg[:3, 3])[:, 2].min()))
    return lowest - floor


def test_a_dead_end_is_nudged_and_the_bin_emptied(tee):
    lines = []
    sim = _dead_end(tee, progress=lambda stage, msg: lines.append((stage, msg)), look_again_poses=())
    with sim:
        (blocked,) = sim.pile.ids.tolist()
        before = sim.pile.pose(blocked).copy()
        report = sim.cell.run(2)
        assert sim.emulator_failures == []
    record = report.records[0]
    assert len(record.nudges) >= 1, [m for s, m in lines if s in ("nudge", "skip")]
    assert sum(s == "nudge" for s, _ in lines) == len(record.nudges)
    assert record.as_dict()["nudges"][0]["heading_deg"] == pytest.approx(record.nudges[0].heading_deg, abs=0.1)
    # The push moved the blocked part in the physics, and the cell then took it out.
    assert any(blocked in p.moved for p in sim.pushes), sim.pushes
    assert record.picked_instance == blocked and len(sim.pile) == 0, (record.failure, record.error)
    assert np.linalg.norm(record.T_base_object[:3, 3] - before[:3, 3]) > 10.0
    assert _lowest_tip_above_floor(sim.cell.config, record.nudges) > 0.0


def _config_and_part(tee):
    sim = _dead_end(tee)
    sim.start()
    return sim, sim.cell.config, sim.pile.poses[0]


def test_a_nudge_through_the_floor_or_out_of_reach_is_refused_with_nothing_sent(tee):
    sim, cfg, T = _config_and_part(tee)
    try:
        sent = []
        robot = sim.cell.robot
        move = robot.move_to
        robot.move_to = lambda *a, **k: sent.append(a) or move(*a, **k)
        T_now = robot.read_pose()
        plan = nudge.plan_nudge(cfg, T, np.zeros((0, 3)), T_now)
        moves = [list(w) for w in plan.waypoints]
        assert nudge.check_nudge(cfg, [tuple(w) for w in moves], T_now, np.zeros((0, 3))) is None
        low = [tuple(w) for w in moves]
        for k, (name, W, lin) in enumerate(low):
            if name != "above":
                W = W.copy()
                W[2, 3] -= 60.0  # fingertips 10 mm under the floor
                low[k] = (name, W, lin)
        assert "floor" in nudge.check_nudge(cfg, low, T_now, np.zeros((0, 3)))
        far = [(n, W.copy(), lin) for n, W, lin in plan.waypoints]
        for _, W, _ in far:
            W[0, 3] += 2000.0
        assert nudge.check_nudge(cfg, far, T_now, np.zeros((0, 3))) is not None
        blind = replace(cfg, reachable=lambda T: False)
        with pytest.raises(SafetyError, match="reach"):
            nudge.plan_nudge(blind, T, np.zeros((0, 3)), T_now)
        # A wall of scanned points where the fingers go down: refused.
        start = plan.waypoints[1][1] @ cfg.gripper.T_flange_gripper
        column = start[:3, 3] + np.array([[0.0, 0.0, -z] for z in np.linspace(-40, 0, 50)])
        assert "scanned points" in nudge.check_nudge(cfg, list(plan.waypoints), T_now, column)
        assert sent == []
    finally:
        sim.close()
