"""Planning the next pick during the carry (``CellConfig.plan_ahead``): the plan made on the last
scan, without the part in the gripper, is used only where the next scan confirms the part where
the plan has it and nothing in the plan's gripper; the planning thread cannot reach a device."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _cell_helpers import recording_tee_cell

from binpick.cell import PickRecord
from binpick.cell.ahead import PlanAhead, _confirm
from binpick.vision import Cloud


@pytest.fixture(scope="module")
def sim():
    """A pile of twelve tees on a cell that plans ahead; its messages in ``sim.lines``. The tests
    that take parts out by hand run first, the run of picks last. (Seed 6: its first pick leaves
    another part the planner can plan ahead on.)"""
    cell = recording_tee_cell(count=12, seed=6, frames=45, plan_ahead=True)
    yield cell
    cell.close()


def _nearest_part(sim, T: np.ndarray) -> int:
    d = np.linalg.norm(sim.pile.poses[:, :3, 3] - T[:3, 3], axis=1)
    return int(sim.pile.ids[int(np.argmin(d))])


def _planned_ahead(sim):
    """A part located and planned on a scan, "lifted" (taken out of the pile), and the pick
    after it planned ahead on that scan: (the planner, the lifted part's clean record, the part
    and plan made ahead). A scan whose rest shows no part the planner confirms (its noise hides
    one: NoObjectFound, as a cell would report it) is followed by another, at most three."""
    cell = sim.cell
    why = []
    for _ in range(3):
        scan = cell.scan()
        located, plan = cell.locate_and_plan(scan)
        ahead = PlanAhead(cell)
        ahead.start(located, [])
        ahead._thread.join()
        if "found" in ahead._done:
            break
        why.append(ahead._done.get("why"))
    assert "found" in ahead._done, why
    sim.pile.remove(_nearest_part(sim, located.T_base_object))
    record = PickRecord(index=1, success=True, T_base_object=located.T_base_object, held=True)
    return ahead, record, ahead._done["found"]


def test_the_plan_stands_on_a_new_scan_that_shows_its_part_where_it_was(sim):
    ahead, record, (planned, plan) = _planned_ahead(sim)
    times: dict = {}
    taken = ahead.take(record, sim.cell.scan(), times)
    assert taken is not None, [m for s, m in sim.lines if s == "plan"][-1]
    located, same_plan = taken
    assert same_plan is plan and times["ahead.used"] == 1.0
    # The pose is the new scan's verdict, judged against the truth when it is used.
    deg, mm = sim.model.pose_error(located.T_base_object, planned.T_base_object)
    assert deg < 0.5 and mm < 0.5
    assert located.truth is not None and located.truth.pick_grade
    assert len(located.indices) > 100 and located.scan is not planned.scan


def test_a_plan_whose_part_left_before_the_next_scan_is_dropped(sim):
    ahead, record, (planned, _) = _planned_ahead(sim)
    sim.pile.remove(_nearest_part(sim, planned.T_base_object))  # taken by hand during the carry
    sim.lines.clear()
    assert ahead.take(record, sim.cell.scan(), {}) is None
    assert any("dropped" in m and "does not show the part" in m for s, m in sim.lines), sim.lines


def test_a_plan_with_the_new_scans_points_in_its_gripper_is_dropped(sim):
    # A plan the new scan confirms as it stands (a part that leaned on the lifted one settles
    # elsewhere, and its plan is rightly dropped for that: then the next lift's plan).
    why = []
    for _ in range(3):
        ahead, record, (planned, plan) = _planned_ahead(sim)
        scan = sim.cell.scan()
        confirmed, reason = _confirm(sim.cell, planned, plan, scan)
        if confirmed is not None:
            break
        why.append(reason)
    assert confirmed is not None, why
    # Something came to lie where a finger goes down: points round the middle of the first finger.
    g = sim.cell.config.gripper
    T = plan.T_base_gripper
    finger = g.outline(plan.opening_mm)[:8].mean(axis=0)
    blob = T[:3, :3] @ finger + T[:3, 3] + np.random.default_rng(0).uniform(-1.0, 1.0, (40, 3))
    c = scan.cloud
    cloud = Cloud(
        points=np.vstack([c.points, blob]),
        frame=np.r_[c.frame, np.zeros(len(blob), dtype=c.frame.dtype)],
        pixels=np.vstack([c.pixels, np.zeros((len(blob), 2), dtype=c.pixels.dtype)]),
        angle=np.r_[c.angle, np.full(len(blob), c.angle[0])],
    )
    sim.lines.clear()
    assert ahead.take(record, replace(scan, cloud=cloud), {}) is None
    assert any("inside the plan's gripper" in m for s, m in sim.lines), sim.lines


def test_a_plan_after_a_pick_that_was_not_clean_is_dropped(sim):
    ahead, record, _ = _planned_ahead(sim)
    sim.lines.clear()
    assert ahead.take(replace(record, held=False, success=False), sim.cell.scan(), {}) is None
    assert any("was not clean" in m for s, m in sim.lines)


def test_the_planning_thread_has_no_device_and_no_truth(sim, monkeypatch):
    cell = sim.cell
    scan = cell.scan()
    located, _ = cell.locate_and_plan(scan)
    seen = {}

    def spy(ahead, picked, done):
        seen.update(robot=ahead.robot, motor=ahead.motor, gripper=ahead.gripper, camera=ahead.camera, truth=ahead.truth)
        done["why"] = "spied"

    monkeypatch.setattr("binpick.cell.ahead._plan", spy)
    ahead = PlanAhead(cell)
    ahead.start(located, [])
    ahead.discard()
    assert seen["motor"] is seen["gripper"] is seen["camera"] is seen["truth"] is None
    assert not hasattr(seen["robot"], "move_to")
    np.testing.assert_allclose(seen["robot"].read_pose(), cell.config.scan_poses[-1])


def test_a_run_picks_with_plans_made_during_the_carry_where_the_next_scan_confirms_them(sim):
    # Five picks: a plan made ahead is dropped where the new scan leaves its part's pose open or
    # does not show it where planned (two of these five), and used where it confirms it.
    report = sim.cell.run(5)
    assert all(r.success for r in report.records), [r.error for r in report.records]
    used = [r for r in report.records if r.timings.get("ahead.used")]
    assert used, [m for s, m in sim.lines if s == "plan"]
    for r in used:
        assert r.truth.pick_grade
        # No pose search in the cycle: its planning ran during the carry, inside the window it had.
        assert "cpu.pose" not in r.timings and r.timings["ahead.compute.pose"] > 0
        assert r.timings["ahead.window"] > 0 and r.timings["cpu.ahead_wait"] == 0.0
        assert r.timings["cpu.confirm"] > 0
    # validate's records say which cycles used a plan made ahead, and count its compute as binpick's.
    from binpick.sim.validate_workers import cycle_record

    rec = cycle_record(1, 12, used[0], cpu_s=None, wall_s=None)
    assert rec["planned_ahead"] is True and rec["binpick_cpu_s"] * 1e3 >= used[0].timings["ahead.compute.pose"]
    assert any(m.startswith("(planning ahead) ") for s, m in sim.lines if s == "locate")
    assert any("the plan made during the carry stands" in m for s, m in sim.lines)
    # The thread is gone when the run is over.
    assert sim.cell._ahead is None
