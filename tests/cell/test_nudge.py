"""The nudge: at a dead end the closed gripper pushes a blocked part over, the physics moves it,
and the cell picks it; a nudge through the floor, into a wall or out of reach is refused with
nothing sent."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

import binpick
from binpick.cell import nudge
from binpick.cell.records import Skipped, cycle_stages_s
from binpick.cell.scene import near_part
from binpick.errors import SafetyError
from binpick.sim import SimulatedCell

#: Tee pile seed 1 of 9 parts (benches/bin_clearing.py): taken out in this order, the last part
#: left stands against the +y wall, where no square grasp within the 45° tool-tilt limit can
#: take it (a grasp from its upright branch's end can: the cell is given square grasps only).
DEAD_END_SEED, DEAD_END_COUNT, DEAD_END_REMOVED = 1, 9, (8, 7, 2, 0, 5, 3, 4, 6)


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee()


def _dead_end(tee, **kwargs):
    square = binpick.cell.branch_grasps(tee, end_pitches_deg=())
    sim = SimulatedCell(tee, count=DEAD_END_COUNT, seed=DEAD_END_SEED, frames=90, grasps=square, **kwargs)
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


def test_a_dead_end_is_nudged_and_the_blocked_part_picked(tee):
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
    assert record.success and record.truth.pick_grade, record.error
    assert len(sim.pushes) == 1, "the nudge's moves push as one continuous sweep"
    assert np.linalg.norm(record.T_base_object[:3, 3] - before[:3, 3]) > 10.0
    assert _lowest_tip_above_floor(sim.cell.config, record.nudges) > 0.0
    # The record is the whole cycle's: the look that found the dead end, the nudge (its planning
    # in binpick's compute, its motion in the physical time beside the scans and the pick), the
    # look after it.
    stages = cycle_stages_s(record.timings)
    assert record.looks == 1 + len(record.nudges)
    assert record.timings["cpu.nudge"] > 0.0 and stages["compute"] * 1e3 >= record.timings["cpu.nudge"]
    assert stages["other"] > 0.5, stages  # the push: down beside the part, across, up


def test_the_last_tee_standing_against_a_wall_is_found_though_a_flip_through_the_wall_screens_better(tee):
    # The dead end's tee stands against the +y wall, its stem hidden: many hypotheses screen onto
    # its flip, which the scan fits as well but which passes through the wall; the true pose
    # screens lower. The detector polishes a third pose at a place for another side of the part
    # (and no copy of a chosen pose): without it, 3 of 12 scans of this tee found it.
    sim = _dead_end(tee, look_again_poses=())
    with sim:
        (pid,) = sim.pile.ids.tolist()
        sim.cell.camera.seed = 0  # a scan of this tee on which the detector found nothing
        scan = sim.cell.scan()
        cfg = sim.cell.config
        (found,) = binpick.estimate_poses(scan.points, tee, bin=cfg.bin_bounds, **sim.cell.pose_options(scan))
    deg, mm = tee.pose_error(found.T_scene_model, sim.pile.pose(pid))
    assert deg < 2.0 and mm < 1.0 and found.confidence > 0.8, (deg, mm, found)


def _narrow_dead_end(tee, **overrides):
    """A lone tee the gripper cannot take (fingers opening 12 mm, narrower than any of its
    branches): every look is a dead end; the cell nudges it once. The run's record and the
    stages of its looks and nudge, in order."""
    lines = []
    square = binpick.cell.branch_grasps(tee, end_pitches_deg=())
    narrow = binpick.cell.GripperGeometry(open_width_mm=12.0)
    progress = lambda stage, msg: lines.append((stage, msg))  # noqa: E731
    sim = SimulatedCell(
        tee, count=1, seed=0, frames=36, grasps=square, gripper=narrow, max_nudges=1, progress=progress, **overrides
    )
    with sim:
        assert len(sim.cell.config.look_again_poses) == 4
        report = sim.cell.run(1)
        assert sim.emulator_failures == []
    (record,) = report.records
    assert record.failure == "no grasp" and len(record.nudges) == 1, report.stopped
    return record, [s for s, m in lines if s in ("look", "nudge") and not m.startswith("the ambiguous")]


def test_after_a_nudge_the_cell_looks_from_the_scan_pose_and_the_best_turned_view_only(tee):
    # Refused for its confidence (a min_confidence no pose reaches), a reason another view may
    # change: before the nudge the cell looks from the scan pose and from every turned view;
    # after it, from the scan pose and from the one turned view that best tells the part apart —
    # the others were just tried, and only the pushed part has moved.
    record, stages = _narrow_dead_end(tee, min_confidence=1.0)
    assert record.looks == 1 + 4 + 2, stages
    assert stages.index("nudge") == 4 and stages.count("look") == 4 + 1, stages


def test_a_part_refused_only_for_where_it_lies_is_nudged_without_looking_again(tee):
    # Decided and refused by every grasp for its tilt and width alone, with nothing else in the
    # bin: no view can change that, so the cell nudges it right after the first look (after the
    # nudge, a second look only where the scan pose's found nothing).
    record, stages = _narrow_dead_end(tee)
    assert stages[0] == "nudge" and record.looks == 2 + stages.count("look") <= 3, stages
    assert all(k.settled for k in record.skipped) and record.skipped, record.skipped


def test_a_nudge_through_the_floor_into_a_wall_or_out_of_reach_is_refused_with_nothing_sent(tee):
    sim = _dead_end(tee)
    with sim:
        cell, cfg, T = sim.cell, sim.cell.config, sim.pile.poses[0]
        sent = []
        move, close = cell.robot.move_to, cell.gripper.close
        cell.robot.move_to = lambda *a, **k: sent.append(("move", a)) or move(*a, **k)
        cell.gripper.close = lambda *a, **k: sent.append(("close", a)) or close(*a, **k)
        T_now, nothing = cell.robot.read_pose(), np.zeros((0, 3))
        plan = nudge.plan_nudge(cfg, T, nothing, T_now)
        assert nudge.check_nudge(cfg, list(plan.waypoints), T_now, nothing) is None
        # Fingertips 10 mm under the floor, the whole path 2 m away, the arm unable to reach.
        low = [(n, W if n == "above" else _lowered(W, 60.0), lin) for n, W, lin in plan.waypoints]
        assert "floor" in nudge.check_nudge(cfg, low, T_now, nothing)
        far = [(n, _shifted(W, 2000.0), lin) for n, W, lin in plan.waypoints]
        assert nudge.check_nudge(cfg, far, T_now, nothing) is not None
        # Scanned points of another part in the fingers' way down: refused.
        tips = (plan.waypoints[1][1] @ cfg.gripper.T_flange_gripper)[:3, 3]
        column = tips + np.array([[0.0, 0.0, z] for z in np.linspace(0.0, 40.0, 50)])
        assert "scanned points" in nudge.check_nudge(cfg, list(plan.waypoints), T_now, column)
        # The loop's entry point with every plan refused: None, and nothing sent.
        cell.config = replace(cfg, reachable=lambda T: False)
        skipped = [Skipped(T, "none of the grasps usable")]
        assert nudge.nudge_blocked(cell, skipped, SimpleNamespace(points=nothing)) is None
        with pytest.raises(SafetyError, match="reach"):
            nudge.plan_nudge(cell.config, T, nothing, T_now)
        assert sent == []


def _lowered(T, dz):
    T = T.copy()
    T[2, 3] -= dz
    return T


def _shifted(T, dx):
    T = T.copy()
    T[0, 3] += dx
    return T


def test_a_part_near_a_wall_is_pushed_off_it_from_the_gap_when_the_closed_fingers_fit(tee):
    # The tee lying flat, its footprint ``gap`` mm from the +y wall, halfway along the bin: the
    # push towards the bin's centre (-y) must start between the part and the wall. The closed
    # fingers (2 × 8 mm thick, 20 mm wide: 12.8 mm from the TCP to a corner) fit in 40 mm with
    # the 8 mm start gap (not with the 30 mm one); not in 3 mm.
    with SimulatedCell(tee, count=1, seed=0, frames=4) as sim:
        cfg = sim.cell.config
        lo, hi = cfg.bin_bounds
        verts = np.asarray(tee.vertices)
        T_now, nothing = sim.robot_emulator.pose(), np.zeros((0, 3))
        for gap in (40.0, 3.0):
            T = np.eye(4)
            T[:3, 3] = [
                (lo[0] + hi[0]) / 2 - (verts[:, 0].min() + verts[:, 0].max()) / 2,
                hi[1] - gap - verts[:, 1].max(),
                lo[2] - verts[:, 2].min(),
            ]
            try:
                plan = nudge.plan_nudge(cfg, T, nothing, T_now)
            except nudge.NudgeRefused:
                plan = None
            from_gap = plan is not None and plan.direction @ np.array([0.0, -1.0]) > 0.99
            if gap > 20.0:
                assert from_gap, plan and plan.heading_deg
                start = (plan.waypoints[1][1] @ cfg.gripper.T_flange_gripper)[:3, 3]
                assert verts[:, 1].max() + T[1, 3] < start[1] < hi[1]
                assert all(
                    binpick.cell.grasp.bin_clash(cfg.gripper, W, cfg.bin_bounds, opening_mm=0.0) is None
                    for _, W, _ in plan.waypoints
                )
            else:
                assert not from_gap, plan.heading_deg


def test_a_part_against_a_wall_leaning_away_from_it_is_pushed_over_towards_the_wall(tee):
    # The tee on its run along the -y wall (5 mm off it), its branch turned 20° from straight up:
    # leaning away from the wall, every approach to the branch within the 45° tilt limit comes
    # over the wall, and no push can start between the part and the wall; pushed towards the wall
    # it leans the other way. Leaning towards the wall, or lying flat, or away from the wall, it
    # is pushed as before (towards the bin's centre first).
    with SimulatedCell(tee, count=1, seed=0, frames=4) as sim:
        cfg = sim.cell.config
        lo, hi = cfg.bin_bounds
        T_now, nothing = sim.robot_emulator.pose(), np.zeros((0, 3))
        verts = np.asarray(tee.vertices)

        def against_wall(lean_deg: float, gap: float = 5.0) -> np.ndarray:
            # object x (the run) along base -x, object y (the branch) up, turned about the run.
            a = np.radians(lean_deg)
            T = np.eye(4)
            T[:3, :3] = np.array([[-1.0, 0.0, 0.0], [0.0, np.sin(a), np.cos(a)], [0.0, np.cos(a), -np.sin(a)]])
            placed = verts @ T[:3, :3].T
            T[:3, 3] = [(lo[0] + hi[0]) / 2, lo[1] + gap - placed[:, 1].min(), lo[2] - placed[:, 2].min()]
            return T

        def heading(T: np.ndarray) -> float:
            return nudge.plan_nudge(cfg, T, nothing, T_now).heading_deg

        assert heading(against_wall(20.0)) == pytest.approx(-90.0, abs=1.0)  # leaning away: over towards the wall
        # Pushed that way and still blocked, it is pushed another way next (along the wall).
        first = nudge.plan_nudge(cfg, against_wall(20.0), nothing, T_now)
        moved = against_wall(20.0)
        moved[0, 3] += 10.0
        again = nudge.plan_nudge(cfg, moved, nothing, T_now, tried=[first])
        assert abs(math.remainder(again.heading_deg + 90.0, 360.0)) >= nudge.RETRY_APART_DEG
        elsewhere = moved.copy()
        elsewhere[0, 3] -= tee.diameter  # another part, or this one pushed far: the first choice again
        assert nudge.plan_nudge(cfg, elsewhere, nothing, T_now, tried=[first]).heading_deg == pytest.approx(
            -90.0, abs=1.0
        )
        # Pushed each way in turn and found each time where it was (the pushes moved it less than
        # UNMOVED_MM), no way is tried twice: the ways run out, and the refusal says why.
        made = [first]
        for _ in range(nudge.NUDGE_DIRECTIONS + 1):
            try:
                made.append(nudge.plan_nudge(cfg, against_wall(20.0), nothing, T_now, tried=made))
            except nudge.NudgeRefused as exc:
                assert "pushed that way already, it did not move" in str(exc)
                break
        else:
            raise AssertionError("the same ways were tried again")
        headings = [p.heading_deg for p in made]
        assert all(
            abs(math.remainder(a - b, 360.0)) >= nudge.RETRY_APART_DEG
            for i, a in enumerate(headings)
            for b in headings[:i]
        )
        assert abs(heading(against_wall(-20.0)) + 90.0) > 30.0  # leaning towards the wall already
        assert abs(heading(against_wall(20.0, gap=60.0)) + 90.0) > 30.0  # room to push it off the wall
        flat = np.eye(4)
        flat[:3, 3] = [(lo[0] + hi[0]) / 2, lo[1] + 5.0 - verts[:, 1].min(), lo[2] - verts[:, 2].min()]
        assert abs(heading(flat) + 90.0) > 30.0  # lying flat: nothing to push over


# --------------------------------------------------------------------------- freeing pushes


def _raft_config(x_span=(250.0, 550.0)):
    """A plain shaft (Ø24 × 150 mm) and a cell over a bin ``x_span`` long and 200 mm wide."""
    from _files import small_calibration
    from binpick.cell import CellConfig
    from binpick.devices import CellLimits
    from binpick.transforms import look_down

    shaft = binpick.parts.keyed_shaft(diameter=24.0, length=150.0, feature=False, spacing=2.0)
    centre = sum(x_span) / 2
    return CellConfig(
        calibration=small_calibration(),
        model=shaft,
        bin_bounds=((x_span[0], -100.0, 0.0), (x_span[1], 100.0, 80.0)),
        scan_poses=(look_down(centre, 0.0, 450.0),),
        drop_pose=look_down(centre, -250.0, 350.0),
        frames=4,
        limits=CellLimits(workspace_min_mm=(100.0, -400.0, 0.0), workspace_max_mm=(700.0, 400.0, 700.0)),
    )


def _raft(cfg, xs, ys):
    """Shafts lying on the floor along x, their centres at (x, y) — touching where the y are a
    diameter apart — and what a scan from above sees of them (their upper halves)."""
    from binpick.transforms import rotation_about

    poses = []
    for x, y in zip(xs, ys):
        T = np.eye(4)
        T[:3, :3] = rotation_about((0.0, 1.0, 0.0), math.pi / 2)  # the model's z (the axis) along x
        T[:3, 3] = (x, y, 12.0)
        poses.append(T)
    pts = np.asarray(cfg.model.points)
    scene = np.concatenate([pts @ T[:3, :3].T + T[:3, 3] for T in poses])
    return poses, scene[scene[:, 2] > 11.0]


def test_a_shaft_in_a_row_of_its_kind_is_slid_out_along_its_axis_until_a_grasp_passes():
    from binpick.cell.grasp import NoGraspError, plan_grasp

    cfg = _raft_config()
    poses, scene = _raft(cfg, (400.0, 400.0, 400.0), (-24.0, 0.0, 24.0))
    here = cfg.scan_poses[0]
    for T in poses:  # three shafts touching side by side: no finger fits beside any of them
        with pytest.raises(NoGraspError, match="collision"):
            plan_grasp(cfg, T, _others(scene, cfg, T), here)
    plan = nudge.plan_separating(cfg, poses[1], scene, here)
    assert plan is not None
    # Along the shaft's axis (a push across would shove the row), far enough that a grasp clears
    # the neighbours' ends, within the safety module's push limit.
    assert abs(plan.direction[0]) > 0.98, plan.direction
    moved = plan.T_after[:3, 3] - poses[1][:3, 3]
    assert np.allclose(moved[1:], 0.0) and 20.0 <= abs(moved[0]) <= cfg.limits.max_push_mm
    np.testing.assert_allclose(plan.T_after[:3, :3], poses[1][:3, :3])
    after, _ = plan_grasp(cfg, plan.T_after, _others(scene, cfg, poses[1]), here)
    assert after.grasp == plan.grasp_after
    # The closed fingers go down beyond the shaft's end, clear of it and of the bin, and push
    # along its axis: every move passes the checks the cell runs.
    assert nudge.check_nudge(cfg, list(plan.waypoints), here, _others(scene, cfg, poses[1])) is None
    tip_x = [T[0, 3] for name, T, _ in plan.waypoints if name.startswith(("descend", "push"))]
    end_x = poses[1][0, 3] - math.copysign(75.0, plan.direction[0])
    assert all((x - end_x) * plan.direction[0] < 0 for x in tip_x[:1]), (tip_x, end_x)
    assert plan.as_dict()["frees"]["grasp"] == plan.grasp_after


def test_no_freeing_push_for_a_row_with_no_room_to_slide_a_standing_part_or_one_on_others():
    # The bin 170 mm long: shafts of 150 mm side by side cannot slide out past each other's
    # ends, and pushing across would shove the row: no freeing push.
    cfg = _raft_config((315.0, 485.0))
    poses, scene = _raft(cfg, (400.0, 400.0, 400.0), (-24.0, 0.0, 24.0))
    assert nudge.plan_separating(cfg, poses[1], scene, cfg.scan_poses[0]) is None
    # Nor is a shaft standing on its end, alone in the open (pushed, it falls over, not slides),
    # nor one lying on top of others.
    cfg = _raft_config()
    standing = np.eye(4)
    standing[:3, 3] = (400.0, 0.0, 75.0)
    pts = np.asarray(cfg.model.points) + standing[:3, 3]
    assert nudge.plan_separating(cfg, standing, pts, cfg.scan_poses[0]) is None
    (lying,), top = _raft(cfg, (400.0,), (0.0,))
    assert nudge.plan_separating(cfg, lying, top, cfg.scan_poses[0]) is not None
    on_top = lying.copy()
    on_top[2, 3] += 20.0
    assert nudge.plan_separating(cfg, on_top, top + (0.0, 0.0, 20.0), cfg.scan_poses[0]) is None


def _others(scene, cfg, T):
    """The scene without the points of the part at ``T`` (as the nudge and the cell leave them out)."""
    own = near_part(scene, np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3])
    return scene[~own]


def test_a_shaft_lying_against_a_wall_is_never_pushed_into_it():
    # Lying along the -x wall, 2 mm from it: every push that could start goes towards the wall
    # or along it, and a part lying on the floor slides as far as it is pushed — into the wall,
    # the arm would crush it there (the physics throws it out of the bin). Along the wall, it
    # has less room than a push is worth.
    cfg = _raft_config()
    T = np.eye(4)
    T[:3, :3] = binpick.transforms.rotation_about((1.0, 0.0, 0.0), math.pi / 2)  # the axis along y
    T[:3, 3] = (250.0 + 12.0 + 2.0, 0.0, 12.0)
    pts = np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3]
    with pytest.raises(nudge.NudgeRefused, match="pushed into the bin's wall"):
        nudge.plan_nudge(cfg, T, pts[pts[:, 2] > 11.0], cfg.scan_poses[0])
    # 40 mm from the wall, it may be pushed towards it, no nearer than the margin.
    T[0, 3] = 250.0 + 12.0 + 40.0
    footprint = (np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3])[:, :2]
    plan = nudge.plan_nudge(cfg, T, np.zeros((0, 3)), cfg.scan_poses[0])
    touch = float(((footprint - T[:2, 3]) @ plan.direction).min()) - nudge._closed_reach(cfg)
    shove = float((plan.waypoints[-2][1][:2, 3] - T[:2, 3]) @ plan.direction) - touch
    assert nudge.SEPARATE_STEP_MM <= shove <= nudge._room(cfg, footprint, plan.direction) - nudge.WALL_MARGIN_MM + 1e-6


def test_a_shaft_located_again_with_its_keyway_turned_has_not_moved():
    # A look after a push places a hidden keyway anywhere round the shaft: a turn about its axis,
    # or its flip end for end, is no move; a slide of 10 mm, or a turn of its axis by 10°, is.
    cfg = replace(_raft_config(), model=binpick.parts.keyed_shaft(diameter=24.0, length=150.0, spacing=2.0))
    (T,), _ = _raft(cfg, (400.0,), (0.0,))
    along = np.asarray(T[:3, :3])[:, 2]  # the shaft's axis, base frame

    def turned(axis, deg):
        R = np.eye(4)
        R[:3, :3] = binpick.transforms.rotation_about(axis, math.radians(deg))
        return T @ R  # about the model's own axes, through its centre

    # (The axis found in the mesh is off the model's z by a hair: a tenth of a millimetre.)
    assert nudge._moved(cfg, T, turned((0.0, 0.0, 1.0), 90.0)) < 0.5
    assert nudge._moved(cfg, T, turned((1.0, 0.0, 0.0), 180.0)) < 0.5
    slid = T.copy()
    slid[:3, 3] += 10.0 * along
    assert nudge._moved(cfg, T, slid) == pytest.approx(10.0, abs=0.01)
    assert nudge._moved(cfg, T, turned((1.0, 0.0, 0.0), 10.0)) > nudge.UNMOVED_MM


def test_a_part_a_push_leaves_out_of_the_bin_is_a_collision_of_that_cycle():
    with SimulatedCell(binpick.parts.keyed_shaft(), count=2, seed=0, frames=4) as sim:
        pid, other = sim.pile.ids.tolist()
        path = np.stack([np.eye(4), np.eye(4)])
        # Through the floor, over the bin: out of it too, once.
        sunk = sim.pile.pose(other).copy()
        sunk[2, 3] = -5000.0
        pose = sim.pile.pose
        sim.pile.pose = lambda i: sunk if i == other else pose(i)
        sim._out_of_bin([other], path, 0.0)
        (event,) = sim.take_collisions()
        assert event["with"].startswith(f"part {other}, pushed out of the bin")
        assert sim.lost == [other] and other not in sim.pile.ids
        sim.lost.clear()
        sim.pile.pose = pose
        sim._out_of_bin([pid], path, 0.0)  # where the pile left it: in the bin
        assert sim.take_collisions() == []
        lifted = sim.pile.pose(pid).copy()
        lifted[2, 3] += 80.0 + 2 * sim.model.diameter  # jammed up a wall, above the rim
        sim.pile.pose = lambda i: lifted if i == pid else None
        sim._out_of_bin([pid], path, 0.0)
        (event,) = sim.take_collisions()
        assert event["with"].startswith(f"part {pid}, pushed out of the bin")
        assert sim.lost == [] and pid in sim.pile.ids  # above its own bin: it falls back in
        thrown = lifted.copy()
        thrown[:3, 3] = (400.0, 4000.0, -5000.0)  # over a wall and falling: the physics threw it out
        sim.pile.pose = lambda i: thrown if i == pid else None
        sim._out_of_bin([pid], path, 0.0)
        (event,) = sim.take_collisions()
        assert "(400, 4000, -5000) mm" in event["with"]
        assert sim.lost == [pid] and pid not in sim.pile.ids and sim.parts_left() == 0
        sim._out_of_bin([pid], path, 0.0)  # recorded once, not again with the next push
        assert sim.take_collisions() == []


# --------------------------------------------------------------------------- pushes the physics predicts


def _against_wall(cfg, gap_mm=1.0):
    """The plain shaft lying along x against the bin's −y wall, ``gap_mm`` from it (x from 335 to
    485 mm: its ends 85 and 65 mm from the end walls), and what a scan from above sees of it (its
    upper half) with the floor around it."""
    T = np.eye(4)
    T[:3, :3] = binpick.transforms.rotation_about((0.0, 1.0, 0.0), math.pi / 2)  # the axis along x
    T[:3, 3] = (410.0, -100.0 + 12.0 + gap_mm, 12.0)
    pts = np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3]
    xs, ys = np.meshgrid(np.arange(252.0, 549.0, 4.0), np.arange(-98.0, 99.0, 4.0))
    floor = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    floor = floor[~near_part(floor, pts, 3.0)]
    return T, np.concatenate([pts[pts[:, 2] > 11.0], floor])


def test_a_shaft_lying_along_a_wall_is_freed_by_a_push_the_physics_predicts():
    from binpick.cell.grasp import NoGraspError, plan_grasp
    from binpick.sim import Bin, Pile, sim_gripper

    # The simulated cell's gripper: fingers long enough for the palm to clear the rim beside a wall.
    cfg = replace(_raft_config(), gripper=sim_gripper())
    T, scene = _against_wall(cfg)
    here = cfg.scan_poses[0]
    others = _others(scene, cfg, T)
    # No grasp: every finger on the wall's side meets the wall; no straight push frees it (into
    # the wall is refused, along it leaves it there).
    with pytest.raises(NoGraspError):
        plan_grasp(cfg, T, others, here)
    assert nudge.plan_separating(cfg, T, scene, here) is None
    plan = nudge.plan_predicted(cfg, T, scene, here)
    assert plan is not None
    assert nudge.check_nudge(cfg, list(plan.waypoints), here, others) is None
    footprint = (np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3])[:, :2]
    assert nudge._room(cfg, footprint, plan.direction) > nudge.WALL_MARGIN_MM  # never into the wall
    # Run in the physics at a friction between the two the plan was predicted at (the twin's):
    # the shaft comes off the wall and a grasp passes where it comes to rest.
    lo, hi = cfg.bin_bounds
    pile = Pile.placed(cfg.model, T[None], bin=Bin(size=tuple(hi - lo), center=tuple((lo[:2] + hi[:2]) / 2)))
    tool = np.array([T_f @ cfg.gripper.T_flange_gripper for _, T_f, _ in plan.waypoints])
    pile.push(cfg.gripper.boxes(0.0), tool, cfg.limits.max_linear_speed_mm_s)
    T_rest = pile.poses[0]
    verts = np.asarray(cfg.model.vertices) @ T_rest[:3, :3].T + T_rest[:3, 3]
    assert verts[:, 1].max() - 8.0 > -100.0 + 24.0, verts[:, 1].max()  # off the wall: more than a finger there
    after, _ = plan_grasp(cfg, T_rest, np.zeros((0, 3)), here)
    assert after.grasp


def test_no_predicted_push_for_a_part_a_grasp_passes_for_a_standing_part_or_with_no_room_in_the_bin():
    from binpick.sim import sim_gripper

    # Off the wall, a grasp passes where the shaft lies: whatever held it back (its pose's
    # doubt), no push mends it.
    cfg = replace(_raft_config(), gripper=sim_gripper())
    T, scene = _against_wall(cfg, gap_mm=40.0)
    assert nudge.plan_predicted(cfg, T, scene, cfg.scan_poses[0]) is None
    assert nudge.plan_predicted(cfg, *_against_wall(cfg), cfg.scan_poses[0]) is not None
    cfg = _raft_config()
    standing = np.eye(4)
    standing[:3, 3] = (400.0, 0.0, 75.0)
    pts = np.asarray(cfg.model.points) + standing[:3, 3]
    assert nudge.plan_predicted(cfg, standing, pts, cfg.scan_poses[0]) is None
    # A bin 160 mm long and 40 mm wide holds the 150 mm shaft with nowhere to go.
    cfg = _raft_config((320.0, 480.0))
    cfg = replace(cfg, bin_bounds=((320.0, -20.0, 0.0), (480.0, 20.0, 80.0)))
    T = np.eye(4)
    T[:3, :3] = binpick.transforms.rotation_about((0.0, 1.0, 0.0), math.pi / 2)
    T[:3, 3] = (400.0, 0.0, 12.0)
    pts = np.asarray(cfg.model.points) @ T[:3, :3].T + T[:3, 3]
    assert nudge.plan_predicted(cfg, T, pts[pts[:, 2] > 11.0], cfg.scan_poses[0], budget=8) is None


def test_the_path_map_keeps_a_moved_footprint_in_the_bin_and_off_other_parts():
    cfg = _raft_config()
    # A neighbour's point 50 mm up the bin, and one against the far (+x) wall.
    other = np.array([[400.0, 50.0, 10.0], [550.0, 0.0, 10.0]])
    path = nudge._PathMap(cfg, other)
    footprint = np.array([[400.0, 0.0], [410.0, 0.0]])
    assert path.clear(footprint, np.array([0.0, 20.0]))
    assert not path.clear(footprint, np.array([0.0, 50.0]))  # onto the neighbour
    assert not path.clear(footprint, np.array([160.0, 0.0]))  # through the +x wall
    # One offset per point (a part turning as it moves): the far point swings into the wall.
    assert not path.clear(footprint, np.array([[0.0, 0.0], [0.0, -120.0]]))
    # A part located a hair past the −x wall may stay there: its points lie in the edge cells
    # there, not in the far wall's (wrapped round the map).
    assert path.clear(np.array([[249.5, 0.0]]), np.zeros(2))


def test_with_no_nudge_to_make_the_cell_takes_the_views_it_left_out_before_it_stops(tee):
    # An arm that reaches nothing below 300 mm: every grasp of the lone tee is refused for reach,
    # a reason no view changes, so the first look goes straight to the nudge; no nudge reaches
    # either, and the cell then looks from the scan pose and every turned view before it stops.
    lines = []
    high = lambda T: bool(T[2, 3] > 300.0)  # noqa: E731
    progress = lambda stage, msg: lines.append((stage, msg))  # noqa: E731
    with SimulatedCell(tee, count=1, seed=0, frames=36, reachable=high, progress=progress) as sim:
        turned = len(sim.cell.config.look_again_poses)
        report = sim.cell.run(1)
        assert sim.emulator_failures == []
    (record,) = report.records
    assert turned == 4 and record.failure == "no grasp" and not record.nudges, report.stopped
    assert report.stopped.endswith("(no nudge passes the checks)"), report.stopped
    assert record.looks == 1 + 1 + turned and sum(s == "look" for s, _ in lines) == turned, lines
    assert all(k.settled and "reach" in k.refused for k in record.skipped), record.skipped
