"""A pile that does not fit the bin is sized before the first scan (issue 38: twelve 190 mm
bunnies in the default bin heaped into the camera and the gripper at the scan pose, and the scan
held no points). A pile above the rim gets the arm's approach raised over it; one that heaps
higher than the gripper can pass with the camera still seeing it is dropped again with fewer
parts, with the reason; a part that stands above the ceiling alone is refused before anything
starts."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from binpick.errors import InvalidInputError
from binpick.sim import sim_limits
from binpick.sim.cell import Cell as Layout
from binpick.sim.twin import TwinWorld


def _tops(world):
    v = np.asarray(world.model.vertices)
    poses = np.asarray(world.pile.poses)
    return (v @ poses[:, 2, :3].T).max(axis=0) + poses[:, 2, 3]


def _reach(world):
    g = world.gripper_geometry
    return g.T_flange_gripper[2, 3] + g.tip_depth_mm


def _said(stage_text):
    return lambda stage, text: stage_text.append((stage, text))


def test_a_pile_heaped_above_the_rim_raises_the_approach_over_it():
    fat = binpick.parts.tee(outer_diameter=60.0, run_length=170.0, branch_length=85.0, boss_height=0.0)
    said = []
    world = TwinWorld(fat, count=12, seed=0, progress=_said(said))
    default = sim_limits(world.layout, world.gripper_geometry).approach_height_mm
    rim = world.layout.bin.bounds[1][2]
    top = _tops(world).max()
    assert top > default - _reach(world), "twelve 60 mm thick tees heap above the tips' pass over an 80 mm bin"
    margin = default - _reach(world) - rim
    assert world.limits.approach_height_mm == pytest.approx(top + margin + _reach(world))
    assert any("approach height over the bin is raised" in t for _, t in said), said


def test_a_pile_heaped_into_the_cameras_view_is_dropped_with_fewer_parts_and_says_why():
    big = binpick.parts.tee(outer_diameter=100.0, run_length=190.0, branch_length=95.0, boss_height=0.0)
    said = []
    world = TwinWorld(big, count=12, seed=0, progress=_said(said))
    assert world.heaped > 0 and len(world.pile) == 12 - world.heaped >= 1
    scan_tips = world.layout.T_base_flange[2, 3] - _reach(world)
    assert _tops(world).max() < scan_tips, "the pile stays below the gripper at the scan pose"
    assert any("12 tee parts heap above z =" in t and f"{len(world.pile)} dropped instead" in t for _, t in said)


def test_a_pile_that_fits_is_left_as_dropped():
    world = TwinWorld(binpick.parts.tee(), count=12, seed=0)
    assert world.heaped == 0 and len(world.pile) == 12
    assert world.limits == sim_limits(world.layout, world.gripper_geometry)


def test_a_part_taller_than_the_callers_pass_alone_is_refused():
    tall = binpick.parts.tee(outer_diameter=125.0, run_length=190.0, branch_length=80.0, boss_height=0.0)
    layout = Layout.for_part(tall)
    with pytest.raises(InvalidInputError, match="deeper bin"):
        TwinWorld(tall, count=1, seed=0, layout=layout, limits=sim_limits(layout))
