"""A scan in which no pose is confirmed is not an empty bin when something stands in it: the cell
looks from every view before it says the bin is empty (the scans here are the simulator's)."""

from __future__ import annotations

from types import MappingProxyType, SimpleNamespace

import numpy as np
import pytest

import binpick
from binpick.cell.records import ScanResult, Skipped
from binpick.cell.views import settled, something_in_bin, worth_another_look
from binpick.sim import SimulatedCell


@pytest.fixture(scope="module")
def sim():
    with SimulatedCell(binpick.parts.tee(), count=1, seed=0, frames=45) as s:
        yield s


def _scan(points: np.ndarray) -> ScanResult:
    return ScanResult(
        cloud=SimpleNamespace(points=points),
        angles=np.zeros(0),
        T_base_flanges=np.zeros((0, 4, 4)),
        frames=MappingProxyType({}),
        timings=MappingProxyType({}),
    )


def test_a_scan_of_the_part_shows_something_in_the_bin_and_its_empty_floor_does_not(sim):
    scan = sim.cell.scan()
    assert something_in_bin(sim.cell.config, scan)
    lo, hi = sim.cell.config.bin_bounds
    floor = scan.points[scan.points[:, 2] < lo[2] + 1.0]  # the floor as scanned, noise and all
    assert len(floor) > 1000 and not something_in_bin(sim.cell.config, _scan(floor))
    # The walls as scanned are not something in the bin either.
    walls = scan.points[(scan.points[:, 0] > hi[0] - 1.0) | (scan.points[:, 0] < lo[0] + 1.0)]
    assert not something_in_bin(sim.cell.config, _scan(np.vstack([floor, walls])))
    # A speck (a few points, 2 mm across) above the floor is noise, not a part.
    speck = np.array([400.0, 0.0, 10.0]) + np.random.default_rng(0).uniform(-1, 1, (20, 3))
    assert not something_in_bin(sim.cell.config, _scan(np.vstack([floor, speck])))


def test_another_look_is_worth_it_only_for_a_refusal_a_view_can_change_or_a_part_not_located(sim):
    cfg = sim.cell.config
    scan = sim.cell.scan()
    (found,) = binpick.estimate_poses(scan.points, cfg.model, bin=cfg.bin_bounds, **sim.cell.pose_options(scan))
    T = np.asarray(found.T_scene_model)
    assert cfg.model.pose_error(T, sim.pile.pose(0))[0] < 2.0 and not found.ambiguous
    where = {"tilt": np.eye(4)[None], "bin": np.eye(4)[None]}
    assert settled(cfg, found, where)
    # A refusal of its confidence or its ambiguity, or none recorded, may change with a view.
    assert not settled(cfg, found, {**where, "ambiguous": np.eye(4)[None]})
    assert not settled(cfg, found, {})
    assert not settled(cfg, SimpleNamespace(confidence=0.99, ambiguous=True, free_axis=None), where)
    assert not settled(cfg, SimpleNamespace(confidence=cfg.min_confidence / 2, ambiguous=False, free_axis=None), where)
    part = Skipped(T, "none of the grasps usable", refused=where, settled=True)
    assert not worth_another_look(cfg, scan, [part])
    assert worth_another_look(cfg, scan, [Skipped(T, "low confidence", settled=False)])
    # A pose 60° off leaves the part's points unexplained: the part may be found from elsewhere.
    turned = T.copy()
    turned[:3, :3] = T[:3, :3] @ binpick.transforms.rotation_about(np.array([0.0, 0.0, 1.0]), np.pi / 3)
    assert worth_another_look(cfg, scan, [Skipped(turned, "none of the grasps usable", refused=where, settled=True)])
    # So is something in the bin no located part explains (a second part, here a copy moved 80 mm).
    other = scan.points[np.linalg.norm(scan.points[:, :2] - T[:2, 3], axis=1) < 30.0] + [0.0, 80.0, 0.0]
    assert worth_another_look(cfg, _scan(np.vstack([scan.points, other])), [part])
