"""The twin pushes its pile when the closed, empty gripper sweeps through the bin, and only then."""

import numpy as np
import pytest

import binpick
from binpick.sim import SimulatedCell
from binpick.transforms import look_down


def _centre(sim):
    T = sim.pile.poses[0]
    return T[:3, :3] @ sim.model.vertices.mean(axis=0) + T[:3, 3]


def _sweep(cell, c, tip_z, reach):
    """Above the part's -x side, straight down, then straight along +x in 20 mm steps, then up."""
    up = cell.config.limits.approach_height_mm + 20.0
    z = tip_z + reach
    xs = np.arange(c[0] - 70.0, c[0] + 30.0, 20.0)
    cell.robot.move_to(look_down(xs[0], c[1], up), linear=False)
    cell.robot.move_to(look_down(xs[0], c[1], z), linear=True)
    for x in xs[1:]:
        cell.robot.move_to(look_down(x, c[1], z), linear=True)
    cell.robot.move_to(look_down(xs[-1], c[1], up), linear=True)


def test_the_closed_gripper_pushes_what_it_sweeps_through_and_nothing_else():
    tee = binpick.parts.tee(resolution=2.0)
    with SimulatedCell(tee, count=1, seed=4, frames=4, speed_scale=50.0) as sim:
        cell = sim.cell
        g = sim.gripper_geometry
        reach = float(g.T_flange_gripper[2, 3]) + g.tip_depth_mm
        c = _centre(sim)
        before = sim.pile.poses[0].copy()
        cell.gripper.open()
        _sweep(cell, c, tip_z=60.0 + 15.0, reach=reach)  # open, and above the part: no push
        sim.settle_pending()
        assert sim.pushes == []
        cell.gripper.close()
        _sweep(cell, c, tip_z=sim.layout.bin.bounds[1][2] + 5.0, reach=reach)  # closed, above the rim
        sim.settle_pending()
        assert sim.pushes == []
        _sweep(cell, c, tip_z=8.0, reach=reach)
        sim.settle_pending()
        assert any(0 in r.moved for r in sim.pushes), sim.pushes
        after = sim.pile.poses[0]
        assert after[0, 3] - before[0, 3] > 5.0, (before[:3, 3], after[:3, 3])
        assert sim.emulator_failures == []


def test_a_push_lasts_as_long_as_the_motion_that_makes_it():
    # A straight move that mostly turns the closed gripper low in the bin: the flange travels a few
    # millimetres while the fingers sweep a quarter turn. The physics runs the sweep for as long
    # as the arm took, not for the flange's travel at the flange's (slow) speed.
    tee = binpick.parts.tee(resolution=2.0)
    with SimulatedCell(tee, count=1, seed=4, frames=4, speed_scale=50.0) as sim:
        cell = sim.cell
        g = sim.gripper_geometry
        reach = float(g.T_flange_gripper[2, 3]) + g.tip_depth_mm
        lo, hi = sim.layout.bin.bounds
        x, y = float(lo[0]) + 60.0, float(lo[1]) + 60.0  # a corner, away from the part
        z = reach + float(lo[2]) + 20.0
        cell.gripper.close()
        cell.robot.move_to(look_down(x, y, cell.config.limits.approach_height_mm + 20.0), linear=False)
        cell.robot.move_to(look_down(x, y, z), linear=True)
        sim.settle_pending()
        seen = []
        hook = sim.robot_emulator.on_motion
        sim.robot_emulator.on_motion = lambda path, speed: (seen.append((path, speed)), hook(path, speed))
        turned = look_down(x + 3.0, y, z)
        turned[:3, :3] = turned[:3, :3] @ binpick.transforms.rotation_about((0.0, 0.0, 1.0), np.pi / 2)
        before = len(sim.pushes)
        cell.robot.move_to(turned, linear=True)
        sim.settle_pending()
        (path, speed), push = seen[-1], sim.pushes[before]
        took = float(np.linalg.norm(np.diff(path[:, :3, 3], axis=0), axis=1).sum()) / speed
        assert push.push_steps / 120.0 == pytest.approx(took, rel=0.15), (push, took)
        assert sim.emulator_failures == []
