"""A scan in which no pose is confirmed is not an empty bin when something stands in it: the cell
looks from every view before it says the bin is empty (the scans here are the simulator's)."""

from __future__ import annotations

from types import MappingProxyType, SimpleNamespace

import numpy as np
import pytest

import binpick
from binpick.cell.records import ScanResult
from binpick.cell.views import something_in_bin
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
