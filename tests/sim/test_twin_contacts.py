"""Collisions are failures: the simulated cell's physics records every contact of the gripper with
a part other than the one it holds (or with the bin) along each motion, and the pick loop turns
one into a ``collision`` failure that the table, picks.json, the failure picture and the exit
status all show."""

from __future__ import annotations

import io
import json
from dataclasses import replace

import numpy as np
import pytest

import binpick
from binpick import cli
from binpick._cli_parts import EXIT_COLLISION, collision_exit
from binpick.sim import SimulatedCell
from binpick.transforms import inverse, look_down

ESTIMATE = {"d_star": 12.0, "min_points": 500}


def _shifted(planned, gripper):
    """``locate_and_plan`` with its plan moved sideways by half the fingers' opening and half a
    finger, after every check passed: the finger comes down on the part it went for."""

    def shifted(*args, **kwargs):
        located, plan = planned(*args, **kwargs)
        d = np.eye(4)
        d[:3, 3] = (plan.opening_mm / 2 + gripper.finger_thickness_mm / 2) * plan.T_base_gripper[:3, 0]
        waypoints = tuple((n, d @ T, lin) for n, T, lin in plan.waypoints)
        return located, replace(
            plan, waypoints=waypoints, T_base_gripper=d @ plan.T_base_gripper, T_base_flange=d @ plan.T_base_flange
        )

    return shifted


def _centre(sim, k=0):
    T = sim.pile.poses[k]
    return T[:3, :3] @ sim.model.vertices.mean(axis=0) + T[:3, 3]


def _flange_for(sim, T_base_gripper):
    return T_base_gripper @ inverse(sim.gripper_geometry.T_flange_gripper)


def test_an_open_finger_coming_down_on_a_part_is_a_collision_a_push_is_not():
    tee = binpick.parts.tee(resolution=2.0)
    with SimulatedCell(tee, count=1, seed=4, frames=4, speed_scale=50.0) as sim:
        cell, g = sim.cell, sim.gripper_geometry
        pid = int(sim.pile.ids[0])
        c = _centre(sim)
        up = cell.config.limits.approach_height_mm + 20.0
        cell.gripper.open()
        above = look_down(c[0], c[1], up)
        cell.robot.move_to(above, linear=False)
        assert sim.take_collisions() == [], "the open gripper high above the part touches nothing"
        # The TCP half an opening and half a finger to the side: the +x finger comes down on the
        # part's centre, its tip at the centre's height.
        T_bg = above @ g.T_flange_gripper
        x = T_bg[:3, 0]
        off = g.open_width_mm / 2 + g.finger_thickness_mm / 2
        T_bg[:3, 3] = c - off * x - g.tip_depth_mm * T_bg[:3, 2]
        side = _flange_for(sim, T_bg)
        over_side = side.copy()
        over_side[2, 3] = up
        cell.robot.move_to(over_side, linear=True)
        assert sim.take_collisions() == []
        cell.robot.move_to(side, linear=True)
        touched = sim.take_collisions()
        assert [e["with"] for e in touched] == [f"part {pid}"], touched
        assert touched[0]["points"] > 0 and touched[0]["opening_mm"] > 40.0
        T_touch = np.asarray(touched[0]["T_base_gripper"])
        tip = T_touch[:3, 3] + g.tip_depth_mm * T_touch[:3, 2]
        assert tip[2] <= c[2] + 60.0, (tip, c)  # the first touch is on the way down, above the part
        cell.robot.move_to(over_side, linear=True)
        sim.take_collisions()
        # The closed, empty gripper sweeping through the part is a push (the physics moves the
        # part), not a collision.
        cell.gripper.close()
        cell.robot.move_to(above, linear=True)
        down = T_bg.copy()
        down[:3, 3] = c - g.tip_depth_mm * down[:3, 2]
        cell.robot.move_to(_flange_for(sim, down), linear=True)
        cell.robot.move_to(above, linear=True)
        assert sim.take_collisions() == []
        assert sim.pushes, "the closed gripper coming down on the part pushed it"
        assert sim.emulator_failures == []


@pytest.fixture(scope="module")
def collided():
    """A pick whose plan is shifted sideways by half the fingers' opening and half a finger, after
    every check passed: the finger comes down on the part it went for."""
    tee = binpick.parts.tee()
    with SimulatedCell(tee, count=3, seed=1, frames=60, estimate_options=ESTIMATE) as sim:
        cell = sim.cell
        cell.locate_and_plan = _shifted(cell.locate_and_plan, cell.config.gripper)
        report = cell.run(1)
        assert sim.emulator_failures == []
        yield sim, report


def test_a_pick_that_touches_a_part_fails_as_a_collision(collided):
    sim, report = collided
    (r,) = report.records
    assert r.failure == "collision" and not r.success, (r.failure, r.error)
    assert r.collisions and r.collisions[0]["with"].startswith("part "), r.collisions
    assert "the gripper touched part" in r.error
    assert report.failures_by_kind() == {"collision": 1}
    assert r.as_dict()["collisions"][0]["with"] == r.collisions[0]["with"]


def test_the_table_pictures_and_exit_status_show_the_collision(collided, tmp_path, capsys):
    sim, report = collided
    table = io.StringIO()
    cli._print_table(report, table)
    text = table.getvalue()
    assert "collision" in text.splitlines()[2], text
    assert "failures: 1 collision" in text
    written = cli._pictures(tmp_path, report, sim.model, sim.cell.config.bin_bounds)
    assert tmp_path / "failure_pick1.png" in written
    doc = json.loads((tmp_path / "picks.json").read_text())
    picks = doc["picks"] if isinstance(doc, dict) else doc
    assert picks[0]["failure"] == "collision" and picks[0]["collisions"], picks[0]
    assert collision_exit(report, "demo") == EXIT_COLLISION == 4
    assert "collided in pick 1" in capsys.readouterr().err


def test_binpick_pick_on_the_twin_records_the_collision_its_physics_saw(tmp_path, capsys, monkeypatch):
    """The commissioning case of issue 38: the twin saw the gripper touch a part while the pick
    report said nothing. `binpick pick` on the twin now asks the twin's ground truth (its camera
    socket's WORLD), and the touch is a collision in the table and picks.json, and exit 4."""
    from _twin import twin_process
    from binpick.cell import Cell

    planned = Cell.locate_and_plan
    monkeypatch.setattr(
        Cell, "locate_and_plan", lambda self, *a, **k: _shifted(planned.__get__(self), self.config.gripper)(*a, **k)
    )
    with twin_process(tmp_path / "twin", "--count", "3") as out:
        code = cli.main(["pick", str(out / "cell.toml"), "--picks", "1", "--out", str(tmp_path / "run")])
        printed = capsys.readouterr()
        world = json.loads((out / "world.json").read_text())
    assert code == EXIT_COLLISION, printed.out[-2000:] + printed.err[-2000:]
    picks = json.loads((tmp_path / "run" / "picks.json").read_text())["picks"]
    assert picks[0]["failure"] == "collision" and picks[0]["collisions"][0]["with"].startswith("part "), picks[0]
    assert "failures: 1 collision" in printed.out
    assert "collided in pick 1" in printed.err
    assert any(c["with"] == picks[0]["collisions"][0]["with"] for c in world["collisions"])
