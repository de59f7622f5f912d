"""What lies between two laser lines is not seen: the planner lets each scene point stand for its
surface out to the next line either side, so that a finger does not come down on an edge the
lines missed (issue 38: the physics saw a finger corner touch a neighbour the planner counted 0
points of). Nor does a scan see under a surface: each point stands for what lies below it, so
that a tilted finger does not slide in under a neighbour's seen top onto its hidden side. And the
fingers close: a neighbour in the gap between the part and an open finger is in their way."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import binpick
from binpick.cell.grasp import GRAZE_MM, _unseen, plan_grasp
from binpick.cell.records import line_step
from binpick.cell.scene import planner_scene
from binpick.models import nearest_distances
from binpick.sim import SimulatedCell
from binpick.transforms import rotation_about


def _lines(step, n=10, x0=300.0):
    """A swept scan of a flat floor: line k at x = x0 + k·step, points 0.5 mm apart along y."""
    ys = np.arange(-40.0, 40.0, 0.5)
    pts = np.concatenate([np.column_stack([np.full_like(ys, x0 + k * step), ys, np.zeros_like(ys)]) for k in range(n)])
    frame = np.repeat(np.arange(n), len(ys))
    return SimpleNamespace(points=pts, frame=frame)


def test_the_line_step_is_the_spacing_of_the_lines_along_the_sweep():
    step = line_step(_lines(4.0))
    assert step == pytest.approx([4.0, 0.0, 0.0], abs=1e-9)
    # A depth shot (one frame) or a cloud without lines has no step.
    one = _lines(4.0, n=1)
    assert line_step(one) is None
    assert line_step(SimpleNamespace(points=np.zeros((0, 3)), frame=np.zeros(0))) is None


def test_each_point_stands_for_its_surface_up_to_the_next_line():
    p = np.array([[0.0, 0.0, 10.0]])
    spread = _unseen(p, np.array([4.0, 0.0, 0.0]))
    assert spread[:, 0].max() == pytest.approx(4.0 - GRAZE_MM)
    assert spread[:, 0].min() == pytest.approx(-(4.0 - GRAZE_MM))
    assert np.diff(np.sort(spread[:, 0])).max() <= 2.0 + 1e-9
    assert (spread[:, 1:] == p[0, 1:]).all()
    assert _unseen(p, None) is p


@pytest.fixture(scope="module")
def lone_tee():
    """A cell with one tee in its bin: (its config, the arm's pose, the tee's true pose)."""
    with SimulatedCell(binpick.parts.tee(resolution=2.0), count=1, seed=0, frames=4) as sim:
        yield sim.cell.config, sim.robot_emulator.pose(), sim.pile.poses[0]


def test_a_finger_is_not_planned_onto_an_edge_between_two_lines(lone_tee):
    cfg, here, T = lone_tee
    plan, hits = plan_grasp(cfg, T, np.zeros((0, 3)), here)
    assert hits == 0
    # A neighbour's edge the lines missed: its last seen line 2 mm beyond the clearance the
    # planner keeps round the finger (along the sweep, the gripper's closing axis), the next
    # line 4 mm on, past the finger's far side, seeing nothing of it.
    g, T_bg = cfg.gripper, plan.T_base_gripper
    outer = plan.opening_mm / 2 + g.finger_thickness_mm
    z = g.tip_depth_mm - 15.0
    out = outer + cfg.scan_clearance_mm + 2.0
    edge_g = np.array([[out, y, z] for y in np.linspace(-5.0, 5.0, 11)])
    assert not g.occupied(edge_g, plan.opening_mm, grow_mm=cfg.scan_clearance_mm).any()
    edge = edge_g @ T_bg[:3, :3].T + T_bg[:3, 3]
    step = -4.0 * T_bg[:3, 0]  # toward the finger
    step[2] = 0.0
    same, _ = plan_grasp(cfg, T, edge, here)
    assert same.grasp == plan.grasp, "seen as points only, the edge is outside the finger's clearance"
    moved, _ = plan_grasp(cfg, T, edge, here, unseen_step=step)
    assert moved.grasp != plan.grasp, "the edge may stand in the finger's way: another grasp"


def test_a_finger_is_not_planned_in_under_a_neighbours_seen_surface(lone_tee):
    # Session 34's one tee collision: a neighbour leaning on the part, its top seen and its side
    # below hidden; a tilted finger slid in under the seen top, clear of every seen point, and met
    # the hidden side. What lies under a seen surface is not known to be free.
    cfg, here, T = lone_tee
    plan, hits = plan_grasp(cfg, T, np.zeros((0, 3)), here, lambda T_bg: -T_bg[2, 2] < np.cos(np.radians(25.0)))
    assert hits == 0 and plan.tilt_deg >= 25.0
    g, T_bg = cfg.gripper, plan.T_base_gripper
    grow = cfg.scan_clearance_mm
    # Over each finger's middle, straight up (base z) to the first height clear of the grown
    # gripper: the finger that leans out from under it is under a ledge there.
    ledges = []
    for side in (-1.0, 1.0):
        middle = np.array([side * (plan.opening_mm / 2 + g.finger_thickness_mm / 2), 0.0, g.tip_depth_mm - 20.0])
        start = middle @ T_bg[:3, :3].T + T_bg[:3, 3]
        for rise in np.arange(1.0, 120.0, 0.5):
            p = start + [0.0, 0.0, rise]
            if not g.occupied((p - T_bg[:3, 3]) @ T_bg[:3, :3], plan.opening_mm, grow_mm=grow + 1.0):
                ledges.append((rise, p))
                break
    rise, top = min(ledges, key=lambda item: item[0])
    assert rise < 60.0, "the tilted gripper leaves a finger under open air"
    # A neighbour's seen top there: a patch of points 1 mm apart, more than the cell tolerates,
    # none of them inside the (grown) gripper at the grasp.
    patch = top + np.array([[dx, dy, 0.0] for dx in np.arange(-2.0, 2.5, 1.0) for dy in np.arange(-2.0, 2.5, 1.0)])
    patch = patch[~g.occupied((patch - T_bg[:3, 3]) @ T_bg[:3, :3], plan.opening_mm, grow_mm=grow)]
    assert len(patch) > cfg.max_collision_points
    assert g.hits(patch, T_bg[None], [plan.opening_mm], grow_mm=grow)[0] == 0
    # Standing for what lies below them, the points are in the finger's way: that grasp is
    # refused, and the one planned instead does not reach under the patch.
    with pytest.raises(binpick.cell.NoGraspError, match="collision"):
        plan_grasp(cfg, T, patch, here, lambda T_bg: np.allclose(T_bg, plan.T_base_gripper))
    other, hits = plan_grasp(cfg, T, patch, here)
    assert not np.allclose(other.T_base_gripper, plan.T_base_gripper)
    floor = float(cfg.bin_bounds[0][2])
    columns = np.concatenate([patch - [0.0, 0.0, d] for d in np.arange(0.0, patch[:, 2].max() - floor, 0.5)])
    columns = columns[columns[:, 2] >= floor]
    inside = g.hits(columns, other.T_base_gripper[None], [other.opening_mm], grow_mm=grow)[0]
    assert inside <= cfg.max_collision_points


@pytest.fixture(scope="module")
def tilted_flange():
    """A cell for the pinned flange (its gripper opens a few mm wider than the part at each
    grasp), and the flange tilted 15° above the middle of its bin: (the config, the arm's pose,
    the flange's pose, its points at that pose)."""
    model = binpick.parts.built_in("pinned_flange")
    with SimulatedCell(model, count=1, seed=0, frames=4) as sim:
        cfg, here = sim.cell.config, sim.robot_emulator.pose()
    lo, hi = (np.asarray(b, dtype=np.float64) for b in cfg.bin_bounds)
    T = np.eye(4)
    T[:3, :3] = rotation_about([1.0, 0.0, 0.0], np.radians(15.0))
    T[:3, 3] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 40.0]
    return cfg, here, T, np.asarray(model.points) @ T[:3, :3].T + T[:3, 3]


def test_the_fingers_do_not_close_onto_a_neighbour_in_the_gap(tilted_flange):
    # The fingers come down open, clear of everything, then close onto the part: a neighbour
    # lying in the gap between the part and an open finger is met as they close.
    cfg, here, T, _ = tilted_flange
    g = cfg.gripper
    plan, hits = plan_grasp(cfg, T, np.zeros((0, 3)), here)
    assert hits == 0
    width = float(cfg.grip_widths([plan.grasp])[0])
    assert plan.opening_mm - width >= 2 * 2.0 + 2 * GRAZE_MM, "a gap to put the neighbour in"
    # A patch of a neighbour's seen edge, 1 mm out from where the +x finger closes on the part
    # (a fifth of the way to the open finger, outside the grown open finger), over the finger's
    # width, 5 mm short of its tip; more points than the cell tolerates.
    x = width / 2 + 1.0
    assert x < plan.opening_mm / 2 - cfg.scan_clearance_mm
    local = np.array([[x, y, g.tip_depth_mm - 5.0] for y in np.linspace(-8.0, 8.0, 2 * cfg.max_collision_points)])
    T_bg = plan.T_base_gripper
    patch = local @ T_bg[:3, :3].T + T_bg[:3, 3]
    grow = cfg.scan_clearance_mm
    assert not g.occupied(local, plan.opening_mm, grow_mm=grow).any(), "clear of the open fingers"
    assert g.occupied(local, width, grow_mm=grow).all(), "in the closed finger's way"
    counted = dict(grow_mm=grow, back_mm=float(cfg.approach_distance_mm), floor_z_mm=float(cfg.bin_bounds[0][2]))
    assert g.hits(patch, T_bg[None], [plan.opening_mm], **counted)[0] == 0
    assert g.hits(patch, T_bg[None], [plan.opening_mm], closing_mm=[width], **counted)[0] == len(patch)
    # That grasp is refused; the one planned instead does not close onto the patch.
    with pytest.raises(binpick.cell.NoGraspError, match="collision"):
        plan_grasp(cfg, T, patch, here, lambda T_bg_: np.allclose(T_bg_, T_bg, atol=1e-6))
    other, hits = plan_grasp(cfg, T, patch, here)
    assert hits <= cfg.max_collision_points
    assert not np.allclose(other.T_base_gripper, T_bg, atol=1e-6)
    other_width = float(cfg.grip_widths([other.grasp])[0])
    back = (patch - other.T_base_gripper[:3, 3]) @ other.T_base_gripper[:3, :3]
    met = np.zeros(len(patch), dtype=bool)
    for w in np.linspace(other_width, other.opening_mm, 30):
        met |= g.occupied(back, w, grow_mm=grow)
    assert met.sum() <= cfg.max_collision_points


def test_the_parts_own_surface_left_out_of_its_indices_does_not_stand_for_a_column_through_it(lone_tee):
    # A ring-screw heap had no usable grasp: the segmentation left a few points of each ring's
    # surface out of its indices, and each stood in the planner's scene for a column down through
    # the ring, which a tilted finger closing on the ring met. The planner's scene leaves out
    # every scanned point on the located part's surface; a neighbour's points stay.
    cfg, here, T = lone_tee
    tilted = lambda T_bg: -T_bg[2, 2] < np.cos(np.radians(25.0))  # noqa: E731
    plan, hits = plan_grasp(cfg, T, np.zeros((0, 3)), here, tilted)
    assert hits == 0
    part = np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3]
    seen = part[part[:, 2] >= part[:, 2].max() - 20.0]  # its upper side, as a scan sees it
    seen = seen + np.random.default_rng(3).normal(0.0, 0.3, seen.shape)
    with pytest.raises(binpick.cell.NoGraspError):
        plan_grasp(cfg, T, seen, here, tilted)
    # A neighbour's patch 10 mm beside the part's highest point, out of the gripper's way.
    lo = part[np.argmax(part[:, 2])]
    side = np.array([-T[1, 0], T[0, 0], 0.0]) / max(np.hypot(T[0, 0], T[1, 0]), 1e-9)
    neighbour = lo + 60.0 * side + np.array([[dx, dy, 0.0] for dx in (-1.0, 0.0, 1.0) for dy in (-1.0, 0.0, 1.0)])
    assert nearest_distances(neighbour, part).min() > 10.0
    scan = np.concatenate([neighbour, seen])
    scene = planner_scene(scan, [], T, cfg.model)
    assert len(scene) == len(neighbour) and (scene == neighbour).all()
    same, _ = plan_grasp(cfg, T, scene, here, tilted)
    assert same.grasp == plan.grasp
