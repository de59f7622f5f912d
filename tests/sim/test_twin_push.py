"""The twin pushes its pile when the closed, empty gripper sweeps through the bin, and only then."""

import numpy as np

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
