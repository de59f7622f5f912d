"""The pick loop end to end on the simulated cell: a physics pile, the robot, laser motor and
gripper emulators on real ptys, the real drivers, the renderer, extraction and pose estimation."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from binpick.cell import CellConfig, check_static_poses
from binpick.cell.records import cycle_stages_s
from binpick.errors import SafetyError
from binpick.sim import SimulatedCell, sim_limits

# The estimator's default segmentation distance follows the along-line spacing; with 60 frames the
# lines lie ~5 mm apart, so the tests give d* and the smallest region explicitly.
ESTIMATE = {"d_star": 12.0, "min_points": 500}


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee()


def test_simulated_pick_removes_the_located_part(tee):
    with SimulatedCell(tee, count=4, seed=1, frames=60, estimate_options=ESTIMATE) as sim:
        before = set(int(i) for i in sim.pile.ids)
        report = sim.cell.run(3)
        assert sim.emulator_failures == []
        after = set(int(i) for i in sim.pile.ids)
        # The planner's checks and the physics agree: no pick touched anything but its part.
        assert sim.collisions == [], sim.collisions
        # The hardware clock: each frame the camera gave took a frame period at 15 fps.
        assert sim.clock.by_device["camera"] == pytest.approx(sim.cell.camera._frame / sim.layout.camera_fps)
        hardware = sim.clock.now()
    # Every cycle's physical time is its stages', the hardware's on the clock (which holds them all).
    cycles = [r for r in report.records if not r.bin_empty]
    for r in cycles:
        stages = cycle_stages_s(r.timings)
        assert r.cycle_time_s == pytest.approx(sum(stages.values()))
        assert stages["scan.sweep"] >= 60 / 15.0 and stages["motion"] > 1.0 and stages["compute"] > 0.0
    assert sum(r.cycle_time_s - cycle_stages_s(r.timings)["compute"] for r in cycles) <= hardware + 1e-9
    picked = [r for r in report.records if r.success]
    assert picked, f"no pick succeeded: {[r.error for r in report.records]}"
    for r in picked:
        assert r.truth is not None and r.truth.pick_grade
        assert r.truth.rotation_error_deg < 5.0 and r.truth.translation_error_mm < 3.0
        assert r.picked_instance == r.truth.instance
        assert r.picked_instance in before and r.picked_instance not in after
        assert r.held is True
    assert len(before) - len(after) >= len(picked)


def test_a_drop_pose_outside_the_workspace_is_refused_before_any_byte_is_sent(tee):
    sim = SimulatedCell(tee, count=1, seed=0, frames=4)
    limits = sim_limits(sim.layout)
    outside = np.eye(4)
    outside[:3, :3] = np.diag([1.0, -1.0, -1.0])
    outside[:3, 3] = (limits.workspace_max_mm[0] + 200.0, 0.0, 400.0)
    bad = SimulatedCell(tee, count=1, seed=0, frames=4, drop_pose=outside)
    try:
        with pytest.raises(SafetyError, match="drop_pose"):
            bad.start()
        for emu in (bad.robot_emulator, bad.motor_emulator, bad.gripper_emulator):
            assert emu is not None and emu.requests == [], f"{emu.device} received {emu.requests[:3]}"
    finally:
        bad.close()


def test_config_checks_scan_pose_below_the_approach_height(tee):
    sim = SimulatedCell(tee, count=1, seed=0, frames=4)
    limits = sim_limits(sim.layout)
    low = sim.layout.T_base_flange.copy()
    low[2, 3] = limits.approach_height_mm - 10.0
    config = CellConfig(
        calibration=sim.layout.calibration(),
        model=tee,
        bin_bounds=sim.layout.bin.bounds,
        scan_poses=(low,),
        drop_pose=sim.drop_pose,
        limits=limits,
    )
    with pytest.raises(SafetyError, match="approach height"):
        check_static_poses(config)


def test_a_part_passed_over_earlier_in_the_run_is_tried_after_the_others(tee):
    with SimulatedCell(tee, count=6, seed=1, frames=60, estimate_options=ESTIMATE) as sim:
        cell = sim.cell
        scan = cell.scan()
        first, _ = cell.locate_and_plan(scan)
        # Where a part was passed over earlier in the run (Cell.run records each cycle's), a part
        # found there again is planned only after the others of its search.
        cell._passed_over = [first.T_base_object]
        other, plan = cell.locate_and_plan(scan)
        assert np.linalg.norm(other.T_base_object[:3, 3] - first.T_base_object[:3, 3]) > tee.diameter / 4
        assert plan is not None
        cell._passed_over = []
        again, _ = cell.locate_and_plan(scan)
        np.testing.assert_allclose(again.T_base_object, first.T_base_object)
