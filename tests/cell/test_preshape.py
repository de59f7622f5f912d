"""Pre-shaped fingers: a gripper that can be set to a width opens each grasp only to the part's
width plus a clearance, the planner checks the fingers at that opening, the loop opens them to
it, and the twin's gripper holds a part only when it fits between the fingers as they are."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from _cell_helpers import located

import binpick
from binpick.cell import GripperGeometry
from binpick.cell.grasp import NoGraspError, bin_clash, grasp_openings, plan_grasp
from binpick.devices.gripper import MelfaHandGripper, ModbusGripper
from binpick.sim import SimulatedCell


@pytest.fixture(scope="module")
def elbow():
    return binpick.parts.elbow()


@pytest.fixture(scope="module")
def sim(elbow):
    with SimulatedCell(elbow, count=1, seed=4, frames=4) as s:
        yield s


def test_outlines_move_only_the_fingers_with_the_opening():
    g = GripperGeometry()
    stack = g.outlines(np.array([20.0, 36.0, 50.0]))
    for k, opening in enumerate((20.0, 36.0, 50.0)):
        np.testing.assert_allclose(stack[k], g.outline(opening))
        inner = np.abs(stack[k][:16, 0]).min()
        assert inner == pytest.approx(opening / 2)  # the fingers' inner faces
    np.testing.assert_array_equal(stack[0][16:], stack[2][16:])  # palm and flange do not move
    np.testing.assert_allclose(g.outline(), g.outline(g.open_width_mm))


def test_an_elbow_grasp_opens_to_the_pipe_and_the_clearance(elbow):
    g = GripperGeometry()
    grasps = binpick.cell.branch_grasps(elbow)
    openings = grasp_openings(g, elbow, grasps)
    # Square to a branch (no pitch) the fingers close across the 26 mm pipe and nothing else:
    # 5 mm clear on each side (within the points' sampling, 1 mm).
    square = np.array([openings[n] for n in grasps if "pitch" not in n])
    assert np.all(np.abs(square - (26.0 + 2 * g.preshape_clearance_mm)) <= 1.0)
    # Pitched 30° along the branch, some grasps put a finger's far end into the other branch: no fit.
    pitched = [openings[n] for n in grasps if "pitch+30" in n or "pitch-30" in n]
    assert 0 < sum(o is None for o in pitched) < len(pitched)
    assert all(o is None or 35.0 <= o <= g.open_width_mm for o in openings.values())
    fully = grasp_openings(replace(g, preshape_clearance_mm=None), elbow, grasps)
    assert {o for o in fully.values() if o is not None} == {g.open_width_mm}
    assert [n for n, o in fully.items() if o is None] == [n for n, o in openings.items() if o is None]


def _flat_elbow_config(sim, clearance):
    cfg = sim.cell.config
    return replace(cfg, gripper=replace(cfg.gripper, preshape_clearance_mm=clearance), grasps=dict(cfg.grasps))


def _flat_elbow_between_neighbours(sim, gap_mm: float):
    """An elbow lying flat on the bin floor and, ``gap_mm`` from its pipes' sides, the scan of the
    parts packed round it: walls of points as tall as the pipe along every side of both branches."""
    cfg = sim.cell.config
    lo, hi = cfg.bin_bounds
    T_bo = np.eye(4)
    T_bo[:3, 3] = [(lo[0] + hi[0]) / 2 - 20.0, (lo[1] + hi[1]) / 2 - 20.0, lo[2] + 13.0]  # pipe axis 13 mm up
    r = 13.0 + gap_mm
    s = np.arange(-60.0, 60.0, 1.0)
    z = np.arange(0.0, 26.0, 2.0)
    walls = []
    for along, across in ((0, 1), (1, 0)):  # beside the branch along x, then beside the one along y
        for side in (-r, r):
            S, Z = np.meshgrid(s, z)
            p = np.zeros((S.size, 3))
            p[:, along] = S.ravel() + 20.0
            p[:, across] = side
            p[:, 2] = Z.ravel() - 13.0
            walls.append(p)
    pts = np.vstack(walls)
    model = np.asarray(sim.cell.config.model.points)
    keep = np.linalg.norm(pts[:, None, :2] - model[None, ::20, :2], axis=2).min(axis=1) > gap_mm - 0.5
    return T_bo, pts[keep] @ T_bo[:3, :3].T + T_bo[:3, 3]


def test_preshaped_fingers_pick_a_flat_elbow_that_open_fingers_cannot(sim):
    # The neighbours 18 mm off: the narrow fingers' outer faces 13 mm from the pipe's axis keep
    # more than the planner's 3 mm clearance against the scan from them.
    T_bo, scene = _flat_elbow_between_neighbours(sim, gap_mm=18.0)
    here = sim.robot_emulator.pose()
    narrow = _flat_elbow_config(sim, 5.0)
    assert narrow.scan_clearance_mm == 3.0
    wide = _flat_elbow_config(sim, None)
    with pytest.raises(NoGraspError):
        plan_grasp(wide, T_bo, scene, here)  # 50 mm apart the fingers land on the neighbours or the floor
    plan, hits = plan_grasp(narrow, T_bo, scene, here)
    assert plan.opening_mm == pytest.approx(narrow.openings([plan.grasp])[0])
    assert plan.opening_mm < 40.0 and hits <= narrow.max_collision_points
    for name in ("approach", "grasp", "lift"):
        assert bin_clash(narrow.gripper, plan.pose(name), narrow.bin_bounds, opening_mm=plan.opening_mm) is None


def test_a_gripper_that_cannot_be_set_to_a_width_plans_every_grasp_fully_open(sim):
    assert ModbusGripper.sets_width and not MelfaHandGripper.sets_width
    assert sim.cell.config.gripper.preshape_clearance_mm is not None  # the twin's gripper is a Modbus one
    cell = binpick.cell.Cell(
        sim.cell.config,
        robot=sim.cell.robot,
        motor=sim.cell.motor,
        gripper=MelfaHandGripper(sim.cell.robot),
        camera=sim.cell.camera,
    )
    assert cell.config.gripper.preshape_clearance_mm is None
    assert cell.config.openings_cpu_ms == 0.0
    openings = cell.config.openings(list(cell.config.grasps)[:50])
    assert set(openings[~np.isnan(openings)]) == {cell.config.gripper.open_width_mm}
    # Measured once: asked again, the openings are looked up, and the time spent stays put.
    spent = cell.config.openings_cpu_ms
    assert spent > 0.0
    assert np.array_equal(cell.config.openings(list(cell.config.grasps)[:50]), openings, equal_nan=True)
    assert cell.config.openings_cpu_ms == spent
    plan = SimpleNamespace(opening_mm=30.0)
    assert cell.finger_opening(plan) == cell.config.gripper.open_width_mm
    assert sim.cell.finger_opening(plan) == 30.0


def test_a_part_whose_turn_is_open_is_gripped_open_for_its_pin_at_any_turn():
    """A flange whose locating pin the scan did not show may lie at any turn about its axis: each
    grasp opens for the pin wherever it may be (swept_points), never less than for the turn located."""
    from binpick.cell.grasp import mesh_grasps, swept_points

    flange, g = binpick.parts.pinned_flange(), GripperGeometry()
    grasps = mesh_grasps(flange, g)
    swept = swept_points(flange)
    assert len(swept) > len(flange.points)
    here, anywhere = grasp_openings(g, flange, grasps), grasp_openings(g, flange, grasps, swept)
    wider = [anywhere[n] - here[n] for n in grasps if here[n] is not None and anywhere[n] is not None]
    assert min(wider) >= 0.0 and max(wider) > 5.0  # the pin turned into the fingers' slab reaches farther
    # A part without a continuous near axis is measured as it is.
    assert len(swept_points(binpick.parts.cut_plate())) == len(binpick.parts.cut_plate().points)


def _located(T_base_object):
    return located(T_base_object, SimpleNamespace(score=1.0, rmse=0.0, method="test", timings={}))


def _plan_on_the_part(sim):
    cfg = sim.cell.config
    T_bo = sim.pile.poses[0]
    plan, _ = plan_grasp(cfg, T_bo, np.zeros((0, 3)), sim.robot_emulator.pose())
    return T_bo, plan


def _shifted(plan, offset_mm: float, opening_mm: float):
    """``plan`` with the gripper moved ``offset_mm`` along its closing direction and opened ``opening_mm``."""
    d = plan.T_base_gripper[:3, 0] * offset_mm
    moved = []
    for n, T, lin in plan.waypoints:
        T = T.copy()
        if n in ("above", "approach", "grasp", "lift"):
            T[:3, 3] += d
        moved.append((n, T, lin))
    T_bg = plan.T_base_gripper.copy()
    T_bg[:3, 3] += d
    return replace(plan, waypoints=tuple(moved), T_base_flange=moved[2][1], T_base_gripper=T_bg, opening_mm=opening_mm)


def test_the_twin_holds_a_part_only_where_it_fits_between_the_fingers(sim):
    T_bo, plan = _plan_on_the_part(sim)
    width = 26.0
    # 4 mm off to one side with the fingers 28 mm apart: a finger comes down on the pipe (its
    # surface 17 mm from the TCP, the finger's inner face at 14 mm), well within the grip
    # tolerance of the grasp, so only the fingers' opening can tell.
    lo, hi = sim.cell.config.bin_bounds
    toward_centre = (lo + hi) / 2 - plan.T_base_gripper[:3, 3]
    landing = _shifted(plan, 4.0 if plan.T_base_gripper[:3, 0] @ toward_centre > 0 else -4.0, width + 2.0)
    record = sim.cell.pick(_located(T_bo), plan=landing)
    assert record.held is False and record.failure == "empty grip"
    assert len(sim.pile.ids) == 1
    sim.cell.robot.move_to(sim.cell.config.scan_poses[0])
    # The same grasp on the part's axis, the fingers opened as planned: held and lifted out.
    T_bo = sim.pile.poses[0]
    _, plan = _plan_on_the_part(sim)
    assert plan.opening_mm < sim.cell.config.gripper.open_width_mm
    opened = []
    gripper = sim.cell.gripper
    real_open, real_settle = gripper.open_for_grasp, gripper.settle
    # The fingers as the command goes out, and once the cell has waited for them (before the
    # arm goes down into the bin).
    gripper.open_for_grasp = lambda w, wait=True: (opened.append(sim.finger_opening_mm()), real_open(w, wait=wait))
    gripper.settle = lambda: (real_settle(), opened.append(sim.finger_opening_mm()))[0]
    try:
        record = sim.cell.pick(
            located(T_bo, SimpleNamespace(score=1.0, rmse=0.0, method="test", timings={})), plan=plan
        )
    finally:
        del gripper.open_for_grasp, gripper.settle
    assert record.held is True  # (the judge has no truth for a pose the test gives: only held or not)
    assert len(sim.pile.ids) == 0
    # The twin's fingers went from fully open (its 85 mm stroke, after the last pick) to the planned opening.
    assert opened[0] == pytest.approx(85.0, abs=0.5)
    assert opened[1] == pytest.approx(plan.opening_mm, abs=0.5)
